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


def parser(name: str, doc: str | None) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=f"experiments/{name}.py", description=doc)
    p.add_argument(
        "--scale",
        choices=["small", "paper"],
        default="small",
        help="small: minutes on a 2-core laptop; paper: the papers' sizes (GPU)",
    )
    p.add_argument(
        "--out",
        type=Path,
        default=ROOT / "results" / name,
        help=f"results folder (default results/{name}/)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the experiment's JAX key")
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


def reuse_or_compute(path: Path, settings: dict, fresh: bool, compute, *, field: str = "curve"):
    """``compute()``'s result, saved at ``path`` as ``{"settings": ..., field: ...}``; a later
    run with the same ``settings`` (and no ``fresh``) reuses the saved value instead."""
    cached = cached_json(path, fresh)
    if cached is not None and cached.get("settings") == settings:
        return cached[field]
    value = compute()
    asp.io.save_json(path, {"settings": settings, field: value}, overwrite=True)
    return value


def best_time(fn, *args, repeats: int, calls: int = 1, warmup: bool = True,
              clock=time.perf_counter, with_output: bool = False):
    """Seconds per call of ``fn(*args)``: the best of ``repeats`` timings of ``calls``
    back-to-back calls, each batch waited for (``jax.block_until_ready``), after one untimed
    call when ``warmup`` (compilation, caches). The minimum is the timing least disturbed by the
    other processes on a shared machine; ``clock=time.process_time`` measures this process's CPU
    time instead of wall time. ``with_output``: ``(seconds, the last call's result)``."""
    import jax

    if repeats < 1 or calls < 1:
        raise ValueError(f"repeats and calls must be >= 1, got {repeats} and {calls}")
    out = jax.block_until_ready(fn(*args)) if warmup else None
    best = float("inf")
    for _ in range(repeats):
        t = clock()
        for _ in range(calls):
            out = fn(*args)
        jax.block_until_ready(out)
        best = min(best, (clock() - t) / calls)
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


def write_record(out: Path, name: str, data: dict, settings: dict, started: float) -> Path:
    """``out/<name>.json`` with the numbers, the settings (paths made repository-relative by
    :func:`portable_path`), the package version and the machine."""
    record = {
        "experiment": name,
        "settings": {key: portable_path(value) for key, value in settings.items()},
        "provenance": asp.io.provenance(),
        "seconds": round(time.time() - started, 2),
        "command": " ".join([Path(sys.argv[0]).name, *sys.argv[1:]]),
        **data,
    }
    return asp.io.save_json(out / f"{name}.json", record, overwrite=True)
