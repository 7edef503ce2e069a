"""Residuals: what the fitted simulator's own implicit step leaves unexplained, frame by frame.

From the observed x_t (velocity from x_{t-1}, x_t) and the body, the simulator steps one frame exactly as its
rollouts do (same substeps, contact handling, pins following their observations) to x*_{t+1}. The residual force
is the gradient of the step's incremental potential at the observed x_{t+1}, r = m a - f_model; one Newton step
turns it into the one-frame position error x_{t+1} - x* ~ H^-1 r (H the step's Hessian). The diagnosis works with
that position error: in force space r is dominated by stiff membrane modes (a strain error of 1e-3 on a light
fabric is hundreds of m/s^2, yet the step corrects it within the frame), while H^-1 r keeps what the motion
shows (equal to r h^2 / m in inertia-dominated modes); under white position noise it is also the
generalized-least-squares weighting. It is shown as an acceleration, (x_{t+1} - x*) / h^2 in m/s^2, h the frame
time. How a change of the model moves x* (`responses`) is measured the same way, through the simulator itself,
so the regression stays within the simulator's own discretization.

Noise: position noise sigma gives acceleration noise ~ sqrt(6) sigma fps^2 (2.2 m/s^2 per mm at 30 fps). It is
cut by pooling in the weak form (`Pooling`): displacements are averaged over spatial patches (mass-weighted) and
over smooth time windows (summation by parts moves the second difference of x onto the window, so independent
per-frame noise is averaged instead of amplified).
"""
from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass, replace
from typing import Callable, ContextManager, Iterator

import numpy as np
import torch
from scipy.cluster.vq import kmeans2

from ..physics.fitting import BehaviorParams, Observed
from ..physics.simulator import ClothState, ImplicitSimulator
from ..physics.terms import StepInputs


@dataclass
class FrameBatch:
    """Teacher-forced one-frame steps of observed sequences: the states the residual is measured at."""

    steps: list[StepInputs]    # per step, numpy, dt = one frame: observed start state, contacts, normals
    bodies: list[tuple[np.ndarray | None, np.ndarray | None]]   # body at the start and end of each step
    x_next: np.ndarray         # [N,V,3] observed end positions
    sequence: np.ndarray       # [N] index into `names`
    frame: np.ndarray          # [N] frame index of the step start
    names: list[str]
    dt: float

    def stacked(self, sim: ImplicitSimulator, ends: np.ndarray | None = None) -> StepInputs:
        """Torch batch with friction's normal forces for the simulator's current collision parameters: at `ends`
        [N,V,3], the simulator's own one-frame predictions, as its steps take them (ImplicitSimulator.solve), or
        lagged from the observed start states."""
        if ends is None:
            return StepInputs.stack([sim.with_contact_force(s) for s in self.steps])
        return StepInputs.stack([replace(s, contact_force=sim.end_contact_force(x, s))
                                 for s, x in zip(self.steps, ends)])

    @property
    def velocity(self) -> np.ndarray:
        """[N,V,3] velocity over each step (m/s)."""
        return (self.x_next - np.stack([s.x_prev for s in self.steps])) / self.dt

    @property
    def acceleration(self) -> np.ndarray:
        """[N,V,3] second difference of the positions (m/s^2)."""
        return (self.x_next - np.stack([s.x_inertial for s in self.steps])) / self.dt ** 2


def build_frames(sim: ImplicitSimulator, sequences: list[Observed]) -> FrameBatch:
    steps, bodies, x_next, seq, frame = [], [], [], [], []
    for k, obs in enumerate(sequences):
        g, b, dt = obs.garment, obs.body, 1.0 / obs.fps
        for t in range(1, len(g) - 1):
            pair = (None, None) if b is None else (b[t], b[t + 1])
            steps.append(sim.prepare(g[t], (g[t] - g[t - 1]) / dt, *pair, dt, pin_target=g[t + 1]))
            bodies.append(pair)
            x_next.append(g[t + 1])
            seq.append(k)
            frame.append(t)
    return FrameBatch(steps, bodies, np.stack(x_next), np.array(seq), np.array(frame), [o.name for o in sequences],
                      1.0 / sequences[0].fps)


def predict(sim: ImplicitSimulator, batch: FrameBatch) -> np.ndarray:
    """[N,V,3] the simulator's one-frame predictions from the observed states (pins follow the observation)."""
    return np.stack([sim.step(ClothState(s.x_prev, s.v_prev), b0, b1, pin_next=x).x
                     for s, (b0, b1), x in zip(batch.steps, batch.bodies, batch.x_next)])


def residual(sim: ImplicitSimulator, batch: FrameBatch) -> np.ndarray:
    """[N,V,3] one-frame position error (m) of the simulator: observed minus predicted, zero on pins."""
    return (batch.x_next - predict(sim, batch)) * sim.num.free[None, :, None]


def responses(sim: ImplicitSimulator, batch: FrameBatch, base: np.ndarray,
              changes: list[tuple[float, Callable[[], ContextManager]]]) -> np.ndarray:
    """[K,N,V,3] change of the one-frame prediction per unit of each model change: for each (size, change), the
    prediction inside the `change()` context minus `base` (the unchanged prediction), over size."""
    out = []
    for size, change in changes:
        with change():
            out.append((predict(sim, batch) - base) * sim.num.free[None, :, None] / size)
    return np.stack(out)


@dataclass
class Pooling:
    """Weak-form pooling of per-vertex, per-step displacement fields into regression rows: mass-weighted patch
    means averaged over time windows, shown as accelerations (divided by the frame time squared, m/s^2)."""

    patch: np.ndarray          # [V] patch of each vertex, -1 for pinned vertices
    mass: np.ndarray           # [V] kg
    windows: np.ndarray        # [W,N] time weights, each row within one sequence, summing to 1
    window_sequence: np.ndarray  # [W] sequence index of each window
    contact: np.ndarray        # [N,V] bool: inside the collision margin at the observed end state
    dt: float

    @property
    def n_patches(self) -> int:
        return int(self.patch.max()) + 1

    def over_time(self, field: np.ndarray) -> np.ndarray:
        """[..., N, V, 3] -> [..., W, V, 3] window averages."""
        return np.einsum("wn,...nvc->...wvc", self.windows, field)

    def patch_means(self, field: np.ndarray) -> np.ndarray:
        """[..., V, 3] displacements -> [..., P, 3] mass-weighted patch means as accelerations (m/s^2)."""
        free = self.patch >= 0
        weights = np.zeros((self.n_patches, len(self.patch)))
        weights[self.patch[free], np.flatnonzero(free)] = self.mass[free]
        weights /= weights.sum(1, keepdims=True)
        return np.einsum("pv,...vc->...pc", weights, field) / self.dt ** 2

    def rows(self, field: np.ndarray) -> np.ndarray:
        """[..., N, V, 3] displacements -> [..., W*P*3] pooled rows."""
        pooled = self.patch_means(self.over_time(field))
        return pooled.reshape(*pooled.shape[:-3], -1)

    def groups(self, windows_per_block: int = 2) -> np.ndarray:
        """[W*P*3] resampling block of each row: runs of consecutive windows within one sequence."""
        block = np.zeros(len(self.window_sequence), int)
        for k in np.unique(self.window_sequence):
            idx = np.flatnonzero(self.window_sequence == k)
            block[idx] = k * len(self.window_sequence) + np.arange(len(idx)) // windows_per_block
        return np.repeat(block, self.n_patches * 3)


def make_pooling(sim: ImplicitSimulator, batch: FrameBatch, patch_vertices: int = 12, window: int = 6,
                 seed: int = 0) -> Pooling:
    """Patches of about `patch_vertices` free vertices (k-means on the template) and Hann windows of `window`
    frames, half-overlapping, within each sequence."""
    num = sim.num
    free = num.free > 0
    n_patches = max(4, int(free.sum()) // patch_vertices)
    _, labels = kmeans2(num.template[free], n_patches, seed=seed, minit="++")
    _, labels = np.unique(labels, return_inverse=True)          # drop empty clusters
    patch = np.full(len(free), -1)
    patch[free] = labels
    rows, seq_of_row = [], []
    for k in range(len(batch.names)):
        idx = np.flatnonzero(batch.sequence == k)
        length = min(window, len(idx))
        shape = np.hanning(length + 2)[1:-1]
        starts = list(range(0, len(idx) - length + 1, max(length // 2, 1)))
        if starts[-1] != len(idx) - length:
            starts.append(len(idx) - length)
        for s in starts:
            w = np.zeros(len(batch.sequence))
            w[idx[s:s + length]] = shape / shape.sum()
            rows.append(w)
            seq_of_row.append(k)
    margin = next((t.p("margin") for t in sim.terms if t.name == "collision"), 0.0)
    normals = np.stack([s.contact_normal for s in batch.steps])
    points = np.stack([s.contact_point for s in batch.steps])
    active = np.stack([s.contact_active for s in batch.steps]) > 0
    gap = ((batch.x_next - points) * normals).sum(-1)
    return Pooling(patch, num.mass, np.stack(rows), np.array(seq_of_row), active & (gap < margin), batch.dt)


def nuisance_changes(sim: ImplicitSimulator, params: BehaviorParams, h: float = 0.02
                     ) -> tuple[list[str], list[tuple[float, Callable[[], ContextManager]]]]:
    """One change per fitted global latent (material values not held, term log-scales), each a step of `h`, and a
    relative change `h` of the vertical gravity. Regressing on their responses with free coefficients judges a candidate
    against a re-adjusted baseline, since the global fit has already absorbed what the material can mimic.

    Gravity's magnitude is a nuisance because the rest shape is an observed frame: hanging under gravity, it is
    stretched, but the model takes it as stress-free, so every capture shows a missing upward force of the order
    of g (measured: an upward gravity offset of 6-10 m/s^2 explained 40-60 % of the residual on Blender skirts
    with and without hidden effects). Only the tilt of gravity stays identifiable (library.py)."""
    free = [(k, n) for k, n in enumerate(params.global_values()) if n not in params.held]
    latents = [(params.global_z, k) for k, _ in free] + [(params.term_s, k) for k in range(len(params.term_s))]
    labels = [f"material.{n}" for _, n in free] + [f"{t.name}.{k}" for t, k, _ in params.term_refs]

    def shift(tensor: torch.Tensor, k: int) -> Callable[[], ContextManager]:
        @contextmanager
        def shifted() -> Iterator[None]:
            tensor[k] += h
            params.apply(sim.cloth)
            sim.refresh()
            try:
                yield
            finally:
                tensor[k] -= h
                params.apply(sim.cloth)
                sim.refresh()
        return shifted

    changes = [(h, shift(t, k)) for t, k in latents]
    gravity = next((t for t in sim.terms if t.name == "gravity"), None)
    if gravity is not None:
        @contextmanager
        def heavier() -> Iterator[None]:
            g = gravity.params["g"]
            gravity.params["g"] = g * (1 + h)
            try:
                yield
            finally:
                gravity.params["g"] = g
        changes.append((h, heavier))
        labels.append("gravity.scale")
    return labels, changes
