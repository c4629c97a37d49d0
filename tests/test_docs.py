"""The documentation runs and says what the results say.

* every ```python block of ``docs/guide.md`` and ``README.md`` runs, each in a fresh namespace;
  guide blocks in a scratch working directory (they may write files), README blocks from the
  repository root (they name repository paths and must not write); a block preceded by the line
  ``<!-- doctest: slow -->`` compiles bigger programs and is marked slow (``make test-all``);
* every number quoted in ``docs/reproduction.md`` after a ``<!-- json:PATH:KEY -->`` marker
  agrees with that JSON to the digits written, when the JSON exists (``results/`` is not
  versioned: a fresh clone skips these until ``make figures``);
* ``docs/gen_api.py`` documents every public module; ``docs/fill_numbers.py`` fills markers.

The number check here is written independently of ``docs/fill_numbers.py`` (its own parser, its own
key walk, a tolerance from the digits written), so the two cross-check each other.
"""

from __future__ import annotations

import importlib.util
import json
import math
import re
import sys
import types
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
REPORT = DOCS / "reproduction.md"
SLOW = "<!-- doctest: slow -->"  # on the line before a fence: run only with `make test-all`
FENCE = re.compile(r"^```python[ \t]*\n(.*?)^```[ \t]*$", re.S | re.M)


def _python_blocks():
    cases = []
    for doc in (ROOT / "README.md", DOCS / "guide.md"):
        if not doc.exists():
            continue
        text = doc.read_text()
        for i, m in enumerate(FENCE.finditer(text)):
            line = text.count("\n", 0, m.start()) + 2  # first line of code
            before = text[: m.start()].rstrip().rsplit("\n", 1)[-1].strip()
            marks = [pytest.mark.slow] if before == SLOW else []
            cases.append(pytest.param(m.group(1), doc.name == "README.md",
                                      id=f"{doc.name}:{line}:block{i}", marks=marks))
    return cases


@pytest.mark.parametrize("code, from_root", _python_blocks())
def test_doc_example_runs(code, from_root, tmp_path, monkeypatch):
    # README examples may name repository paths: they run from the root
    monkeypatch.chdir(ROOT if from_root else tmp_path)
    # a real module, so that classes defined in an example (equinox Modules are dataclasses,
    # which look their module up in sys.modules) behave as in a user's script
    module = types.ModuleType("__doc_example__")
    monkeypatch.setitem(sys.modules, module.__name__, module)
    exec(compile(code, "<doc example>", "exec"), module.__dict__)  # noqa: S102


def test_guide_has_examples():
    assert len([p for p in _python_blocks() if "guide.md" in p.id]) >= 10


# --- numbers quoted in the reproduction report -------------------------------------------------

_QUOTE = re.compile(
    r"<!--\s*json:(?P<body>[^>]*?)\s*-->"
    r"(?P<value>not yet measured|true|false|[-+]?(?:\d+(?:\.\d+)?|\.\d+)(?:[eE][-+]?\d+)?)"
)
_FORMAT_SPEC = re.compile(r"[-+ #0-9,._]*[a-zA-Z%]")


def _parse(m):
    """(json path, key path, value written) of one marker; a trailing format spec is dropped."""
    path, _, key = m.group("body").partition(":")
    head, _, last = key.rpartition(" ")
    if head and _FORMAT_SPEC.fullmatch(last):
        key = head
    return path, key.strip(), m.group("value")


def _walk(data, dotted: str):
    """Follow ``dotted`` through dicts (longest matching key first) and lists (integer index)."""
    parts = dotted.split(".") if dotted else []
    while parts:
        if isinstance(data, dict):
            for i in range(len(parts), 0, -1):
                if ".".join(parts[:i]) in data:
                    data, parts = data[".".join(parts[:i])], parts[i:]
                    break
            else:
                raise KeyError(dotted)
        elif isinstance(data, list):
            data, parts = data[int(parts[0])], parts[1:]
        else:
            raise KeyError(dotted)
    return data


def _tolerance(written: str) -> float:
    """Half a unit in the last digit written: '1.74' -> 0.005, '2.3e-05' -> 5e-07, '12' -> 0.5."""
    mantissa, _, exponent = written.lower().partition("e")
    decimals = len(mantissa.split(".")[1]) if "." in mantissa else 0
    return 0.5 * 10.0 ** (int(exponent or 0) - decimals)


def _quotes():
    if not REPORT.exists():
        return []
    text = REPORT.read_text()
    return [
        pytest.param(*_parse(m), id=f"line{text.count(chr(10), 0, m.start()) + 1}:{_parse(m)[1]}")
        for m in _QUOTE.finditer(text)
    ]


def test_report_has_markers():
    assert REPORT.exists()
    assert len(_quotes()) >= 10


@pytest.mark.parametrize("path, key, written", _quotes())
def test_report_number_matches_json(path, key, written):
    source = ROOT / path
    if not source.exists():
        pytest.skip(f"{path} not produced yet (make figures)")
    try:
        value = _walk(json.loads(source.read_text()), key)
    except (KeyError, IndexError, ValueError):
        pytest.fail(f"docs/reproduction.md quotes {key!r} from {path}, which has no such entry: "
                    "the experiment's JSON changed or skipped it; fix the marker")
    if written == "not yet measured":
        pytest.skip(f"{path} exists now: run `make docs` to quote {key}")
    if isinstance(value, bool):
        assert written == str(value).lower(), f"{path}:{key} is {value}, report says {written}"
        return
    quoted = float(written)
    assert isinstance(value, (int, float)) and math.isfinite(value), f"{path}:{key} = {value!r}"
    assert abs(value - quoted) <= _tolerance(written) * (1 + 1e-9) + 1e-300, (
        f"docs/reproduction.md quotes {written} for {path}:{key}, the JSON holds {value!r}; "
        "run `make docs` after rerunning the experiment"
    )


# --- the two doc tools ------------------------------------------------------------------------


def _load(name):
    spec = importlib.util.spec_from_file_location(f"_docs_{name}", DOCS / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_numbers_fills_and_keeps_missing(tmp_path):
    numbers = _load("fill_numbers")
    (tmp_path / "r").mkdir()
    (tmp_path / "r" / "x.json").write_text(json.dumps(
        {"fits": {"sheared pmj02bn 30.5deg": {"slope": -1.7449}}, "ns": [256, 1024, 4096],
         "ok": True, "tiny": 2.346e-07}))
    doc = tmp_path / "doc.md"
    doc.write_text(
        "a <!-- json:r/x.json:fits.sheared pmj02bn 30.5deg.slope .2f -->not yet measured\n"
        "b <!-- json:r/x.json:ns.-1 -->0 c <!-- json:r/x.json:ok -->false\n"
        "d <!-- json:r/x.json:tiny -->1 e <!-- json:r/missing.json:k -->not yet measured\n")
    assert numbers.main(["--doc", str(doc), "--root", str(tmp_path), "--write"]) == 0
    assert doc.read_text() == (
        "a <!-- json:r/x.json:fits.sheared pmj02bn 30.5deg.slope .2f -->-1.74\n"
        "b <!-- json:r/x.json:ns.-1 -->4096 c <!-- json:r/x.json:ok -->true\n"
        "d <!-- json:r/x.json:tiny -->2.35e-7 e <!-- json:r/missing.json:k -->not yet measured\n")
    # the independent checker agrees with what the filler wrote
    for m in _QUOTE.finditer(doc.read_text()):
        path, key, written = _parse(m)
        if "missing" in path or written in ("true", "false"):
            continue
        value = _walk(json.loads((tmp_path / path).read_text()), key)
        assert abs(value - float(written)) <= _tolerance(written)
    doc.write_text("<!-- json:r/x.json:fits.nope -->1\n")
    assert numbers.main(["--doc", str(doc), "--root", str(tmp_path)]) == 1


def test_api_reference_covers_every_module():
    gen_api = _load("gen_api")
    text = gen_api.generate()
    for mod in gen_api.public_modules():
        assert f"\n## {mod}\n" in text
    assert "Import failed" not in text
    for name in ("power_spectrum", "estimator_variance", "synthesize", "compose", "get"):
        assert f"### `{name}(" in text
