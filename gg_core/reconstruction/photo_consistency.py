"""Photo-consistency refinement: move surface vertices along their normals to where the cameras agree.

Silhouettes cannot see concave regions (the valleys between a skirt's folds): the hull bridges them. For each
vertex a plane sweep along the normal scores candidate depths by the pairwise normalized cross-correlation (NCC)
of small tangent-plane patches seen by the cameras that face the vertex, at each depth averaged over the better
half of the camera pairs (a camera whose view of a valley is blocked by a fold's ridge, which the hull cannot
tell, disagrees with the others; the classic k-best selection of multi-view stereo); score curves are aggregated over
mesh neighbours (neighbouring points move alike), the best depth is found with sub-step precision, and the
offsets are fitted smoothly over the mesh, weighted by how clearly each vertex's best score stands out.
Visibility is decided once, on the hull (which contains the true surface) and the frame's body (arms and legs
in front of the garment), so later rounds keep the cameras. The body matters: on the demo capture (00_walk
frame 0) it cuts the sweep's peaks more than 1 cm off the true surface from 23 % to 17 % of the vertices (16 %
with visibility decided on the true surface) and the template's CD from 0.602 to 0.525 cm (F@1cm 82.2 -> 86.2 %).
Measured with the body and not kept: also hiding vertices behind the refined garment itself after each round
(0.517 cm), loopy belief propagation over the whole score curves with a truncated-linear smoothness instead of
the argmax and quadratic fit (peaks > 1 cm off 20 -> 18 %), prominence instead of peak height as confidence
(CD 1.06 cm), denoising the 8-sample renders first (Gaussian 0.7 px: 0.648 cm, non-local means: 0.736 cm).

Where the template still erred before the body hid the garment (demo capture, 00_walk frame 0, 8.8 mm pixels): the
hull alone has CD 1.23 cm, area 0.58 m^2 against the true 0.64, every point more than 1 cm off lies in a valley the
hull bridges; after this refinement CD 0.62 cm, but area 0.53 m^2, and of the points still more than 1 cm off 43 %
are in valleys and 47 % where the surface was pulled inside the cloth (the smooth offset field drags ridges in with
their valleys). Measured and not kept: holding vertices on silhouette rims (projecting within 1 px of an outline,
seen within 17 degrees of edge-on) at the hull, CD 1.01 / 1.21 cm at weight 1 / 10: it also holds the valleys'
neighbours. More rounds (5: 0.608 cm), a softer field (stiffness 1: 0.621), wider search (10 cm: 0.775), larger
patches (7: 0.662) or more grazing cameras (cosine 0.3: 0.645) do not help; nor does a robust (Charbonnier, IRLS)
smoothness that lets neighbouring offsets differ by more than 2 / 5 / 10 mm (0.634 / 0.619 / 0.620). The sweep
itself is the limit: the first round's peaks against the true surface along the hull normal, confident vertices:
median error 4 mm (half a pixel), 60 % within 5 mm, 9 % more than 1 cm too deep and 9 % more than 1 cm too shallow;
seen by only 2 cameras, 30 % within 5 mm (ray cast to the demo capture's true surface). Swept on the true surface
itself, along its true normals, with visibility decided on it and the body: the peak is still more than 1 cm off at
18 % of the vertices (median 3.6 mm; no camera pair stands out), so at 8.8 mm pixels the matching itself, not the
geometry it starts from, bounds what this refinement can reach.

Best pairs instead of all (2026-11-26), template CD / F@1cm with all pairs -> the better half: demo capture 00_walk
frame 0 0.521 -> 0.500 cm / 86.6 -> 88.0 %; the same frame rendered with 64 samples 0.510 -> 0.482 cm / 87.5 ->
88.9 %; a capture of seed 3 0.512 -> 0.497 cm / 86.8 -> 87.4 %. The best third scores like the half (88.0 / 87.4 %);
ranking pairs per vertex by their best depth instead of per depth gains half as much (87.3 / 87.0 %); with it, more
grazing cameras (cosine 0.3 / 0.4) still lose (86.8 / 85.9 %, 87.6 / 86.8 %). The better scores then allow a
softer offset field (stiffness 4 -> 2): 0.500 -> 0.484 cm / 88.0 -> 88.9 % and 0.497 -> 0.484 cm / 87.4 -> 88.0 %
on those two captures; on a capture of seed 5 not used to choose either change, all pairs at stiffness 4 -> the
better half -> stiffness 2: 0.553 -> 0.521 -> 0.515 cm, 84.9 -> 86.8 -> 87.2 % (stiffness 1 / 0.5: 88.4 / 87.6 %
and 88.4 / 88.6 % on the first two, with more neighbour aggregation 88.6 / 88.5 %).
Then (same day) each colour channel centred on its own mean instead of one mean over all three, and the patch
weighted by a Gaussian of one sample: with one mean, a coloured fabric's constant channel differences (blue cloth:
B above R everywhere) correlate at every depth and flatten the score curve. Template CD / F@1cm on the two
captures 0.484 -> 0.441 cm / 88.9 -> 91.0 % and 0.484 -> 0.442 cm / 88.0 -> 90.7 % (per-channel means alone 90.6 /
90.1 %); on the seed-5 capture, not used for choosing, 0.515 -> 0.427 cm / 87.2 -> 91.6 % (p2m 0.358 cm), and all
camera pairs instead of the better half there 90.9 %. Retuned on the two captures and not kept: stiffness 1 / 4
(91.0 / 91.0 %, 89.7 / 89.6 %), cosine 0.3 (91.2 / 91.3 %, but 91.5 % on seed 5), a 7-sample patch with sigma 1.5
(90.8 / 90.3 %), samples 0.75 pixels apart (90.7 / 90.1 %). What no matching can reach: on that
frame 4.1 / 5.4 / 8.0 % of the true skirt is seen by fewer than two cameras within 84 / 73 / 60 degrees
(metrics/coverage.py), but of the 12.3 % of true points the template misses by more than 1 cm (17.0 % with all
pairs and one mean), 8.0 % (12.4 %) are seen by at least two cameras within 60 degrees: the matching, not
visibility, still bounds this step. By height (lowest fifth first) the misses are 29.6 / 16.5 / 10.4 / 5.1 / 0.2 %
of the true points (were 37.5 / 23.1 / 17.1 / 6.4 / 1.1 %); the hem stays 1.1 cm high (was 1.6 cm), see below.

The hem: the vote cuts the hull where the masks put the hem (demo capture, 00_walk frame 0, without this step:
mean hem height 0.553 m, truth 0.554 m), but this step raises it to 0.568 m, because a flared skirt's normals tilt
down and the bridged surface moves inwards along them. Measured and not kept: moving border vertices within the
plane of their border loop (so they keep their height) and blending that over 1 / 3 / 6 rings. The hem stays at
0.553 m and the lowest band's recall rises (50 -> 56 %), but the restored strip lies on the hull outside the hem's
folds, so F@1cm falls 85.4 -> 84.5 % and CD rises 0.596 -> 0.623 cm: the raised hem scores better by leaving that
strip out. Normals taken from two rings further in changed nothing (hem 0.568 m).

Curved patches (2026-11-26, session 11). The reconstruction was too smooth: on a registered demo frame (walk frame
15) the signed error along the normal follows the true surface's curvature (Spearman -0.53 against the truth's
2 cm-scale curvature): fold crests cut about 3 mm short, valleys about 2.5 mm shallow, the crests' error twice the
rest. A tangent-plane patch leaves a curved surface on both sides and matches best inside a crest (the test's 3 cm
cylinder: 1.4 mm too deep). So each round bends the patches to the local quadric of the current mesh (least squares
over the 2-ring; local_quadrics), which carries some of the folds (its 2 cm-scale curvature correlates 0.45 with the
truth's, at 40 % of the amplitude) and recovers more of them round after round. Template CD / p2m / F@1cm, 00_walk
frame 0 of the three captures (seeds 0, 3, 5): 0.441 -> 0.425 / 0.374 -> 0.360 / 91.0 -> 91.2 %, 0.442 -> 0.431 /
0.380 -> 0.372 / 90.7 -> 91.1 %, 0.427 -> 0.411 / 0.358 -> 0.346 / 91.6 -> 92.1 %. The registration's stereo step
(registration/stereo.py) gains more, starting closer to the cloth.
The quadric is still too flat: a registered mesh holds 40-45 % of the truth's 2 cm-scale fold curvature, the hull
less. So the patches are bent to `curvature_gain` times it (session 12). Template CD / p2m / F@1cm on the three
captures, gain 1 / 1.5 / 2 / 3: 0.425 / 0.421 / 0.419 / 0.420 cm, 0.360 / 0.358 / 0.355 / 0.358 cm, 91.2 / 91.3 /
91.5 / 91.5 %; 0.431 / 0.426 / 0.422 / 0.417 cm, 0.372 / 0.368 / 0.364 / 0.358 cm, 91.1 / 91.3 / 91.5 / 91.7 %;
0.411 / 0.406 / 0.403 / 0.403 cm, 0.346 / 0.343 / 0.338 / 0.338 cm, 92.1 / 92.4 / 92.4 / 92.2 %: gain 2 (the
default). The registration's step, starting from a fit with more of the folds, uses 1.5 (stereo.py).

Smoothed normals (2026-11-27, session 17). The sweep moves each vertex along, and faces its patches to, its normal
smoothed over `normal_smoothing` steps (Sweep.normals), not the mesh's own. Found on the demo capture's template
(00_walk frame 0): the hull bridged the skirt's front 4-7 cm out from the hip to the hem, and at the hem 30 of the
112 vertices in front were seen by no camera; moved by different amounts along their own normals, the vertices
there crumpled into a flap 3-5 cm in front of the cloth, its normals pointing every way, which neither later rounds
nor the registration's stereo step could undo (each frame's sweep moved it along those normals). Elsewhere a
vertex's own normal carries the tilt of wrinkles and noise smaller than a patch, so the sweep slides it sideways
and tilts its patch. Replaying this step from the demo template's cut hull (occluder: the cut surface and the body),
CD / p2m (cm) / F@1cm against 0.4327 / 0.3998 / 90.81 % with the mesh's normals: 1 / 2 / 3 / 4 / 6 / 10 / 16 / 25
steps 0.4295 / 0.3935 / 90.75, 0.4224 / 0.3801 / 91.04, 0.4173 / 0.3723 / 91.14, 0.4201 / 0.3775 / 91.07, 0.4174 /
0.3729 / 91.11, 0.4120 / 0.3638 / 91.37, 0.4134 / 0.3641 / 91.22, 0.4162 / 0.3684 / 91.19 %; at 3 steps, only the
direction smoothed (patches on the mesh's normals) 0.4207 / 0.3754 / 91.21 %, only the cameras chosen with the
smoothed normals 0.4335 / 0.4028 / 90.85 %: the direction and the patch both count, the visibility not. 10 steps
(the default; about 3 edge lengths): `gg template` on the demo capture 0.4243 / 0.3634 / 91.07 -> 0.4099 / 0.3432 /
91.51 %, on a capture of seed 3 used for no choice 0.4127 / 0.3460 / 91.93 -> 0.4004 / 0.3183 / 92.35 %. The flap
shrinks (its vertices 27 -> 24 mm off) but stays: no camera sees it.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import scipy.sparse as sp

from ..capture.cameras import Camera
from ..geometry.raycast import RayCaster
from .mesh_graph import adjacency, smooth, smoothed_normals, vertex_normals
from .patch_kernels import normalized_patches
from .visual_hull import bilinear

_VERTEX_CHUNK = 1024
WEIGHTINGS = ("score", "snr")
SNR_SCORE_CAP = 0.98          # a score of 1 would weigh infinitely: 0.98 weighs 49


@dataclass
class PhotoOptions:
    search_in: float = 0.06      # m searched inwards (the hull over-estimates) ...
    search_out: float = 0.01     # ... and outwards (mask and voxel errors)
    patch: int = 5               # patch side in samples ...
    patch_spacing: float = 1.0   # ... this many pixel footprints apart ...
    patch_sigma: float | None = 1.0   # ... weighted by a Gaussian of this many samples (None: evenly)
    min_cosine: float = 0.5      # only cameras facing the vertex within 60 degrees vote
    aggregate: int = 2           # neighbour-averaging iterations on the score curves
    min_score: float = 0.2       # aggregated NCC below this: the vertex has no say in the fit
    stiffness: float = 2.0       # weight of the offset field's smoothness (graph Laplacian; module docstring)
    rounds: int = 3              # later rounds search a third of the previous range around the last result
    pair_share: float = 0.5      # each depth scored by the better half of the camera pairs (module docstring)
    curved: bool = True          # patches bent to the mesh's local quadric (module docstring); False: tangent plane
    curvature_gain: float = 2.0  # the quadric's curvature times this: the mesh is flatter than the cloth (docstring)
    weighting: str = "score"     # a vertex's weight in the offset field: its peak score, or "snr" (fit_weights)
    normal_smoothing: int = 10   # smoothing steps of the normals the sweep moves along (Sweep.normals; docstring)

    def __post_init__(self) -> None:
        check_weighting(self.weighting, "weighting")
        if self.normal_smoothing < 0:
            raise ValueError(f"normal_smoothing must be 0 or more steps, got {self.normal_smoothing}")


def check_weighting(weighting: str, option: str) -> None:
    """ValueError unless `weighting` is one of WEIGHTINGS; `option` names where it was set, for the message."""
    if weighting not in WEIGHTINGS:
        raise ValueError(f"{option} must be one of {WEIGHTINGS}, got {weighting!r}")


def fit_weights(score: np.ndarray, weighting: str) -> np.ndarray:
    """Each vertex's weight in the offset field from its peak NCC `score`: the score itself ("score"), or its
    signal-to-noise ratio score / (1 - score) ("snr"; scores capped at SNR_SCORE_CAP). Why the ratio: a patch
    correlation rho between two noisy views of one texture has signal-to-noise power rho / (1 - rho), and the
    precision of its peak grows with it; so a clear match (0.9: 9) outweighs a mediocre one (0.6: 1.5) six
    times where the score weighs it 1.5 times. Measured in registration/stereo.py; the template's sweep keeps the
    score (template_mesh)."""
    if weighting == "snr":
        capped = np.minimum(score, SNR_SCORE_CAP)
        return capped / (1.0 - capped)
    return score


def visible_cameras(verts: np.ndarray, normals: np.ndarray, cameras: Sequence[Camera], occluder: RayCaster,
                    min_cosine: float, lift: float) -> np.ndarray:
    """[C, V] bool: camera c faces vertex v (cosine above min_cosine), v projects into its image, and the
    segment from the camera to the vertex (lifted off the surface by `lift`) is not blocked by `occluder`."""
    seen = np.zeros((len(cameras), len(verts)), bool)
    lifted = verts + lift * normals
    for c, cam in enumerate(cameras):
        to_cam = cam.center - verts
        cos = np.einsum("ij,ij->i", normals, to_cam) / np.linalg.norm(to_cam, axis=1)
        uv, z = cam.project(verts)
        ok = (cos > min_cosine) & (z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] <= cam.width) & \
             (uv[:, 1] >= 0) & (uv[:, 1] <= cam.height)
        idx = np.flatnonzero(ok)
        ok[idx] = ~occluder.segment_blocked(np.broadcast_to(cam.center, (len(idx), 3)), lifted[idx], eps=0.0)
        seen[c] = ok
    return seen


def tangent_frames(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.where(np.abs(normals[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
    t1 = np.cross(normals, helper)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    return t1, np.cross(normals, t1)


def local_quadrics(verts: np.ndarray, normals: np.ndarray, adj: sp.csr_matrix) -> np.ndarray:
    """[V, 3] (A, B, C) of the height h = (A a^2 + 2 B a b + C b^2) / 2 over each vertex's tangent frame
    (tangent_frames) that fits its 2-ring neighbours best in least squares (zero where they do not determine it)."""
    ring2 = ((adj + adj @ adj) > 0).tocoo()
    i, j = ring2.row, ring2.col
    keep = i != j
    i, j = i[keep], j[keep]
    t1, t2 = tangent_frames(normals)
    d = verts[j] - verts[i]
    a, b, h = (np.einsum("ij,ij->i", d, t[i]) for t in (t1, t2, normals))
    basis = np.stack([0.5 * a * a, a * b, 0.5 * b * b], axis=1)          # [P, 3]
    n = len(verts)
    normal_eq = np.zeros((n, 3, 3))
    np.add.at(normal_eq, i, basis[:, :, None] * basis[:, None, :])
    rhs = np.zeros((n, 3))
    np.add.at(rhs, i, basis * h[:, None])
    ok = np.linalg.det(normal_eq) > 1e-12 * np.maximum(np.einsum("nii->n", normal_eq), 1e-300) ** 3
    out = np.zeros((n, 3))
    out[ok] = np.linalg.solve(normal_eq[ok], rhs[ok][:, :, None])[:, :, 0]
    return out


def sweep_scores(verts: np.ndarray, normals: np.ndarray, offsets: np.ndarray, seen: np.ndarray,
                 cameras: Sequence[Camera], images: Sequence[np.ndarray], spacing: float, patch: int,
                 pair_share: float = 1.0, sigma: float | None = None, quadrics: np.ndarray | None = None,
                 masks: Sequence[np.ndarray] | None = None) -> np.ndarray:
    """[V, D] NCC of the patch at verts + offset * normal: at each depth the mean over the best `pair_share` of
    the pairs of seeing cameras (1.0: all pairs; NaN when fewer than two cameras see the vertex). Each colour
    channel is centred on its own (weighted) mean; `sigma` (in samples) weights the patch by a Gaussian around
    its centre, None weighs it evenly; `quadrics` (local_quadrics) bend the patch; `masks` ([H, W] per camera,
    1 on the garment) weigh each camera's samples by whether they land on the garment."""
    t1, t2 = tangent_frames(normals)
    steps = np.arange(patch) - (patch - 1) / 2
    a, b = [g.ravel() * spacing for g in np.meshgrid(steps, steps, indexing="ij")]
    r2 = np.add.outer(steps ** 2, steps ** 2).ravel()
    weight = np.ones(patch * patch) if sigma is None else np.exp(-0.5 * r2 / sigma ** 2)
    weight /= weight.sum()
    scores = np.full((len(verts), len(offsets)), np.nan)
    for s in range(0, len(verts), _VERTEX_CHUNK):
        sl = slice(s, s + _VERTEX_CHUNK)
        # [n, D, P, 3] sample points: centre moved along the normal, patch in the tangent plane (or on the quadric)
        centre = verts[sl, None, :] + offsets[None, :, None] * normals[sl, None, :]
        spread = a[None, :, None] * t1[sl, None, :] + b[None, :, None] * t2[sl, None, :]
        if quadrics is not None:
            q = quadrics[sl]
            height = 0.5 * q[:, :1] * a * a + q[:, 1:2] * a * b + 0.5 * q[:, 2:] * b * b     # [n, P]
            spread = spread + height[:, :, None] * normals[sl, None, :]
        points = centre[:, :, None, :] + spread[:, None, :, :]
        n, d, p = points.shape[:3]
        colours: dict[int, np.ndarray] = {}       # camera -> [n, D, P*3] zero-mean unit patches (zero where unseen)
        for c, (cam, image) in enumerate(zip(cameras, images)):
            idx = np.flatnonzero(seen[c, sl])
            if len(idx) == 0:
                continue
            patches = normalized_patches(points[idx].reshape(-1, p, 3), cam, image, weight,
                                         None if masks is None else masks[c])
            colours[c] = np.zeros((n, d, p * 3), np.float32)
            colours[c][idx] = patches.reshape(len(idx), d, p * 3)
        scores[sl] = _best_pairs(colours, seen[:, sl], d, pair_share)
    return scores


def _best_pairs(colours: dict[int, np.ndarray], seen: np.ndarray, d: int, share: float) -> np.ndarray:
    """[n, d] mean over the best `share` of the pairwise NCCs (at least one pair) at each of the d depths."""
    cams = sorted(colours)
    both = {(i, j): seen[i] & seen[j] for k, i in enumerate(cams) for j in cams[k + 1:]}
    pairs = [pair for pair, mask in both.items() if mask.any()]
    n = seen.shape[1]
    if not pairs:
        return np.full((n, d), np.nan)
    ncc = np.full((len(pairs), n, d), -np.inf, np.float32)
    for k, (i, j) in enumerate(pairs):
        mask = both[i, j]
        ncc[k, mask] = np.einsum("ndk,ndk->nd", colours[i][mask], colours[j][mask])
    count = np.sum([both[pair] for pair in pairs], axis=0)          # [n] pairs that see each vertex
    keep = np.maximum(1, np.ceil(share * count)).astype(np.int64)
    ranked = -np.sort(-ncc, axis=0)                                   # best pair first at each depth
    used = np.arange(len(pairs))[:, None, None] < keep[None, :, None]
    total = np.where(used & np.isfinite(ranked), ranked, 0.0).sum(axis=0)
    return np.where(count[:, None] > 0, total / keep[:, None], np.nan)


def refine_along_normals(verts: np.ndarray, faces: np.ndarray, cameras: Sequence[Camera],
                         images: Sequence[np.ndarray], occluder: RayCaster, spacing: float,
                         options: PhotoOptions | None = None, masks: Sequence[np.ndarray] | None = None
                         ) -> tuple[np.ndarray, dict]:
    """(moved verts, log). `spacing` (m) is the patch sample spacing and the sweep step, about one pixel; `masks`
    (the garment's, per camera) keep the patches' samples off the background (sweep_scores)."""
    opt = options or PhotoOptions()
    verts = np.asarray(verts, np.float64).copy()
    sweep = Sweep(faces, len(verts), opt)
    normals = sweep.normals(verts)
    seen = visible_cameras(verts, normals, cameras, occluder, opt.min_cosine, spacing)
    log = {"cameras_per_vertex": float(seen.sum(axis=0).mean()), "rounds": []}
    total_offset = np.zeros(len(verts))
    for offsets in sweep.depths(spacing):
        curves, weight = sweep.curves(verts, normals, offsets, seen, cameras, images, spacing, masks)
        move, round_log = sweep.solve(curves, weight, offsets)
        verts += move[:, None] * normals
        total_offset += move
        log["rounds"].append(round_log)
        normals = sweep.normals(verts)
    log["mean_offset_m"] = float(total_offset.mean())
    return verts, log


class Sweep:
    """One mesh's photo-consistency rounds, in pieces that a caller can interleave: the depths each round
    searches, the (neighbour-aggregated) score curves at them, and the smooth offset field they ask for.
    registration/stereo.py averages the curves of neighbouring frames between the last two."""

    def __init__(self, faces: np.ndarray, n_verts: int, options: PhotoOptions) -> None:
        self.faces = np.asarray(faces, np.int64)
        self.options = options
        self.adj = adjacency(self.faces, n_verts)
        self.lap = sp.diags(np.asarray(self.adj.sum(axis=1)).ravel()) - self.adj

    def normals(self, verts: np.ndarray) -> np.ndarray:
        """[V, 3] the directions the sweep moves along and its patches face: the mesh's vertex normals smoothed
        over `normal_smoothing` steps (module docstring, "Smoothed normals")."""
        normals = vertex_normals(verts, self.faces)
        steps = self.options.normal_smoothing
        return smoothed_normals(normals, self.adj, steps) if steps else normals

    def depths(self, spacing: float) -> list[np.ndarray]:
        """Offsets along the normal each round scores: the first spans the search range in half-`spacing`
        steps, each later one a third of the previous range around the last result at half the step. The rounds
        stop before one of fewer than 3 depths: its argmax would only say which end is nearer (coarse images,
        where a late round's range is under two steps; a 40 x 30 px capture's 4th round had one depth)."""
        opt = self.options
        lo, hi, step = -opt.search_in, opt.search_out, 0.5 * spacing
        out = []
        for _ in range(opt.rounds):
            offsets = np.arange(lo, hi + 0.5 * step, step)
            if len(offsets) < 3:
                break
            out.append(offsets)
            third = (hi - lo) / 6.0
            lo, hi, step = -third, third, step / 2
        return out

    def curves(self, verts: np.ndarray, normals: np.ndarray, offsets: np.ndarray, seen: np.ndarray,
               cameras: Sequence[Camera], images: Sequence[np.ndarray], spacing: float,
               masks: Sequence[np.ndarray] | None) -> tuple[np.ndarray, np.ndarray]:
        """([V, D] score curves averaged over `aggregate` neighbour steps, [V] the share of each average that
        had scores: 0 where no two cameras see the vertex)."""
        opt = self.options
        quadrics = opt.curvature_gain * local_quadrics(verts, normals, self.adj) if opt.curved else None
        scores = sweep_scores(verts, normals, offsets, seen, cameras, images, opt.patch_spacing * spacing,
                              opt.patch, opt.pair_share, opt.patch_sigma, quadrics, masks)
        valid = np.isfinite(scores[:, 0])
        filled = np.where(valid[:, None], scores, 0.0)
        agg = np.stack([smooth(filled[:, k], self.adj, opt.aggregate) for k in range(len(offsets))], axis=1)
        weight = smooth(valid.astype(np.float64), self.adj, opt.aggregate)
        return agg / np.maximum(weight[:, None], 1e-12), weight

    def solve(self, curves: np.ndarray, weight: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, dict]:
        """([V] move along the normals: the curves' sub-step peaks fitted by an offset field as stiff as the
        options say, each vertex weighted by fit_weights of its peak score where `weight` > 0.5 and the score >
        min_score; the round's log). `offsets` is one of `depths`' grids (3 depths or more)."""
        opt = self.options
        step = offsets[1] - offsets[0]
        best = np.argmax(curves, axis=1)
        target = offsets[best] + step * _parabola_peak(curves, best)
        confidence = np.where(weight > 0.5, np.max(curves, axis=1), 0.0)
        w = np.where(confidence > opt.min_score, fit_weights(confidence, opt.weighting), 0.0)
        system = (sp.diags(w) + opt.stiffness * self.lap + sp.identity(len(w)) * 1e-6).tocsc()
        move = sp.linalg.spsolve(system, w * target)
        confident = w > 0
        return move, {"search_m": [float(offsets[0]), float(offsets[-1])], "confident_vertices": int(confident.sum()),
                      "mean_score": float(np.mean(confidence[confident])) if confident.any() else 0.0,
                      "mean_move_m": float(np.abs(move).mean())}


def _parabola_peak(values: np.ndarray, best: np.ndarray) -> np.ndarray:
    """Sub-step shift in [-0.5, 0.5] of each row's maximum from a parabola through it and its neighbours."""
    n = values.shape[1]
    i = np.clip(best, 1, n - 2)
    rows = np.arange(len(values))
    left, mid, right = values[rows, i - 1], values[rows, i], values[rows, i + 1]
    denom = left - 2 * mid + right
    shift = np.where(denom < 0, 0.5 * (left - right) / np.where(denom < 0, denom, -1.0), 0.0)
    interior = (best > 0) & (best < n - 1)
    return np.where(interior, np.clip(shift, -0.5, 0.5), 0.0)
