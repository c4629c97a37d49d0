"""What every experiment script shares: arguments, the results folder, and the JSON record.

Experiments call the library only; this module holds no science, just the plumbing.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import anisosample as asp

ROOT = Path(__file__).resolve().parent.parent


def parser(name: str, doc: str | None, *, seed: int | None = 0, fresh: bool = True,
           scale: bool = True, out: bool = True, **options) -> argparse.ArgumentParser:
    """The parser every experiment and benchmark starts from: ``--scale small|paper`` (unless
    ``scale`` is false), ``--out`` (default ``results/<name>/`` of the repository, wherever the
    script is run from; none unless ``out``: a benchmark that only prints), ``--seed`` (default
    ``seed``; None: the script has fixed keys and no such option) and ``--fresh`` (unless
    ``fresh`` is false: nothing is reused). ``options`` go to ``argparse.ArgumentParser``."""
    p = argparse.ArgumentParser(prog=f"experiments/{name}.py", description=doc, **options)
    if scale:
        p.add_argument(
            "--scale",
            choices=["small", "paper"],
            default="small",
            help="small: minutes on a 2-core laptop; paper: the papers' sizes (GPU)",
        )
    if out:
        p.add_argument(
            "--out",
            type=Path,
            default=ROOT / "results" / name,
            help=f"results folder (default results/{name}/)",
        )
    if seed is not None:
        p.add_argument("--seed", type=int, default=seed,
                       help=f"seed of the experiment's JAX key (default {seed})")
    if fresh:
        p.add_argument(
            "--fresh",
            action="store_true",
            help="recompute everything instead of reusing finished results",
        )
    return p


def cached_json(path: Path, fresh: bool):
    """The JSON at ``path`` if it exists and ``fresh`` is false (rerun reuse), else None."""
    if path.exists() and not fresh:
        return json.loads(path.read_text())
    return None


def same_settings(saved, settings) -> bool:
    """Whether ``saved`` (settings read back from a JSON record) are ``settings`` as JSON keeps
    them (tuples become lists)."""
    return saved == json.loads(json.dumps(settings))


def reuse(path: Path, settings: dict, fresh: bool):
    """The record at ``path`` if it exists, ``fresh`` is false and its ``"settings"`` are
    ``settings`` (:func:`same_settings`), else None: every cache an experiment reuses is checked
    against the settings it would be made with now."""
    cached = cached_json(path, fresh)
    if cached is not None and same_settings(cached.get("settings"), settings):
        return cached
    return None


def reuse_or_compute(path: Path, settings: dict, fresh: bool, compute, *, field: str = "curve",
                     reused=None):
    """``compute()``'s result, saved at ``path`` as ``{"settings": ..., field: ...}``; a later
    run with the same ``settings`` (and no ``fresh``) reuses the saved value instead (and calls
    ``reused()`` if given: a progress bar skips the part). One such file a part keeps a long
    experiment resumable: an interrupted run redoes only the parts it had not saved."""
    cached = reuse(path, settings, fresh)
    if cached is not None:
        if reused is not None:
            reused()
        return cached[field]
    value = compute()
    asp.io.save_json(path, {"settings": settings, field: value}, overwrite=True)
    return value


RECORD_KEYS = ("experiment", "settings", "provenance", "seconds", "command")
"""What :func:`write_record` adds around an experiment's numbers."""


def run(name: str, doc: str | None, scales: dict, compute, *, figure=None, report=None,
        arguments=None, settings=None, seed: int | None = 0, argv=None, record: str | None = None,
        outputs=(), adjust=None, complete=None) -> dict:
    """One experiment on the shared harness; returns its numbers.

    1. Arguments: :func:`parser` (``seed`` as there), plus ``arguments(p)``'s own options;
       ``adjust(args)``, if given, may then change the parsed arguments (a per-case ``--out``).
    2. Settings: ``settings(scales[args.scale], args)`` if given, else ``{**scales[scale],
       "scale": ..., "seed": ...}`` (no seed when ``seed`` is None).
    3. Numbers: the record ``--out/<record>`` (``record`` is a file name formatted with the
       arguments, e.g. ``"w_fig4_{scale}.json"``; default ``"<name>.json"``) when it was made
       with these settings and every file of ``outputs`` (names under ``--out``, formatted the
       same way) is there (rerun reuse, :func:`reuse`; ``--fresh`` recomputes), else
       ``compute(settings, args)`` (a dict), written as that record (:func:`write_record`).
       ``compute`` may write more files under ``--out``: figures drawn from arrays the record
       does not keep, images; name them in ``outputs``. Long computations keep resumable parts
       of their own with :func:`reuse_or_compute` (one settings-checked file a part).
    4. ``figure(numbers, args)`` (a figure drawn from the record alone, redrawn on reuse), then
       ``report(numbers, args)`` (what the script prints); ``args.settings`` holds the settings.
    """
    p = parser(name, doc, seed=seed)
    if arguments is not None:
        arguments(p)
    args = p.parse_args(argv)
    if adjust is not None:
        adjust(args)
    started = time.time()
    cfg = scales[args.scale]
    if settings is not None:
        chosen = settings(cfg, args)
    else:
        chosen = {**cfg, "scale": args.scale, **({} if seed is None else {"seed": args.seed})}
    args.settings = chosen
    fields = {**vars(args), "name": name}
    path = args.out / (record or "{name}.json").format(**fields)
    found = reuse(path, chosen, args.fresh)
    data = None
    if found is not None and all((args.out / o.format(**fields)).exists() for o in outputs):
        data = {k: v for k, v in found.items() if k not in RECORD_KEYS}
        if complete is not None and not complete(data, args):
            data = None
    if data is not None:
        print(f"reusing {path}")
    else:
        args.out.mkdir(parents=True, exist_ok=True)
        data = compute(chosen, args)
        write_record(args.out, path.stem, data, chosen, started, experiment=name)
    if figure is not None:
        figure(data, args)
    if report is not None:
        report(data, args)
    return data


def devices_option(p, default: int | None = None) -> None:
    """``--cpu-devices N`` (``default``; None: one per core): JAX's CPU backend starts with
    ``N`` devices (``jax_num_cpu_devices``) for the renders to be split over
    (:func:`render_devices`); 1: one device. On a GPU the option changes nothing: the GPUs are
    the devices."""
    import os

    n = default or os.cpu_count() or 1
    p.add_argument("--cpu-devices", type=int, default=n,
                   help=f"JAX CPU devices to render over (default: {n})")


def render_devices(args) -> list | None:
    """The ``devices`` argument of ``render(...)`` for the parsed ``--cpu-devices``: every local
    device when there are several, else None (the default device). It configures the CPU
    backend: call it once, before anything runs on JAX."""
    import jax

    if args.cpu_devices < 1:
        raise SystemExit(f"--cpu-devices must be at least 1, got {args.cpu_devices}")
    if args.cpu_devices > 1:
        jax.config.update("jax_num_cpu_devices", args.cpu_devices)
    devices = jax.local_devices()
    return devices if len(devices) > 1 else None


def run_script(name: str, out: Path, *args: str) -> dict:
    """Run the experiment ``experiments/<name>.py`` with ``--out out`` and ``args`` in its own
    process (an experiment never imports another) and return its record ``out/<name>.json``.
    Its output goes to this process's stdout and stderr; a failure raises
    ``subprocess.CalledProcessError``."""
    import subprocess

    subprocess.run([sys.executable, str(ROOT / "experiments" / f"{name}.py"), "--out", str(out),
                    *args], check=True)
    return json.loads((Path(out) / f"{name}.json").read_text())


def best_time(fn, *args, repeats: int, calls: int = 1, warmup: bool = True,
              clock=time.perf_counter, with_output: bool = False, cores: bool = False):
    """Seconds per call of ``fn(*args)``: the best of ``repeats`` timings of ``calls``
    back-to-back calls, each batch waited for (``jax.block_until_ready``), after one untimed
    call when ``warmup`` (compilation, caches). The minimum is the timing least disturbed by the
    other processes on a shared machine; ``clock=time.process_time`` measures this process's CPU
    time instead of wall time. ``with_output``: ``(seconds, the last call's result)``.
    ``cores``: ``(seconds, cores)``, the cores the best batch kept busy (this process's CPU time
    over ``clock``'s time)."""
    import jax

    if repeats < 1 or calls < 1:
        raise ValueError(f"repeats and calls must be >= 1, got {repeats} and {calls}")
    if cores and with_output:
        raise ValueError("cores and with_output do not go together")
    out = jax.block_until_ready(fn(*args)) if warmup else None
    best, busy = float("inf"), 0.0
    for _ in range(repeats):
        c, t = time.process_time(), clock()
        for _ in range(calls):
            out = fn(*args)
        jax.block_until_ready(out)
        seconds = clock() - t
        if seconds / calls < best:
            best, busy = seconds / calls, (time.process_time() - c) / max(seconds, 1e-12)
    if cores:
        return best, busy
    return (best, out) if with_output else best


def portable_path(value):
    """A path as a record may keep it: relative to the repository (``results/demo``) when it lies
    inside, else ``<outside>/<name>``; never an absolute path of the machine that wrote it.
    Anything that is not an absolute path comes back unchanged."""
    if not isinstance(value, str | Path) or not Path(value).is_absolute():
        return value
    path = Path(value).resolve()
    try:
        return path.relative_to(ROOT).as_posix()
    except ValueError:
        return f"<outside>/{path.name}"


def write_record(out: Path, name: str, data: dict, settings: dict, started: float, *,
                 experiment: str | None = None) -> Path:
    """``out/<name>.json`` with the numbers, the settings (paths made repository-relative by
    :func:`portable_path`), the package version and the machine; its ``"experiment"`` is
    ``experiment`` (default ``name``)."""
    record = {
        "experiment": experiment or name,
        "settings": {key: portable_path(value) for key, value in settings.items()},
        "provenance": asp.io.provenance(),
        "seconds": round(time.time() - started, 2),
        "command": " ".join([Path(sys.argv[0]).name, *sys.argv[1:]]),
        **data,
    }
    return asp.io.save_json(out / f"{name}.json", record, overwrite=True)
