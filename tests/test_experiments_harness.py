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


PARTS = '''
import sys
sys.path.insert(0, {experiments!r})
import common

SCALES = {{"small": {{"parts": [1, 2, 3]}}, "paper": {{"parts": [1, 2, 3, 4]}}}}


def compute(settings, args):
    def part(i):
        print("computing part", i)
        return i * i

    squares = [common.reuse_or_compute(args.out / "parts" / f"{{i}}.json",
                                       {{**settings, "part": i}}, args.fresh,
                                       lambda i=i: part(i), field="square",
                                       reused=lambda i=i: print("reused part", i))
               for i in settings["parts"]]
    (args.out / f"{{args.tag}}.txt").write_text(str(sum(squares)))  # an extra output
    return {{"squares": squares}}


if __name__ == "__main__":
    common.run("parts", None, SCALES, compute, seed=None, record="parts_{{scale}}.json",
               outputs=("{{tag}}.txt",),
               arguments=lambda p: p.add_argument("--tag", default="sum"),
               adjust=lambda args: setattr(args, "out", args.out / args.tag),
               report=lambda data, args: print("report", data["squares"], args.settings["scale"]))
'''


def test_run_keeps_parts_extra_outputs_and_a_named_record(tmp_path):
    """Per-part caches (common.reuse_or_compute) resume an interrupted run; the record's name
    follows the arguments; a record whose extra outputs are gone is recomputed; ``adjust``
    changes the parsed arguments first; ``args.settings`` holds the settings."""
    script = tmp_path / "parts.py"
    script.write_text(PARTS.format(experiments=str(REPO / "experiments")))
    base = tmp_path / "out"
    first = _run(script, tmp_path, "--out", str(base))
    out = base / "sum"  # adjust: --out/<tag>
    assert first == ["computing part 1", "computing part 2", "computing part 3",
                     "report [1, 4, 9] small"]
    record = json.loads((out / "parts_small.json").read_text())
    assert record["experiment"] == "parts" and record["squares"] == [1, 4, 9]
    assert record["settings"] == {"parts": [1, 2, 3], "scale": "small"}
    assert (out / "sum.txt").read_text() == "14"
    assert _run(script, tmp_path, "--out", str(base)) == [
        f"reusing {out / 'parts_small.json'}", "report [1, 4, 9] small"]
    # the extra output gone: the record is recomputed, from the parts already saved but one
    (out / "sum.txt").unlink()
    (out / "parts" / "2.json").unlink()
    assert _run(script, tmp_path, "--out", str(base)) == [
        "reused part 1", "computing part 2", "reused part 3", "report [1, 4, 9] small"]
    # another scale: its own record, parts recomputed (their settings differ)
    assert _run(script, tmp_path, "--out", str(base), "--scale", "paper")[-1] == \
        "report [1, 4, 9, 16] paper"
    assert (out / "parts_paper.json").exists() and (out / "parts_small.json").exists()
    assert _run(script, tmp_path, "--out", str(base), "--fresh")[:1] == ["computing part 1"]


PARTIAL = '''
import sys
sys.path.insert(0, {experiments!r})
import common

SCALES = {{"small": {{"n": 2}}, "paper": {{"n": 3}}}}


def compute(settings, args):
    kept = common.reuse(args.out / "partial.json", settings, False) or {{}}
    data = {{k: kept[k] for k in ("a", "b") if k in kept}}
    for part in ("a", "b") if args.part == "all" else (args.part,):
        print("computing", part)
        data[part] = settings["n"]
    return data


if __name__ == "__main__":
    common.run("partial", None, SCALES, compute,
               arguments=lambda p: p.add_argument("--part", default="all"),
               complete=lambda data, args: args.part in data or (
                   args.part == "all" and {{"a", "b"}} <= set(data)),
               report=lambda data, args: print("report", sorted(data)))
'''


def test_run_recomputes_a_record_that_lacks_what_is_asked(tmp_path):
    """``complete``: a record made with these settings but without the part a run asks for is
    recomputed (the compute may keep the record's other parts)."""
    script = tmp_path / "partial.py"
    script.write_text(PARTIAL.format(experiments=str(REPO / "experiments")))
    out = tmp_path / "out"
    assert _run(script, tmp_path, "--out", str(out), "--part", "a") == [
        "computing a", "report ['a']"]
    assert _run(script, tmp_path, "--out", str(out), "--part", "a") == [
        f"reusing {out / 'partial.json'}", "report ['a']"]
    assert _run(script, tmp_path, "--out", str(out), "--part", "b") == [
        "computing b", "report ['a', 'b']"]
    assert _run(script, tmp_path, "--out", str(out)) == [
        f"reusing {out / 'partial.json'}", "report ['a', 'b']"]


BEST_TIME = '''
import sys, time
sys.path.insert(0, {experiments!r})
import common


def busy():
    end = time.perf_counter() + 0.05
    while time.perf_counter() < end:
        pass


s_busy, c_busy = common.best_time(busy, repeats=3, warmup=False, cores=True)
s_idle, c_idle = common.best_time(lambda: time.sleep(0.05), repeats=3, warmup=False, cores=True)
print(s_busy, c_busy, s_idle, c_idle)
try:
    common.best_time(busy, repeats=1, cores=True, with_output=True)
except ValueError:
    print("refused")
'''


def test_best_time_reports_the_cores_its_best_batch_kept_busy(tmp_path):
    """cores=True: this process's CPU time over the best batch's wall time -- a busy loop keeps
    a core, a sleep none (bounds far from both, for a loaded machine)."""
    script = tmp_path / "bt.py"
    script.write_text(BEST_TIME.format(experiments=str(REPO / "experiments")))
    first, last = _run(script, tmp_path)
    s_busy, c_busy, s_idle, c_idle = map(float, first.split())
    assert s_busy >= 0.05 and s_idle >= 0.05
    assert c_busy > 0.3 and c_idle < 0.1
    assert last == "refused"
