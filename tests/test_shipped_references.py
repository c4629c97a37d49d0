"""Shipped files name only files that exist: every repository path written in the package, the
experiments, the scenes, the docs, the tests and the top-level files (``tests/...py``,
``anisosample/scenes/...xml``, ``docs/...md``) is checked against the tree. The team's notes
outside the repository (``shared/``, ``papers/``) count as dangling too: users do not have them.
"""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SHIPPED = ["anisosample", "experiments", "docs", "tests"]
TOP_LEVEL = ["README.md", "Makefile", "pyproject.toml"]
SUFFIXES = {".py", ".md", ".xml", ".obj", ".toml", ".txt", ".cfg", ""}
# a path beginning at one of the repository's folders (or the team's unshipped ones), ending in a
# file suffix; "results/NAME/NAME.json" style placeholders (capitals) are patterns, not files
PATH = re.compile(
    r"(?<![\w/.-])((?:anisosample|experiments|docs|tests|shared|papers)/[\w./-]*\w"
    r"\.(?:py|xml|md|obj|exr|json|npz|npy|txt|toml|png|csv))(?![\w/])"
)


def shipped_files() -> list[Path]:
    files = [ROOT / name for name in TOP_LEVEL if (ROOT / name).exists()]
    for folder in SHIPPED:
        for p in sorted((ROOT / folder).rglob("*")):
            if p.is_file() and p.suffix in SUFFIXES and "__pycache__" not in p.parts \
                    and not p.name.startswith("."):
                files.append(p)
    return files


def references(text: str) -> list[tuple[int, str]]:
    out = []
    for m in PATH.finditer(text):
        ref = m.group(1)
        if re.search(r"[A-Z]{3,}", ref):  # a placeholder such as NAME
            continue
        out.append((text.count("\n", 0, m.start()) + 1, ref))
    return out


def test_the_scanner_finds_paths_and_skips_placeholders():
    text = ("see tests/render/test_patch_mitsuba.py does\n"
            "(anisosample/render/mitsuba_compat.py), results/NAME/NAME.json, x/tests/a.py")
    assert references(text) == [(1, "tests/render/test_patch_mitsuba.py"),
                                (2, "anisosample/render/mitsuba_compat.py")]


def test_no_shipped_file_names_a_missing_file():
    dangling = []
    for path in shipped_files():
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError:
            continue
        for line, ref in references(text):
            if path == Path(__file__):
                continue  # this file's own examples
            if not (ROOT / ref).exists():
                dangling.append(f"{path.relative_to(ROOT)}:{line}: {ref}")
    if dangling:
        pytest.fail("shipped files name files that do not exist:\n" + "\n".join(dangling))
