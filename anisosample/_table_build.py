"""Building aligned point-set tables (W Sec. 5.4): resumable, parallel over devices and hosts.

``build(n, kind)`` synthesizes every canonical set of a table (:func:`anisosample.tables.
canonical_sets`: 46 for ``kind=3``, 4,141 for ``kind=4``) with
:func:`anisosample.synthesis.synthesize` and writes each finished set at once (atomically), so an
interrupted build resumes where it stopped: finished sets are verified and skipped, the set that
was in progress resumes from its synthesis checkpoint (``.ckpt/`` inside the table directory;
synthesize resumes bit-identically). When every set exists, ``table.json`` gets the SHA-256 of
each set file and ``"complete": true``.

Determinism: set ``i`` of the canonical list uses the key ``fold_in(key(seed), i)``, so a set does
not depend on which sets were built before it, on which device or host built it, or on
interruptions -- a resumed build writes exactly the sets an uninterrupted one writes.

Parallelism. ``synthesize`` optimizes one set per call (its loop, checkpoints and per-direction
frequency sets of different sizes are not batched), so the sets of a table are distributed, not
vmapped: one worker thread per local device (``jax.local_devices()``), each running synthesize
under ``jax.default_device(device)`` (XLA releases the GIL while it computes). On the CPU, test it
with ``XLA_FLAGS=--xla_force_host_platform_device_count=2``. Several hosts: start the same
command on every host after ``jax.distributed.initialize(...)`` (coordinator address, number of
processes, process id; on SLURM/TPU pods it needs no arguments) with a shared ``--out``; host
``p`` of ``P`` builds the sets ``i`` with ``i % P == p`` and the last host to finish writes the
checksums (any later ``build`` call also does, and builds nothing if all sets exist).
"""

from __future__ import annotations

import json
import queue
import threading
import time
from pathlib import Path

import jax
import numpy as np

from . import io as _io
from . import tables as _t
from ._validate import check_int
from .progress import progress as _progress

_SYNTH_OPTIONS = ("recipe", "steps", "learning_rate", "c", "boundary", "init", "method",
                  "frequency_options", "b1", "b2", "adam_eps", "final_lr_fraction", "nufft_eps")


def _settings(n: int, kind: int, seed: int, synthesis: dict) -> dict:
    s = {
        "format": _t.FORMAT,
        "format_version": _t.FORMAT_VERSION,
        "n": n,
        "kind": kind,
        "count": len(_t.canonical_sets(kind)),
        "seed": seed,
        "synthesis": dict(sorted(synthesis.items())),
        # the recipe's defaults as they are now: a later change of synthesize's defaults makes
        # a resumed build refuse this table instead of mixing sets of two settings
        "synthesis_resolved": {**_resolved(synthesis)},
        "axes_deg": list(_t.AXES_DEG),
        "symmetry": "W Sec. 5.4: identity, mirror (x,1-y), swap (y,x), rotate90 (1-y,x)",
    }
    s["fingerprint"] = _t.settings_fingerprint(s)
    return s


def _resolved(synthesis: dict) -> dict:
    from . import synthesis as _synthesis

    recipe = synthesis.get("recipe", "rate")
    return dict(sorted({**_synthesis.recipe_defaults(recipe), "recipe": recipe,
                        **synthesis}.items()))


def _key_for(seed: int, index: int):
    return jax.random.fold_in(jax.random.key(seed), index)


def _set_ok(table: _t.Table, extra) -> bool:
    try:
        _t.read_set(table, extra)
        return True
    except (ValueError, FileNotFoundError):
        return False


def _build_one(table: _t.Table, index: int, extra, device, checkpoint_every: int) -> float:
    from . import synthesis

    settings = table.settings
    opts = dict(settings["synthesis"])
    ckdir = table.path / ".ckpt"
    ckdir.mkdir(exist_ok=True)
    ckpt = ckdir / f"{_t.set_name(extra)}.npz"
    t0 = time.perf_counter()
    with jax.default_device(device):
        pts, info = synthesis.synthesize(
            _key_for(settings["seed"], index), table.n, _t.set_directions(extra),
            checkpoint=ckpt, checkpoint_every=checkpoint_every, show_progress=False,
            return_info=True, **opts,
        )
    extra_meta = {
        "index": index,
        "final_loss": info.get("final_loss"),
        "initial_loss": (info.get("history") or [None])[0],
        "frequency_count": info.get("frequency_count"),
        "seconds": time.perf_counter() - t0,
    }
    write_set(table, extra, pts, extra_meta)
    return extra_meta["seconds"]


def write_set(table: _t.Table, extra, points, metadata: dict | None = None) -> Path:
    """Write one canonical set of ``table`` atomically, with its checksum and fingerprint."""
    extra = tuple(int(a) for a in extra)
    pts = np.asarray(points, dtype=np.float32)
    if pts.shape != (table.n, 2):
        raise ValueError(f"points must have shape ({table.n}, 2), got {pts.shape}")
    meta = dict(metadata or {})
    meta.update({
        "extra_deg": list(extra),
        "directions_deg": list(_t.set_directions(extra)),
        "n": table.n,
        "kind": table.kind,
        "fingerprint": table.settings["fingerprint"],
        "points_sha256": _t.points_checksum(pts),
    })
    return _io.save_npz(table.set_path(extra), {"points": pts}, meta, overwrite=True)


def create_table(out, n: int, kind: int, *, seed: int = 0, synthesis: dict | None = None):
    """Create (or open, if its settings match) the table directory ``out``."""
    out = Path(out)
    settings = _settings(n, kind, seed, dict(synthesis or {}))
    if (out / "table.json").exists():
        table = _t.open_table(out)
        if table.settings["fingerprint"] != settings["fingerprint"]:
            old = {k: table.settings.get(k) for k in ("n", "kind", "seed", "synthesis")}
            raise ValueError(
                f"the table at {out} was built with other settings ({json.dumps(old)}); "
                "choose another --out or delete it"
            )
        return table
    out.mkdir(parents=True, exist_ok=True)
    _io.save_json(out / "table.json", dict(settings, complete=False,
                                           anisosample_version=_io.package_version()),
                  overwrite=True)
    return _t.open_table(out)


def _finalize(table: _t.Table, all_sets) -> bool:
    """Write the checksums into ``table.json`` when every set exists and verifies."""
    if not all(table.has(e) for e in all_sets):
        return False
    for e in all_sets:
        _t.read_set(table, e)  # raises on a damaged set rather than blessing it
    sums = {table.set_path(e).name: _t._sha256_file(table.set_path(e)) for e in all_sets}
    settings = dict(table.settings, complete=True, checksums=sums,
                    anisosample_version=_io.package_version())
    _io.save_json(table.path / "table.json", settings, overwrite=True)
    ck = table.path / ".ckpt"
    if ck.exists() and not any(ck.iterdir()):
        ck.rmdir()
    return True


def build(n: int, kind: int = 3, *, out=None, seed: int = 0, sets=None,
          devices=None, checkpoint_every: int = 25, show_progress: bool = True,
          **synthesis_options) -> dict:
    """Synthesize the canonical sets of the ``kind``-direction table for ``n`` points.

    Args:
        n: points per set.
        kind: 3 (axes + one extra direction, 46 sets) or 4 (two extra, 4,141 sets).
        out: table directory (default ``tables.cache_dir()/d{kind}_n{n}``). An existing table
            there must have the same settings (n, kind, seed, synthesis options), else
            ``ValueError``; its finished sets are verified and kept, damaged ones rebuilt.
        seed: integer seed; set ``i`` uses ``fold_in(key(seed), i)``.
        sets: build only these canonical extra-direction tuples (default: all).
        devices: the devices to spread sets over (default ``jax.local_devices()``).
        checkpoint_every: synthesis checkpoint interval in steps (resume granularity).
        synthesis_options: passed to :func:`anisosample.synthesize` (``recipe``, ``steps``, ...).

    Returns a summary dict (``path``, ``built``, ``skipped``, ``seconds`` per built set,
    ``complete``).
    """
    n = check_int("n", n, minimum=2)
    kind = _t._check_kind(kind)
    seed = check_int("seed", seed, minimum=0)
    checkpoint_every = check_int("checkpoint_every", checkpoint_every, minimum=1)
    for name in synthesis_options:
        if name not in _SYNTH_OPTIONS:
            raise TypeError(f"build() got an unexpected keyword argument {name!r}; synthesis "
                            f"options are {', '.join(_SYNTH_OPTIONS)}")
    synth = {k: v for k, v in synthesis_options.items() if v is not None}
    all_sets = _t.canonical_sets(kind)
    index = {e: i for i, e in enumerate(all_sets)}
    if sets is None:
        todo = list(all_sets)
    else:
        todo = []
        for e in sets:
            e = tuple(int(a) for a in np.atleast_1d(e))
            if e not in index:
                raise ValueError(f"sets must hold canonical extra directions of a {kind}-direction"
                                 f" table (see tables.canonical_sets({kind})), got {list(e)}")
            if e not in todo:
                todo.append(e)
    out = Path(out) if out is not None else _t.cache_dir() / _t.table_name(kind, n)
    table = create_table(out, n, kind, seed=seed, synthesis=synth)

    # Hosts split the work (jax.distributed); each host spreads its share over its devices.
    pid, pcount = jax.process_index(), jax.process_count()
    mine = [e for e in todo if index[e] % pcount == pid]
    skipped = [e for e in mine if _set_ok(table, e)]
    remaining = [e for e in mine if e not in skipped]
    devices = list(devices) if devices is not None else jax.local_devices()
    if not devices:
        raise ValueError("devices must hold at least one device")

    seconds: dict[str, float] = {}
    errors: list[BaseException] = []
    work: queue.Queue = queue.Queue()
    for e in remaining:
        work.put(e)
    bar = _progress(total=len(mine), initial=len(skipped),
                    desc=f"table d{kind} n={n} ({len(devices)} device(s))",
                    disable=None if show_progress else True)
    lock = threading.Lock()

    def worker(device):
        while not errors:
            try:
                e = work.get_nowait()
            except queue.Empty:
                return
            try:
                sec = _build_one(table, index[e], e, device, checkpoint_every)
            except BaseException as exc:  # noqa: BLE001 -- re-raised in the main thread
                errors.append(exc)
                return
            with lock:
                seconds[_t.set_name(e)] = sec
                bar.update(1)

    try:
        if len(devices) == 1 or len(remaining) <= 1:
            worker(devices[0])
        else:
            threads = [threading.Thread(target=worker, args=(d,), daemon=True)
                       for d in devices[: len(remaining)]]
            for th in threads:
                th.start()
            for th in threads:
                th.join()
    finally:
        bar.close()
    if errors:
        raise errors[0]
    complete = _finalize(_t.open_table(out), all_sets)
    return {
        "path": str(out),
        "built": [_t.set_name(e) for e in remaining],
        "skipped": [_t.set_name(e) for e in skipped],
        "seconds": seconds,
        "devices": [str(d) for d in devices],
        "complete": complete,
    }
