"""The vectorised OBJ reader (render/obj.py) against a line-by-line reference.

Truth: ``_reference_read_obj`` below, the reader as it was before it was vectorised (a Python
loop over lines; kept here verbatim as the semantics to match). On valid files, tricky ones
included (polygons, negative indices, ``v//vn`` forms, comments, blank and indented lines, tabs,
CRLF, extra coordinates), the two give the same arrays bit for bit; bad files give a
``ValueError`` naming ``file:line``.
"""

from pathlib import Path

import numpy as np
import pytest

from anisosample.render.obj import read_obj


def _reference_read_obj(path: Path):
    """The reader before vectorisation (anisosample 4a35ac9, render/obj.py), unchanged."""
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
    corners = [c for f in faces for c in f]
    if max(c[0] for c in corners) >= len(v) or min(c[0] for c in corners) < 0:
        raise ValueError(f"{path}: face refers to a missing vertex")
    vv = v[[c[0] for c in corners]]
    uv = np.array([uvs[c[1]] if c[1] >= 0 and uvs else (0.0, 0.0) for c in corners], np.float64)
    f = np.arange(len(corners)).reshape(-1, 3)
    return vv, uv, f, has_vn


TRICKY = {
    "plain": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    "no_final_newline": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3",
    "polygons_and_negative": (
        "# a quad, a pentagon and a triangle by relative indices\n"
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
        "f 1 2 3 4\n"
        "v 2 0 0\nv 3 0 0\nv 3 1 0\nv 2.5 2 0\nv 2 1 0\n"
        "f -5 -4 -3 -2 -1\n"
        "f -1 -3 -5\n"
        "f 1 2\n"  # fewer than three corners: no triangle
    ),
    "uv_forms": (
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0.5\n"
        "vt 0.25 0.75\nvt 1 0\nvt 0.5 0.5 0.0\n"
        "vn 0 0 1\n"
        "f 1/1 2/2 3/3\n"
        "f 2/-1/1 4/-2/1 3/-3/1\n"
        "f 1//1 2//1 4//1\n"
        "f 1/3/ 2/ 3/1/1/1\n"  # trailing slashes; an extra component
    ),
    "whitespace": (
        "\n   # indented comment\n\tv  0.5\t0 0\n  v 1 0 0   \n"
        "v\t0 1 0 1.0\n"  # a weight w
        "v 1e-3 -2.5E+2 .5 0.1 0.2 0.3\n"  # vertex colours
        "\n\n  f   1  2\t3  \nf 1 3 4 \r\n"
        "o name\ng group\ns off\nusemtl m\nmtllib x.mtl\nvp 0.1 0.2\nl 1 2\n"
    ),
    "crlf": "v 0 0 0\r\nv 1 0 0\r\nv 0 1 0\r\nvt 0.1 0.2\r\nf 1/1 2/1 3/1\r\n",
    "mixed_uv": "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 1\nvt 0.3 0.6\nf 1/1 2 3\nf 2 4 3/1\n",
    "later_vertices": "f 1 2 3\nv 0 0 0\nv 1 0 0\nv 0 1 0\n",  # positive indices look ahead
    "digits": "v -0.0 1.000000000000000222 3.14159265358979323846\nv 1e-320 +2 1e5\n"
              "v 123456789.123456789 -7 0 x\nf +1 2 0003\n",
}


@pytest.mark.parametrize("name", sorted(TRICKY))
def test_matches_the_line_by_line_reader(name, tmp_path):
    path = tmp_path / f"{name}.obj"
    path.write_bytes(TRICKY[name].encode())
    want = _reference_read_obj(path)
    got = read_obj(path)
    assert got[3] == want[3]
    for g, w, what in zip(got[:3], want[:3], ("vertices", "uvs", "faces"), strict=True):
        assert g.shape == w.shape and g.dtype == w.dtype, what
        np.testing.assert_array_equal(g.view(np.uint8), w.view(np.uint8), err_msg=what)


def test_matches_on_a_random_mesh(tmp_path):
    """Polygons of 3-6 corners with every index form, signs and spacing, drawn at random."""
    rng = np.random.default_rng(0)
    lines, nv, nt = [], 0, 0
    for _ in range(400):
        r = rng.random()
        if r < 0.35 or nv < 6:
            lines.append("v " + " ".join(repr(float(x)) for x in rng.normal(size=3) * 10))
            nv += 1
        elif r < 0.5 or nt < 3:
            u, w = (float(x) for x in rng.random(2))
            lines.append(f"vt {u!r} {w!r}")
            nt += 1
        else:
            corners = []
            for _ in range(int(rng.integers(3, 7))):
                i = int(rng.integers(1, nv + 1))
                vi = str(i) if rng.random() < 0.5 else str(i - nv - 1)
                form = rng.integers(4)
                t = int(rng.integers(1, nt + 1))
                ti = str(t) if rng.random() < 0.5 else str(t - nt - 1)
                corners.append([vi, f"{vi}/{ti}", f"{vi}//1", f"{vi}/{ti}/1"][form])
            lines.append("f" + "".join(" " * int(rng.integers(1, 3)) + c for c in corners))
    path = tmp_path / "random.obj"
    path.write_text("\n".join(lines) + "\n")
    want, got = _reference_read_obj(path), read_obj(path)
    assert len(want[2]) > 100
    for g, w in zip(got[:3], want[:3], strict=True):
        np.testing.assert_array_equal(g.view(np.uint8), w.view(np.uint8))


BAD = [
    ("v 0 0 0\nv 1 x 0\nv 0 1 0\nf 1 2 3\n", ":2: cannot parse 'v 1 x 0'"),
    ("v 0 0 0\nv 1 0\nv 0 1 0\nf 1 2 3\n", ":2: cannot parse 'v 1 0'"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0.5\nf 1 2 3\n", ":4: cannot parse 'vt 0.5'"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2.5 3\n", ":5: cannot parse 'f 1 2.5 3'"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 - 3\n", ":4: cannot parse 'f 1 - 3'"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\n\tf 1 /2 3\n", ":4: cannot parse '\\\\tf 1 /2 3'"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/a 2 3\n", ":5: cannot parse 'f 1/a 2 3'"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 4\n", ":5: face refers to a missing vertex"),
    ("v 0 0 0\nv 1 0 0\nf -3 1 2\nv 0 1 0\n", ":3: face refers to a missing vertex"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", ":4: face refers to a missing vertex"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/2 2/1 3/1\n",
     ":5: face refers to a missing texture coordinate"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1 2/1 3/1\n", ":4: face refers to a missing texture"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\n# f 1 2 3\n", ": no faces"),
]


@pytest.mark.parametrize("text, message", BAD)
def test_bad_files_name_the_line(text, message, tmp_path):
    path = tmp_path / "bad.obj"
    path.write_text(text)
    with pytest.raises(ValueError, match="bad.obj" + message.replace(".", r"\.")):
        read_obj(path)


def test_a_bad_line_deep_in_a_big_file_is_found(tmp_path):
    n = 20000
    lines = [f"v {i} {i % 7} 0" for i in range(n)] + [f"f {i + 1} {i + 2} {i + 3}"
                                                        for i in range(n - 2)]
    lines[n + 12345] = "f 1 2 3x"
    path = tmp_path / "big.obj"
    path.write_text("\n".join(lines))
    with pytest.raises(ValueError, match=f"big.obj:{n + 12346}: cannot parse 'f 1 2 3x'"):
        read_obj(path)


def test_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="file not found"):
        read_obj(tmp_path / "gone.obj")
