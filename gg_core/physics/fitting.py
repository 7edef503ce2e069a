"""Behaviour fitting: material and rest lengths from observed garment motion, by implicit differentiation.

Teacher-forced one-frame prediction: from the observed x_{t-1}, x_t and the body, the simulator solves the
frame's implicit (sub)steps for x*_{t+1}(theta), each x* = argmin_x E(x; theta), and the loss compares it with the
observed x_{t+1}. At a solved state grad_x E(x*; theta) = 0, so dL/dtheta = -lambda^T d(grad_x E)/dtheta with
H lambda = dL/dx*: the adjoint solve runs on the exact Hessian (torch Hessian-vector products, all frames
batched), refined from the solver's PSD approximation (numba PCG per frame); mixed derivatives come from torch
autograd on the energies, and with substeps the adjoint walks back through them. Free rollouts evaluate the
result.

Parameters live in an unconstrained latent space (material.py): a global latent per material value, per-vertex
offsets from it, and per-edge log-scales of the rest lengths. The stage fits the global values first, then the
regularized per-vertex and per-edge fields.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import torch

from . import kernels
from .cloth import Cloth
from .material import MATERIAL_NAMES, MATERIAL_SPEC, Material, from_latent, to_latent
from .simulator import ClothState, ImplicitSimulator, blend
from .terms import StepInputs, System, Term

_ADJOINT_CG_MAX = 100     # CG iterations of each inner adjoint solve (TeacherForced._adjoint says why)


@dataclass
class Observed:
    """One observed (registered) sequence: garment frames [T,V,3] (template topology), body frames [T,Vb,3]."""

    name: str
    garment: np.ndarray
    body: np.ndarray | None
    fps: float


def _limited(term: Term, key: str, raw: torch.Tensor) -> torch.Tensor:
    """A fitted positive term parameter below its physical limit (Term.limits): raw / (1 + raw / limit), which is
    raw while small and approaches the limit smoothly (a hard clip would stop the gradient)."""
    limit = term.limits.get(key)
    return raw if limit is None else raw / (1.0 + raw / limit)


def _raw(term: Term, key: str, value: torch.Tensor) -> torch.Tensor:
    """Inverse of _limited (a start at or above the limit starts just below it)."""
    limit = term.limits.get(key)
    return value if limit is None else value / (1.0 - torch.clamp(value / limit, max=0.99))


class BehaviorParams:
    """Latents of a cloth's behaviour and their mapping onto a Cloth and its terms (differentiable).

    `term_params` names positive scalar parameters of the simulator's terms ("collision.margin") that are fitted
    with the global material as log-scale factors of their current values; `held` names global material values
    the fits leave at `initial` (minimize_lbfgs masks their gradients).
    """

    def __init__(self, cloth: Cloth, initial: dict[str, float] | None = None, terms: list[Term] = (),
                 term_params: tuple[str, ...] = (), held: tuple[str, ...] = ()) -> None:
        initial = initial or {}
        unknown = set(held) - set(MATERIAL_NAMES)
        if unknown:
            raise ValueError(f"cannot hold {sorted(unknown)}: the global material values are {MATERIAL_NAMES}")
        self.held = tuple(held)
        self.free_global = torch.tensor([0.0 if n in held else 1.0 for n in MATERIAL_NAMES], dtype=torch.float64)
        self.base_rest = cloth.rest_lengths.detach().clone()
        self.global_z = torch.stack([to_latent(n, initial.get(n, MATERIAL_SPEC[n][0])) for n in MATERIAL_NAMES])
        self.vertex_z = torch.zeros(len(MATERIAL_NAMES), cloth.n_vertices, dtype=torch.float64)
        self.edge_s = torch.zeros(len(self.base_rest), dtype=torch.float64)
        by_name = {t.name: t for t in terms}
        self.term_refs: list[tuple[Term, str, torch.Tensor]] = []
        for spec in term_params:
            name, _, key = spec.partition(".")
            if name not in by_name or key not in by_name[name].params:
                raise ValueError(f"cannot fit '{spec}': the simulator has no such term parameter")
            term = by_name[name]
            self.term_refs.append((term, key, _raw(term, key, term.params[key].detach().clone())))
        self.term_s = torch.zeros(len(self.term_refs), dtype=torch.float64)
        self._edges = torch.from_numpy(cloth.topology.edges)

    def tensors(self) -> dict[str, torch.Tensor]:
        return {"global_z": self.global_z, "vertex_z": self.vertex_z, "edge_s": self.edge_s, "term_s": self.term_s}

    def apply(self, cloth: Cloth) -> None:
        z = self.global_z[:, None] + self.vertex_z
        cloth.material = Material(**{n: from_latent(n, z[k]) for k, n in enumerate(MATERIAL_NAMES)})
        cloth.rest_lengths = self.base_rest * torch.exp(self.edge_s)
        for (term, key, init), s in zip(self.term_refs, self.term_s):
            term.params[key] = _limited(term, key, init * torch.exp(s))

    def regularizer(self, w_offset: float, w_smooth: float, w_rest: float) -> torch.Tensor:
        """Keeps the per-vertex and per-edge fields small and smooth (they could otherwise absorb noise)."""
        e = self._edges
        smooth = ((self.vertex_z[:, e[:, 0]] - self.vertex_z[:, e[:, 1]]) ** 2).mean()
        return w_offset * (self.vertex_z ** 2).mean() + w_smooth * smooth + w_rest * (self.edge_s ** 2).mean()

    def global_values(self) -> dict[str, float]:
        return {n: float(from_latent(n, self.global_z[k].detach())) for k, n in enumerate(MATERIAL_NAMES)}

    def term_values(self) -> dict[str, float]:
        return {f"{term.name}.{key}": float(_limited(term, key, init * torch.exp(s.detach())))
                for (term, key, init), s in zip(self.term_refs, self.term_s)}

    def state(self) -> dict[str, torch.Tensor]:
        return {k: v.detach().clone() for k, v in self.tensors().items()}

    def load(self, state: dict[str, torch.Tensor]) -> None:
        for k, v in state.items():
            getattr(self, k).data.copy_(v)


@dataclass
class _Sample:
    x: np.ndarray             # observed x_t
    v: np.ndarray             # observed velocity at t (frames t-1, t)
    body: np.ndarray | None   # body at t .. t+H [H+1,Vb,3]
    target: np.ndarray        # observed x_{t+1} .. x_{t+H} [H,V,3] (also the pinned vertices' positions)
    first: StepInputs         # the first substep's inputs depend on observations only: prepared once

    def observed(self, f: int) -> np.ndarray:
        """Observed positions at frame t + f."""
        return self.x if f == 0 else self.target[f - 1]


@dataclass
class FitLog:
    stage: list[str] = field(default_factory=list)
    loss: list[float] = field(default_factory=list)
    l2: list[float] = field(default_factory=list)


class TeacherForced:
    """Prediction loss over observed sequences, `horizon` frames ahead of each observed state, and its gradient
    in the behaviour parameters.

    A frame is sim.substeps implicit steps, exactly as rollouts integrate it. The adjoint runs backwards through
    the substeps: each substep's end state solves grad E = 0, and its inputs x_prev, v_prev = (y_{s-1} -
    y_{s-2}) / h carry the sensitivity back to the earlier substeps (contact planes and normals are lagged
    inputs, held fixed). With a horizon of several frames the loss compares every frame's end state, so
    dissipation, which one frame barely shows, accumulates where the fit can see it."""

    def __init__(self, sim: ImplicitSimulator, sequences: list[Observed], max_samples: int | None = None,
                 seed: int = 0, refinements: int = 3, horizon: int = 1) -> None:
        self.sim = sim
        self.horizon = horizon
        self.samples: list[_Sample] = []
        frames = [(obs, t) for obs in sequences for t in range(1, len(obs.garment) - horizon)]
        if max_samples is not None and len(frames) > max_samples:
            keep = np.sort(np.random.default_rng(seed).choice(len(frames), max_samples, replace=False))
            frames = [frames[i] for i in keep]
        for obs, t in frames:
            g, b = obs.garment, obs.body
            if abs(1.0 / obs.fps - sim.dt * sim.substeps) > 1e-9:
                raise ValueError(f"sequence {obs.name} runs at {obs.fps} fps, the simulator at {sim.fps}")
            sample = _Sample(g[t], (g[t] - g[t - 1]) * obs.fps, None if b is None else b[t:t + horizon + 1],
                             g[t + 1:t + horizon + 1], first=None)
            sample.first = self._prepare(sample, 0, sample.x, sample.v)
            self.samples.append(sample)
        self.free = sim.cloth.numeric().free
        self.refinements = refinements

    def _blend(self, s: _Sample, k: int) -> tuple[np.ndarray | None, np.ndarray]:
        """Body and pin targets at the end of substep k (linear within each frame)."""
        n = self.sim.substeps
        f, w = divmod(k, n)
        w = (w + 1) / n
        body = None if s.body is None else blend(s.body[f], s.body[f + 1], w)
        return body, blend(s.observed(f), s.observed(f + 1), w)

    def _prepare(self, s: _Sample, k: int, x: np.ndarray, v: np.ndarray) -> StepInputs:
        """Inputs of substep k of a sample."""
        b0 = None
        if s.body is not None:
            b0 = s.body[0] if k == 0 else self._blend(s, k - 1)[0]
        b1, pins = self._blend(s, k)
        return self.sim.prepare(x, v, b0, b1, self.sim.dt, pin_target=pins)

    def _frame(self, s: _Sample) -> list[tuple[np.ndarray, StepInputs]]:
        """(end positions, inputs) of every substep of the sample's horizon under the current parameters."""
        sim, out = self.sim, []
        x, v = s.x, s.v
        for k in range(sim.substeps * self.horizon):
            step = sim.with_contact_force(s.first) if k == 0 else self._prepare(s, k, x, v)
            y, step = sim.solve(step, self._blend(s, k)[0])
            out.append((y, step))
            v = (y - x) / sim.dt
            x = y
        return out

    def evaluate(self, params: BehaviorParams, trainable: list[torch.Tensor],
                 regularizer: Callable[[], torch.Tensor] | None = None) -> tuple[float, float, list[torch.Tensor]]:
        """(loss, mean one-frame vertex error in m, gradients of the loss for `trainable`)."""
        cloth, sim = self.sim.cloth, self.sim
        with torch.no_grad():
            params.apply(cloth)
        sim.refresh()
        num = sim.num
        free = self.free[:, None]
        n = sim.substeps
        scale = 1.0 / (len(self.samples) * self.horizon * max(float(self.free.sum()), 1.0))
        chains, systems, loss, dist = [], [], 0.0, 0.0
        rhs = [[] for _ in range(self.horizon)]
        for s in self.samples:
            chain = self._frame(s)
            for f in range(self.horizon):
                r = (chain[(f + 1) * n - 1][0] - s.target[f]) * free
                loss += float((r * r).sum()) * scale
                dist += float(np.linalg.norm(r, axis=1).sum()) * scale
                rhs[f].append(2 * r * scale)
            chains.append(chain)
            if trainable:
                per_step = []
                for y, step in chain:
                    system = System(num)
                    for term in sim.terms:
                        term.assemble(y, step, num, system)
                    system.finalize(y)
                    per_step.append(system)
                systems.append(per_step)
        if regularizer is not None:
            with torch.no_grad():
                loss += regularizer().item()
        if not trainable:
            return loss, dist, []
        grads = self._backward(params, trainable, chains, systems,
                               {(f + 1) * n - 1: np.stack(r) for f, r in enumerate(rhs)})
        if regularizer is not None:
            for t in trainable:
                t.requires_grad_(True)
            reg_grads = torch.autograd.grad(regularizer(), trainable, allow_unused=True)
            for t in trainable:
                t.requires_grad_(False)
            grads = [g if r is None else g + r for g, r in zip(grads, reg_grads)]
        return loss, dist, grads

    def _backward(self, params: BehaviorParams, trainable: list[torch.Tensor], chains: list, systems: list,
                  mu: dict[int, np.ndarray]) -> list[torch.Tensor]:
        """Reverse pass through the substeps of all samples at once (samples batched); `mu` holds the loss's
        gradient in each substep's end state where the loss looks at it (frame ends)."""
        sim, cloth = self.sim, self.sim.cloth
        for t in trainable:
            t.requires_grad_(True)
        params.apply(cloth)
        rest = cloth.rest()
        grads = [torch.zeros_like(t) for t in trainable]
        free = torch.from_numpy(self.free)[None, :, None]
        for k in range(len(chains[0]) - 1, -1, -1):
            y = torch.tensor(np.stack([c[k][0] for c in chains]), requires_grad=True)
            batch = StepInputs.stack([c[k][1] for c in chains])
            inputs = list(trainable)
            if k > 0:
                batch.x_prev.requires_grad_(True)
                batch.v_prev.requires_grad_(True)
                inputs += [batch.x_prev, batch.v_prev]
            energy = sum(term.energy(y, batch, rest).sum() for term in sim.terms)
            (gx,) = torch.autograd.grad(energy, y, create_graph=True)
            lam = self._adjoint(gx, y, [s[k] for s in systems], mu.pop(k))
            out = torch.autograd.grad(-(gx * torch.from_numpy(lam)).sum(), inputs, allow_unused=True,
                                      retain_graph=k > 0)
            for i, g in enumerate(out[:len(trainable)]):
                if g is not None:
                    grads[i] = grads[i] + g
            if k > 0:
                g_x, g_v = (torch.zeros_like(y) if g is None else g for g in out[len(trainable):])
                mu[k - 1] = mu.get(k - 1, 0) + ((g_x + g_v / sim.dt) * free).numpy()
                if k > 1:
                    mu[k - 2] = mu.get(k - 2, 0) - ((g_v / sim.dt) * free).numpy()
        for t in trainable:
            t.requires_grad_(False)
        with torch.no_grad():
            params.apply(cloth)
        return grads

    def _adjoint(self, gx: torch.Tensor, x_t: torch.Tensor, systems: list[System], rhs: np.ndarray) -> np.ndarray:
        """Solve H lambda = rhs per frame with the exact Hessian H (torch Hessian-vector products, all frames in one
        pass) by iterative refinement on the solver's PSD approximation H~: H~ alone drops compressive and
        curvature terms and was measured to give gradients off by 2x; a few refinements bring the residual from
        ~30% to a few %. The best iterate is kept.

        Inner solves stop at 100 CG iterations. Measured and not kept (session 14): 50. On the diagnosis of a
        Blender test capture (400 vertices, 2 substeps, 18 adjoints against a converged solve) 73 % of the solves
        run out of the 100-iteration budget short of 1e-3, and 50 iterations gave the same adjoint error (median
        2.5 %, 90th percentile 5.9 %) in 61 % of the time (30 with 6 refinements 2.4 / 3.7 % in 68 %, 15 with 6
        7.1 / 13 %). But the L-BFGS path changed: on the diagnosis benchmark's air damping case (seed 1, noise 0)
        the baseline's held-out error went 8.4 -> 9.2 mm and the diagnosis named quadratic drag (a wrong class)
        where 100 iterations name linear damping right; gravity (seed 2) stayed right (held-out 14.9 / 14.0 mm).
        The diagnosis is sensitive to where its baseline fit lands, so the budget stays."""
        num = self.sim.num

        def solve_approx(b: np.ndarray) -> np.ndarray:
            # loose inner solves: the refinement loop corrects their error along with the Hessian's
            out = np.zeros_like(b)
            for k, system in enumerate(systems):
                kernels.pcg(system.hdiag, system.hpair, num.pairs, num.sweep, self.free, b[k], out[k], 1e-3,
                            _ADJOINT_CG_MAX)
            return out

        lam = solve_approx(rhs)
        best, best_norm = lam, np.inf
        b_norm = np.linalg.norm(rhs)
        for _ in range(self.refinements):
            (hl,) = torch.autograd.grad(gx, x_t, grad_outputs=torch.from_numpy(lam), retain_graph=True)
            residual = (rhs - hl.numpy()) * self.free[None, :, None]
            norm = np.linalg.norm(residual)
            if norm >= best_norm:
                break       # x* is an inexact minimizer: on its few non-convex modes refinement stops helping
            best, best_norm = lam, norm
            if norm <= 1e-3 * b_norm:
                break
            lam = lam + solve_approx(residual)
        return best


def free_rollout(sim: ImplicitSimulator, obs: Observed) -> np.ndarray:
    """Frames 1.. [T-1,V,3] of a free rollout that starts from the observed frame 1 with the velocity of frames
    0-1 (the backward-Euler velocity the simulator's own steps produce; noisy sequences are smoothed in time
    first, see gg_core/diagnosis/noise.py); pinned vertices follow their observations."""
    g = obs.garment
    state = ClothState(g[1].copy(), (g[1] - g[0]) * obs.fps)
    return sim.rollout(state, None if obs.body is None else obs.body[1:], n_frames=len(g) - 1, pin_frames=g[1:])


def rollout_distance(traj: np.ndarray, obs: Observed, pinned: np.ndarray) -> float:
    """Mean distance (m) between a free rollout (free_rollout) and the observation over all frames after the
    first two and all simulated vertices."""
    d = np.linalg.norm(traj[1:] - obs.garment[2:], axis=2)[:, ~pinned]
    return float(d.mean())


def rollout_error(sim: ImplicitSimulator, obs: Observed, pinned: np.ndarray) -> float:
    """rollout_distance of a fresh free rollout."""
    return rollout_distance(free_rollout(sim, obs), obs, pinned)


def mean_rollout_error(sim: ImplicitSimulator, sequences: list[Observed], pinned: np.ndarray) -> float:
    """rollout_error averaged over `sequences` (a set of training or held-out recordings)."""
    return float(np.mean([rollout_error(sim, obs, pinned) for obs in sequences]))


@dataclass
class FitConfig:
    global_iterations: int = 20     # L-BFGS iterations (each may evaluate the loss more than once)
    local_iterations: int = 20
    w_offset: float = 1e-5      # regularizer weights, relative to the mean squared one-frame error (m^2)
    w_smooth: float = 1e-4
    w_rest: float = 1e-2
    # Observed states per evaluation, each predicted `horizon` frames ahead (TeacherForced). One-frame fits learn the
    # noise of registered meshes: on the tiny demo capture's registered motion, held-out rollout 63.8 mm with the
    # default material -> 85.1 mm fitted at horizon 1 (24 states), 19.2 mm at horizon 3 (Chamfer to the ground
    # truth 2.85 -> 3.17 vs 2.26 cm). On ground truth they tie (Blender skirt, 3 x 16 frames: 5.49 mm at 1/24,
    # 5.27 mm at 3/24 in 2.7x the time, 5.32 mm at 3/12 in 1.3x).
    max_samples: int | None = 12
    seed: int = 0
    horizon: int = 3
    # term parameters fitted with the global material: the garment-body contact thickness was measured to matter
    # as much as the material on Blender captures (its collision keeps cloth ~1 cm off the body)
    term_params: tuple[str, ...] = ("collision.margin",)
    held: tuple[str, ...] = ()      # global material values left as they are (BehaviorParams)


def minimize_lbfgs(sim: ImplicitSimulator, params: BehaviorParams, trainable: list[torch.Tensor],
                   evaluate: Callable[[], tuple[float, list[torch.Tensor]]], iterations: int) -> float:
    """Strong-Wolfe L-BFGS on `trainable`, `evaluate()` giving (loss, gradients) at the current parameters.

    The loss is divided by its first value: L-BFGS's first step has no curvature history and assumes an O(1)
    problem, which squared distances in metres are far from. Its last iterate need not be the best point it
    evaluated, so the best state seen is kept: it is left applied to the cloth of `sim`, and its loss is returned.
    Held material values (params.held) get no gradient, so no L-BFGS direction moves them.
    """
    best: list = [np.inf, params.state()]
    scale: list[float] = []

    def closure() -> torch.Tensor:
        loss, grads = evaluate()
        if loss < best[0]:
            best[:] = [loss, params.state()]
        scale.append(scale[0] if scale else 1.0 / max(loss, 1e-30))
        for t, g in zip(trainable, grads):
            t.grad = g * scale[0] * (params.free_global if t is params.global_z else 1.0)
        return torch.tensor(loss * scale[0], dtype=torch.float64)

    torch.optim.LBFGS(trainable, lr=1.0, max_iter=iterations, max_eval=int(iterations * 1.5), history_size=10,
                      line_search_fn="strong_wolfe", tolerance_grad=1e-12, tolerance_change=1e-14).step(closure)
    params.load(best[1])
    params.apply(sim.cloth)
    sim.refresh()
    return float(best[0])


def fit_behavior(sim: ImplicitSimulator, train: list[Observed], config: FitConfig,
                 on_iteration: Callable[[str, int, float, float], None] | None = None
                 ) -> tuple[BehaviorParams, FitLog]:
    """Fit global material, then per-vertex material offsets and rest lengths with regularization, each by
    L-BFGS on the one-frame loss (the global problem is small but badly scaled: bending barely moves one frame,
    which first-order methods crawl along). The cloth of `sim` is left with the best parameters seen."""
    params = BehaviorParams(sim.cloth, {n: float(getattr(sim.cloth.material, n).mean()) for n in MATERIAL_NAMES},
                            sim.terms, config.term_params, config.held)
    problem = TeacherForced(sim, train, config.max_samples, config.seed, horizon=config.horizon)
    log = FitLog()
    stages = [("global", [params.global_z, params.term_s], config.global_iterations, None),
              ("local", [params.vertex_z, params.edge_s], config.local_iterations,
               lambda: params.regularizer(config.w_offset, config.w_smooth, config.w_rest))]
    for name, trainable, iterations, reg in stages:
        if iterations <= 0:
            continue

        def evaluate() -> tuple[float, list[torch.Tensor]]:
            loss, l2, grads = problem.evaluate(params, trainable, reg)
            log.stage.append(name)
            log.loss.append(loss)
            log.l2.append(l2)
            if on_iteration is not None:
                on_iteration(name, len(log.loss), loss, l2)
            return loss, grads

        minimize_lbfgs(sim, params, trainable, evaluate, iterations)
    return params, log
