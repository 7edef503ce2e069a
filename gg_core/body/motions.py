"""Procedural body motions (walk, arm swing, torso twist, squat, jump, idle) for any BodyModel.

Motions are written on canonical SMPL-X joint names (resolved through BodyModel.aliases), on swing axes
derived from the rest geometry ("swing this arm forward", "raise it") and on the sagittal axis for legs,
so the same motion drives the anny body and an SMPL-X body. Each motion is a smooth function of time; the
root height then comes from foot contact (the lowest sole point touches y=0) except while airborne, which
gives walking its natural bob and keeps squats and landings on the floor. A seed varies period, phase and
amplitude by a few percent.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..errors import InputError
from .model import BodyModel, skin

MOTIONS: tuple[str, ...] = ("rest", "idle", "walk", "arm_swing", "torso_twist", "squat", "jump")
GRAVITY = 9.81
# Rest vertices this close to the floor are the soles used for foot contact.
_SOLE_HEIGHT_M = 0.02
_DEG = np.pi / 180.0


@dataclass(frozen=True)
class _Variation:
    """Per-seed jitter: period scale, phase (fraction of a cycle) and amplitude gain."""

    period: float
    phase: float
    gain: float


@dataclass
class _Raw:
    """A motion before grounding: rotations [T,J,3], root translation [T,3], and which frames stand on the
    floor (their root height comes from foot contact; the others keep translation[:, 1]). `plant` keeps the
    ankles' midpoint fixed horizontally (all motions but the in-place walk). `contact_smoothing` (s) > 0
    averages the floor contact over time: handing the contact from one foot to the other is a kink in the
    lowest-sole height that would jolt the body (and the cloth on it) at every step."""

    rotations: np.ndarray
    translation: np.ndarray
    grounded: np.ndarray
    plant: bool
    contact_smoothing: float = 0.0


class _Rig:
    """Canonical joints of a body and the rest-geometry swing axes motions are written in."""

    def __init__(self, body: BodyModel) -> None:
        self.body = body
        self.soles = np.flatnonzero(body.rest_vertices[:, 1] < body.rest_vertices[:, 1].min() + _SOLE_HEIGHT_M)

    def j(self, name: str) -> int:
        return self.body.joint(name)

    def _direction(self, joint: str, child: str) -> np.ndarray:
        d = self.body.rest_joints[self.j(child)] - self.body.rest_joints[self.j(joint)]
        return d / np.linalg.norm(d)

    def forward_axis(self, joint: str, child: str) -> np.ndarray:
        """Axis whose positive rotation at `joint` swings the segment joint->child toward +Z (forward)."""
        a = np.cross(self._direction(joint, child), [0.0, 0.0, 1.0])
        return a / np.linalg.norm(a)

    def raise_axis(self, joint: str, child: str) -> np.ndarray:
        """Axis whose positive rotation at `joint` swings the segment joint->child toward +Y (up)."""
        a = np.cross(self._direction(joint, child), [0.0, 1.0, 0.0])
        return a / np.linalg.norm(a)

    def empty(self, n: int) -> _Raw:
        return _Raw(np.zeros((n, self.body.n_joints, 3)), np.zeros((n, 3)), np.ones(n, dtype=bool), True)

    def add(self, raw: _Raw, joint: str, axis: np.ndarray, angle: np.ndarray) -> None:
        """Add a rotation of `angle` [T] radians about `axis` to a joint (small-angle composition)."""
        raw.rotations[:, self.j(joint)] += np.asarray(angle)[:, None] * axis

    # Composite channels shared by several motions; angles in radians, [T] arrays.
    def leg(self, raw: _Raw, side: str, hip: np.ndarray, knee: np.ndarray, ankle: np.ndarray) -> None:
        """Sagittal leg: hip flexion (thigh forward), knee flexion (shank back), ankle dorsiflexion (toes up).
        All three turn about -X, which keeps every point of the leg at its x: a planted foot cannot slide
        sideways however the joints bend."""
        axis = np.array([-1.0, 0.0, 0.0])
        self.add(raw, f"{side}_hip", axis, hip)
        self.add(raw, f"{side}_knee", axis, -knee)
        self.add(raw, f"{side}_ankle", axis, ankle)

    def arm(self, raw: _Raw, side: str, swing: np.ndarray, lift: np.ndarray, elbow: np.ndarray) -> None:
        """Arm: shoulder swing forward, sideways lift (abduction) from the A-pose, elbow flexion."""
        self.add(raw, f"{side}_shoulder", self.forward_axis(f"{side}_shoulder", f"{side}_elbow"), swing)
        self.add(raw, f"{side}_shoulder", self.raise_axis(f"{side}_shoulder", f"{side}_elbow"), lift)
        self.add(raw, f"{side}_elbow", self.forward_axis(f"{side}_shoulder", f"{side}_elbow"), elbow)

    def spine(self, raw: _Raw, flex: np.ndarray, twist: np.ndarray) -> None:
        """Spread a forward bend and a twist (about +Y, turning the chest to the left) over the spine."""
        for name in ("spine1", "spine2", "spine3"):
            self.add(raw, name, np.array([1.0, 0.0, 0.0]), flex / 3.0)
            self.add(raw, name, np.array([0.0, 1.0, 0.0]), twist / 3.0)


def _bump(phase: np.ndarray, centre: float, sharpness: int) -> np.ndarray:
    """Smooth periodic bump in [0,1] peaking at `centre` (radians), narrower for higher `sharpness`."""
    return ((1.0 + np.cos(phase - centre)) / 2.0) ** sharpness


def _hermite(t: np.ndarray, knots: np.ndarray, values: np.ndarray, slopes: np.ndarray) -> np.ndarray:
    """C1 cubic Hermite curve through (knots, values) with the given slopes; t clipped to the knot range."""
    t = np.clip(t, knots[0], knots[-1])
    i = np.clip(np.searchsorted(knots, t, side="right") - 1, 0, len(knots) - 2)
    h = knots[i + 1] - knots[i]
    u = (t - knots[i]) / h
    h00, h10, h01, h11 = 2 * u**3 - 3 * u**2 + 1, u**3 - 2 * u**2 + u, -2 * u**3 + 3 * u**2, u**3 - u**2
    return h00 * values[i] + h10 * h * slopes[i] + h01 * values[i + 1] + h11 * h * slopes[i + 1]


def _gait(fraction: float) -> float:
    """Leg phase of a point of the gait cycle, given as a fraction (0: heel strike, 0.6: toe-off)."""
    return np.pi / 2 + 2 * np.pi * fraction


def _rest(rig: _Rig, t: np.ndarray, var: _Variation, amp: float) -> _Raw:
    return rig.empty(len(t))


def _idle(rig: _Rig, t: np.ndarray, var: _Variation, amp: float) -> _Raw:
    """Standing: breathing, a slow weight shift, slightly swaying arms and head."""
    raw = rig.empty(len(t))
    breath = 2 * np.pi * t / (4.0 * var.period) + 2 * np.pi * var.phase
    sway = breath / 2.0
    rig.spine(raw, amp * 2.0 * _DEG * np.sin(breath), amp * 3.0 * _DEG * np.sin(sway))
    rig.add(raw, "pelvis", np.array([0.0, 0.0, 1.0]), amp * 1.5 * _DEG * np.sin(sway))
    rig.add(raw, "head", np.array([1.0, 0.0, 0.0]), amp * 3.0 * _DEG * np.sin(breath + 1.0))
    for sign, side in ((1.0, "left"), (-1.0, "right")):
        rig.arm(raw, side, amp * 4.0 * _DEG * np.sin(sway + sign), amp * 2.0 * _DEG * (1 + np.sin(breath)),
                amp * 5.0 * _DEG * (1 + np.sin(sway)))
    return raw


def _walk(rig: _Rig, t: np.ndarray, var: _Variation, amp: float) -> _Raw:
    """In-place walk, 1.1 s stride (~110 steps/min): hip, knee and ankle gait curves, pelvis and chest
    counter-rotation, arms swinging against the legs, lateral sway; the bob comes from foot contact."""
    raw = rig.empty(len(t))
    raw.plant = False
    raw.contact_smoothing = 0.04
    phase = 2 * np.pi * (t / (1.1 * var.period) + var.phase)
    for sign, side in ((0.0, "left"), (np.pi, "right")):
        p = phase + sign  # this leg's phase: heel strike at p = pi/2, where hip flexion peaks
        hip = 5 * _DEG + 18 * _DEG * np.sin(p)
        knee = 5 * _DEG + 15 * _DEG * _bump(p, _gait(0.15), 6) + 55 * _DEG * _bump(p, _gait(0.72), 3)
        ankle = (10 * _DEG * _bump(p, _gait(0.42), 4) - 18 * _DEG * _bump(p, _gait(0.62), 10)
                 + 3 * _DEG * _bump(p, _gait(0.85), 4))
        rig.leg(raw, side, amp * hip, amp * knee, amp * ankle)
        # Arms counter-swing: this arm goes forward when the other leg does.
        rig.arm(raw, side, amp * (4 * _DEG - 18 * _DEG * np.sin(p)), np.zeros_like(t),
                amp * (18 * _DEG - 10 * _DEG * np.sin(p)))
    rig.add(raw, "pelvis", np.array([0.0, 1.0, 0.0]), amp * -5 * _DEG * np.sin(phase))
    rig.spine(raw, amp * np.full_like(t, 3 * _DEG), amp * 8 * _DEG * np.sin(phase))
    raw.translation[:, 0] = amp * -0.02 * np.cos(phase)
    return raw


def _arm_swing(rig: _Rig, t: np.ndarray, var: _Variation, amp: float) -> _Raw:
    """Both arms swinging forward and back in opposition (±45 degrees, 1.6 s), lifting a little sideways."""
    raw = rig.empty(len(t))
    phase = 2 * np.pi * (t / (1.6 * var.period) + var.phase)
    for sign, side in ((1.0, "left"), (-1.0, "right")):
        s = np.sin(phase) * sign
        rig.arm(raw, side, amp * 45 * _DEG * s, amp * 15 * _DEG * (1 - np.cos(2 * phase)) / 2,
                amp * (20 * _DEG + 15 * _DEG * s))
    rig.spine(raw, np.zeros_like(t), amp * -6 * _DEG * np.sin(phase))
    return raw


def _torso_twist(rig: _Rig, t: np.ndarray, var: _Variation, amp: float) -> _Raw:
    """Chest turning ±35 degrees over the spine (2.4 s) with the head following and the arms flung out."""
    raw = rig.empty(len(t))
    phase = 2 * np.pi * (t / (2.4 * var.period) + var.phase)
    twist = amp * 35 * _DEG * np.sin(phase)
    rig.spine(raw, np.zeros_like(t), twist)
    rig.add(raw, "neck", np.array([0.0, 1.0, 0.0]), 0.3 * twist)
    for sign, side in ((1.0, "left"), (-1.0, "right")):
        rig.arm(raw, side, amp * 15 * _DEG * np.sin(phase + np.pi / 2) * sign,
                amp * 12 * _DEG * (1 - np.cos(2 * phase)) / 2, amp * np.full_like(t, 25 * _DEG))
    return raw


def _crouch(rig: _Rig, raw: _Raw, depth: np.ndarray) -> None:
    """Crouch of depth [T] in [0,1]: hips, knees and ankles bend with the feet flat (ankle = knee - hip)
    and the trunk leans forward."""
    hip, knee = 70 * _DEG * depth, 100 * _DEG * depth
    for side in ("left", "right"):
        rig.leg(raw, side, hip, knee, knee - hip)
    rig.spine(raw, 20 * _DEG * depth, np.zeros_like(depth))


def _squat(rig: _Rig, t: np.ndarray, var: _Variation, amp: float) -> _Raw:
    """Squats down and up (3 s), arms raised forward for balance; feet planted flat."""
    raw = rig.empty(len(t))
    phase = 2 * np.pi * (t / (3.0 * var.period) + var.phase)
    depth = amp * (1 - np.cos(phase)) / 2
    _crouch(rig, raw, depth)
    for side in ("left", "right"):
        rig.arm(raw, side, 55 * _DEG * depth, np.zeros_like(t), 15 * _DEG * depth)
    return raw


def _crouch_drop(rig: _Rig) -> tuple[np.ndarray, np.ndarray]:
    """Pelvis drop (m) of crouch depths 0..1 on this body: the lowest sole point's rise, by forward kinematics."""
    depth = np.linspace(0.0, 1.0, 21)
    raw = rig.empty(len(depth))
    _crouch(rig, raw, depth)
    return depth, _lowest_sole(rig, raw.rotations) - rig.body.rest_vertices[:, 1].min()


def _jump(rig: _Rig, t: np.ndarray, var: _Variation, amp: float) -> _Raw:
    """Counter-movement jump: crouch with the arms back, push off swinging them forward, a ballistic flight
    (pelvis rising `0.22 m * amplitude`) with the legs extending and bending again, a landing crouch that
    absorbs the fall, and standing up. The legs leave and meet the floor still bent: the take-off speed
    then needs a knee extension rate of ~10 rad/s (a straight leg would need an infinite one)."""
    raw = rig.empty(len(t))
    if amp <= 0.0:
        return raw
    v0 = np.sqrt(2 * GRAVITY * 0.22 * amp)
    flight = 2 * v0 / GRAVITY
    contact_depth = 0.45 * amp
    depth_grid, drop_grid = _crouch_drop(rig)
    drop_rate = np.interp(contact_depth, depth_grid, np.gradient(drop_grid, depth_grid))
    rate = v0 / max(drop_rate, 1e-6)  # crouch-depth rate that moves the pelvis at v0 at take-off and landing
    takeoff = 0.75
    landing = takeoff + flight
    period = landing + 0.9
    local = np.mod(t + var.phase * period, period)
    knots = np.array([0.0, 0.45, takeoff, takeoff + flight / 2, landing, landing + 0.3, period])
    depth = _hermite(local, knots, amp * np.array([0.0, 1.0, 0.45, 0.12, 0.45, 0.7, 0.0]),
                     np.array([0.0, 0.0, -rate, 0.0, rate, 0.0, 0.0]))
    _crouch(rig, raw, depth)
    arm_values = amp * _DEG * np.array([0.0, -25.0, 25.0, 20.0, 5.0, -10.0, 0.0])
    slopes = np.gradient(arm_values, knots)
    slopes[[0, -1]] = 0.0
    swing = _hermite(local, knots, arm_values, slopes)
    for side in ("left", "right"):
        rig.arm(raw, side, swing, np.zeros_like(t), 20 * _DEG * depth)
    tau = local - takeoff
    raw.grounded = (tau <= 0) | (tau >= flight)
    contact_height = -np.interp(contact_depth, depth_grid, drop_grid)
    raw.translation[:, 1] = contact_height + v0 * tau - GRAVITY * tau**2 / 2
    return raw


_GENERATORS: dict[str, Callable[[_Rig, np.ndarray, _Variation, float], _Raw]] = {
    "rest": _rest, "idle": _idle, "walk": _walk, "arm_swing": _arm_swing, "torso_twist": _torso_twist,
    "squat": _squat, "jump": _jump,
}


def _lowest_sole(rig: _Rig, rotations: np.ndarray) -> np.ndarray:
    """Height [T] of the lowest sole point per frame, root untranslated."""
    body = rig.body
    world, posed = body.joint_transforms(rotations)
    shift = posed - np.einsum("tjab,jb->tja", world, body.rest_joints.astype(np.float64))
    heights = skin(body.rest_vertices[rig.soles], body.weights[rig.soles], world, shift)[..., 1]
    return heights.min(axis=1).astype(np.float64)


def _planted(rig: _Rig, raw: _Raw) -> np.ndarray:
    """Root translation [T,3] with the ankles' midpoint held over its rest position when `raw.plant`."""
    translation = raw.translation.copy()
    if raw.plant:
        ankles = [rig.j("left_ankle"), rig.j("right_ankle")]
        posed = rig.body.posed_joints(raw.rotations)[:, ankles].mean(axis=1)
        rest = rig.body.rest_joints[ankles].mean(axis=0)
        translation[:, [0, 2]] += rest[[0, 2]] - posed[:, [0, 2]]
    return translation


def _ease_in(t: np.ndarray, start: float, duration: float) -> np.ndarray:
    """Quintic smoothstep from 0 at `start` to 1 at `start + duration` (zero velocity and acceleration at
    both ends); all ones when there is no ease-in."""
    if duration <= 0.0:
        return np.ones_like(t)
    u = np.clip((t - start) / duration, 0.0, 1.0)
    return u**3 * (10 - 15 * u + 6 * u**2)


def _generate(body: BodyModel, name: str, t: np.ndarray, seed: int, amplitude: float,
              ease_start: float = 0.0, ease_duration: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Rotations [T,J,3] and root translation [T,3] at times `t` (s), eased in from the rest pose."""
    if name not in _GENERATORS:
        raise InputError(f"unknown motion '{name}'", "--motion", "use one of: " + ", ".join(MOTIONS))
    if not amplitude >= 0.0:
        raise InputError(f"motion amplitude {amplitude} is negative", "--amplitude", "use 0 (rest) or more")
    rng = np.random.default_rng(seed)
    var = _Variation(period=1.0 + rng.uniform(-0.05, 0.05), phase=rng.uniform(-0.05, 0.05),
                     gain=1.0 + rng.uniform(-0.1, 0.1))
    rig = _Rig(body)

    def raw_at(times: np.ndarray) -> _Raw:
        raw = _GENERATORS[name](rig, times, var, amplitude * var.gain)
        ease = _ease_in(times, ease_start, ease_duration)
        raw.rotations *= ease[:, None, None]
        raw.translation *= ease[:, None]
        return raw

    raw = raw_at(t)
    translation = _planted(rig, raw)
    if raw.contact_smoothing > 0.0:
        # Gaussian average of the floor contact over neighbouring instants (the motion itself re-sampled,
        # so the result does not depend on the frame rate or the clip's ends).
        offsets = raw.contact_smoothing * np.linspace(-2.5, 2.5, 11)
        kernel = np.exp(-0.5 * (offsets / raw.contact_smoothing) ** 2)
        kernel /= kernel.sum()
        contact = sum(k * -_lowest_sole(rig, raw_at(t + o).rotations) for k, o in zip(kernel, offsets))
    else:
        contact = -_lowest_sole(rig, raw.rotations)
    translation[:, 1] = np.where(raw.grounded, contact, translation[:, 1])
    return raw.rotations, translation


def motion(body: BodyModel, name: str, n_frames: int, fps: int = 30, seed: int = 0,
           amplitude: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Local joint rotations [T,J,3] (axis-angle) and root translation [T,3] of a named motion."""
    return _generate(body, name, np.arange(n_frames) / fps, seed, amplitude)


def animate(body: BodyModel, name: str, n_frames: int, fps: int = 30, seed: int = 0,
            amplitude: float = 1.0, settle_frames: int = 0) -> np.ndarray:
    """Posed vertices [settle_frames + T, V, 3]. The settle frames start in the rest (A-)pose and ease
    (quintic smoothstep, zero velocity and acceleration at the start) into the motion, which they join at
    its first frame with matching velocity; the last T frames equal `motion(...)` posed."""
    t = np.arange(-settle_frames, n_frames) / fps
    ease = settle_frames / fps
    rotations, translation = _generate(body, name, t, seed, amplitude, -ease, ease)
    return body.pose(rotations, translation)
