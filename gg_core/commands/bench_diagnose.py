"""`gg bench diagnose`: does the diagnosis name hidden physics it never saw, and say "none" when there is none?

For each effect, strength and seed, a small ground-truth-only capture is generated with Blender's cloth (cached:
reruns reuse captures and finished diagnoses), the diagnosis runs on it (optionally with spatially correlated
noise), and the answer is scored against truth.json, which the diagnosis never reads: the named class
(equivalences of gg_core/diagnosis/library.py), parameter errors where our parameter and Blender's mean the
same thing, and held-out gains. The baseline every gain is measured against is the global-parameter simulator of
the same run; "true effect" is the same simulator given the true effect's term (on the true region for region
effects), refitted the same way, which gives the share of the reachable gain the diagnosis closed (all of it, by
construction, where the diagnosis named that term), in every fold of the cross-validation as well: a recording
that barely shows the effect even to the true term caps the mean gain over the folds whatever the diagnosis
names (session 30). On captures of our own simulator the "true model" is also rolled out: the capture's own
material, terms and hidden effect, from the diagnosis's rest state at its substeps, which nothing fitted: the gain
a diagnosis knowing the physics could reach from that rest state.

Two sizes need no simulator of ours (gg_core/metrics/motion.py): the effect's `signal` (how differently its
capture moves from the same seed's capture with nothing hidden) and its `step change` (how much that difference
changes when both are simulated with twice Blender's steps per frame). Measured on the skirt (session 18, seed 1):
Blender's own motion moves 6.8-11.2 mm RMS per sequence between 5 and 10 steps per frame, and 5.6-9.9 mm more at
20 and again at 40, while gravity x 1.0001 moves it 0.03-0.45 mm: the trajectories depend on the step size, not
chaotically on any perturbation. Hidden friction changes the motion by 6 mm, and by 7 mm more between 5 and 10
steps (cosine 0.14-0.70 between the two changes); hidden air damping by 17 mm, and 8-12 mm between the steps
(cosine 0.78-0.88). An effect whose step change is as large as its signal is as much the reference's numerics
as physics. More steps help some effects (`--cloth-steps`; session 29, seeds 1-2): the stiff patch's step change
is 0.86-0.99 of its signal at 5 steps and 0.57-0.58 at 20 (against 40), hidden friction's 1.17 / 1.12 / 0.96 at
5 / 10 / 20 (seed 1): friction stays the reference's numerics. At 20 steps the effects named at 5 also move less
with the step (gravity 0.46 -> 0.28 of the signal, wind 0.64 -> 0.41) and gain more held-out, so 20 is the default.

With `--truth-simulator ours` the captures' garments are moved by our own simulator instead (the same garment,
bodies and pins as the seed's Blender capture with nothing hidden; gg_core/diagnosis/resimulated.py): the
well-specified check, where what the diagnosis's baseline lacks is the hidden effect alone and not Blender's cloth.

Prints a confusion table on stderr and ONE JSON line on stdout.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..cli import add_vertex_mass_option
from ..diagnosis.blender_units import offset_tilt, truth_parameters, wind_push
from ..diagnosis.report_regions import candidate_regions
from ..storage import exclusive

if TYPE_CHECKING:
    from ..stages.diagnose import DiagnoseRequest

HELP = "missing-physics diagnosis on synthetic captures with hidden effects: confusion table, errors, gains"

EFFECTS = ("none", "wind", "air_drag", "friction", "shrink", "stiff_patch", "gravity")
# effect parameter -> (reference value, default value): strength s sets reference + s (default - reference)
STRENGTH = {"wind": {"strength": (0.0, 1000.0)}, "air_drag": {"air_damping": (1.0, 10.0)},
            "friction": {"friction": (5.0, 60.0)}, "shrink": {"factor": (0.0, 0.15)},
            "stiff_patch": {"factor": (1.0, 30.0)}, "gravity": {"scale": (1.0, 1.25), "tilt_deg": (0.0, 12.0)}}
# Blender's cloth steps per frame in the captures. Its own default Quality Steps (5) leaves the stiff patch's effect
# as much its step size as physics (module docstring); captures at that count keep the unsuffixed names of the
# caches of sessions 1-29, all others end in _q<steps>.
CLOTH_STEPS = 20
BLENDER_DEFAULT_STEPS = 5
# the library candidate that models each class (the "true effect" simulator)
CLASS_CANDIDATE = {"wind": "wind", "linear_damping": "mass_damping", "friction": "body_friction",
                   "rest_length": "rest_length_region", "region_stiffness": "region_stiffness",
                   "gravity": "gravity_offset"}


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--effects", nargs="+", default=list(EFFECTS), choices=EFFECTS, help="hidden effects")
    parser.add_argument("--strengths", nargs="+", type=float, default=[1.0],
                        help="effect strength relative to gg synth's default (0 = the reference physics)")
    parser.add_argument("--seeds", nargs="+", type=int, default=[1, 2], help="capture seeds (motions, looks)")
    parser.add_argument("--noise-mm", nargs="+", type=float, default=[0.0],
                        help="spatially correlated noise levels (mm) added to the ground-truth meshes")
    parser.add_argument("--cache", type=Path, default=Path("/work/data/bench_diagnose"),
                        help="folder for generated captures and diagnosis projects (reused across runs)")
    parser.add_argument("--frames", type=int, default=24, help="recorded frames per sequence")
    parser.add_argument("--vertices", type=int, default=600, help="garment template vertex count")
    parser.add_argument("--garment", default="skirt", help="garment template of gg_core.synth.garments")
    parser.add_argument("--bootstrap", type=int, default=100, help="block-bootstrap replicates of each diagnosis")
    parser.add_argument("--truth-simulator", choices=("blender", "ours"), default="blender",
                        help="what moves the captures' garments: Blender's cloth, or our own simulator on the same "
                             "bodies and pins (the well-specified check, gg_core/diagnosis/resimulated.py)")
    parser.add_argument("--rest-given", action="store_true",
                        help="give each diagnosis the garment's unloaded template as its rest mesh (gg diagnose "
                             "--rest-mesh), as a user with the sewing pattern could; default: the first frame")
    add_vertex_mass_option(parser, "; a user knowing the data came from Blender's cloth could give uniform. "
                                   "Projects then end in _um")
    parser.add_argument("--cloth-steps", type=int, default=CLOTH_STEPS,
                        help="Blender's cloth steps per frame (Quality Steps) of the captures; the step change is "
                             "measured against twice as many. Captures at other than Blender's own default (5) are "
                             "cached under names ending in _q<steps>")
    parser.add_argument("--fit-horizon", type=int, default=3,
                        help="frames each fitted observed state is predicted ahead (gg diagnose --fit-horizon)")


def preset(frames: int, vertices: int, cloth_steps: int = CLOTH_STEPS):
    from ..synth.presets import Preset

    return Preset("bench_diagnose", camera_rows=((4, 8.0),), height=64, n_sequences=3, n_frames=frames,
                  settle_frames=14, garment_vertices=vertices, samples=1, denoise=False, cloth_quality=cloth_steps,
                  collision_quality=2, self_collision=False, motions=("walk", "torso_twist", "arm_swing"))


def case_name(args: argparse.Namespace, effect: str, strength: float, seed: int) -> str:
    """The cached capture of one benchmark case; the effects' reference capture is ("none", 0). Captures of our
    simulator (--truth-simulator ours) are named with an `ours_` prefix, those at other than Blender's own default
    steps per frame (5, not the benchmark's) with a `_q<steps>` suffix."""
    prefix = "ours_" if args.truth_simulator == "ours" else ""
    suffix = "" if args.cloth_steps == BLENDER_DEFAULT_STEPS else f"_q{args.cloth_steps}"
    return f"{prefix}{args.garment}_{effect}_s{strength:g}_seed{seed}{suffix}"


def capture_of(args: argparse.Namespace, name: str, seed: int, effect: str = "none", params: Sequence[str] = (),
               quality_factor: int = 1) -> Path:
    """The cached ground-truth capture `name` (generated on first use; `quality_factor` multiplies the cloth
    solver's steps per frame)."""
    from ..synth.generate import SynthRequest, generate

    capture = args.cache / name
    with exclusive(args.cache / f".{name}.lock"):     # runs sharing the cache generate each capture once
        if (capture / "truth.json").is_file():
            return capture
        if args.truth_simulator == "ours":
            from ..diagnosis.resimulated import resimulate
            from ..stages.behavior import hand_mask
            from ..stages.diagnose import DiagnoseRequest

            blender = argparse.Namespace(**{**vars(args), "truth_simulator": "blender"})
            reference = capture_of(blender, case_name(blender, "none", 0.0, seed), seed)
            resimulate(reference, capture, effect, list(params), hand_mask,
                       substeps=2 * DiagnoseRequest.substeps * quality_factor)
        else:
            steps = args.cloth_steps * quality_factor
            generate(SynthRequest(preset=preset(args.frames, args.vertices, steps), out=capture, seed=seed,
                                  garment=args.garment, effect=effect, effect_params=list(params), render=False,
                                  progress="none"))
    return capture


def effect_sizes_of(args: argparse.Namespace, name: str, seed: int, effect: str, params: Sequence[str]
                    ) -> tuple[float, float]:
    """(signal, step change) in metres of the case capture `name` (metrics.motion.effect_sizes), against the same
    seed's capture with nothing hidden, the finer step from captures simulated with twice the steps per frame."""
    from ..metrics.motion import effect_sizes

    none = case_name(args, "none", 0.0, seed)
    return effect_sizes(capture_of(args, name, seed, effect, params), capture_of(args, none, seed),
                        capture_of(args, f"{name}_steps_x2", seed, effect, params, quality_factor=2),
                        capture_of(args, f"{none}_steps_x2", seed, quality_factor=2))


def reference_divergence_of(args: argparse.Namespace, name: str, seed: int, effect: str, params: Sequence[str]
                            ) -> dict[str, float]:
    """metrics.motion.reference_divergence of the case capture `name` against its twin simulated with twice the
    steps per frame: per recording, how far the reference's own numerics move the motion a rollout is scored on."""
    from ..metrics.motion import reference_divergence

    return reference_divergence(capture_of(args, name, seed, effect, params),
                                capture_of(args, f"{name}_steps_x2", seed, effect, params, quality_factor=2))


def effect_params(effect: str, strength: float) -> list[str]:
    return [f"{k}={ref + strength * (default - ref):g}" for k, (ref, default) in STRENGTH.get(effect, {}).items()]


def parameter_errors(truth: dict[str, object], values: dict[str, object] | None) -> dict[str, float]:
    """Relative error of every comparable parameter (vector norm for vectors; for scale factors, of the change
    from 1); empty where nothing was refitted."""
    out: dict[str, float] = {}
    values = scored_values(values or {})
    for key, true in truth.items():
        if key not in values:
            continue
        ours = np.asarray(values[key], np.float64)
        true_v = np.asarray(true, np.float64)
        if key.startswith("region."):
            ours, true_v = ours - 1.0, true_v - 1.0
        out[key] = float(np.linalg.norm(ours - true_v) / max(np.linalg.norm(true_v), 1e-12))
    return out


def scored_values(values: dict[str, object]) -> dict[str, object]:
    """Refitted `values` with what the truth is scored in added: the gravity offset's tilt, the wind's push."""
    out = dict(values)
    if "gravity_offset.delta_g" in out:
        out["gravity.tilt"] = offset_tilt(out["gravity_offset.delta_g"])
    if (push := wind_push(out)) is not None:
        out["wind.push"] = push
    return out


def identified_truth(truth: dict[str, object], values: dict[str, object] | None, ranges: dict[str, dict] | None
                     ) -> dict[str, bool]:
    """For each comparable true parameter: whether it lies in the range the recordings leave open around the
    delivered value (identify.profiles' range_factors on the parameter it is scored from; an open end at the
    profile's last factor: beyond it the recordings were not probed; norms of vectors, whose direction the
    profiles do not vary). Empty without a final fit."""
    if not values or not ranges:
        return {}
    delivered = scored_values(values)
    out: dict[str, bool] = {}
    for name, profile in ranges.items():
        low, high = profile["range_factors"]

        def scored_at(factor: float) -> dict[str, object]:
            return scored_values({**values, name: (np.asarray(values[name], np.float64) * factor).tolist()})

        moved = scored_at(2.0)
        for key, true in truth.items():
            if key not in delivered or np.allclose(moved[key], delivered[key]):
                continue        # not scored from this parameter
            ends = [np.linalg.norm(scored_at(f if f is not None else grid_end)[key])
                    for f, grid_end in ((low, profile["factors"][0]), (high, profile["factors"][-1]))]
            out[key] = bool(min(ends) <= np.linalg.norm(np.asarray(true, np.float64)) <= max(ends))
    return out


def parameter_error(truth: dict[str, object], values: dict[str, object] | None) -> float | None:
    """The largest relative error over the comparable parameters (parameter_errors): a stiff patch counts as
    refitted only if both its stretch and its bending scale are right."""
    errors = parameter_errors(truth, values)
    return max(errors.values()) if errors else None


def region_overlap(report: dict, name: str | None, truth: np.ndarray | None) -> dict[str, float] | None:
    """How well the region candidate `name` was placed: the share of its region on the true region (precision) and
    of the true region it covers (recall); None unless both a region and the truth are there."""
    if name is None or truth is None:
        return None
    loc = report["localization"]
    own = candidate_regions(loc)
    vertices = own[name] if name in own else loc.get("region_vertices")
    if not vertices:
        return None
    found = np.zeros(len(truth), bool)
    found[vertices] = True
    true = truth > 0
    return {"precision": float((found & true).sum() / found.sum()), "recall": float((found & true).sum() / true.sum())}


def true_model_l2(request: DiagnoseRequest, report: dict) -> float | None:
    """Held-out rollout error of the true model of a capture our simulator made (its material, terms and hidden
    effect: truth.json) simulated as the diagnosis simulates, from the same rest state at the same substeps on the
    same (noisy, smoothed) data: what the diagnosis could reach knowing the physics. None for Blender's captures
    and for garments simulated on a remeshed copy (the true regions are on the recorded vertices)."""
    from ..capture.layout import Capture
    from ..diagnosis.resimulated import recorded_effect, true_simulator
    from ..physics.fitting import mean_rollout_error
    from ..stages.behavior import hand_mask
    from ..stages.diagnose import prepare

    capture = Path(request.capture)
    truth = json.loads((capture / "truth.json").read_text())
    if "ours" not in truth.get("effect", {}):
        return None
    inputs = prepare(request, Capture(capture), report["train_sequences"], report["heldout_sequences"],
                     report["source"])
    if inputs.mesh_log["remeshed"]:
        return None
    with np.load(capture / "gt" / "regions.npz") as z:
        regions = {k: z[k] for k in z.files}
    n_body = inputs.train[0].body.shape[1]
    sim = true_simulator(inputs.rest, inputs.faces, inputs.attached, inputs.body_faces, n_body, hand_mask(n_body),
                         recorded_effect(truth), regions, request.fps, request.substeps, flat=not request.rest_mesh)
    return mean_rollout_error(sim, inputs.heldout, inputs.attached)


def run_case(args: argparse.Namespace, effect: str, strength: float, seed: int, noise: float) -> dict:
    from ..diagnosis.library import BY_NAME, SYNTH_EFFECT_CLASS
    from ..stages.diagnose import DiagnoseRequest, run_diagnose

    name = case_name(args, effect, strength, seed)
    hidden = effect if strength > 0 else "none"
    params = effect_params(effect, strength) if strength > 0 else []
    capture = capture_of(args, name, seed, hidden, params)
    signal, step_change = (0.0, 0.0) if hidden == "none" else effect_sizes_of(args, name, seed, hidden, params)
    divergence = reference_divergence_of(args, name, seed, hidden, params)
    truth = json.loads((capture / "truth.json").read_text())
    true_class = SYNTH_EFFECT_CLASS[truth["effect"]["name"]]
    suffix = ("_rest" if args.rest_given else "") + ("_um" if args.vertex_mass == "uniform" else "")
    project = args.cache / "projects" / f"{name}_noise{noise:g}{suffix}"
    reference, region_path = [], ""
    if true_class != "none":
        reference = [CLASS_CANDIDATE[true_class]]
        region_name = truth["effect"]["params"].get("region")
        if region_name:
            with np.load(capture / "gt" / "regions.npz") as z:
                region_path = str(project / "truth_region.npy")
                project.mkdir(parents=True, exist_ok=True)
                np.save(region_path, (z[region_name] > 0).astype(np.float64))
    request = DiagnoseRequest(capture=capture, project=project, noise_mm=noise, seed=seed, bootstrap=args.bootstrap,
                              fit_horizon=args.fit_horizon, reference=reference, reference_region=region_path,
                              rest_mesh=str(capture / "gt" / "template.obj") if args.rest_given else "",
                              vertex_mass=args.vertex_mass,
                              progress="none")
    report = json.loads(run_diagnose(request).read_text())
    true_model = true_model_l2(request, report)
    predicted = report["accepted_classes"][0] if report["accepted_classes"] else "none"
    accepted = next((e for e in report["effects"] if report["accepted"] and e["name"] == report["accepted"][0]),
                    None)
    ref = report["reference_trials"].get(reference[0]) if reference else None
    before, after = report["heldout_l2_before"], report["heldout_l2_after"]
    true_params = truth_parameters(truth)
    gap = None if ref is None else before - ref["heldout_l2"]
    named_refit = accepted["refit"] if accepted and predicted == true_class else None
    named_final = accepted.get("refit_all_recordings") if accepted and predicted == true_class else None
    folds = fold_gains(report, accepted["name"] if accepted else None, reference[0] if reference else None)
    cv_gain = None if accepted is None or not accepted.get("cross_validated") \
        else accepted["cross_validated"]["heldout_gain"]
    cv_true = report.get("cross_validation", {}).get("given_truth", {}).get(reference[0], {}).get("heldout_gain") \
        if reference else None
    return {
        "capture": name, "effect": effect, "strength": strength, "seed": seed, "noise_mm": noise,
        "truth_simulator": args.truth_simulator, "rest_given": args.rest_given,
        "vertex_mass": args.vertex_mass,
        "true_class": true_class, "predicted": predicted, "accepted": report["accepted"],
        "correct": predicted == true_class,
        "proposed": report["selection"]["order"],
        "rollouts_first": report.get("cross_validation", {}).get("rollouts_first"),   # where the residual overruled
        "not_separated_from": accepted.get("not_separated_from", []) if accepted else [],   # the class left open
        "implausible": [e["name"] for e in report["effects"] if e.get("implausible")],
        "closest": report.get("closest"),     # where nothing was named: the near miss and why (verdict.closest)
        "activity_excess": report["localization"].get("activity_excess"),   # localize.activity_map: noise's share
        "activity_blind": report["localization"].get("activity_blind"),
        "heldout_l2_before": before, "heldout_l2_after": after, "heldout_gain": 1.0 - after / before,
        "cross_validated_gain": cv_gain,
        "true_effect_l2": None if ref is None else ref["heldout_l2"],
        "gap_closed": None if gap is None or gap <= 0 else (before - after) / gap,
        "cross_validated_true_effect_gain": cv_true,
        "cross_validated_gap_closed": None if cv_gain is None or cv_true is None or cv_true <= 0
        else cv_gain / cv_true,
        "folds": folds,
        "true_model_l2": true_model,
        "true_model_gap_closed": None if true_model is None or before <= true_model
        else (before - after) / (before - true_model),
        "true_parameters": true_params,
        "parameter_error": parameter_error(true_params, named_refit),
        "parameter_errors": parameter_errors(true_params, named_refit),
        "parameter_error_all_recordings": parameter_error(true_params, named_final),   # pipeline.final_fit
        "parameter_errors_all_recordings": parameter_errors(true_params, named_final),
        "true_effect_parameter_error": parameter_error(true_params, None if ref is None else ref["refit"]),
        "truth_in_identified_range": identified_truth(true_params, named_final,
                                                      (report.get("final_fit") or {}).get("identified_ranges")),
        "region_overlap": region_overlap(report, accepted["name"] if accepted and BY_NAME[accepted["name"]].needs_region
                                         else None, np.load(region_path) if region_path else None),
        "signal_mm": signal * 1e3, "step_change_mm": step_change * 1e3,
        "resolved_by_reference": bool(step_change < signal),
        # the floor every simulator but the reference at its own step carries: compare with heldout_l2_after
        "reference_divergence_mm": {k: v * 1e3 for k, v in divergence.items()},
        "heldout_reference_divergence_mm": 1e3 * float(np.mean([divergence[k] for k in report["heldout_sequences"]])),
        "seconds": report["timings"]["total_s"],
    }


def fold_gains(report: dict, named: str | None, true: str | None) -> list[dict]:
    """Per fold of the diagnosis's cross-validation: the held-out sequences, the held-out gain of the named
    candidate and of the simulator given the true effect (None where that fold did not try it). The second says
    how much a recording can show of the effect at all: a fold whose true effect gains little caps the mean."""
    out = []
    for fold in report.get("cross_validation", {}).get("folds", []):
        named_trial, true_trial = fold["trials"].get(named or ""), fold.get("given_truth", {}).get(true or "")
        out.append({"heldout": fold["heldout"],
                    "named_gain": None if named_trial is None else named_trial["heldout_gain"],
                    "true_effect_gain": None if true_trial is None else true_trial["heldout_gain"]})
    return out


def summarize(cases: list[dict], min_gain: float) -> dict:
    present = [c for c in cases if c["true_class"] != "none"]
    none = [c for c in cases if c["true_class"] == "none"]
    errors = [c["parameter_error"] for c in present if c["parameter_error"] is not None]
    final_errors = [c["parameter_error_all_recordings"] for c in present
                    if c.get("parameter_error_all_recordings") is not None]
    gains = [c["heldout_gain"] for c in present if c["correct"]]
    cv_gains = [c["cross_validated_gain"] for c in present if c["correct"] and c["cross_validated_gain"] is not None]
    closed = [c["gap_closed"] for c in present if c["gap_closed"] is not None]
    cv_closed = [c["cross_validated_gap_closed"] for c in present
                 if c["correct"] and c.get("cross_validated_gap_closed") is not None]
    cv_true = [c["cross_validated_true_effect_gain"] for c in present
               if c.get("cross_validated_true_effect_gain") is not None]
    closed_to_truth = [c["true_model_gap_closed"] for c in present if c.get("true_model_gap_closed") is not None]
    overruled = [c for c in cases if c["rollouts_first"]]
    floored = [c for c in cases if c.get("heldout_reference_divergence_mm") is not None]   # older runs lack it
    identified = [all(c["truth_in_identified_range"].values()) for c in present if c.get("truth_in_identified_range")]

    def mean(xs: list[float]) -> float | None:
        return float(np.mean(xs)) if xs else None

    # an effect leaves a trace the diagnosis can confirm only if the simulator given the true effect beats the
    # baseline on held-out rollouts by the acceptance gain: the accuracy on those separates what the method misses
    # from what these data cannot show (e.g. a shrink baked into the rest shape taken from the first frame)
    detectable = [c for c in present if c["true_effect_l2"] is not None
                  and 1.0 - c["true_effect_l2"] / c["heldout_l2_before"] >= min_gain]
    # a split without our simulator: effects the reference resolves (their change under a finer step is smaller
    # than the effect), i.e. physics rather than Blender's numerics
    resolved = [c for c in present if c["resolved_by_reference"]]
    return {"cases": len(cases),
            "accuracy_effect_present": mean([float(c["correct"]) for c in present]),
            "detectable_cases": len(detectable),
            "accuracy_detectable": mean([float(c["correct"]) for c in detectable]),
            "cases_resolved_by_reference": len(resolved),
            "accuracy_resolved_by_reference": mean([float(c["correct"]) for c in resolved]),
            "false_alarm_rate_none": mean([float(not c["correct"]) for c in none]),
            "median_parameter_error": float(np.median(errors)) if errors else None,
            "median_parameter_error_all_recordings": float(np.median(final_errors)) if final_errors else None,
            "truth_in_identified_range": mean([float(x) for x in identified]),
            "mean_heldout_gain_when_named": mean(gains),
            "mean_cross_validated_gain_when_named": mean(cv_gains),
            "median_gap_closed": float(np.median(closed)) if closed else None,
            "median_cross_validated_gap_closed": float(np.median(cv_closed)) if cv_closed else None,
            "mean_cross_validated_true_effect_gain": mean(cv_true),
            "median_true_model_gap_closed": float(np.median(closed_to_truth)) if closed_to_truth else None,
            # the delivered model's held-out error next to the floor the reference's own step puts under it
            "mean_heldout_l2_after_mm": mean([1e3 * c["heldout_l2_after"] for c in floored]),
            "mean_heldout_reference_divergence_mm": mean([c["heldout_reference_divergence_mm"] for c in floored]),
            "residual_tie_breaks": len(overruled),
            "residual_tie_breaks_right": sum(c["correct"] for c in overruled)}


def confusion(cases: list[dict]) -> str:
    classes = sorted({c["true_class"] for c in cases} | {c["predicted"] for c in cases})
    width = max(len(c) for c in classes) + 2
    lines = ["truth \\ named".ljust(width) + "".join(c[:10].rjust(12) for c in classes)]
    for t in sorted({c["true_class"] for c in cases}):
        row = [sum(1 for c in cases if c["true_class"] == t and c["predicted"] == p) for p in classes]
        lines.append(t.ljust(width) + "".join(str(n).rjust(12) for n in row))
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    cases = []
    for noise in args.noise_mm:
        for effect in args.effects:
            for strength in ([0.0] if effect == "none" else args.strengths):
                for seed in args.seeds:
                    case = run_case(args, effect, strength, seed, noise)
                    cases.append(case)
                    print(f"{case['capture']} noise {noise:g} mm: named {case['predicted']} "
                          f"({'right' if case['correct'] else 'WRONG'}), held-out "
                          f"{case['heldout_l2_before'] * 1e3:.1f} -> {case['heldout_l2_after'] * 1e3:.1f} mm"
                          + ("" if case["cross_validated_gain"] is None else
                             f" ({-case['cross_validated_gain']:+.0%} over the folds)")
                          + ("" if not case["closest"] else
                             f" (closest {case['closest']['name']}, {-case['closest']['heldout_gain']:+.0%}"
                             + (" over the folds)" if len(case["closest"]["folds"]) > 1 else ")"))
                          + ("" if not case["activity_blind"] else
                             f" (noise swamps the stretching: activity excess {case['activity_excess']:.1f})")
                          + ("" if not case["rollouts_first"] else
                             f" (the rollouts led with {case['rollouts_first']}, the residual chose)")
                          + ("" if not case["not_separated_from"] else
                             f" (not separated from {' or '.join(case['not_separated_from'])})")
                          + ("" if case["true_effect_l2"] is None else
                             f", true effect {case['true_effect_l2'] * 1e3:.1f} mm")
                          + ("" if case["cross_validated_true_effect_gain"] is None else
                             f" ({-case['cross_validated_true_effect_gain']:+.0%} over the folds)")
                          + ("" if case["true_model_l2"] is None else
                             f", true model {case['true_model_l2'] * 1e3:.1f} mm")
                          + ("" if not case["truth_in_identified_range"] else
                             ", truth in the range the recordings leave open: "
                             + ", ".join(f"{k} {'yes' if v else 'NO'}"
                                         for k, v in case["truth_in_identified_range"].items()))
                          + f"; motion change {case['signal_mm']:.1f} mm, {case['step_change_mm']:.1f} mm "
                            "of it moves at twice the steps; the reference itself moves "
                            f"{case['heldout_reference_divergence_mm']:.1f} mm on the held-out recordings at twice "
                            "the steps", file=sys.stderr, flush=True)
    for noise in args.noise_mm:
        subset = [c for c in cases if c["noise_mm"] == noise]
        print(f"\nnoise {noise:g} mm\n" + confusion(subset), file=sys.stderr)
    from ..stages.diagnose import DiagnoseRequest

    min_gain = DiagnoseRequest.min_gain
    summary = {"all": summarize(cases, min_gain)}
    summary.update({f"noise_{n:g}mm": summarize([c for c in cases if c["noise_mm"] == n], min_gain)
                    for n in args.noise_mm})
    print(json.dumps({"bench": "diagnose", "summary": summary, "cases": cases},
                     default=lambda o: None if isinstance(o, float) and math.isnan(o) else o))
    return 0
