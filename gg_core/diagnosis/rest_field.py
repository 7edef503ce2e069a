"""A rest-length field fitted vertex by vertex on the training recordings: where their motion says the cloth's rest
lengths differ from the given rest mesh, found by the fit itself rather than patch by patch.

Why: the patch scan (scan.py) proposes regions from a one-frame residual that a seam's uniform tension cancels
inside and shows at its ends, and the rollouts then choose among a few patches; the seam's exact vertices matter
as much as the whole scan gains (session 57). Fitting every vertex's rest log-scale against the simulator's own
prediction of the recordings uses the signal the rollouts see, everywhere at once.

The fit: one log-scale u per vertex (an edge's rest length scales by exp of the mean of its ends', as
library.apply_region scales a region), minimizing the teacher-forced loss (physics.fitting.TeacherForced: SAMPLES
observed states, each HORIZON frames ahead) plus TV_WEIGHT times the edges' mean smoothed total variation
sqrt(du^2 + TV_EPS^2), both relative to the unchanged loss, by L-BFGS-B within +-LOG_BOUND on adjoint gradients
(at most EVALUATIONS). Total variation favours a piecewise constant field, a jump along a curve, which is what a
shrunk seam or an elastic band is; a squared-difference smoothness would smear it.

Measured offline (sessions 60-61, /work/data/s60/tvrest.py on session 58's stored baselines of Blender's seam
shrink, 15 % on a 36-vertex side seam, the unloaded garment given; each fold fitted on two recordings, the third
held out; the whole field scaled by the factor that rolls the training recordings out best, held-out gain against
the fold's baseline, the true seam's in brackets): s3 holding out the twist (where the patch scan's rollout seeds
found no region) 30 vertices shrunk by more than 5 %, 26 on the seam, -26.9 % [-30.6 %]; s1 holding out the walk
34 (33 on the seam), -47.1 % [-47.7 %]; s1 holding out the twist 35 (32), -35.8 % [-36.7 %]. A weight of 1e-5
over-fits (s3 twist: +4.6 % held out). On `none` s1 holding out the twist the field stays within +-2.6 % and
gains 1.4 % held out (its training rollouts 14 % better: a held-out gain, not a training one, confirms). About
60 evaluations, 10 minutes on one core for the benchmark's 640-vertex skirt (3 x 24 frames).

The region the scan takes from it (scan.field_region: where it reaches half its extreme) at the strength that
rolls the training recordings out best (scan.fitted_field), same probes (session 61,
/work/data/s61/{fieldeval,binaryeval}.py): s3 holding out the walk 22 vertices, all on the seam, x0.866, held out
-35.2 % (the benchmark's true-effect refit in that fold, session 58: -31.2 %); holding out the arm swing 19, all on
the seam, x0.880, -52.1 % (-50.2 %). A graded region (the field over its extreme, from a tenth of it) took 48 / 65
vertices (34 / 31 on the seam) and gained -33.3 / -43.5 %.
"""
from __future__ import annotations

import numpy as np
import torch
from scipy.optimize import minimize

from ..physics.fitting import BehaviorParams, Observed, TeacherForced
from ..physics.material import MATERIAL_NAMES
from ..physics.simulator import ImplicitSimulator

TV_WEIGHT = 1e-4     # total variation's weight relative to the unchanged teacher-forced loss
TV_EPS = 1e-3        # smoothing of |du| (log-scale), so the penalty has a gradient at a jump of zero
SAMPLES = 24         # observed states per evaluation, as the refits use (physics.fitting.FitConfig)
HORIZON = 3          # frames predicted ahead of each
EVALUATIONS = 60     # loss-and-gradient evaluations of L-BFGS-B
LOG_BOUND = 0.5      # |u| at most: rest lengths within x0.61 - x1.65


def total_variation(u: np.ndarray, edges: np.ndarray) -> tuple[float, np.ndarray]:
    """(mean over `edges` of sqrt(du^2 + TV_EPS^2), its gradient in the per-vertex `u`)."""
    du = u[edges[:, 0]] - u[edges[:, 1]]
    r = np.sqrt(du * du + TV_EPS * TV_EPS)
    g = du / r / len(edges)
    grad = np.zeros_like(u)
    np.add.at(grad, edges[:, 0], g)
    np.add.at(grad, edges[:, 1], -g)
    return float(r.mean()), grad


def fit_rest_field(sim: ImplicitSimulator, train: list[Observed], seed: int, weight: float = TV_WEIGHT) -> np.ndarray:
    """[V] rest log-scale per vertex that predicts the `train` recordings best under a total-variation penalty of
    `weight`; the simulator is left as it was (its material must be uniform: the baseline fit's global one)."""
    cloth = sim.cloth
    saved = cloth.material, cloth.rest_lengths
    edges = cloth.topology.edges
    params = BehaviorParams(cloth, {n: float(getattr(cloth.material, n).mean()) for n in MATERIAL_NAMES}, sim.terms)
    problem = TeacherForced(sim, train, SAMPLES, seed, horizon=HORIZON)

    def set_field(u: np.ndarray) -> None:
        with torch.no_grad():
            params.edge_s.copy_(torch.from_numpy(0.5 * (u[edges[:, 0]] + u[edges[:, 1]])))

    try:
        loss0 = problem.evaluate(params, [])[0]
        if not loss0 > 0.0:      # the simulator predicts the recordings exactly: nothing to change
            return np.zeros(cloth.n_vertices)

        def objective(u: np.ndarray) -> tuple[float, np.ndarray]:
            set_field(u)
            loss, _, (g_edge,) = problem.evaluate(params, [params.edge_s])
            g_edge = 0.5 * g_edge.numpy()
            grad = np.zeros_like(u)
            np.add.at(grad, edges[:, 0], g_edge)
            np.add.at(grad, edges[:, 1], g_edge)
            tv, g_tv = total_variation(u, edges)
            return (loss + weight * tv) / loss0, (grad + weight * g_tv) / loss0

        n = cloth.n_vertices
        res = minimize(objective, np.zeros(n), jac=True, method="L-BFGS-B", bounds=[(-LOG_BOUND, LOG_BOUND)] * n,
                       options={"maxfun": EVALUATIONS, "maxiter": EVALUATIONS})
        return res.x if np.isfinite(res.x).all() else np.zeros(n)
    finally:
        cloth.material, cloth.rest_lengths = saved
        sim.refresh()
