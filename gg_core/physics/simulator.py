"""The Simulator interface (step, rollout) and its implicit energy-minimizing implementation.

A learned graph-network simulator can implement the same interface later: it maps a cloth state and the body at
the start and end of a frame to the next cloth state.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Callable, Protocol

import numpy as np

from .cloth import Cloth
from .contact import BodyCollider, BodyPose, Proximity
from .energies import Collision, vertex_normals
from .forces import make_terms
from .solver import SolverOptions, SolveStats, minimize
from .terms import StepInputs, Term


@dataclass
class ClothState:
    x: np.ndarray  # [V,3] positions
    v: np.ndarray  # [V,3] velocities (m/s)


class Simulator(Protocol):
    """Advance a garment over one body frame, or over a whole body sequence."""

    fps: float

    def step(self, state: ClothState, body_now: np.ndarray | None, body_next: np.ndarray | None,
             pin_next: np.ndarray | None = None) -> ClothState: ...

    def rollout(self, state: ClothState, body_frames: np.ndarray | None, n_frames: int | None = None,
                pin_frames: np.ndarray | None = None,
                callback: Callable[[int, ClothState], None] | None = None) -> np.ndarray: ...


@dataclass
class StepLog:
    newton_iterations: list[int] = field(default_factory=list)
    cg_iterations: list[int] = field(default_factory=list)

    def add(self, s: SolveStats) -> None:
        self.newton_iterations.append(s.newton_iterations)
        self.cg_iterations.append(s.cg_iterations)


class ImplicitSimulator:
    """Backward-Euler cloth: each substep minimizes the incremental potential of `terms` (default: the base terms
    + body friction) with the Newton-PCG solver; the body (if any) is a BodyCollider whose vertex positions are
    given per frame and interpolated linearly across substeps."""

    def __init__(self, cloth: Cloth, terms: list[Term] | None = None, collider: BodyCollider | None = None,
                 fps: float = 30.0, substeps: int = 1, options: SolverOptions | None = None,
                 contact_reach: float = 0.05) -> None:
        self.cloth = cloth
        self.terms = terms if terms is not None else make_terms()
        self.collider = collider
        self.fps = float(fps)
        self.substeps = int(substeps)
        self.options = options or SolverOptions()
        self.contact_reach = contact_reach
        self.num = cloth.numeric()
        self.log = StepLog()
        self._collision = next((t for t in self.terms if isinstance(t, Collision)), None)
        self._poses: list[tuple[np.ndarray, BodyPose]] = []
        self._last_query: tuple[np.ndarray, np.ndarray, Proximity] | None = None

    def refresh(self) -> None:
        """Re-read the cloth's parameters (after fitting changed them)."""
        self.num = self.cloth.numeric()

    @property
    def dt(self) -> float:
        return 1.0 / (self.fps * self.substeps)

    def prepare(self, x: np.ndarray, v: np.ndarray, body_now: np.ndarray | None, body_next: np.ndarray | None,
                dt: float, pin_target: np.ndarray | None = None) -> StepInputs:
        """Inputs of one step from state (x, v) while the body moves from body_now to body_next."""
        n = len(x)
        zeros3 = np.zeros((n, 3))
        active = np.zeros(n)
        point, normal, motion, distance = zeros3, zeros3, zeros3, np.zeros(n)
        if self.collider is not None and body_now is not None:
            now, nxt = self._pose(body_now), self._pose(body_next)
            prox = self._query(x, body_now)
            c_now, _ = self.collider.surface_point(prox, now)
            point, normal = self.collider.surface_point(prox, nxt)
            motion = point - c_now
            active = prox.found.astype(np.float64)
            distance = np.where(prox.found, prox.distance, 0.0)
        step = StepInputs(dt=dt, x_prev=x, v_prev=v, pin_target=x if pin_target is None else pin_target,
                          contact_active=active, contact_point=point, contact_normal=normal, contact_motion=motion,
                          contact_distance=distance, contact_force=np.zeros(n),
                          normal_prev=vertex_normals(x, self.num.faces))
        return self.with_contact_force(step)

    def with_contact_force(self, step: StepInputs) -> StepInputs:
        """The step with friction's normal forces at its start state, for the current collision parameters (with
        SolverOptions.friction_at_end only the first solve's)."""
        return replace(step, contact_force=self._penalty_force(step.contact_distance, step))

    def _penalty_force(self, distance: np.ndarray, step: StepInputs) -> np.ndarray:
        """The collision penalty's force (N) at signed distances [V] from the step's contact planes (zero where
        there is no contact or no penalty)."""
        if self._collision is None:
            return np.zeros(len(distance))
        return self._collision.normal_force(distance, self.num.vertex_area) * step.contact_active

    def _pose(self, verts: np.ndarray) -> BodyPose:
        """Posed body with normals; the two most recent are kept, since each frame is the end of one step and
        the start of the next. Arrays viewing the same memory are the same frame (body frames are never modified
        in place, and the cache holds a reference, so the memory cannot be reused for another frame)."""
        for key, pose in self._poses:
            if _same_array(key, verts):
                return pose
        pose = self.collider.pose(verts)
        self._poses = [self._poses[-1], (verts, pose)] if self._poses else [(verts, pose)]
        return pose

    def _query(self, x: np.ndarray, body: np.ndarray) -> Proximity:
        """Closest body points of x; the check after a solve is the next step's start query, so it is kept."""
        key = self._last_query
        if key is not None and key[0] is x and _same_array(key[1], body):
            return key[2]
        prox = self.collider.query(x, self._pose(body), reach=self.contact_reach)
        self._last_query = (x, body, prox)
        return prox

    def initial_guess(self, step: StepInputs) -> np.ndarray:
        """Inertial prediction, with vertices that would end deeper than a third of the collision margin moved
        out to it: the Newton iterations then start near the contact solution, where the cubic penalty already
        has curvature, instead of deep inside the stiff penalty."""
        x = step.x_prev + step.dt * step.v_prev
        if self._collision is not None:
            margin = self._collision.p("margin")
            gap = margin - ((x - step.contact_point) * step.contact_normal).sum(1)
            push = np.maximum(gap - margin / 3, 0.0) * step.contact_active
            x = x + push[:, None] * step.contact_normal
        return x

    def solve(self, step: StepInputs, body_next: np.ndarray | None = None) -> tuple[np.ndarray, StepInputs]:
        """Minimize the step's potential. Vertices that end within half the margin of body_next without a
        contact (they were out of reach at the start, e.g. a flap swinging in), or inside it behind a stale
        contact plane, get the plane at their new closest body point and the step is solved again from there.
        Returns the positions and the step inputs they minimize (fitting differentiates exactly that)."""
        x, stats = minimize(self.initial_guess(step), step, self.terms, self.num, self.options)
        if self.collider is not None and body_next is not None and self._collision is not None:
            prox = self._query(x, body_next)
            missing = prox.found & (prox.distance < 0.5 * self._collision.p("margin")) & (
                (step.contact_active == 0) | (prox.distance < 0))
            if missing.any():
                point, normal = self.collider.surface_point(prox, self._pose(body_next))
                m = missing[:, None]
                step = replace(step, contact_active=np.where(missing, 1.0, step.contact_active),
                               contact_point=np.where(m, point, step.contact_point),
                               contact_normal=np.where(m, normal, step.contact_normal),
                               contact_motion=np.where(m, 0.0, step.contact_motion))
                x, more = minimize(x, step, self.terms, self.num, self.options)
                stats.add(more)
        if self.options.friction_at_end and step.contact_active.any() and any(
                t.name == "body_friction" for t in self.terms):
            step = replace(step, contact_force=self.end_contact_force(x, step))
            x, more = minimize(x, step, self.terms, self.num, self.options)
            stats.add(more)
        self.log.add(stats)
        return x, step

    def end_contact_force(self, x: np.ndarray, step: StepInputs) -> np.ndarray:
        """Friction's normal force with SolverOptions.friction_at_end: the collision penalty's force at the step's
        solved end positions x, and the step is solved once more with it (one lagged update, as IPC lags
        friction's normal force). By default friction takes the force at the start state.

        Why: where a step starts from an observed state (fitting, residuals), the observed cloth may sit deeper
        in the contact margin than this model's own equilibrium, and the stiff penalty there is no force that
        acts: measured on the benchmark t-shirt (margin 15 mm), the start force was a median 259 vertex weights
        at observed states against 8 in free rollouts, so every contact stuck in teacher-forced steps whatever
        the friction coefficient, and fits could not see it. The end state is this model's own contact solution,
        observed start or not. Not the default: the second solve halves `gg bench sim` (17.6 -> 7.6 fps, Newton
        iterations 3 -> 6 a step). Taking it only for steps from observed states (rollouts keeping the start's)
        cost nothing but lost the gravity tilt of the small Blender test capture (-8.6 % held-out, < 10 %;
        -26.6 % with every step)."""
        return self._penalty_force(((x - step.contact_point) * step.contact_normal).sum(1), step)

    def step(self, state: ClothState, body_now: np.ndarray | None, body_next: np.ndarray | None,
             pin_next: np.ndarray | None = None) -> ClothState:
        """One frame. Pinned vertices move linearly from their current position to `pin_next` [V,3] (default:
        they stay)."""
        x, v = state.x, state.v
        pin_start = x
        for s in range(self.substeps):
            t0, t1 = s / self.substeps, (s + 1) / self.substeps
            b0 = b1 = None
            if body_now is not None:
                b0, b1 = blend(body_now, body_next, t0), blend(body_now, body_next, t1)
            pin = None if pin_next is None else blend(pin_start, pin_next, t1)
            x_new, _ = self.solve(self.prepare(x, v, b0, b1, self.dt, pin), b1)
            v = (x_new - x) / self.dt
            x = x_new
        return ClothState(x, v)

    def rollout(self, state: ClothState, body_frames: np.ndarray | None, n_frames: int | None = None,
                pin_frames: np.ndarray | None = None,
                callback: Callable[[int, ClothState], None] | None = None) -> np.ndarray:
        """Positions [T,V,3] for the body frames [T,Vb,3] (frame 0 = the given state); without a body, n_frames.
        `pin_frames` [T,V,3] gives the pinned vertices' positions per frame."""
        total = len(body_frames) if body_frames is not None else int(n_frames)
        out = np.empty((total, len(state.x), 3))
        out[0] = state.x
        for t in range(1, total):
            b0 = body_frames[t - 1] if body_frames is not None else None
            b1 = body_frames[t] if body_frames is not None else None
            state = self.step(state, b0, b1, None if pin_frames is None else pin_frames[t])
            out[t] = state.x
            if callback is not None:
                callback(t, state)
        return out


def _same_array(a: np.ndarray, b: np.ndarray) -> bool:
    """Same object or a view of the same memory with the same layout (indexing a frame creates a new view)."""
    return a is b or (a.__array_interface__["data"][0] == b.__array_interface__["data"][0]
                      and a.shape == b.shape and a.strides == b.strides)


def blend(a: np.ndarray, b: np.ndarray, t: float) -> np.ndarray:
    """Linear interpolation that returns the frames themselves at t = 0 and 1, so the per-frame caches hit."""
    if t == 0.0:
        return a
    if t == 1.0:
        return b
    return (1 - t) * a + t * b
