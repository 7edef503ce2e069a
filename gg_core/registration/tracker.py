"""Stage 2's per-frame fit: only the mesh vertices move; the Gaussians stay bound to the faces.

Loss (REFERENCE §3, release weights): L_rgb + 0.03 L_bend + 0.01 L_strain + 0.05 L_VE (first half of the
iterations) + 1e3 L_body (second half). Virtual edges keep the garment from collapsing while it is far from
the images; the body term then pushes it out of the body once the images have pulled it into place (switched
on from the start, it fights a garment that is still misaligned: the paper's "w/ body" ablation).
Virtual edges act only on a sequence's first frame, where the aligned template starts far from the images. Their
rest lengths are the template's facing distances, which a garment in another pose legitimately shortens (a
twisting torso brings a skirt's front and back closer); on warm-started frames they pushed the fit off the
images in the first half of every frame and the body term and images pulled it back in the second, so the
frames alternated (demo capture, torso twist: odd frames 0.2-0.3 cm worse in CD for all 30 frames). Measured
on that sequence, frames 1 and 2 each fitted from the fitted frame 0 (CD 0.67 / 0.69 cm to their truths):
1.03 / 1.00 cm with virtual edges, 0.68 / 0.67 cm with their rest lengths blended like the strain's (0.7
previous frame), 0.63 / 0.63 cm without them (`ve_tracking` False, the default).
L_bend is the mean over hinges (resolution independent, see losses.py), L_strain, L_VE and L_body are sums.
The rest shape is 0.7 x previous frame + 0.3 x template, blended in rotation-invariant quantities: edge lengths
(strain) and dihedral angles (bending). Blending vertex positions instead, as the formula reads literally,
shrinks the rest shape of a garment that turned between the two (measured: CD against ground truth grew every
frame of a walking sequence while the photometric loss rose).

Schedule per frame: `iterations` Adam steps with an exponentially decaying learning rate on the smooth
parameterization u = (I + lam L) x of the vertices (smooth_param; measured on the demo capture, frame 4 started from
the ground truth of frame 2, 100 steps: CD 0.66 -> 0.37 cm with lam 10 vs 0.66 -> 0.49 cm on plain vertices), two
random cameras per step, SH colours and Gaussian visibility per camera refreshed every few steps, body contacts
every few steps. Measured and left off by default: a coarse phase on half-resolution images (frame 6 from frame 4:
CD 0.72 vs 0.48 cm without), Adam with one second moment for all vertices (no better), early stopping (the fits
never settle: per-frame appearance changes keep the gradients noisy). What limits accuracy is the objective, not the
optimizer: started at the ground truth of a frame, the fit drifts 0.3-0.45 cm away from it even with all cameras per
step and small steps, because the Gaussian texture (fitted on the template frame) does not reproduce the shading of
other poses; the error then accumulates by about 0.05 cm per frame. Measured and not kept: a static studio lighting
fitted with the vertices (order-2 SH irradiance per channel, each Gaussian's colour scaled by E(n_frame) /
E(n_template) of its face normal): walk frames 0-11, mean CD 0.809 cm with the normals differentiable, 0.765 cm with
them detached, 0.767 cm without, so diffuse shading of turned faces is not what drifts (shadows and occlusion by the
moving body are the remaining suspects). Part of it is under-convergence: 200 iterations per frame instead of 100
give 0.739 cm on the same frames (frame 11: 0.95 vs 1.06 cm), and on all 3 x 30 frames of the demo capture CD 0.80
vs 0.89 cm, p2m 0.73 vs 0.82 cm, F@1cm 72.9 vs 69.2 %, at 17.1 s per frame (the issue's limit is 20 s): the default
since then.
How well the Gaussian texture is converged matters more than the optimizer (2026-11-25, demo walk frame 0 fitted
from the 0.525 cm template with L_rgb alone): with the block-averaged registration texture the fit drifts to
0.604 cm; with that texture refitted on the template frame for 300 / 1000 / 2500 steps to 0.592 / 0.550 / 0.527
cm (the images then hold the mesh where it is; see stages/register.registration_texture). Measured and not kept,
walk frames 0-11 from the 0.52 cm template (per-entry Adam: CD 0.617 cm): one second moment for all vertices
(UniformAdam, max) lr 5e-3 / 2e-2: 0.664 / 0.655 cm (frame 0 better, 0.58, then it falls behind the motion:
0.76 cm by frame 11); one second moment as the mean square: 0.784 cm (frame 0 0.53, frame 11 1.06); per-entry
Adam with the mean square added to the denominator: 0.619 / 0.616 cm (lr 2e-3 / 4e-3); a learning rate decaying to
0.02 instead of 0.1: 0.617 cm; L1 on high-passed images (sigma 2 px, against pose-dependent shading) with the
2500-step texture: 0.557 cm, the same as without, so pose-dependent shading is at most a small part of the drift.
What corrects the drift (2026-11-26): after the fits, a multi-view stereo step (stereo.py, run by stage 2 over the
sequence's fits) moves the vertices along their normals to where the cameras' own images of the frame agree. It
refines each frame's output only; the next frame starts from the photometric fit, which is what this class returns.
Demo walk, 30 frames: mean CD 0.530 -> 0.419 cm; with nothing held and a softer offset field (session 11) 0.368
cm, with patches bent to the surface's folds 0.347 cm.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np
import torch

from ..gaussians.texture import GaussianTexture
from ..physics.contact import BodyCollider
from ..reconstruction.photo_consistency import check_weighting
from .appearance import contrast_background
from .losses import Bending, BodyTerm, Strain, virtual_edges
from .photometric import view_colors, view_loss, visible_gaussians
from .smooth_param import SmoothParam, UniformAdam
from .views import View

SCHEDULES = ("never", "first_half", "second_half", "always")


@dataclass
class TrackerConfig:
    iterations: int = 200              # per frame (100 drifts more: demo capture CD 0.89 vs 0.80 cm)
    first_iterations: int = 533        # first frame of a sequence (starts from the aligned template), 8/3 as many
    views_per_iteration: int = 2
    lr: float = 2e-3                   # Adam step at the start of a frame (m, in the smooth parameterization)
    lr_final: float = 0.1              # learning rate at the end, as a fraction of lr (exponential decay)
    smoothing: float = 10.0            # lam of the smooth parameterization u = (I + lam L) x (0: plain vertices)
    uniform_adam: bool = False         # one second moment for all vertices (smooth_param.UniformAdam)
    coarse_scale: float = 1.0          # image scale of a coarse phase (1.0: none; 0.5 was measured worse)
    coarse_fraction: float = 0.5       # share of the iterations in the coarse phase
    w_bend: float = 0.03
    w_strain: float = 0.01
    w_ve: float = 0.05
    w_body: float = 1e3
    ve: str = "first_half"
    ve_tracking: bool = False          # virtual edges also on frames warm-started from the previous one (see above)
    body: str = "second_half"
    body_projection: bool = True       # enforce the body term by projection (see _project_out) instead of a penalty
    rest_previous: float = 0.7         # rest shape = 0.7 previous frame + 0.3 template (lengths, angles)
    contact_every: int = 10            # iterations between body-contact queries
    visibility_every: int = 25         # iterations between Gaussian visibility updates per view
    stop_motion: float = 0.0           # early stop: mean vertex step (m) per iteration below this ...
    stop_patience: int = 20            # ... for this many iterations in the fine phase (0 m: never stop early)
    stereo_rounds: int = 4             # photo-consistency rounds over the fits (stage 2, stereo.py; 0: none) ...
    stereo_search: float = 0.02        # ... searching this far (m) along the normals either way ...
    stereo_weighting: str = "snr"      # ... each vertex weighted by its peak's signal-to-noise ratio (stereo.py) ...
    stereo_stiffness: float = 4.0      # ... in an offset field this stiff (4 with "snr" = 1 with "score") ...
    stereo_aggregate: int = 0          # ... score curves averaged over this many neighbour steps (template: 2) ...
    stereo_curvature_gain: float = 1.25  # ... patches bent to this times the mesh's curvature (stereo.py) ...
    stereo_frames: int = 9             # ... and score curves averaged over this many frames (odd; stereo.py) ...
    stereo_normal_smoothing: int = 10  # ... moving along normals smoothed this many steps (stereo.py)
    smooth_window: int = 7             # frames of the finished sequence's temporal filter (temporal.py; 1: none) ...
    smooth_order: int = 2              # ... and its polynomial order
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("ve", "body"):
            if getattr(self, name) not in SCHEDULES:
                raise ValueError(f"{name} schedule must be one of {SCHEDULES}, got {getattr(self, name)!r}")
        check_weighting(self.stereo_weighting, "stereo_weighting")
        if self.stereo_frames < 1 or self.stereo_frames % 2 == 0:
            raise ValueError(f"stereo_frames must be a positive odd frame count, got {self.stereo_frames}")


ABLATIONS: dict[str, dict] = {
    "full": {},
    "only-rgb": {"w_bend": 0.0, "w_strain": 0.0, "w_ve": 0.0, "w_body": 0.0, "ve": "never", "body": "never"},
    "no-body": {"w_body": 0.0, "body": "never"},
    "body-always": {"body": "always"},
}


def ablation_config(name: str, base: TrackerConfig | None = None) -> TrackerConfig:
    """`base` (default TrackerConfig()) with the ablation's loss terms switched off or rescheduled."""
    if name not in ABLATIONS:
        raise ValueError(f"unknown ablation {name!r}; choose one of {list(ABLATIONS)}")
    return replace(base or TrackerConfig(), **ABLATIONS[name])


def _active(schedule: str, phase: float) -> bool:
    return schedule == "always" or (schedule == "first_half" and phase < 0.5) or \
        (schedule == "second_half" and phase >= 0.5)


@dataclass
class FrameResult:
    verts: np.ndarray                  # the frame's photometric fit
    log: dict = field(default_factory=dict)


class Tracker:
    """Fits the template's vertices to one frame after another of a sequence."""

    def __init__(self, texture: GaussianTexture, template: np.ndarray, faces: np.ndarray, collider: BodyCollider,
                 config: TrackerConfig | None = None) -> None:
        self.texture = texture
        self.template = np.asarray(template, np.float64)
        self.faces = np.asarray(faces, np.int64)
        self.faces_t = torch.from_numpy(self.faces)
        self.collider = collider
        self.config = config or TrackerConfig()
        self.bending = Bending(self.template, self.faces)
        self.strain = Strain(self.template, self.faces)
        self.virtual_edges = virtual_edges(self.template, self.faces)
        self.rng = np.random.default_rng(self.config.seed)
        self.param = SmoothParam(self.faces, len(self.template), self.config.smoothing) \
            if self.config.smoothing > 0 else None

    def set_rest(self, previous: np.ndarray | None) -> None:
        """Rest edge lengths and dihedral angles: the template's, blended with the previous frame's if given."""
        lengths, angles = self.strain.lengths(self.template), self.bending.angles(self.template)
        if previous is not None:
            a = self.config.rest_previous
            lengths = a * self.strain.lengths(previous) + (1 - a) * lengths
            angles = a * self.bending.angles(previous) + (1 - a) * angles
        self.strain.set_rest(lengths)
        self.bending.set_rest(angles)

    def fit_frame(self, init: np.ndarray, views: list[View], body_verts: np.ndarray,
                  previous: np.ndarray | None = None, iterations: int | None = None) -> FrameResult:
        """Vertex positions of one frame, starting from `init`; `previous` is the last frame's fit (None on the
        first frame of a sequence: the strain rest shape is then the template)."""
        cfg = self.config
        n_iter = cfg.iterations if iterations is None else iterations
        start, cpu_start = time.perf_counter(), time.process_time()
        self.set_rest(previous)
        body = BodyTerm(self.collider, body_verts)
        background = contrast_background(views)
        levels = {1.0: views}
        if cfg.coarse_scale != 1.0 and cfg.coarse_fraction > 0:
            levels[cfg.coarse_scale] = [v.scaled(cfg.coarse_scale) for v in views]
        init = np.asarray(init, np.float64)
        u = torch.tensor(init if self.param is None else self.param.encode(init), dtype=torch.float32,
                         requires_grad=True)
        optimizer = (UniformAdam if cfg.uniform_adam else torch.optim.Adam)([u], lr=cfg.lr)
        x = self._decode(u)
        decay = cfg.lr_final ** (1.0 / max(n_iter - 1, 1))
        keep: dict[int, tuple[int, torch.Tensor, torch.Tensor]] = {}   # view -> (iteration, visible, colours)
        contacts = body.contacts(x)
        order: list[int] = []
        trace: dict[str, list[float]] = {"loss": [], "rgb": [], "motion": []}
        term_sums: dict[str, float] = {}
        calm = 0
        it = 0
        for it in range(n_iter):
            phase = it / n_iter
            scale = cfg.coarse_scale if phase < cfg.coarse_fraction and cfg.coarse_scale in levels else 1.0
            chosen = []
            for _ in range(min(cfg.views_per_iteration, len(views))):
                if not order:
                    order = list(self.rng.permutation(len(views)))
                chosen.append(order.pop())
            rgb = x.new_zeros(())
            for i in chosen:
                if i not in keep or it - keep[i][0] >= cfg.visibility_every:
                    visible = visible_gaussians(self.texture, x, self.faces_t, views[i])
                    keep[i] = (it, visible, view_colors(self.texture, x, self.faces_t, views[i], visible))
                loss_i, _ = view_loss(self.texture, x, self.faces_t, levels[scale][i], background, keep=keep[i][1],
                                      colors=keep[i][2])
                rgb = rgb + loss_i / len(chosen)
            terms = {"rgb": rgb, "bend": cfg.w_bend * self.bending(x), "strain": cfg.w_strain * self.strain(x)}
            if cfg.w_ve > 0 and (previous is None or cfg.ve_tracking) and _active(cfg.ve, phase):
                terms["ve"] = cfg.w_ve * self.virtual_edges(x)
            pushing = cfg.w_body > 0 and _active(cfg.body, phase)
            if pushing and it % cfg.contact_every == 0:
                contacts = body.contacts(x)
            if pushing and not cfg.body_projection:
                terms["body"] = cfg.w_body * body(x, contacts)
            loss = sum(terms.values())
            before = x.detach().clone()
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            x = self._decode(u)
            if pushing and cfg.body_projection:
                x = self._project_out(u, x, contacts, body.eps)
            for group in optimizer.param_groups:
                group["lr"] *= decay
            motion = float((x.detach() - before).norm(dim=1).mean())
            trace["loss"].append(float(loss.detach()))
            trace["rgb"].append(float(rgb.detach()))
            for name, value in terms.items():
                term_sums[name] = term_sums.get(name, 0.0) + float(value.detach())
            trace["motion"].append(motion)
            calm = calm + 1 if motion < cfg.stop_motion and scale == 1.0 and phase >= 0.5 else 0
            if cfg.stop_patience and calm >= cfg.stop_patience:
                break
        final = x.detach().double()
        log = {"iterations": it + 1, "seconds": time.perf_counter() - start,
               "cpu_seconds": time.process_time() - cpu_start, "l_body": float(body(final, body.contacts(final))),
               "rgb_first": trace["rgb"][0], "rgb_last": float(np.mean(trace["rgb"][-10:])),
               "weighted_terms_mean": {k: v / (it + 1) for k, v in term_sums.items()},
               "trace": trace}
        return FrameResult(final.numpy(), log)

    def _project_out(self, u: torch.Tensor, x: torch.Tensor, contacts, eps: float) -> torch.Tensor:
        """Moves the vertices closer than `eps` to the body along the contact normal to `eps` (the minimizer of
        the cubic penalty as its weight grows, vertex by vertex) and re-encodes u. Through the smooth
        parameterization the penalty's gradient, orders of magnitude above the photometric one on a vertex a
        centimetre deep, drags a whole neighbourhood along (measured on the demo's template frame: CD 0.66 ->
        0.81 cm once the penalty switched on); the projection moves only the offending vertices and lets the
        other terms reshape their surroundings."""
        with torch.no_grad():
            depth = _depth(x, contacts, eps)
            if not bool((depth > 0).any()):
                return x
            x = x + depth[:, None] * contacts.normals
            u.copy_(x if self.param is None else torch.from_numpy(self.param.encode(x.double().numpy())).to(u.dtype))
        return self._decode(u)

    def _decode(self, u: torch.Tensor) -> torch.Tensor:
        return u if self.param is None else self.param.decode(u)


def _depth(x: torch.Tensor, contacts, eps: float) -> torch.Tensor:
    """[V] how far each vertex in contact is closer than `eps` to the body (0 elsewhere)."""
    return (eps - ((x - contacts.points) * contacts.normals).sum(-1)).clamp(min=0.0) * contacts.active


def pushed_out(x: torch.Tensor, body: BodyTerm) -> torch.Tensor:
    """`x` with vertices closer than the body term's eps to the body moved out along the contact normal to eps
    (the stereo step moves vertices after the fit's own projection)."""
    contacts = body.contacts(x)
    return x + _depth(x, contacts, body.eps)[:, None] * contacts.normals
