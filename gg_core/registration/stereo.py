"""Multi-view stereo after each frame's photometric fit: the template's photo-consistency sweep
(reconstruction.photo_consistency), run from the fitted mesh over a small depth range.

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
next frame starts from the photometric fit (tracker.FrameResult.track; stage 2 keeps the fits in
stage2/<sequence>/fit/ for resuming). Demo walk, all 30 frames, with the holds: the fit alone mean CD 0.530 cm
(p2m 0.484 cm, F@1cm 87.9 %); refined 0.42-0.43 cm on every frame, mean 0.419 cm (0.377 cm, 92.4 %).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from ..geometry.raycast import RayCaster
from ..reconstruction.photo_consistency import PhotoOptions, refine_along_normals
from ..reconstruction.template_mesh import pixel_footprint
from .views import View


def stereo_refine(verts: np.ndarray, faces: np.ndarray, views: Sequence[View], body: tuple[np.ndarray, np.ndarray],
                  search: float, rounds: int, stiffness: float, aggregate: int, curvature_gain: float
                  ) -> tuple[np.ndarray, dict]:
    """(verts moved along their normals to where the cameras agree, within `search` metres either way, the offset
    field as stiff as `stiffness`, score curves averaged over `aggregate` neighbour steps, the patches bent to
    `curvature_gain` times the mesh's local curvature; log)."""
    cameras = [v.camera for v in views]
    options = PhotoOptions(search_in=search, search_out=search, rounds=rounds, stiffness=stiffness, aggregate=aggregate,
                           curvature_gain=curvature_gain)
    occluder = RayCaster([(verts, faces), body])
    return refine_along_normals(verts, faces, cameras, [v.rgb.numpy() for v in views], occluder,
                                pixel_footprint(cameras, verts.mean(axis=0)), options,
                                [v.garment.numpy() for v in views])
