"""A small Wavefront OBJ reader for triangle meshes (positions, texture coordinates, faces).

Polygons are fanned into triangles; texture ``v`` is flipped as Mitsuba 3 does (image rows run
top-down); vertex normals are only reported (the renderer uses face normals).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def read_obj(path: Path):
    """``(vertices (3f, 3), uvs (3f, 2), faces (f, 3), has_vertex_normals)``, per-corner."""
    if not path.exists():
        raise FileNotFoundError(f"file not found: {path}")
    verts, uvs, faces, has_vn = [], [], [], False
    for lineno, line in enumerate(path.read_text().splitlines(), 1):
        parts = line.split()
        if not parts or parts[0].startswith("#"):
            continue
        try:
            if parts[0] == "v":
                verts.append([float(x) for x in parts[1:4]])
            elif parts[0] == "vt":
                # Mitsuba flips v of OBJ texture coordinates (image rows run top-down).
                uvs.append([float(parts[1]), 1.0 - float(parts[2])])
            elif parts[0] == "vn":
                has_vn = True
            elif parts[0] == "f":
                idx = []
                for p in parts[1:]:
                    comp = p.split("/")
                    vi = int(comp[0])
                    ti = int(comp[1]) if len(comp) > 1 and comp[1] else 0
                    idx.append(
                        (
                            vi - 1 if vi > 0 else len(verts) + vi,
                            ti - 1 if ti > 0 else (len(uvs) + ti if ti < 0 else -1),
                        )
                    )
                for k in range(1, len(idx) - 1):
                    faces.append([idx[0], idx[k], idx[k + 1]])
        except (ValueError, IndexError):
            raise ValueError(f"{path}:{lineno}: cannot parse {line!r}") from None
    if not faces:
        raise ValueError(f"{path}: no faces")
    v = np.array(verts, np.float64)
    # Unroll to per-corner vertices so that each corner can carry its own uv.
    corners = [c for f in faces for c in f]
    if max(c[0] for c in corners) >= len(v) or min(c[0] for c in corners) < 0:
        raise ValueError(f"{path}: face refers to a missing vertex")
    vv = v[[c[0] for c in corners]]
    uv = np.array([uvs[c[1]] if c[1] >= 0 and uvs else (0.0, 0.0) for c in corners], np.float64)
    f = np.arange(len(corners)).reshape(-1, 3)
    return vv, uv, f, has_vn
