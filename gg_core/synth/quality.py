"""Checks that a synthetic capture is what it claims: renders agree with the ground truth, the garment
moves, stays out of the body, and a hidden effect really changes the motion.

Everything is measured from the files of the capture (capture layout + gt meshes), so the same checks
run in the generator's report and in the tests.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..capture.images import read_mask
from ..capture.layout import GARMENT_MASK, Capture, Sequence
from ..geometry.meshio import read_mesh
from .proximity import MeshProximity

PENETRATION_DEPTH = 0.005   # m: deeper than this inside the body counts as penetration


def gt_frames(seq: Sequence) -> np.ndarray:
    """Ground-truth garment vertices [T,V,3] in frame order."""
    files = seq.gt_garment_files
    return np.stack([read_mesh(files[f])[0] for f in sorted(files)])


def body_frames(seq: Sequence) -> tuple[np.ndarray, np.ndarray]:
    meshes = [read_mesh(seq.body_path(f)) for f in seq.frames]
    return np.stack([v for v, _ in meshes]), meshes[0][1]


def mean_displacement(frames: np.ndarray) -> float:
    """Mean per-frame vertex displacement (m/frame) over a sequence [T,V,3]."""
    return float(np.linalg.norm(np.diff(frames, axis=0), axis=2).mean())


def penetration(garment: np.ndarray, body: np.ndarray, body_faces: np.ndarray,
                depth: float = PENETRATION_DEPTH) -> np.ndarray:
    """Per frame, the fraction of garment vertices more than `depth` inside the body ([T])."""
    prox = MeshProximity(body[0], body_faces)
    out = []
    for g, b in zip(garment, body):
        prox.update(b)
        out.append(float((prox.signed_distance(g) < -depth).mean()))
    return np.asarray(out)


def projection_consistency(seq: Sequence, garment: np.ndarray, body: np.ndarray, body_faces: np.ndarray,
                           tolerance_px: int = 1) -> dict[str, float]:
    """Per camera, the fraction of in-image garment vertices unoccluded by the body that fall on the mask.

    Occlusion is a ray from the camera centre to the vertex hitting the body first (embree). Vertices on
    the garment's silhouette (waistband, hem) lie on the mask's edge, where pixel-centre sampling puts
    them on either side: `tolerance_px` accepts a garment pixel that near (0 = the vertex's own pixel)."""
    import trimesh  # noqa: PLC0415
    from scipy import ndimage  # noqa: PLC0415

    out: dict[str, float] = {}
    hits = {cid: [0, 0] for cid in seq.camera_ids}
    for t, frame in enumerate(seq.frames):
        body_mesh = trimesh.Trimesh(body[t], body_faces, process=False)
        ray = trimesh.ray.ray_pyembree.RayMeshIntersector(body_mesh)
        for cid, cam in seq.cameras.items():
            uv, z = cam.project(garment[t])
            px = np.floor(uv).astype(int)
            inside = (z > 0) & (px[:, 0] >= 0) & (px[:, 0] < cam.width) & (px[:, 1] >= 0) & (px[:, 1] < cam.height)
            direction = garment[t] - cam.center
            dist = np.linalg.norm(direction, axis=1)
            direction /= dist[:, None]
            loc, rows, _ = ray.intersects_location(np.repeat(cam.center[None], len(dist), 0), direction,
                                                   multiple_hits=False)
            occluded = np.zeros(len(dist), bool)
            occluded[rows] = np.linalg.norm(loc - cam.center, axis=1) < dist[rows] - 1e-4
            check = inside & ~occluded
            mask = read_mask(seq.image_path(cid, frame, GARMENT_MASK))
            if tolerance_px:
                mask = ndimage.binary_dilation(mask, np.ones((3, 3), bool), iterations=tolerance_px)
            hits[cid][0] += int(mask[px[check, 1], px[check, 0]].sum())
            hits[cid][1] += int(check.sum())
    for cid, (good, total) in hits.items():
        out[cid] = good / total if total else float("nan")
    return out


def trajectory_difference(a: Path, b: Path) -> dict[str, float]:
    """Mean and max vertex distance (m) between the ground truths of two captures, per common sequence."""
    ca, cb = Capture(a), Capture(b)
    out = {}
    for name in sorted(set(ca.sequences) & set(cb.sequences)):
        ga, gb = gt_frames(ca.sequence(name)), gt_frames(cb.sequence(name))
        d = np.linalg.norm(ga - gb, axis=2)
        out[name] = {"mean_m": float(d.mean()), "max_m": float(d.max()), "last_frame_mean_m": float(d[-1].mean())}
    return out


def capture_quality(root: Path, collider_faces: np.ndarray | None = None) -> dict:
    """All checks for every sequence of a synthetic capture (the generator's report section)."""
    out = {}
    for name, seq in Capture(root).sequences.items():
        garment = gt_frames(seq)
        body, faces = body_frames(seq)
        pen = penetration(garment, body, faces if collider_faces is None else collider_faces)
        proj = projection_consistency(seq, garment, body, faces)
        strict = projection_consistency(seq, garment, body, faces, tolerance_px=0)
        out[name] = {"mean_displacement_m_per_frame": mean_displacement(garment),
                     "max_penetrating_fraction": float(pen.max()),
                     "projection_consistency_min": float(min(proj.values())),
                     "projection_consistency": proj,
                     "projection_consistency_exact_pixel_min": float(min(strict.values()))}
    return out
