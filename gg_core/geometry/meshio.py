"""Mesh files (PLY/OBJ) without trimesh's processing, so vertex order and topology are kept exactly.

Numpy + stdlib only (the Blender add-on reads body and garment meshes through this module).
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import InputError

_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
              "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
              "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}


def read_mesh(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """(vertices float64 [V,3], triangles int64 [F,3]) of a PLY or OBJ file; bad files raise InputError."""
    path = Path(path)
    if not path.is_file():
        raise InputError("mesh file not found", path, "check the path")
    try:
        if path.suffix.lower() == ".ply":
            verts, faces = _read_ply(path)
        elif path.suffix.lower() == ".obj":
            verts, faces, _, _ = read_obj(path)
        else:
            raise InputError(f"unsupported mesh format '{path.suffix}'", path, "use .ply or .obj")
    except InputError:
        raise
    except (ValueError, IndexError, UnicodeDecodeError, KeyError) as exc:
        raise InputError(f"mesh file cannot be parsed ({exc})", path, "re-export it as PLY or OBJ") from None
    if not np.isfinite(verts).all():
        raise InputError("mesh has NaN or infinite vertex coordinates", path, "re-export the mesh")
    if faces.size and (faces.min() < 0 or faces.max() >= len(verts)):
        raise InputError("mesh faces index vertices that do not exist", path, "re-export the mesh")
    return verts, faces


def write_ply(path: str | os.PathLike, verts: np.ndarray, faces: np.ndarray | None = None) -> None:
    """Binary little-endian PLY, written atomically."""
    from ..storage import atomic_path

    verts = np.ascontiguousarray(verts, dtype="<f4")
    faces = np.zeros((0, 3), np.int64) if faces is None else np.asarray(faces)
    header = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(verts)}\n"
              "property float x\nproperty float y\nproperty float z\n"
              f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n")
    rec = np.empty(len(faces), dtype=[("n", "u1"), ("idx", "<i4", (3,))])
    rec["n"] = 3
    rec["idx"] = faces
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        fh.write(header.encode("ascii"))
        fh.write(verts.tobytes())
        fh.write(rec.tobytes())


def write_obj(path: str | os.PathLike, verts: np.ndarray, faces: np.ndarray,
              uvs: np.ndarray | None = None, face_uvs: np.ndarray | None = None) -> None:
    """OBJ with optional UVs (`uvs` [T,2], `face_uvs` [F,3] indices into them), written atomically."""
    from ..storage import atomic_path

    lines = ["# gaussian-garments"]
    lines += [f"v {x:.7g} {y:.7g} {z:.7g}" for x, y, z in verts]
    if uvs is not None:
        lines += [f"vt {u:.7g} {v:.7g}" for u, v in uvs]
        fu = faces if face_uvs is None else face_uvs
        lines += [f"f {a+1}/{ta+1} {b+1}/{tb+1} {c+1}/{tc+1}" for (a, b, c), (ta, tb, tc) in zip(faces, fu)]
    else:
        lines += [f"f {a+1} {b+1} {c+1}" for a, b, c in faces]
    with atomic_path(path) as tmp:
        tmp.write_text("\n".join(lines) + "\n")


def read_obj(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """(verts, triangles, uvs or None, face_uvs or None); polygons are fan-triangulated."""
    verts, uvs, faces, face_uvs = [], [], [], []
    for line in Path(path).read_text().splitlines():
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "v":
            verts.append([float(x) for x in parts[1:4]])
        elif parts[0] == "vt":
            uvs.append([float(x) for x in parts[1:3]])
        elif parts[0] == "f":
            corners = [p.split("/") for p in parts[1:]]
            vi = [int(c[0]) for c in corners]
            ti = [int(c[1]) if len(c) > 1 and c[1] else 0 for c in corners]
            for k in range(1, len(vi) - 1):
                faces.append([vi[0], vi[k], vi[k + 1]])
                face_uvs.append([ti[0], ti[k], ti[k + 1]])
    v = np.asarray(verts, np.float64).reshape(-1, 3)
    f = np.asarray(faces, np.int64).reshape(-1, 3)
    f = np.where(f < 0, f + len(v), f - 1)
    if uvs and np.all(np.asarray(face_uvs) != 0):
        t = np.asarray(uvs, np.float64)
        ft = np.asarray(face_uvs, np.int64)
        return v, f, t, np.where(ft < 0, ft + len(t), ft - 1)
    return v, f, None, None


def _read_ply(path: Path) -> tuple[np.ndarray, np.ndarray]:
    data = path.read_bytes()
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise InputError("not a PLY file (no ply header)", path, "re-export the mesh")
    body_start = data.index(b"\n", end) + 1
    header = data[:body_start].decode("ascii").splitlines()
    fmt = next(l.split()[1] for l in header if l.startswith("format"))
    elements: list[tuple[str, int, list[tuple]]] = []
    for line in header:
        parts = line.split()
        if parts[0] == "element":
            elements.append((parts[1], int(parts[2]), []))
        elif parts[0] == "property":
            if parts[1] == "list":
                elements[-1][2].append(("list", parts[2], parts[3], parts[4]))
            else:
                elements[-1][2].append(("scalar", parts[1], parts[2]))
    if fmt == "ascii":
        return _read_ply_ascii(data[body_start:].decode("ascii"), elements)
    endian = "<" if fmt == "binary_little_endian" else ">"
    offset, verts, faces = body_start, None, np.zeros((0, 3), np.int64)
    for name, count, props in elements:
        if all(p[0] == "scalar" for p in props):
            dt = np.dtype([(p[2], endian + _PLY_TYPES[p[1]]) for p in props])
            arr = np.frombuffer(data, dt, count, offset)
            offset += dt.itemsize * count
            if name == "vertex":
                verts = np.stack([arr["x"], arr["y"], arr["z"]], axis=1).astype(np.float64)
        elif name == "face" and len(props) == 1:
            _, cnt_t, idx_t, _ = props[0]
            cdt, idt = np.dtype(endian + _PLY_TYPES[cnt_t]), np.dtype(endian + _PLY_TYPES[idx_t])
            first = int(np.frombuffer(data, cdt, 1, offset)[0]) if count else 3
            rec = np.dtype([("n", cdt), ("idx", idt, (first,))])
            arr = np.frombuffer(data, rec, count, offset)
            if count and not (arr["n"] == first).all():
                raise InputError("PLY faces are not all of one size", path, "triangulate the mesh before export")
            offset += rec.itemsize * count
            faces = _triangulate(arr["idx"].astype(np.int64))
        else:
            raise InputError(f"PLY element '{name}' has an unsupported layout", path, "re-export as plain PLY")
    if verts is None:
        raise InputError("PLY has no vertex element", path, "re-export the mesh")
    return verts, faces


def _read_ply_ascii(text: str, elements: list) -> tuple[np.ndarray, np.ndarray]:
    rows = iter(text.split("\n"))
    verts, faces = None, np.zeros((0, 3), np.int64)
    for name, count, props in elements:
        lines = [next(rows).split() for _ in range(count)]
        if name == "vertex":
            names = [p[2] for p in props]
            arr = np.asarray(lines, np.float64).reshape(count, len(names))
            verts = arr[:, [names.index(a) for a in "xyz"]]
        elif name == "face":
            polys = [[int(x) for x in l[1:1 + int(l[0])]] for l in lines]
            faces = np.asarray([[p[0], p[k], p[k + 1]] for p in polys for k in range(1, len(p) - 1)],
                               np.int64).reshape(-1, 3)
    if verts is None:
        raise ValueError("no vertex element")
    return verts, faces


def _triangulate(polys: np.ndarray) -> np.ndarray:
    if polys.shape[1] == 3:
        return polys
    return np.concatenate([polys[:, [0, k, k + 1]] for k in range(1, polys.shape[1] - 1)])
