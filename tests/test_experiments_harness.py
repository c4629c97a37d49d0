"""experiments/common.py, the harness every experiment script runs on: one parser whose --out
lies under the repository's results/ wherever the script runs, records reused only when made
with the same settings, and common.run's order (compute once, record, figure, report).

The harness is a script module, not part of the package, so it is exercised the way scripts use
it: a small experiment in a temporary folder, run in its own process from another directory.
"""

import json
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

TOY = '''
import sys
sys.path.insert(0, {experiments!r})
import common

SCALES = {{"small": {{"n": 3}}, "paper": {{"n": 5}}}}


def compute(settings, args):
    print("computing", settings["n"])
    return {{"total": sum(range(settings["n"]))}}


if __name__ == "__main__":
    common.run("toy", "a toy experiment", SCALES, compute,
               figure=lambda data, args: print("figure", data["total"]),
               report=lambda data, args: print("report", data["total"]))
'''


def _run(script, cwd, *args):
    out = subprocess.run([sys.executable, str(script), *args], cwd=cwd, capture_output=True,
                         text=True, check=True)
    return out.stdout.splitlines()


def test_run_computes_once_then_reuses_and_rechecks_settings(tmp_path):
    script = tmp_path / "toy.py"
    script.write_text(TOY.format(experiments=str(REPO / "experiments")))
    out = tmp_path / "out"
    first = _run(script, tmp_path, "--out", str(out))
    assert first == ["computing 3", "figure 3", "report 3"]
    record = json.loads((out / "toy.json").read_text())
    assert record["settings"] == {"n": 3, "scale": "small", "seed": 0}
    assert record["total"] == 3 and record["experiment"] == "toy"
    again = _run(script, tmp_path, "--out", str(out))
    assert again == [f"reusing {out / 'toy.json'}", "figure 3", "report 3"]
    assert _run(script, tmp_path, "--out", str(out), "--seed", "1")[0] == "computing 3"
    assert _run(script, tmp_path, "--out", str(out), "--seed", "1", "--fresh")[0] == \
        "computing 3"


def test_the_default_out_is_the_repository_results_folder(tmp_path):
    probe = tmp_path / "probe.py"
    probe.write_text(f"import sys\nsys.path.insert(0, {str(REPO / 'experiments')!r})\n"
                     "import common\n"
                     "p = common.parser('w_fig3', None, seed=None, fresh=False)\n"
                     "a = p.parse_args([])\nprint(a.out)\nprint(sorted(vars(a)))\n"
                     "print(common.same_settings({'a': [1, 2]}, {'a': (1, 2)}))\n")
    lines = _run(probe, tmp_path)
    assert lines == [str(REPO / "results" / "w_fig3"), "['out', 'scale']", "True"]
