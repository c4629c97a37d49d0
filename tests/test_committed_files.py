"""What the repository ships: no committed record names a path of the machine that wrote it
(issue 27 item 6). Records keep paths relative to the repository (``results/demo``); an absolute
path would tell every reader where one developer's clone lay and point nowhere on theirs.
"""

from __future__ import annotations

import json
import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
MACHINE_PATH = re.compile(r"^(/[^/\s]+/|[A-Za-z]:[\\/])")  # /dir/... or a Windows drive


def _committed(pattern: str) -> list[Path]:
    try:
        out = subprocess.run(["git", "ls-files", pattern], cwd=ROOT, check=True,
                             capture_output=True, text=True).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout")
    return [ROOT / line for line in out.splitlines() if line]


def _absolute_paths(value, where=""):
    """(key path, string) for every string in a JSON value that is an absolute path."""
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _absolute_paths(v, f"{where}.{k}")
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from _absolute_paths(v, f"{where}[{i}]")
    elif isinstance(value, str) and MACHINE_PATH.match(value):
        yield where, value


def test_the_check_finds_an_absolute_path():
    record = {"settings": {"out": "/home/someone/results/demo", "scale": "small"},
              "rows": [{"file": "C:\\Users\\x\\a.npz"}, "results/demo", "1/2"]}
    assert [w for w, _ in _absolute_paths(record)] == [".settings.out", ".rows[0].file"]


def test_no_committed_json_records_a_machine_path():
    files = _committed("*.json")
    assert files, "git ls-files found no JSON: the check would pass vacuously"
    found = [(f.relative_to(ROOT).as_posix(), where, s)
             for f in files for where, s in _absolute_paths(json.loads(f.read_text()))]
    assert not found, found[:5]
