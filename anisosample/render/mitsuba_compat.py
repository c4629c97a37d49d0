"""Scene files for stock Mitsuba 3: our XML extension replaced by what Mitsuba loads.

``<shape type="bilinear">`` (a bilinear patch, :mod:`anisosample.render.patch`) is ours; Mitsuba
3 has no such plugin. :func:`mitsuba_compatible_copy` writes a copy of a scene file in which
every bilinear patch is a fine triangle tessellation (an OBJ with the patch's orientation), so
that Mitsuba renders the same scene as the reference for tests and experiments. Mitsuba itself
is not needed to write the copy.
"""

from __future__ import annotations

import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

# 64x64 cells: chord error 1.0e-4 for the shipped patch light (4.7e-5 of its diagonal; the bound
# is |q| / (4 N^2) with the twist q = p11 - p10 - p01 + p00) and at most 4.6e-5 relative change
# of the unoccluded floor irradiance (against 200^2-point Gauss-Legendre on the exact patch).
PATCH_TESSELLATION = 64


def mitsuba_compatible_copy(path, folder, *, tessellation: int = PATCH_TESSELLATION,
                            **params) -> Path:
    """Write ``folder/<name>.xml``: the scene at ``path`` with every ``<shape type="bilinear">``
    replaced by an OBJ of a ``tessellation x tessellation`` grid whose faces keep the patch's
    orientation (``p_u x p_v``, flips applied). Files the scene refers to by relative path
    (meshes, bitmaps) are copied next to it. ``params`` are the scene's ``<default>``
    overrides, used to read the patch corners. Returns the new file's path.
    """
    from .._validate import check_int
    from .xml import load_xml

    path = Path(path)
    folder = Path(folder)
    tess = check_int("tessellation", tessellation, minimum=1)
    if folder.resolve() == path.parent.resolve():
        raise ValueError(f"folder must differ from the scene's own folder {path.parent}")
    folder.mkdir(parents=True, exist_ok=True)
    tree = ET.parse(path)
    shapes = [s for s in tree.getroot().iter("shape") if s.get("type") == "bilinear"]
    corners = np.asarray(load_xml(path, **params).patches.corners, np.float64) if shapes else []
    if len(shapes) != len(corners):
        raise ValueError(f"{path}: {len(shapes)} bilinear shapes but {len(corners)} patches")
    g = np.linspace(0.0, 1.0, tess + 1)
    u, v = (a[..., None] for a in np.meshgrid(g, g, indexing="ij"))
    i, j = np.meshgrid(np.arange(tess), np.arange(tess), indexing="ij")
    idx = lambda a, b: (a * (tess + 1) + b + 1).ravel()  # noqa: E731  (OBJ is 1-based)
    faces = np.concatenate([
        np.stack([idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)], 1),
        np.stack([idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)], 1)])
    for k, (shape, c) in enumerate(zip(shapes, corners, strict=True)):
        verts = ((1 - u) * ((1 - v) * c[0, 0] + v * c[0, 1])
                 + u * ((1 - v) * c[1, 0] + v * c[1, 1])).reshape(-1, 3)
        name = f"{path.stem}_patch{k}.obj"
        (folder / name).write_text("\n".join(
            [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in verts]
            + [f"f {a} {b} {cc}" for a, b, cc in faces]) + "\n")
        for child in list(shape):
            if child.tag in ("point", "transform") or child.get("name") == "flip_normals":
                shape.remove(child)
        shape.set("type", "obj")
        shape.insert(0, ET.Element("string", name="filename", value=name))
        shape.insert(1, ET.Element("boolean", name="face_normals", value="true"))
    for el in tree.getroot().iter("string"):
        if el.get("name") == "filename" and (path.parent / el.get("value", "")).is_file():
            src = path.parent / el.get("value")
            dst = folder / el.get("value")
            dst.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(src, dst)
    out = folder / path.name
    tree.write(out)
    return out
