"""Minimal PLY point-cloud I/O (x, y, z, red, green, blue), ASCII and binary little/big endian.

Enough for nerfstudio's ``sparse_pc.ply`` and what our synthetic scene writes; other vertex
properties are skipped, faces are ignored.
"""

from __future__ import annotations

from pathlib import Path
from typing import Union

import numpy as np

from nerf2gs_plugin.errors import DataError

_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
    "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}


def read_ply_vertices(path: Union[str, Path]) -> dict[str, np.ndarray]:
    """The vertex element of a PLY (ASCII or binary, either byte order): property name -> ``[P]`` column,
    in file order. The one PLY parser: point clouds (:func:`read_ply_points`) and 3DGS files
    (``methods/gaussian_utils.read_gaussian_ply``) both read through it."""
    path = Path(path)
    if not path.is_file():
        raise DataError("PLY file does not exist", path)
    raw = path.read_bytes()
    end = raw.find(b"end_header")
    if not raw.startswith(b"ply") or end < 0:
        raise DataError("not a PLY file (no 'ply' magic or no end_header)", path)
    header = raw[:end].decode("ascii", errors="replace").splitlines()
    body_start = raw.index(b"\n", end) + 1
    fmt, count, props, in_vertex, before = None, 0, [], False, 0
    for line in header:
        tok = line.split()
        if not tok:
            continue
        if tok[0] == "format":
            fmt = tok[1]
        elif tok[0] == "element":
            in_vertex = tok[1] == "vertex"
            if in_vertex:
                count = int(tok[2])
            elif count == 0:
                before += 1  # an element before the vertices: unsupported below
        elif tok[0] == "property" and in_vertex:
            if tok[1] == "list":
                raise DataError("PLY vertex lists are not supported", path)
            if tok[1] not in _TYPES:
                raise DataError(f"unknown PLY property type '{tok[1]}'", path)
            props.append((tok[2], _TYPES[tok[1]]))
    names = [p[0] for p in props]
    if before or not all(k in names for k in ("x", "y", "z")):
        raise DataError("PLY has no leading vertex element with x, y, z", path)
    try:
        if fmt == "ascii":
            text = raw[body_start:].decode("ascii").split("\n")[:count]
            arr = np.loadtxt(text, dtype=np.float64, ndmin=2) if count else np.zeros((0, len(props)))
            return {n: arr[:, i] for i, n in enumerate(names)}
        if fmt in ("binary_little_endian", "binary_big_endian"):
            order = "<" if fmt == "binary_little_endian" else ">"
            dt = np.dtype([(n, order + t) for n, t in props])
            if len(raw) - body_start < count * dt.itemsize:
                raise DataError(f"PLY file is truncated ({count} vertices declared, {(len(raw) - body_start) // dt.itemsize} present)", path)
            rec = np.frombuffer(raw, dtype=dt, count=count, offset=body_start)
            return {n: rec[n] for n in names}
        raise DataError(f"unknown PLY format '{fmt}'", path)
    except (ValueError, UnicodeDecodeError) as e:
        raise DataError(f"malformed PLY body ({e})", path) from None


def read_ply_points(path: Union[str, Path]) -> tuple[np.ndarray, np.ndarray]:
    """PLY -> (xyz ``[P, 3]`` float32, rgb ``[P, 3]`` uint8; grey 128 where the file has no colour)."""
    cols = read_ply_vertices(path)
    xyz = np.stack([cols["x"], cols["y"], cols["z"]], axis=1).astype(np.float32)
    if all(k in cols for k in ("red", "green", "blue")):
        rgb = np.stack([cols["red"], cols["green"], cols["blue"]], axis=1)
        if rgb.dtype.kind == "f" and rgb.size and rgb.max() <= 1.0:
            rgb = rgb * 255.0
        rgb = np.clip(rgb, 0, 255).astype(np.uint8)
    else:
        rgb = np.full((len(xyz), 3), 128, dtype=np.uint8)
    return xyz, rgb


def write_ply_points(path: Union[str, Path], xyz: np.ndarray, rgb: np.ndarray) -> None:
    """Binary little-endian PLY with float x, y, z and uchar red, green, blue."""
    path = Path(path)
    xyz = np.asarray(xyz, dtype=np.float32).reshape(-1, 3)
    rgb = np.asarray(rgb, dtype=np.uint8).reshape(-1, 3)
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {len(xyz)}\n"
        "property float x\nproperty float y\nproperty float z\n"
        "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n"
    )
    dt = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1")])
    rec = np.empty(len(xyz), dtype=dt)
    rec["x"], rec["y"], rec["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    rec["red"], rec["green"], rec["blue"] = rgb[:, 0], rgb[:, 1], rgb[:, 2]
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_bytes(header.encode("ascii") + rec.tobytes())
    tmp.replace(path)
