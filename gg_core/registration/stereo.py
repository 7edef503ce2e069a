"""Multi-view stereo after each frame's photometric fit: the template's photo-consistency sweep
(reconstruction.photo_consistency), run from the fitted mesh over a small depth range.

Why: the photometric fit compares renders of a Gaussian texture fitted on the template frame, which does not
reproduce the shading and occlusions of other poses; so each frame ends a few millimetres off the cloth and the
next frame starts there: the error accumulates (tracker.py). Patch correlation between the cameras' own images
of this frame needs no texture model, so it measures where the surface is now. Visibility is decided on the fitted
mesh itself and the frame's body (the fit is near the cloth: a fold's ridge hides its valley as it should).

The garment's border rings are held, and so are vertices touching the body: a patch there straddles the cloth's
edge or lies on the skin, and two cameras that see the same background or leg can agree at a wrong depth.
Measured fed back (the next frame started from the refined mesh) on the demo capture's walk, frames 0-9 from the
0.441 cm template, CD (cm) of frames 0 / 4 / 9 and the mean over the 10 (F@1cm):
- photometric fit alone: 0.441 / 0.510 / 0.548, mean 0.502 (89.0 %): the drift;
- with this step, nothing held: 0.417 / 0.426, then the hem went astray from frame 5 and took the fit with it
  (frame 7 0.76, frame 9 3.13 cm);
- border's 2 rings held: 0.418 / 0.375 / 0.981 (frames 0-7 at most 0.418; the front hem, where the swinging leg
  presses the skirt, went astray from frame 8);
- also vertices within 2 cm of the body (a third of them): 0.423 / 0.434 / 0.481, mean 0.446 (91.6 %);
- within 5 mm: 0.418 / 0.394 / 0.450, mean 0.415 cm, p2m 0.377 cm, F@1cm 92.1 %, at 1.1 CPU-s per frame (18.3
  against 17.2 s for the fit).
Over longer sequences, fed back, the step diverged: the full demo sequences (30 frames) held to frame 11 and
then went astray: walk 0.45 cm at frame 10, then 0.53 / 0.69 / 0.99 and 3.41 cm by frame 24; torso twist 3.31
cm by frame 23 (a ±8 mm search: walk 1.25 cm by frame 19; also a 1 cm body gap: 0.8 cm by frame 20).
The error starts at the front of the hem, where the swinging leg presses the skirt: a wrong move
starts the next frame off, the fit follows partly, and the next sweep moves it further. So the step refines each
frame's output only and the next frame starts from the photometric fit (tracker.FrameResult.track; stage 2 keeps
the fits in stage2/<sequence>/fit/ for resuming). Demo walk, all 30 frames, CD of frames 0 / 10 / 20 / 29 and
the mean (p2m, F@1cm): the fit alone 0.44 / 0.56 / 0.52 / 0.57, mean 0.530 cm (0.484 cm, 87.9 %); refined
0.42 / 0.43 / 0.43 / 0.43, mean 0.419 cm (0.377 cm, 92.4 %).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from ..geometry.raycast import RayCaster
from ..geometry.topology import build_topology
from ..reconstruction.mesh_graph import adjacency
from ..reconstruction.photo_consistency import PhotoOptions, refine_along_normals
from ..reconstruction.template_mesh import pixel_footprint
from .views import View


def border_rings(faces: np.ndarray, n_vertices: int, rings: int) -> np.ndarray:
    """[V] bool: vertices at most `rings` edges from the mesh's border."""
    near = build_topology(faces, n_vertices).boundary_vertices
    adj = adjacency(faces, n_vertices)
    for _ in range(rings):
        near = near | (adj @ near.astype(np.float64) > 0)
    return near


def stereo_refine(verts: np.ndarray, faces: np.ndarray, views: Sequence[View], body: tuple[np.ndarray, np.ndarray],
                  search: float, rounds: int, hold_rings: int, hold: np.ndarray) -> tuple[np.ndarray, dict]:
    """(verts moved along their normals to where the cameras agree, within `search` metres either way; the
    border's `hold_rings` rings and the vertices where `hold` is set stay; log)."""
    cameras = [v.camera for v in views]
    options = PhotoOptions(search_in=search, search_out=search, rounds=rounds)
    occluder = RayCaster([(verts, faces), body])
    return refine_along_normals(verts, faces, cameras, [v.rgb.numpy() for v in views], occluder,
                                pixel_footprint(cameras, verts.mean(axis=0)), options,
                                hold=hold | border_rings(faces, len(verts), hold_rings))
