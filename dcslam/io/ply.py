"""Point-cloud PLY files: binary little-endian, ``x y z`` (float32), ``nx ny nz`` (float32) and ``red green blue``
(uchar) per vertex, the layout Open3D's ``read_point_cloud`` reads with colours and normals.

The reader takes that layout (normals and colours optional, float or double coordinates) and fails with a message
naming the expected layout on anything else.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from dcslam.errors import DcslamError
from dcslam.io.atomic import atomic_output

LAYOUT = "binary_little_endian PLY with one 'vertex' element: x y z [nx ny nz] [red green blue]"
_PLY_TYPES = {"float": "f4", "float32": "f4", "double": "f8", "float64": "f8", "uchar": "u1", "uint8": "u1",
              "char": "i1", "int8": "i1", "ushort": "u2", "uint16": "u2", "short": "i2", "int16": "i2",
              "uint": "u4", "uint32": "u4", "int": "i4", "int32": "i4"}


#: Vertices converted and written at a time: the file is written in pieces, so that writing a map costs memory in
#: proportion to this, not to the map (a drive's whole map is written at the end of its run).
WRITE_CHUNK = 1 << 16


def write_ply(path: Path | str, points: np.ndarray, normals: np.ndarray | None = None,
              colors: np.ndarray | None = None, force: bool = False) -> Path:
    """Write a point cloud atomically. Shape: points (P, 3), normals (P, 3) or None, colors (P, 3) in [0, 1]
    (floats, clipped) or uint8, or None."""
    points = np.asarray(points, dtype=np.float32)
    if points.ndim != 2 or points.shape[1] != 3:
        raise DcslamError(f"points has shape {points.shape}, expected (P, 3)")
    if not np.all(np.isfinite(points)):
        raise DcslamError(f"{path}: refusing to write non-finite points")
    fields = [("x", "f4"), ("y", "f4"), ("z", "f4")]
    if normals is not None:
        normals = np.asarray(normals, dtype=np.float32)
        if normals.shape != points.shape:
            raise DcslamError(f"normals has shape {normals.shape}, expected {points.shape}")
        fields += [("nx", "f4"), ("ny", "f4"), ("nz", "f4")]
    if colors is not None:
        colors = np.asarray(colors)
        if colors.shape != points.shape:
            raise DcslamError(f"colors has shape {colors.shape}, expected {points.shape}")
        fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
    layout = np.dtype([(name, "<" + t) for name, t in fields])
    names = {"f4": "float", "u1": "uchar"}
    header = ["ply", "format binary_little_endian 1.0", "comment written by dcslam", f"element vertex {len(points)}"]
    header += [f"property {names[t]} {name}" for name, t in fields] + ["end_header"]
    with atomic_output(path, force=force) as tmp:
        with open(tmp, "wb") as f:
            f.write(("\n".join(header) + "\n").encode("ascii"))
            for start in range(0, len(points), WRITE_CHUNK):
                part = slice(start, start + WRITE_CHUNK)
                data = np.empty(len(points[part]), dtype=layout)
                for k, axis in enumerate("xyz"):
                    data[axis] = points[part, k]
                    if normals is not None:
                        data["n" + axis] = normals[part, k]
                if colors is not None:
                    rgb = colors[part]
                    if rgb.dtype != np.uint8:
                        rgb = np.clip(np.round(rgb.astype(np.float64) * 255), 0, 255).astype(np.uint8)
                    for k, channel in enumerate(("red", "green", "blue")):
                        data[channel] = rgb[:, k]
                f.write(memoryview(data).cast("B"))
    return Path(path)


def read_ply(path: Path | str) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Read a point cloud → (points (P, 3) float32, normals (P, 3) float32 or None, colors (P, 3) uint8 or None)."""
    path = Path(path)
    if not path.exists():
        raise DcslamError(f"PLY file {path} not found")
    raw = path.read_bytes()
    end = raw.find(b"end_header\n")
    if not raw.startswith(b"ply\n") or end < 0:
        raise DcslamError(f"{path}: not a PLY file (expected {LAYOUT})")
    lines = raw[:end].decode("ascii", errors="replace").splitlines()
    body = raw[end + len(b"end_header\n"):]
    if "format binary_little_endian 1.0" not in lines:
        raise DcslamError(f"{path}: unsupported PLY format (expected {LAYOUT})")
    count, props, element = None, [], None
    for line in lines[1:]:
        words = line.split()
        if not words or words[0] in ("comment", "obj_info", "format"):
            continue
        if words[0] == "element":
            element = words[1]
            if element != "vertex" or len(words) != 3 or not words[2].isdigit():
                raise DcslamError(f"{path}: unexpected element {' '.join(words[1:])!r} (expected {LAYOUT})")
            count = int(words[2])
        elif words[0] == "property" and element == "vertex":
            if len(words) != 3 or words[1] not in _PLY_TYPES:
                raise DcslamError(f"{path}: unsupported property {' '.join(words[1:])!r} (expected {LAYOUT})")
            props.append((words[2], "<" + _PLY_TYPES[words[1]]))
        else:
            raise DcslamError(f"{path}: unexpected header line {line!r} (expected {LAYOUT})")
    names = [name for name, _ in props]
    if count is None or names[:3] != ["x", "y", "z"]:
        raise DcslamError(f"{path}: no vertex element with x y z (expected {LAYOUT})")
    dtype = np.dtype(props)
    if len(body) != count * dtype.itemsize:
        raise DcslamError(f"{path}: {len(body)} bytes of vertex data, expected {count * dtype.itemsize} "
                          f"({count} vertices); the file is truncated or corrupt")
    data = np.frombuffer(body, dtype=dtype, count=count)
    points = np.stack([data["x"], data["y"], data["z"]], 1).astype(np.float32)
    normals = np.stack([data[k] for k in ("nx", "ny", "nz")], 1).astype(np.float32) \
        if {"nx", "ny", "nz"} <= set(names) else None
    colors = np.stack([data[k] for k in ("red", "green", "blue")], 1).astype(np.uint8) \
        if {"red", "green", "blue"} <= set(names) else None
    return points, normals, colors
