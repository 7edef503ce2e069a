"""The template's geometry from one multi-view frame: person hull -> garment vote -> remesh -> cut.

1. Visual hull of the foreground masks (person plus garment), first coarsely (COARSE_VOXEL) to find the person
   and, by a garment vote on that coarse hull, the garment's box and area.
2. The hull again inside the garment's box (plus a margin) at the fine voxel size, as a closed surface.
3. Isotropic remesh of that surface to the edge length that gives the target vertex count on the garment.
4. Garment vote per vertex, unseen regions and mask noise decided by their surroundings, the vote smoothed,
   the surface cut at vote 0.5 and only the main pieces kept.
5. Photo-consistency: vertices moved along their normals into the concave regions the hull bridges.
6. The hull's bevel cut off the borders that hang free of the body (a hem; border_bevel.py).
7. The border tidied (short border edges collapsed, border relaxed), then a last isotropic remesh of the open
   garment (which keeps border vertices) for even triangles.

Why no pycolmap step (measured 2026-11-27, session 17): pycolmap here has no CUDA, so COLMAP's dense stereo
(patch_match_stereo) is out, and Poisson meshing needs its dense oriented points. What pycolmap offers on CPU is
sparse: SIFT features, exhaustive matching, and triangulation with the known cameras. It was tried on the demo
capture's template frame (00_walk frame 0; 12 cameras 30 degrees apart, 192 x 256 px). Inside the garment masks:
28-57 keypoints per image, 14 raw matches over 2 of the 66 pairs, and no point triangulated (even at a peak
threshold of 0.001 and at least 3 matches per pair). On the whole images: 134-177 keypoints, 122 verified matches
over 13 pairs, 14 points triangulated, all 40-60 cm off the garment. At this pixel size the printed cloth gives SIFT
nothing to match across 30 degrees. Step 5's dense plane sweep of patch correlations (photo_consistency.py) takes
the multi-view stereo role on CPU.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np
from scipy.ndimage import gaussian_filter

from ..capture.cameras import Camera
from .border_bevel import trim_free_border
from .isosurface import extract_surface
from .mask_vote import garment_vote
from ..geometry.raycast import RayCaster
from .mesh_graph import adjacency, face_components, genus, smooth, vertex_area, vertex_components
from .photo_consistency import PhotoOptions, refine_along_normals
from .remesh import edge_length_for, isotropic_remesh, remesh_open
from .surface_cut import cut_at_level, main_pieces
from .visual_hull import Grid, Silhouette, hull_bounds

COARSE_VOXEL = 0.02       # m: person search and garment box
BOX_MARGIN = 0.04         # m around the garment's coarse box
# Automatic voxel: the garment's pixel footprint, clamped to 3-10 mm. Measured on the demo preset (8.8 mm
# footprint), template CD after photo-consistency for 3 / 4.4 / 6 / 8 mm voxels: 0.660 / 0.668 / 0.649 / 0.649 cm;
# the hull is sub-voxel accurate (interpolated field), so the coarser grids only save time.
VOXEL_PER_PIXEL = 1.0
VOXEL_RANGE = (0.003, 0.01)
MAX_VERTICES = 8000          # default vertex count (the paper's) ...
MIN_VERTICES = 300           # ... lowered until edges are no shorter than a pixel's footprint
# Blur (in voxels) of the fine hull field before marching cubes: closes gaps thinner than a voxel, which
# otherwise leave tiny tunnels (handles) in the surface; measured on demo 00_walk frame 0: genus 1 -> 0, CD same.
FIELD_BLUR = 0.7
GEOMETRY_STEPS = 7             # `step` callbacks of reconstruct_template (6 without photo-consistency)
FINAL_REMESH_ITERATIONS = 3


@dataclass
class TemplateGeometryOptions:
    vertices: int | None = None        # target vertex count; None: MAX_VERTICES, fewer for coarse images
    voxel: float | None = None         # fine voxel (m); None: from the garment's pixel footprint
    vote_smoothing: int = 3            # Laplacian iterations on the vote before the cut
    hole_fraction: float = 0.005       # non-garment islands below this share of the garment's area are filled
    piece_fraction: float = 0.2        # garment pieces below this share of the largest are dropped
    remesh_iterations: int = 10
    free_border_trim: float = 1.0      # edge lengths cut off the borders that hang free of the body (border_bevel)
    photo: PhotoOptions | None = field(default_factory=PhotoOptions)   # None: no photo-consistency step


@dataclass
class TemplateGeometry:
    verts: np.ndarray
    faces: np.ndarray
    log: dict = field(default_factory=dict)


def pixel_footprint(cameras: Sequence[Camera], point: np.ndarray) -> float:
    """Median size (m) of one pixel at `point` over the cameras."""
    sizes = []
    for cam in cameras:
        z = (cam.R @ point + cam.t)[2]
        sizes.append(z / (0.5 * (cam.K[0, 0] + cam.K[1, 1])))
    return float(np.median(sizes))


def auto_vertex_count(area: float, footprint: float) -> int:
    """MAX_VERTICES, or fewer where the images cannot resolve edges that short (edge >= pixel footprint)."""
    resolvable = 2.0 * area / (np.sqrt(3.0) * footprint ** 2)
    return int(np.clip(round(resolvable, -2), MIN_VERTICES, MAX_VERTICES))


def reconstruct_template(cameras: Sequence[Camera], foreground: Sequence[np.ndarray], garment: Sequence[np.ndarray],
                         images: Sequence[np.ndarray] | None = None, options: TemplateGeometryOptions | None = None,
                         step: Callable[[str], None] | None = None,
                         occluders: Sequence[tuple[np.ndarray, np.ndarray]] = ()) -> TemplateGeometry:
    """Garment surface (open, manifold pieces) of one frame from per-camera foreground and garment masks,
    refined by photo-consistency when the RGB `images` ([H, W, 3] floats) are given. `occluders` (the frame's
    body) hide the garment from cameras in the photo-consistency step besides the hull itself."""
    opt = options or TemplateGeometryOptions()
    timings: dict[str, float] = {}
    clock = time.perf_counter()

    def lap(name: str) -> None:
        nonlocal clock
        now = time.perf_counter()
        timings[name] = round(now - clock, 3)
        clock = now
        if step is not None:
            step(name)

    masks = [np.asarray(f, bool) | np.asarray(g, bool) for f, g in zip(foreground, garment)]
    garment_f = [np.asarray(g, np.float64) for g in garment]
    silhouettes = [Silhouette.from_mask(c, m) for c, m in zip(cameras, masks)]
    person = hull_bounds(silhouettes, COARSE_VOXEL)
    if person is None:
        raise ValueError("the foreground masks have no common volume: the cameras do not see one subject")
    coarse = Grid.covering(*person, COARSE_VOXEL)
    cv, cf = extract_surface(coarse, coarse.sample(silhouettes))
    vote, weight = garment_vote(cv, cf, cameras, garment_f)
    on_garment = (vote >= 0.5) & (weight > 0)
    if on_garment.sum() < 3:
        raise ValueError("no part of the person's hull is seen as garment")
    garment_area = float(vertex_area(cv, cf)[on_garment].sum())
    lo = cv[on_garment].min(axis=0) - BOX_MARGIN
    hi = cv[on_garment].max(axis=0) + BOX_MARGIN
    lap("coarse hull and garment box")

    footprint = pixel_footprint(cameras, 0.5 * (lo + hi))
    voxel = opt.voxel or float(np.clip(VOXEL_PER_PIXEL * footprint, *VOXEL_RANGE))
    fine = Grid.covering(lo, hi, voxel)
    hv, hf = extract_surface(fine, gaussian_filter(fine.sample(silhouettes), FIELD_BLUR))
    lap("fine hull")

    vertices = opt.vertices or auto_vertex_count(garment_area, footprint)
    edge = edge_length_for(garment_area, vertices)
    rv, rf = isotropic_remesh(hv, hf, edge, opt.remesh_iterations)
    lap("remesh")

    vote, weight = garment_vote(rv, rf, cameras, garment_f)
    adj = adjacency(rf, len(rv))
    vote = _resolve_unseen(vote, weight, rv, rf, adj, opt.hole_fraction)
    vote = smooth(vote, adj, opt.vote_smoothing)
    gv, gf = cut_at_level(rv, rf, vote, 0.5)
    gv, gf = main_pieces(gv, gf, opt.piece_fraction)
    lap("garment vote and cut")
    if len(gf) == 0:
        raise ValueError("the garment vote left no surface")
    photo_log = None
    if images is not None and opt.photo is not None:
        occluder = RayCaster([(rv, rf), *occluders])
        gv, photo_log = refine_along_normals(gv, gf, cameras, images, occluder, footprint, opt.photo)
        lap("photo-consistency")
    trim_log = None
    if occluders:          # the body tells which borders hang free
        gv, gf, trim_log = trim_free_border(gv, gf, occluders, opt.free_border_trim * edge, opt.piece_fraction)
    lap("free border trim")
    gv, gf = remesh_open(gv, gf, edge, FINAL_REMESH_ITERATIONS)
    lap("final remesh")
    labels = face_components(gf)
    log = {"timings_s": timings, "target_vertices": vertices, "voxel_m": voxel, "pixel_footprint_m": footprint,
           "edge_length_m": edge, "garment_box": [lo.tolist(), hi.tolist()], "coarse_garment_area_m2": garment_area,
           "hull_vertices": len(hv), "remeshed_vertices": len(rv), "photo_consistency": photo_log,
           "free_border_trim": trim_log,
           "pieces": [{"faces": int((labels == k).sum()), "genus": genus(gf[labels == k])}
                      for k in range(int(labels.max()) + 1)]}
    return TemplateGeometry(gv, gf, log)


def _resolve_unseen(vote: np.ndarray, weight: np.ndarray, verts: np.ndarray, faces: np.ndarray, adj,
                    fraction: float) -> np.ndarray:
    """Vote with the unseen vertices and mask noise decided by their surroundings.

    Regions outside the seen garment are pieces of non-garment vertices (seen as such, or seen by no camera).
    A piece that no camera sees as non-garment is enclosed by garment (an armpit, a fold's hidden side) and
    becomes garment; so does a piece smaller than `fraction` of the garment area (mask noise, a finger on the
    cloth). The rest is not garment: real openings and the hull under a hem, which no camera sees and which
    touches the legs, stay outside.
    """
    seen = weight > 0
    garment = seen & (vote >= 0.5)
    area = vertex_area(verts, faces)
    labels = vertex_components(adj, ~garment)
    out = np.where(seen, vote, 0.0)
    if labels.max() < 0:
        return out
    pieces = labels >= 0
    piece_area = np.bincount(labels[pieces], area[pieces])
    piece_seen = np.bincount(labels[pieces], seen[pieces].astype(np.float64), minlength=len(piece_area))
    enclosed = piece_seen == 0
    small = piece_area < fraction * area[garment].sum()
    fill = pieces & (enclosed | small)[np.maximum(labels, 0)]
    out[fill] = 1.0
    return out
