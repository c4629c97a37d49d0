"""A small Wavefront OBJ reader for triangle meshes (positions, texture coordinates, faces).

Polygons are fanned into triangles; texture ``v`` is flipped as Mitsuba 3 does (image rows run
top-down); vertex normals are only reported (the renderer uses face normals).

The reader is vectorised: it never loops over lines in Python. The file's bytes are tokenised
with NumPy (lines end at ``\\n``, ``\\r\\n``, ``\\r`` and the other ASCII breaks of Python's
``str.splitlines``; tokens are separated by ASCII blanks), each line is classified by its first
token (``v``, ``vt``, ``vn``, ``f``; anything else, comments included, is skipped), the numbers of
all ``v`` lines (their first three), of all ``vt`` lines (their first two) and the indices of all
``f`` lines (``v``, ``v/vt``, ``v//vn``, ``v/vt/vn``) are parsed by one ``np.fromstring`` each, a
negative (relative) index counts back from the last vertex defined above its line, and polygons
are fanned ``(0, k, k + 1)`` with array operations: a 998,000-triangle file (70 MB) reads in
3.2-5.0 s on the 2-core reference machine, depending on its load
(``experiments/bench_render.py``). A line that does not parse, and a face that refers to a vertex
or texture coordinate that is not there (index 0 included), raise ``ValueError`` naming
``file:line``; a bad line is found by bisection over the parsed ranges, so errors cost no loop
either.
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np

# Line breaks of Python's str.splitlines besides \n, \r\n, \r; \t and \x1f are blanks.
_BREAKS = bytes.maketrans(b"\x0b\x0c\x1c\x1d\x1e", b"\n\n\n\n\n")
_BLANKS = bytes.maketrans(b"\t\x1f", b"  ")
_SP, _NL, _SLASH, _PLUS, _MINUS = 32, 10, 47, 43, 45
_V, _VT, _VN, _F = 1, 2, 3, 4


def read_obj(path: Path):
    """``(vertices (3f, 3), uvs (3f, 2), faces (f, 3), has_vertex_normals)``, per-corner.

    Raises ``FileNotFoundError`` for a missing file and ``ValueError`` (``file:line: ...``) for a
    line that does not parse, a face corner without its vertex or texture coordinate, and a file
    without faces.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"file not found: {path}")
    raw = path.read_bytes()
    if b"\r" in raw:
        raw = raw.replace(b"\r\n", b"\n").replace(b"\r", b"\n")
    if any(c in raw for c in (b"\x0b", b"\x0c", b"\x1c", b"\x1d", b"\x1e")):
        raw = raw.translate(_BREAKS)
    if not raw.endswith(b"\n"):
        raw += b"\n"
    text = raw.translate(_BLANKS) if b"\t" in raw or b"\x1f" in raw else raw
    if text.startswith(b" ") or b"\n " in text:
        text = re.sub(rb"(?m)^ +", b"", text)  # leading blanks (keeps the lines)
    tok = _Tokens(text)

    def fail(line: int, what: str):
        shown = raw.split(b"\n", line + 1)[line].decode("utf-8", "replace")
        raise ValueError(f"{path}:{line + 1}: {what} {shown!r}")

    def numbers(kind: int, columns: int):
        """The first ``columns`` numbers of every line of ``kind``: ``(lines, (k, columns))``."""
        lines, counts, idx, rank = tok.body(kind)
        if np.any(counts < columns):
            fail(int(lines[np.argmax(counts < columns)]), "cannot parse")
        idx = idx[rank < columns]
        lo, hi = tok.start[idx], tok.end[idx]
        out = _floats(tok.arr, lo, hi)
        if out is None:
            fail(int(tok.line[idx[_first_bad(_floats, tok.arr, lo, hi)]]), "cannot parse")
        return lines, out.reshape(-1, columns)

    v_lines, verts = numbers(_V, 3)
    t_lines, uvs = numbers(_VT, 2)
    uvs[:, 1] = 1.0 - uvs[:, 1]  # Mitsuba flips v of OBJ texture coordinates (rows top-down)

    # Faces: each corner token is "v", "v/vt", "v//vn" or "v/vt/vn" (the normal is not read).
    f_lines, counts, idx, _ = tok.body(_F)
    lo, end = tok.start[idx], tok.end[idx]
    line = tok.line[idx]
    slash = np.flatnonzero(tok.arr[: tok.n] == _SLASH)
    k = np.searchsorted(slash, lo)
    at = lambda j: slash[np.minimum(j, len(slash) - 1)] if len(slash) else end  # noqa: E731
    s1 = np.where((k < len(slash)) & (at(k) < end), at(k), end)
    s2 = np.where((s1 < end) & (k + 1 < len(slash)) & (at(k + 1) < end), at(k + 1), end)
    vi = _integers(tok.arr, lo, s1)
    if vi is None:
        fail(int(line[_first_bad(_integers, tok.arr, lo, s1)]), "cannot parse")
    has_t = s2 > s1 + 1
    ti = np.zeros(len(idx), np.int64)
    t = _integers(tok.arr, s1[has_t] + 1, s2[has_t])
    if t is None:
        sub = np.flatnonzero(has_t)
        fail(int(line[sub[_first_bad(_integers, tok.arr, s1[sub] + 1, s2[sub])]]),
             "cannot parse")
    ti[has_t] = t
    vi = _resolve(vi, np.searchsorted(v_lines, line), len(verts))
    ti = np.where(has_t, _resolve(ti, np.searchsorted(t_lines, line), len(uvs)), -1)

    # Fan every polygon of m >= 3 corners into the triangles (0, k, k + 1), k = 1 .. m - 2.
    ntri = np.maximum(counts - 2, 0)
    first = np.cumsum(counts) - counts  # the polygon's first corner
    poly = np.repeat(np.arange(len(counts)), ntri)
    k = 1 + np.arange(int(ntri.sum())) - np.repeat(np.cumsum(ntri) - ntri, ntri)
    corners = (first[poly][:, None] + np.stack([np.zeros_like(k), k, k + 1], 1)).reshape(-1)
    if corners.size == 0:
        raise ValueError(f"{path}: no faces")
    bad = vi[corners] < 0
    if bad.any():
        fail(int(line[corners[np.argmax(bad)]]), "face refers to a missing vertex:")
    bad = ti[corners] < -1
    if bad.any():
        fail(int(line[corners[np.argmax(bad)]]), "face refers to a missing texture coordinate:")
    vv = verts[vi[corners]]
    uv = np.zeros((corners.size, 2))
    tc = ti[corners]
    uv[tc >= 0] = uvs[tc[tc >= 0]]
    faces = np.arange(corners.size).reshape(-1, 3)
    return vv, uv, faces, bool(np.any(tok.kind == _VN))


def _resolve(index: np.ndarray, defined_before: np.ndarray, total: int) -> np.ndarray:
    """OBJ indices (1-based; negative: relative to the ``defined_before`` entries above the line)
    to 0-based ones; ``-2`` where none is there (index 0 or out of range)."""
    out = np.where(index > 0, index - 1, defined_before + index)
    return np.where((index != 0) & (out >= 0) & (out < total), out, -2)


class _Tokens:
    """The lines and blank-separated tokens of ``text`` (ending with a newline, no leading
    blanks, blanks are spaces): line starts and kinds, token byte ranges and lines."""

    def __init__(self, text: bytes):
        self.n = n = len(text)
        self.arr = arr = np.frombuffer(text + b"\n\n", np.uint8)  # two bytes of look-ahead
        ends = np.flatnonzero(arr[:n] == _NL)
        self.first = first = np.concatenate([[0], ends[:-1] + 1])  # line starts
        c0, c1, c2 = arr[first], arr[first + 1], arr[first + 2]
        end1 = (c1 == _SP) | (c1 == _NL)
        end2 = (c2 == _SP) | (c2 == _NL)
        kind = np.zeros(len(first), np.int8)
        kind[(c0 == ord("v")) & end1] = _V
        kind[(c0 == ord("v")) & (c1 == ord("t")) & end2] = _VT
        kind[(c0 == ord("v")) & (c1 == ord("n")) & end2] = _VN
        kind[(c0 == ord("f")) & end1] = _F
        self.kind = kind
        sep = (arr[: n + 1] == _SP) | (arr[: n + 1] == _NL)
        inside = ~sep[:n]
        self.start = np.flatnonzero(inside & np.concatenate([[True], sep[: n - 1]]))
        self.end = np.flatnonzero(inside & sep[1:]) + 1
        self.line = np.searchsorted(ends, self.start)

    def body(self, kind: int):
        """Lines of ``kind`` (indices), their token counts past the first, those tokens
        (indices, in file order) and each one's rank in its line (0 for the first)."""
        lines = np.flatnonzero(self.kind == kind)
        sel = np.flatnonzero((self.kind[self.line] == kind) & (self.start != self.first[self.line]))
        counts = np.bincount(self.line[sel], minlength=len(self.kind))[lines]
        rank = np.arange(len(sel)) - np.repeat(np.cumsum(counts) - counts, counts)
        return lines, counts, sel, rank


def _floats(arr: np.ndarray, lo: np.ndarray, hi: np.ndarray):
    """The numbers written in the byte ranges ``[lo, hi)`` of ``arr`` (increasing, disjoint),
    one per range, parsed by one ``np.fromstring`` (correctly rounded, as Python's ``float``);
    ``None`` if a range is empty or holds anything but one number."""
    if lo.size == 0:
        return np.zeros(0)
    if np.any(hi <= lo):
        return None
    a, b = int(lo[0]), int(hi[-1])
    d = np.zeros(b - a + 1, np.int8)
    d[lo - a] = 1
    d[hi - a] = -1  # disjoint, non-empty ranges: no end is a start
    keep = np.cumsum(d[:-1], dtype=np.int8) > 0
    chunk = arr[a:b].copy()
    chunk[hi[:-1] - a] = _SP  # one blank after each range
    keep[hi[:-1] - a] = True
    text = chunk[keep].tobytes()
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)  # older NumPy: unread data warns
        try:
            out = np.fromstring(text, dtype=np.float64, sep=" ")
        except (ValueError, DeprecationWarning):
            return None
    return out if out.size == lo.size else None


def _integers(arr: np.ndarray, lo: np.ndarray, hi: np.ndarray):
    """The integers written in the byte ranges ``[lo, hi)`` of ``arr`` (an optional sign, then
    1 to 18 decimal digits), one per range, read digit by digit over all ranges at once;
    ``None`` if a range holds anything else."""
    c = arr[lo]
    signed = (c == _PLUS) | (c == _MINUS)
    pos = lo + signed  # the first digit
    digits = hi - pos
    if lo.size and (digits.min() < 1 or digits.max() > 18):
        return None
    value = np.zeros(lo.size, np.int64)
    for j in range(int(digits.max()) if lo.size else 0):
        live = j < digits
        dig = arr[np.where(live, pos + j, 0)].astype(np.int64) - ord("0")
        if np.any(live & ((dig < 0) | (dig > 9))):
            return None
        value = np.where(live, 10 * value + dig, value)
    return np.where(c == _MINUS, -value, value)


def _first_bad(parse, arr: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> int:
    """The first range that ``parse`` (:func:`_floats`, :func:`_integers`) rejects, by
    bisection (some range must be bad)."""
    i, j = 0, len(lo)  # the first bad range is in [i, j)
    while j - i > 1:
        m = (i + j) // 2
        if parse(arr, lo[i:m], hi[i:m]) is None:
            j = m
        else:
            i = m
    return i
