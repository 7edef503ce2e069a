"""Multi-view stereo over a sequence's photometric fits: the template's photo-consistency sweep
(reconstruction.photo_consistency), run from each fitted mesh over a small depth range, with each round's score
curves averaged over neighbouring frames before their peaks are taken.

Why: the photometric fit compares renders of a Gaussian texture fitted on the template frame, which does not
reproduce the shading and occlusions of other poses; so each frame ends a few millimetres off the cloth and the
next frame starts there: the error accumulates (tracker.py). Patch correlation between the cameras' own images
of this frame needs no texture model, so it measures where the surface is now. Visibility is decided on the fitted
mesh itself and the frame's body (the fit is near the cloth: a fold's ridge hides its valley as it should).

What it holds still, measured (2026-11-26, session 11): nothing. While the step was fed back (the next frame
started from its output, below) the garment's border rings and the vertices touching the body had to be held: a
patch there straddles the cloth's edge or lies on the skin, two cameras that see the same background or leg can agree
at a wrong depth, and a wrong move compounded over the frames. Refining each frame's output only, such a move stays
in its frame, and holding costs more than it saves. On the stored photometric fits of the demo capture (walk frames
0, 5, ..., 29 / torso twist frames 2, 7, ..., 27; arm swing kept aside to confirm), CD / p2m (cm) / F@1cm:
- border's 2 rings and vertices within 5 mm of the body held (the earlier default): 0.423 / 0.381 / 92.2 % and
  0.436 / 0.389 / 91.3 %; 1 ring: 0.417 / 0.375 / 92.5 %; the border vertices alone and the body contacts:
  0.411 / 0.370 / 92.7 %; the border vertices alone: 0.395 / 0.353 / 93.3 %;
- nothing held: 0.389 / 0.348 / 93.6 % and 0.403 / 0.354 / 93.1 % (the hem's rings follow the cameras too);
- then a softer offset field, stiffness 4 / 2 / 1 / 0.5: walk 0.401 / 0.389 / 0.382 / 0.379 cm (F 93.1 / 93.6 /
  94.0 / 94.0 %), twist 0.417 / 0.403 / 0.393 / 0.386 cm; 3 rounds instead of 2 at stiffness 1: 0.377 / 0.340 /
  94.1 % and 0.389 / 0.345 / 93.6 %; no neighbour averaging of the score curves: 0.373 / 0.384 cm. Not better: a 3
  or 1.5 cm search, cameras within 73 degrees, the step run twice, smaller patches (3 samples, 0.7 pixels apart);
- then patches bent to the mesh's local quadric (photo_consistency.local_quadrics): 0.360 / 0.329 / 94.5 % and
  0.366 / 0.330 / 94.3 %; without averaging the score curves over neighbours (the template's 2 steps):
  0.356 / 0.325 / 94.6 % and 0.363 / 0.328 / 94.4 % (the default). Not kept: 4 rounds (0.354 / 0.323 / 94.7 % on the
  walk, a third more time), wider patches (7 samples, sigma 1.5: 0.361 cm), the step run twice (0.366 cm); earlier,
  planar patches: each sweep started from the fit plus half / all of the previous frame's correction (walk frames
  1-8: mean CD 0.366 -> 0.367 / 0.372 cm);
- then each camera's patch samples weighted by the frame's garment mask (the background beyond the hem and the skin
  above the waist kept out of the patches), from session 11's curved template's fits: 0.355 -> 0.352 / 0.328 ->
  0.323 / 94.59 -> 94.63 % and 0.363 -> 0.361 / 0.329 -> 0.327 / 94.50 -> 94.52 %. (On the template, sweeping from
  the hull, the masks do not help: CD 0.425 -> 0.425, 0.431 -> 0.432, 0.411 -> 0.419 cm on seeds 0, 3, 5.)
- then (session 12) the patches bent to 1.5 times the mesh's quadric: the registered meshes hold only 40-45 % of
  the truth's fold curvature (regression slope of our 2 cm-scale curvature on the truth's, walk frames 5 / 15 / 25:
  0.41 / 0.45 / 0.46), so a patch bent to the mesh's own quadric is still too flat at a crest. From session 11's
  final fits: 0.352 -> 0.349 / 0.323 -> 0.323 / 94.63 -> 94.80 % and 0.361 -> 0.358 / 0.327 -> 0.327 / 94.52 ->
  94.67 %; on arm swing frames 2, 7, ..., 27, kept aside: 0.375 -> 0.371 / 0.342 -> 0.342 / 93.89 -> 94.01 %.
  Gain 2: F@1cm 94.86 / 94.75 % but p2m 0.326 / 0.331 cm. Not kept: a softer field (stiffness 0.5 / 0.25: p2m
  0.334 / 0.355 cm on the walk), bicubic instead of bilinear image samples (0.349 / 0.320 / 94.71 % and 0.361 /
  0.328 / 94.48 %).

Earlier, fed back, with the border's 2 rings held (demo walk, frames 0-9 from the 0.441 cm template, CD of frames
0 / 4 / 9, mean, F@1cm): photometric fit alone 0.441 / 0.510 / 0.548, mean 0.502 (89.0 %), the drift; nothing held:
the hem went astray from frame 5 and took the fit with it (frame 9 3.13 cm); border's 2 rings held: the front hem,
where the swinging leg presses the skirt, went astray from frame 8; also vertices within 5 mm of the body: mean
0.415 cm, F@1cm 92.1 %, at 1.1 CPU-s per frame.
Over longer sequences, fed back, the step diverged: the full demo sequences (30 frames) held to frame 11 and
then went astray: walk 3.41 cm by frame 24, torso twist 3.31 cm by frame 23 (a wrong move starts the next frame off,
the fit follows partly, and the next sweep moves it further). So the step refines each frame's output only and the
next frame starts from the photometric fit (stage 2 keeps the fits in stage2/<sequence>/fit/, runs this step
over them once a sequence is fitted, and resumes from them). Demo walk, all 30 frames, with the holds: the fit
alone mean CD 0.530 cm (p2m 0.484 cm, F@1cm 87.9 %); refined 0.42-0.43 cm on every frame, mean 0.419 cm (0.377
cm, 92.4 %).

Score curves averaged over neighbouring frames (session 13, 2026-11-26). The error left after the temporal
filter (temporal.py) is mostly not frame-to-frame noise (its Savitzky-Golay window absorbs that), but a vertex's
score curve at frame t and at t +- 1, 2 measure the same material point a few millimetres apart along nearly the
same normal, so their average has a cleaner peak than either; each round now takes the peaks of the curves
averaged over `frames` frames with triangular weights (1, 2, 3, 2, 1 for 5), a vertex's own frame deciding
whether it has a say. Measured offline on session 12's final fits (/work/data/q7), all 30 frames, then the
temporal filter, CD / p2m (cm) / F@1cm: walk 0.332 / 0.304 / 95.62 % (one frame, 3 rounds: the stage as it was)
-> 3 frames 0.330 / 0.303 / 95.70 -> 5 frames 0.328 / 0.301 / 95.76 (7 frames evenly: 0.329 / 0.303 / 95.83);
with 5 frames, 4 rounds 0.326 / 0.301 / 95.80 % (kept: 4 rounds were +0.002 cm alone, session 11) and torso twist
0.351 / 0.320 / 94.93 -> 0.346 / 0.317 / 95.11 %, arm swing 0.367 / 0.339 / 94.15 -> 0.365 / 0.339 / 94.21 % (3
rounds: 0.367 / 0.339 / 94.19 %). Not kept, with 5 frames on the walk: a softer field (stiffness 0.5: 0.325 / 0.305 /
95.82 %), tighter patches (sigma 0.7 samples: 0.332 / 0.304 / 95.60 %), cameras within 66 degrees (0.330 / 0.303
/ 95.70 %). The rounds run in lock-step over the sequence as a wavefront, so only (rounds - 1) * frames // 2 + 1
frames' images are held at once. Cost: 6.1 s per frame with 4 rounds (demo walk, 5 frames, one core) with the
patch sampling in numpy, 2.3 s since it is one compiled pass (reconstruction/patch_kernels.py; the same meshes
to the last bit).

Which cameras see a vertex is decided with its normal smoothed over 3 steps (VISIBILITY_SMOOTHING; session 14,
2026-11-26): a fit's per-vertex normals carry the tilt of wrinkles smaller than a patch, which flips cameras near
the 60-degree cone in and out from vertex to vertex. Offline on session 13's fits (/work/data/q10, all 30 frames,
then the temporal filter), CD / p2m (cm) / F@1cm, raw normals -> 3 steps: walk 0.3265 / 0.3009 / 95.80 -> 0.3249 /
0.2990 / 95.85 %, arm swing 0.3651 / 0.3384 / 94.22 -> 0.3638 / 0.3371 / 94.24 %, torso twist 0.3463 / 0.3173 /
95.11 -> 0.3467 / 0.3174 / 95.10 %; 6 steps on the walk 0.3255 / 0.2994 / 95.84 %. Not kept (arm swing, with 3
steps): cameras within 73 degrees for vertices fewer than 3 cameras see (p2m 0.3377 cm), a vertex with no say in its
own frame given one by its neighbours' (walk 0.3011 cm), min_score 0.35 / 0.1 (0.3369 / 0.3375 cm).

Measured and not kept (session 15, the same fits): the camera pairs chosen once per vertex (the better half by
their peak score) instead of at each depth, so that pairs with a short baseline, whose curves are flat, do not
fill the wrong depths: arm swing 0.3638 / 0.3371 / 94.24 -> 0.3630 / 0.3354 / 94.27 %, walk 0.3249 / 0.2990 /
95.85 -> 0.3261 / 0.2994 / 95.79 %, torso twist 0.3467 / 0.3174 / 95.10 -> 0.3469 / 0.3170 / 95.09 % (from the
session's trimmed template's fits, arm swing 0.3194 -> 0.3186 cm p2m); with a third or 70 % of the pairs 0.3357 /
0.3377 cm on arm swing; pairs weighted by the sine of their rays' angle 0.3384 cm (fixed pairs: 0.3367 cm).

Each vertex weighted by its peak's signal-to-noise ratio (session 16, 2026-11-27; photo_consistency.fit_weights).
The offset field weighed each vertex by its peak score c, so a clear match (0.9) counted 1.5 times a mediocre one
(0.6); weighed by c / (1 - c), the signal-to-noise ratio of a correlation between two noisy views, it counts 6
times. Measured on a fresh synthesis of the demo capture (its template 0.424 cm where session 15's copy gave
0.421; stage 2 with the score weights 0.339 / 0.309 / 95.40 %), this step and the temporal filter rerun over its
stored fits, CD / p2m (cm) / F@1cm, walk and torso twist (arm swing kept aside):
- score weights (before): 0.3270 / 0.2981 / 95.77 % and 0.3383 / 0.3066 / 95.55 %;
- the score squared: walk 0.3273 / 0.2947 / 95.70 %; a ramp (c - 0.4) / 0.6: 0.3270 / 0.2938 / 95.68 % and
  0.3396 / 0.3041 / 95.48 % (0.3 / 0.5: p2m 0.2950 / 0.2934 cm, CD 0.3265 / 0.3289 cm): p2m gains, CD and F lose;
- SNR weights with stiffness 2 / 4 / 6 / 8: walk 0.3282 / 0.3058 / 95.78, 0.3242 / 0.2944 / 95.82, 0.3260 /
  0.2929 / 95.71, 0.3295 / 0.2945 / 95.57 %; twist at 2 / 4: 0.3388 / 0.3157 / 95.67, 0.3358 / 0.3045 / 95.67 %;
- with them, patches bent to 1.25 times the quadric instead of 1.5 (kept): 0.3244 / 0.2932 / 95.75 % and
  0.3363 / 0.3034 / 95.63 % (2: walk 0.3279 / 0.3012 / 95.91 %); arm swing, kept aside, 0.3514 / 0.3237 / 94.87 ->
  0.3515 / 0.3205 / 94.81 %. `gg register` over the stored fits gives the same (mean 0.339 / 0.309 / 95.40 ->
  0.337 / 0.306 / 95.40 %).
Then the frames' curves pooled in Fisher's z (fisher_average: the mean of atanh(NCC), mapped back) instead of
their plain mean, over 9 frames instead of 5 (same session, same fits): walk 0.3244 / 0.2932 / 95.75 % -> 5
frames 0.3235 / 0.2928 / 95.78 -> 7 frames 0.3228 / 0.2925 / 95.83 -> 9 frames 0.3223 / 0.2915 / 95.88 % (11:
0.3230 / 0.2921 / 95.91 %); torso twist 0.3363 / 0.3034 / 95.63 -> 0.3357 / 0.3030 / 95.63 -> 0.3344 / 0.3013 /
95.67 -> 0.3334 / 0.3003 / 95.69 %; arm swing, kept aside, 0.3515 / 0.3205 / 94.81 -> 5 frames 0.3512 / 0.3203 /
94.81 -> 9 frames 0.3498 / 0.3188 / 94.85 %. With the plain mean, more frames do not help (walk, 9 frames:
0.3242 / 0.2926 / 95.82 %; session 13: 7 frames no better than 5): a frame whose patches match clearly now
outweighs neighbours that match poorly instead of being flattened by them. The curves are clipped to 1 - 1e-6
before atanh (0.99 gives the same figures to 4 decimals). 9 frames hold (rounds - 1) * 4 + 1 = 13 frames' images.
A capture of seed 3 used for no choice (walk, 12 frames): 0.3266 / 0.2897 / 95.51 % with session 15's step over
the same fits -> 0.3239 / 0.2868 / 95.52 % with both changes. On the tiny preset (6 cameras, 72 x 96 px, 8 frames)
both lose: CD / p2m 1.423 / 1.381 cm -> 1.442 / 1.396 cm (SNR weights over 5 frames 1.437 / 1.392 cm): at that
resolution the peak scores are too noisy to rank matches, and 9 frames span most of a sequence.
Not kept: the pairs' NCCs (rather than the frames' curves) averaged as Fisher z, with SNR weights: 0.3233 /
0.2946 / 95.86 % and 0.3353 / 0.3049 / 95.72 %; a robust data term (3 Cauchy reweightings at 4 depth steps:
walk 0.3243 / 0.2920 / 95.73 %, twist 0.3365 / 0.3019 / 95.58 %, but arm swing 0.3533 / 0.3213 / 94.71 %; at 2
steps walk 0.3263 / 0.2915 / 95.58 %); pair shares 0.35 / 0.7 (walk 0.3244 / 0.2936 / 95.77 %, 0.3303 / 0.2952 /
95.53 %); min_score 0.05 / 0.35 (unchanged to 0.0005 cm); cameras within 55 / 50 degrees (walk 0.3212 / 0.2908 /
95.92 % and 0.3229 / 0.2933 / 95.93 %, twist at 55: 0.3354 / 0.3025 / 95.59 %); 5 rounds (walk p2m 0.2919 cm);
patches weighted by a Gaussian of 0.85 samples instead of 1 (walk 0.3215 / 0.2905 / 95.92 %, twist 0.3330 /
0.2998 / 95.65 %, but arm swing 0.3509 / 0.3201 / 94.81 %; 0.75 on the walk: 0.3229 / 0.2920 / 95.92 %; 7 samples
at 1.3: 0.3339 / 0.3057 / 95.63 %); with score weights, on the walk: each vertex's weight times min(cameras, 4) /
4 (p2m 0.2978 cm), the border ring or its two rings given no say (0.2991 / 0.3006 cm), 7 frames (0.2987 cm), 5
rounds (0.2982 cm), stiffness 1.5 (0.2976 cm), gain 1 / 1.25 (0.2977 / 0.2974 cm). The template's sweep keeps
the score weights (SNR weights at stiffness 8 / 16: 0.4255 / 0.3579 / 90.54 % and 0.4589 / 0.3820 / 89.06 %
against 0.4243 / 0.3634 / 91.07 %).

Normals smoothed over 10 steps (session 17, 2026-11-27; PhotoOptions.normal_smoothing, photo_consistency's
docstring): the sweep moves each vertex along, and faces its patches to, its normal smoothed over the mesh instead
of its own, which carries the tilt of wrinkles smaller than a patch (and at the front of the demo template's hem a
crumpled flap whose normals point every way: walk frame 0's lowest rings in front were 13.6 mm off against 4.9 mm
at frame 4). The same fits (session 16's final run), the step and the filter rerun, CD / p2m (cm) / F@1cm, walk /
torso twist / arm swing (kept aside), from 0.3223 / 0.2915 / 95.88 %, 0.3334 / 0.3003 / 95.69 %, 0.3498 / 0.3188
/ 94.85 %: 3 steps 0.3165 / 0.2840 / 96.09, 0.3274 / 0.2929 / 95.83, 0.3450 / 0.3133 / 95.00 %; 6 steps 0.3146 /
0.2810 / 96.13, 0.3257 / 0.2902 / 95.85 %; 10 steps 0.3136 / 0.2785 / 96.11, 0.3253 / 0.2882 / 95.82, 0.3435 /
0.3091 / 94.97 % (kept); 16 steps 0.3123 / 0.2744 / 96.08, 0.3270 / 0.2885 / 95.76 %; 25 steps 0.3138 / 0.2750 /
96.00, 0.3293 / 0.2895 / 95.70 %. Which cameras see a vertex is still decided with its own normal smoothed over
VISIBILITY_SMOOTHING steps.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from ..capture.cameras import Camera
from ..geometry.raycast import RayCaster
from ..reconstruction.mesh_graph import smoothed_normals, vertex_normals
from ..reconstruction.photo_consistency import PhotoOptions, Sweep, visible_cameras
from ..reconstruction.template_mesh import pixel_footprint
from .views import View

Body = tuple[np.ndarray, np.ndarray]          # (verts, faces) of a frame's body, an occluder
VISIBILITY_SMOOTHING = 3      # smoothing steps of the normals that decide which cameras face a vertex (docstring)
FISHER_CLIP = 1.0 - 1e-6      # curves clipped below 1 before atanh: a perfect score would weigh infinitely


@dataclass
class _Frame:
    """What a frame's remaining rounds need from its images; dropped after its last round's curves."""
    cameras: list[Camera]
    images: list[np.ndarray]
    masks: list[np.ndarray]
    seen: np.ndarray              # [C, V] cameras that see each vertex of the fit


def temporal_weights(frames: int) -> np.ndarray:
    """Triangular weights over `frames` (odd) neighbouring frames, the middle one heaviest: 1, 2, 3, 2, 1 for 5."""
    if frames < 1 or frames % 2 == 0:
        raise ValueError(f"the stereo window must be a positive odd frame count, got {frames}")
    half = frames // 2
    return (half + 1 - np.abs(np.arange(-half, half + 1))).astype(np.float64)


def fisher_z(curves: np.ndarray) -> np.ndarray:
    """Fisher's z = atanh(NCC) of score curves, clipped below 1 (FISHER_CLIP). Taken once per frame and round:
    each frame's curves are pooled into up to `frames` neighbours' averages."""
    return np.arctanh(np.clip(curves, -FISHER_CLIP, FISHER_CLIP))


def fisher_average(zs: Sequence[tuple[np.ndarray, np.ndarray]], weights: np.ndarray) -> np.ndarray:
    """[V, D] weighted average of frames' NCC curves, given as their Fisher's z ([V, D] fisher_z of the curves,
    [V] share that had scores), mapped back to NCC (tanh): z of a correlation is near normal with a variance that
    does not depend on the correlation, so its mean is the right way to pool them; a frame whose curve has a clear
    peak (0.95: z 1.8) then outweighs neighbours with mediocre ones (0.6: z 0.7) where a plain mean flattens it."""
    total = np.zeros_like(zs[0][0], dtype=np.float64)
    mass = np.zeros(len(total))
    for (z, w), weight in zip(zs, weights):
        total += weight * w[:, None] * z
        mass += weight * w
    return np.tanh(total / np.maximum(mass, 1e-12)[:, None])


def stereo_sequence(fits: Sequence[np.ndarray], faces: np.ndarray, load: Callable[[int], tuple[list[View], Body]],
                    options: PhotoOptions, frames: int, done: Callable[[int, np.ndarray, dict], None]) -> None:
    """Refines every fit of a sequence along its normals where the cameras agree; `load(t)` gives frame t's
    views and body. Each round's score curves are averaged over `frames` neighbouring frames (temporal_weights,
    fisher_average) before their peaks are fitted by the offset field. `done(t, verts, log)` receives each frame as
    it is finished, in order. Visibility is decided once per frame, on its fit and its body."""
    weights = temporal_weights(frames)
    half = frames // 2
    count = len(fits)
    rounds = options.rounds          # until the first frame sets the grid: coarse images allow fewer (Sweep.depths)
    sweep = Sweep(faces, len(fits[0]), options)
    meshes = [np.asarray(f, np.float64).copy() for f in fits]
    normals: list[np.ndarray | None] = [None] * count
    held: dict[int, _Frame] = {}
    curves: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}     # (frame, round) -> (fisher_z, share)
    logs: list[dict] = [{"rounds": [], "seconds": 0.0, "cpu_seconds": 0.0} for _ in range(count)]
    depths: list[np.ndarray] = []
    spacing = 0.0

    def timed(t: int, work: Callable[[], None]) -> None:
        wall, cpu = time.perf_counter(), time.process_time()
        work()
        logs[t]["seconds"] += time.perf_counter() - wall
        logs[t]["cpu_seconds"] += time.process_time() - cpu

    def score(t: int, r: int) -> None:
        frame = held[t]
        scores, share = sweep.curves(meshes[t], normals[t], depths[r], frame.seen, frame.cameras, frame.images,
                                     spacing, frame.masks)
        curves[t, r] = fisher_z(scores), share

    def enter(t: int) -> None:
        nonlocal spacing, depths, rounds
        if t > 0 and not rounds:          # frame 0's cameras allowed no round: the other frames' images are not needed
            return
        views, body = load(t)
        cameras = [v.camera for v in views]
        if t == 0:          # one depth grid for the sequence, so the frames' curves line up
            spacing = pixel_footprint(cameras, meshes[t].mean(axis=0))
            depths = sweep.depths(spacing)
            rounds = len(depths)
        if not rounds:          # images too coarse for a single round: the fit stands
            return
        normals[t] = sweep.normals(meshes[t])
        occluder = RayCaster([(meshes[t], sweep.faces), body])
        facing = smoothed_normals(vertex_normals(meshes[t], sweep.faces), sweep.adj, VISIBILITY_SMOOTHING)
        seen = visible_cameras(meshes[t], facing, cameras, occluder, options.min_cosine, spacing)
        logs[t]["cameras_per_vertex"] = float(seen.sum(axis=0).mean())
        held[t] = _Frame(cameras, [v.rgb.numpy() for v in views], [v.garment.numpy() for v in views], seen)
        score(t, 0)

    def advance(t: int, r: int) -> None:
        """Round r of frame t from the round's curves of its neighbours; then its next round's curves."""
        near = range(max(0, t - half), min(count, t + half + 1))
        averaged = fisher_average([curves[k, r] for k in near], weights[[k - t + half for k in near]])
        move, log = sweep.solve(averaged, curves[t, r][1], depths[r])
        meshes[t] = meshes[t] + move[:, None] * normals[t]
        logs[t]["rounds"].append(log)
        curves.pop((t - half, r), None)          # frames after t no longer need it
        if r + 1 < rounds:
            normals[t] = sweep.normals(meshes[t])
            score(t, r + 1)
        else:
            del held[t]

    # frame t's round r needs round r's curves up to frame t + half, which need that frame's round r - 1:
    # so it runs once frame t + (r + 1) * half has entered
    for step in range(count + rounds * half):
        if step < count:
            timed(step, lambda: enter(step))
            if not rounds:
                done(step, meshes[step], logs[step])
        for r in range(rounds):
            t = step - (r + 1) * half
            if 0 <= t < count:
                timed(t, lambda: advance(t, r))
                if r + 1 == rounds:
                    done(t, meshes[t], logs[t])
