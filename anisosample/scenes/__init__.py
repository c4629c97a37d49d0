"""The shipped scenes: Mitsuba 3 XML files (and their meshes and textures), installed with the
package so that they load from anywhere.

``anisosample.scenes.path("cornell")`` is the file's path, for
``anisosample.render.load_xml(path, width=..., height=...)``, for Mitsuba 3
(``mitsuba.load_file(str(path))``) or for the command line (``anisosample render cornell`` takes
a shipped scene's name too). :func:`names` lists them:

* W Sec. 6.2's look-alikes: ``cornell`` (CORNELL-BOX), ``blinds`` (BREAKFAST-ROOM), ``attic``
  (ATTIC, a textured sky light), ``dof`` (DEPTH-OF-FIELD, thin lens, point light);
* beyond W: ``pillars`` (three pillars whose penumbra directions turn within a 16x16 block:
  at 128^2 the 10-90 percentile spread per block is up to 28 degrees, median 14; per-pixel
  directions);
* H Sec. 4: ``triangle_light`` and ``h_triangle_plane`` (Fig. 2), ``patch_light`` (Fig. 3, a
  bilinear-patch light, our XML extension), ``glossy`` (Table 5, GGX), ``plastic``
  (roughplastic).

Each file's opening comment says what it is for; each declares ``<default>`` ``spp``,
``width`` and ``height`` parameters.
"""

from __future__ import annotations

from pathlib import Path

FOLDER = Path(__file__).resolve().parent
"""The folder that holds the scene files (next to this module)."""


def names() -> tuple[str, ...]:
    """The shipped scenes' names (file stems), sorted."""
    return tuple(sorted(p.stem for p in FOLDER.glob("*.xml")))


def path(name: str) -> Path:
    """The XML file of the shipped scene ``name`` (one of :func:`names`, without ``.xml``).

    ``TypeError`` for a non-string, ``ValueError`` naming the shipped scenes for any other name.
    """
    if not isinstance(name, str):
        raise TypeError(f"name must be a scene name (str), got {type(name).__name__} {name!r}")
    known = names()
    if name not in known:
        hint = " (give the name without .xml)" if name.removesuffix(".xml") in known else ""
        raise ValueError(f"name must be one of the shipped scenes {', '.join(known)}; got "
                         f"{name!r}{hint}")
    return FOLDER / f"{name}.xml"
