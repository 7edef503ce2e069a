"""Test helpers of the diagnosis and behaviour (stage 4) tests: captures simulated by our own simulator with a
known material and optionally a known extra force (fast, exact physics): a sheet hanging from two corners attached
to a swaying sphere 'body', written in the capture layout (ground-truth meshes only)."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parents[1] / "physics"))

from physics_helpers import sheet, uv_sphere  # noqa: E402

from gg_core.diagnosis.confirm import CandidateParams, Trial  # noqa: E402
from gg_core.diagnosis.folds import Fold  # noqa: E402
from gg_core.diagnosis.library import apply_region  # noqa: E402
from gg_core.geometry.meshio import write_obj, write_ply  # noqa: E402
from gg_core.physics.cloth import Cloth  # noqa: E402
from gg_core.physics.fitting import Observed  # noqa: E402
from gg_core.physics.forces import DEFAULT_TERMS, make_terms  # noqa: E402
from gg_core.physics.material import Material  # noqa: E402
from gg_core.physics.simulator import ClothState, ImplicitSimulator  # noqa: E402
from gg_core.storage import write_json  # noqa: E402

MATERIAL = {"density": 0.3, "mu": 40000.0, "lam": 20000.0, "bending": 4e-4}
SEQUENCES = {"a": (0.08, 1.3), "b": (0.12, 0.9), "c": (0.1, 1.1)}   # sway amplitude (m), frequency (Hz)


def hanging_sheet() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertices, faces, pinned): a 0.3 m sheet in the XY plane, its two top corners pinned."""
    v, f = sheet(6, 6, 0.3, 0.3)
    v = v[:, [0, 2, 1]] + [0.0, 0.7, 0.0]
    top = np.flatnonzero(np.isclose(v[:, 1], v[:, 1].max()))
    pinned = np.zeros(len(v), bool)
    pinned[[top[0], top[-1]]] = True
    return v, f, pinned


def side_strip(v: np.ndarray) -> np.ndarray:
    """[V] bool: the hanging sheet's two vertex columns at largest x, where tests hide a seam-like region change."""
    return np.isclose(v[:, 0], v[:, 0].max()) | np.isclose(v[:, 0], np.sort(np.unique(v[:, 0]))[-2])


def sheet_simulator(v: np.ndarray, f: np.ndarray, pinned: np.ndarray) -> ImplicitSimulator:
    """The hanging sheet's simulator: MATERIAL, gravity, stretching and bending only."""
    return ImplicitSimulator(Cloth(v, f, pinned=pinned, material=Material.uniform(len(v), **MATERIAL)),
                             terms=make_terms(["gravity", "stretching", "bending"]))


def swaying(sim: ImplicitSimulator, v: np.ndarray) -> list[Observed]:
    """Two 14-frame recordings of `sim` from rest at `v`, its pinned corners swaying sideways (8 and 12 cm)."""
    sequences = []
    for k, amp in enumerate((0.08, 0.12)):
        shift = np.zeros((14, 3))
        shift[:, 0] = amp * np.sin(2 * np.pi * 1.2 * np.arange(14) / 30)
        traj = sim.rollout(ClothState(v.copy(), np.zeros_like(v)), None, n_frames=14,
                           pin_frames=v[None] + shift[:, None])
        sequences.append(Observed(f"s{k}", traj, None, 30.0))
    return sequences


def shrunk_strip(scale: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[Observed], ImplicitSimulator]:
    """(vertices, pinned, side_strip, the swaying recordings of the hanging sheet with the strip's rest lengths
    scaled by `scale`, the unchanged simulator): a seam-like hidden rest-length change."""
    v, f, pinned = hanging_sheet()
    strip = side_strip(v)
    truth = sheet_simulator(v, f, pinned)
    apply_region(truth.cloth, strip.astype(np.float64), {"rest": float(np.log(scale))})
    truth.refresh()
    return v, pinned, strip, swaying(truth, v), sheet_simulator(v, f, pinned)


def write_sim_capture(root: Path, extra: dict[str, dict] | None = None, n_frames: int = 16,
                      region: tuple[np.ndarray, dict[str, float]] | None = None, uniform_mass: bool = False) -> Path:
    """Sequences a, b (train) and c (held out) of the sheet simulated with the default model (its air damping
    included) plus `extra`, and a `region` [V] of it changed by log-scales (library.apply_region); `uniform_mass`:
    every vertex the same mass, as Blender's cloth (the sheet's border then weighs twice its share, corners more)."""
    extra = extra or {}
    bv, bf = uv_sphere(0.1, 12, 24, center=(0.0, 1.0, 0.0))
    v, f, pinned = hanging_sheet()
    cloth = Cloth(v, f, pinned=pinned, material=Material.uniform(len(v), **MATERIAL), uniform_mass=uniform_mass)
    if region is not None:
        apply_region(cloth, *region)
    terms = make_terms(["gravity", "stretching", "bending", "mass_damping"] + list(extra), extra)
    for name, (amp, freq) in SEQUENCES.items():
        t = np.arange(n_frames) / 30
        shift = np.zeros((n_frames, 3))
        shift[:, 0] = amp * np.sin(2 * np.pi * freq * t)
        shift[:, 2] = 0.5 * amp * (1 - np.cos(2 * np.pi * freq * t))
        body = bv[None] + shift[:, None]
        traj = ImplicitSimulator(cloth, terms=terms).rollout(ClothState(v.copy(), np.zeros_like(v)), None,
                                                            n_frames=n_frames, pin_frames=v[None] + shift[:, None])
        (root / name).mkdir(parents=True)
        (root / name / "cameras.json").write_text("{}")
        for k in range(n_frames):
            write_ply(root / name / "gt" / "garment" / f"{k:06d}.ply", traj[k], f)
            write_ply(root / name / "body" / f"{k:06d}.ply", body[k], bf)
    write_json(root / "truth.json", {"split": {"train_sequences": ["a", "b"], "heldout_sequences": ["c"]}})
    return root


# the truth.json fields of a Blender synth capture that re-simulating it reads (gg_core/diagnosis/resimulated.py)
BLENDER_TRUTH = {"preset": {"fps": 30},
                 "material": {"blender_cloth": {"mass": 0.3, "tension_stiffness": 15.0, "compression_stiffness": 15.0,
                                                "shear_stiffness": 5.0, "bending_stiffness": 0.5},
                              "blender_body_collision": {"cloth_friction": 5.0}, "gravity": [0.0, -9.81, 0.0]}}


def write_blender_layout_capture(root: Path) -> Path:
    """The hanging sheet's capture (write_sim_capture, 6 frames) in the Blender synth's layout: its template and
    regions ('patch' and 'side_seam': the lower half) and the truth fields of BLENDER_TRUTH."""
    write_sim_capture(root, n_frames=6)
    v, f, pinned = hanging_sheet()
    write_obj(root / "gt" / "template.obj", v, f)
    low = (v[:, 1] < np.median(v[:, 1])).astype(np.float64)
    np.savez(root / "gt" / "regions.npz", patch=low, side_seam=low)
    truth = json.loads((root / "truth.json").read_text())
    truth.update(BLENDER_TRUTH, garment={"pinned_vertices": np.flatnonzero(pinned).tolist()})
    (root / "truth.json").write_text(json.dumps(truth))
    return root


def fold(held: str, ref: tuple[float, float], **trials: tuple[float, float]) -> Fold:
    """A fold judged against (held-out, training) rollout errors `ref`, with trials name=(held-out, training)."""
    return Fold(["a", "b"], [held], Trial([], ref[0], 1.0, ref[1]),
                {n: Trial([n], h, 1.0, t) for n, (h, t) in trials.items()})


def hanging(tilt: float) -> ImplicitSimulator:
    """A sheet pinned along one edge, falling under gravity tilted sideways by `tilt` m/s^2."""
    v, f = sheet(6, 6, 0.3, 0.3)
    pinned = np.abs(v[:, 2] + 0.15) < 1e-9
    terms = make_terms([*DEFAULT_TERMS, "gravity_offset"], {"gravity_offset": {"delta_g": (tilt, 0.0, 0.0)}})
    return ImplicitSimulator(Cloth(v, f, pinned=pinned), terms=terms)


def stiff_half(bending_log: float, region_range: dict[str, tuple[float, float]] | None = None
               ) -> tuple[ImplicitSimulator, CandidateParams]:
    """The hanging sheet (no tilt) with its free half's bending scaled by exp(bending_log), as a region candidate's
    trial holds it (within `region_range`, where given)."""
    sim = hanging(0.0)
    region = (sim.cloth.template[:, 2] > 0.0).astype(np.float64)
    params = CandidateParams(sim.cloth, sim, ("collision.margin",), region, {"bending": bending_log},
                             region_range=region_range)
    params.apply(sim.cloth)
    sim.refresh()
    return sim, params


def fall(truth: ImplicitSimulator) -> tuple[Observed, np.ndarray]:
    """12 frames of `truth`'s sheet falling from rest (no body), and its pinned vertices."""
    rest = truth.cloth.template
    return (Observed("fall", truth.rollout(ClothState(rest.copy(), np.zeros_like(rest)), None, 12), None, 30.0),
            truth.cloth.pinned)
