"""Building aligned point-set tables (W Sec. 5.4): resumable, parallel over devices and hosts.

``build(n, direction_count)`` synthesizes every canonical set of a table (:func:`anisosample.tables.
canonical_sets`: 46 for ``direction_count=3``, 4,141 for ``direction_count=4``) with
:func:`anisosample.synthesis.synthesize` and writes each finished set at once (atomically), so an
interrupted build resumes where it stopped: finished sets are verified and skipped, the set that
was in progress resumes from its synthesis checkpoint (``.ckpt/`` inside the table directory;
synthesize resumes bit-identically). When every set exists, ``table.json`` gets the SHA-256 of
each set file and ``"complete": true``.

Determinism: set ``i`` of the canonical list uses the key ``fold_in(key(seed), i)``, so a set does
not depend on which sets were built before it, on which device or host built it, or on
interruptions -- a resumed build writes exactly the sets an uninterrupted one writes.

Parallelism. With ``batch=1`` each set is one :func:`~anisosample.synthesize` call (with
checkpoints inside the set), and sets are spread over the local devices
(``jax.local_devices()``), one worker thread per device running under
``jax.default_device(device)`` (XLA releases the GIL while it computes). With ``batch=B`` groups of
``B`` sets of equal direction count run one after the other, each as one
:func:`~anisosample.synthesis.synthesize_batch` loop (every step evaluates the terms of all the
group's sets on the cores at once, each set with its own frequency plan; checkpointed in
``.ckpt/`` on one device), its sets split over the local devices (one slice and thread per
device; the same bits as one device). On the CPU, test either with
``XLA_FLAGS=--xla_force_host_platform_device_count=2``.

Several hosts: run the same command on every host with a shared ``--out``, e.g.
``anisosample tables build --n 4096 --direction-count 4 --out /shared/d4 --distributed --coordinator
host0:1234 --num-processes P --process-id p`` (``--distributed`` alone auto-detects SLURM, Open MPI
and TPU pods). It calls ``jax.distributed.initialize`` before anything touches the XLA backend
(importing anisosample does not); work unit ``i`` (a set, or a group with ``batch > 1``) is built
by process ``i % P``, and the last process to finish writes the checksums (any later ``build``
call also does, and builds nothing if all sets exist). Tested with two processes on one machine
(a localhost coordinator).

One machine, several cores: ``anisosample tables build --n 4096 --direction-count 4 --processes P``
starts P such workers itself (a localhost coordinator), each pinned to its share of the cores,
so each runs one term at a time (:func:`anisosample.synthesis.usable_cores`). On this project's
2-core machine two workers build the 4-direction table about 1.4 times as fast as one process
whose two threads share a step's terms (``experiments/bench_tables.py --processes 2``, float64:
3.0 s per set against 4.1 s for one-at-a-time lookups, at load 1.3-1.7): the two threads of one
process spend about a third more CPU per step than one. Runs of consecutive sets, as a whole
build meets them, share their box shapes' compilations; with the 4-direction tables' float32
transforms (:data:`FOUR_DIRECTION_PRECISION`) that is 1.6 s per set, 1.88 h projected for the
4,141 sets (``--sets 40 --block 10 --processes 2``; 2.8 h in float64).
"""

from __future__ import annotations

import json
import queue
import threading
import time
from pathlib import Path

import jax
import numpy as np

from . import _table_store as _t
from . import io as _io
from . import prefix as _prefix
from ._validate import check_int
from .progress import progress as _progress


def _synth_options() -> tuple[str, ...]:
    from . import synthesis

    return ("recipe", *synthesis.OPTIONS)


def _settings(n: int, direction_count: int, seed: int, synthesis: dict) -> dict:
    s = {
        "format": _t.FORMAT,
        "format_version": _t.FORMAT_VERSION,
        "n": n,
        "kind": direction_count,
        "count": len(_t.canonical_sets(direction_count)),
        "seed": seed,
        "synthesis": dict(sorted(synthesis.items())),
        # the recipe's defaults as they are now: a later change of synthesize's defaults makes
        # a resumed build refuse this table instead of mixing sets of two settings
        "synthesis_resolved": {**_resolved(synthesis, n, direction_count)},
        "axes_deg": list(_t.AXES_DEG),
        "symmetry": "W Sec. 5.4: identity, mirror (x,1-y), swap (y,x), rotate90 (1-y,x)",
    }
    s["fingerprint"] = _t.settings_fingerprint(s)
    return s


def _resolved(synthesis: dict, n: int, direction_count: int = 3) -> dict:
    """The table's synthesis record: the :class:`~anisosample.synthesis.Recipe` the options
    make (every option, defaults included: a later change of a default makes a resumed build
    refuse this table instead of mixing sets of two settings), the batch size, and the
    frequency design evaluated at a probe size: 1024 points, or the table's ``n`` below that
    (the design's weights change with ``n`` there, :data:`anisosample.frequencies.ROBUST_MIN_N`;
    tables from 1024 points up keep the fingerprint they had before), for directions of the
    table's count: 3-direction tables probe (0, 90, 45) as they always have, 4-direction tables
    from :data:`anisosample.frequencies.ROBUST_MIN_N` points (0, 90, 30, 120) (since the axes'
    weight of :data:`anisosample.frequencies.AXIS_WEIGHT_4`, so that a 4-direction table of the
    design before is not resumed with sets of this one). Below that size the axes' weight does
    not act, the design is the one before, and 4-direction tables probe (0, 90, 45) as they did:
    their sets and fingerprints did not change."""
    from . import frequencies as _freq
    from . import synthesis as _synthesis

    options = {k: v for k, v in synthesis.items() if k not in ("batch", "warm_start")}
    recipe = _synthesis.make_recipe(**options)
    # the record as tables have always stored it (the named recipe's defaults, its name and the
    # options given), so tables built before the Recipe existed still resume; plus every other
    # Recipe field that differs from the Recipe's own default
    resolved = {**_synthesis.recipe_defaults(recipe.name), "recipe": recipe.name, **synthesis}
    base = _synthesis.Recipe(name=recipe.name).record()
    for k, v in recipe.record().items():
        if k not in resolved and v != base.get(k):
            resolved[k] = v
    # The frequency design's formulas (wedge length, width, weights' offsets, ...) evaluated at a
    # probe size: a change of the design changes the fingerprint, so a table of the old design
    # is not resumed with sets of the new one.
    # Up to 1024 points, the probe size tables have always used; below it the table's own n,
    # since the design changes with n there (frequencies.ROBUST_MIN_N must stay <= 1024, or
    # tables between it and 1024 points would change design under the same fingerprint).
    at = min(n, 1024)
    four = direction_count == 4 and at >= _freq.ROBUST_MIN_N  # where AXIS_WEIGHT_4 acts
    probe_dirs = (0.0, 90.0, 30.0, 120.0) if four else (0.0, 90.0, 45.0)
    probe = _freq.design(at, probe_dirs, recipe.design, **dict(recipe.frequency_options)).params
    resolved[f"frequency_design_at_n{at}"] = {k: v for k, v in probe.items()
                                              if k not in ("n", "directions_deg")}
    return dict(sorted(resolved.items()))


WARM_STEPS = 150
"""Steps of a warm-started set (the cold recipe's default is 200; the quality measured against
cold sets is in the :mod:`anisosample.tables` docstring)."""
WARM_LEARNING_RATE = 0.2
"""Learning rate of a warm-started set (in units of the point spacing; cold: 0.5)."""


def warm_source(n: int, *, exclude=None, prefix: str = "none",
                sequence_from: int = 0) -> _t.Table | None:
    """The complete 3-direction table for ``n`` (and ``prefix``) on the search path (the shipped
    tables first after ``$ANISOSAMPLE_TABLES``), the fixed source a 4-direction set is
    warm-started from."""
    for root in _t.table_dirs():
        path = root / _t.table_name(3, n, prefix, sequence_from)
        if exclude is not None and path == Path(exclude):
            continue
        if (path / "table.json").exists():
            try:
                tab = _t.open_table(path, n=n, direction_count=3)
            except ValueError:
                continue
            if tab.complete:
                return tab
    return None


def warm_points(n: int, extra, fingerprint: str, prefix: str = "none",
                sequence_from: int = 0) -> np.ndarray:
    """The warm start of the 4-direction set ``extra = (a, b)``: the set of the 3-direction
    table ``fingerprint`` for ``a`` (dark along 0, 90 and ``a``), turned by the symmetry that
    maps its canonical set to ``a`` (its prefix put back in the prefix's order). Deterministic:
    it depends on the source table only."""
    for root in _t.table_dirs():
        path = root / _t.table_name(3, n, prefix, sequence_from)
        if (path / "table.json").exists():
            tab = _t.open_table(path, n=n, direction_count=3)
            if tab.settings["fingerprint"] == fingerprint:
                c = _t.canonicalize((int(extra[0]),), direction_count=3)
                return _prefix.restore_prefix(
                    _t.transform_points(tab.load(c.extra), c.transform), prefix, c.transform)
    raise FileNotFoundError(f"the 3-direction table for n={n} this table is warm-started from "
                            f"(fingerprint {fingerprint[:12]}...) is not on the search path")


def _key_for(seed: int, index: int):
    return jax.random.fold_in(jax.random.key(seed), index)


def _set_ok(table: _t.Table, extra) -> bool:
    try:
        _t.read_set(table, extra)
        return True
    except (ValueError, FileNotFoundError):
        return False


def _build_one(table: _t.Table, index: int, extra, device, checkpoint_every: int,
               show_progress: bool = False) -> float:
    from . import synthesis

    settings = table.settings
    opts = dict(settings["synthesis"])
    opts.pop("batch", None)
    warm = opts.pop("warm_start", None)
    init = None if warm is None else warm_points(table.n, extra, warm["fingerprint"],
                                                 _t.table_prefix(table),
                                                 _t.table_sequence_from(table))
    ckdir = table.path / ".ckpt"
    ckdir.mkdir(exist_ok=True)
    ckpt = ckdir / f"{_t.set_name(extra)}.npz"
    t0 = time.perf_counter()
    with jax.default_device(device):
        result = synthesis.synthesize(
            _key_for(settings["seed"], index), table.n, _t.set_directions(extra),
            initial_points=init, checkpoint=ckpt, checkpoint_every=checkpoint_every,
            show_progress=show_progress, **opts,
        )
    pts = result.points
    extra_meta = {
        "index": index,
        "final_loss": result.final_loss,
        "initial_loss": float(result.history[0]),
        "frequency_count": result.frequency_count,
        "seconds": time.perf_counter() - t0,
        "device": str(device),
    }
    write_set(table, extra, pts, extra_meta)
    return extra_meta["seconds"]


def _build_group(table: _t.Table, indices, group, devices, checkpoint_every: int) -> list[float]:
    """One :func:`synthesize_batch` call for a group of sets with equal direction counts, its
    sets split over ``devices`` (one device: checkpointed in ``.ckpt/``, so it resumes)."""
    from . import synthesis

    settings = table.settings
    opts = dict(settings["synthesis"])
    opts.pop("batch", None)
    warm = opts.pop("warm_start", None)
    init = None if warm is None else np.stack([warm_points(table.n, e, warm["fingerprint"],
                                                           _t.table_prefix(table),
                                                           _t.table_sequence_from(table))
                                               for e in group])
    ckpt = None
    if len(devices) == 1:
        (table.path / ".ckpt").mkdir(exist_ok=True)
        ckpt = table.path / ".ckpt" / f"group_{indices[0]:04d}.npz"
    t0 = time.perf_counter()
    with jax.default_device(devices[0]):
        result = synthesis.synthesize_batch(
            _key_for(settings["seed"], indices[0]), table.n,
            [_t.set_directions(e) for e in group], show_progress=False,
            devices=devices if len(devices) > 1 else None, checkpoint=ckpt, initial_points=init,
            checkpoint_every=checkpoint_every, **opts,
        )
    pts = result.points
    device = ",".join(str(d) for d in devices)
    sec = (time.perf_counter() - t0) / len(group)
    final = np.asarray(result.final_loss).reshape(-1)
    for b, (i, e) in enumerate(zip(indices, group, strict=True)):
        write_set(table, e, np.asarray(pts[b]), {
            "index": i, "group": [list(g) for g in group], "group_position": b,
            "final_loss": float(final[b]) if final.size == len(group) else None,
            "seconds": sec, "device": str(device),
        })
    return [sec] * len(group)


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
        "kind": table.direction_count,
        "fingerprint": table.settings["fingerprint"],
        "points_sha256": _t.points_checksum(pts),
    })
    return _io.save_npz(table.set_path(extra), {"points": pts}, meta, overwrite=True)


def create_table(out, n: int, direction_count: int, *, seed: int = 0,
                 synthesis: dict | None = None):
    """Create (or open, if its settings match) the table directory ``out``."""
    out = Path(out)
    settings = _settings(n, direction_count, seed, dict(synthesis or {}))
    if (out / "table.json").exists():
        table = _t.open_table(out)
        if table.settings["fingerprint"] != settings["fingerprint"]:
            keys = ("n", "kind", "seed", "synthesis")
            old = {k: table.settings.get(k) for k in keys}
            new = _io.to_jsonable({k: settings[k] for k in keys})
            was = table.settings.get("synthesis_resolved", {})
            now = _io.to_jsonable(settings["synthesis_resolved"])
            moved = sorted(k for k in set(was) | set(now) if was.get(k) != now.get(k))
            why = (f"; the package's defaults for them changed since: {', '.join(moved)} "
                   f"(table: {json.dumps({k: was.get(k) for k in moved})}, now: "
                   f"{json.dumps({k: now.get(k) for k in moved})})" if old == new and moved
                   else "")
            raise ValueError(
                f"the table at {out} was built with other settings ({json.dumps(old)}) than "
                f"these ({json.dumps(new)}){why}; choose another --out or delete it"
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
    sums = {table.set_path(e).name: _t.sha256_file(table.set_path(e)) for e in all_sets}
    settings = dict(table.settings, complete=True, checksums=sums,
                    anisosample_version=_io.package_version())
    _io.save_json(table.path / "table.json", settings, overwrite=True)
    return True


def _remove_empty_checkpoints(table: _t.Table) -> None:
    ck = table.path / ".ckpt"
    try:
        if ck.exists() and not any(ck.iterdir()):
            ck.rmdir()
    except OSError:  # another host or thread is writing a checkpoint there
        pass


FOUR_DIRECTION_PRECISION = "single"
"""``nufft_precision`` of a new 4-direction table (:class:`anisosample.synthesis.Recipe`): the
type-1 transforms in float32, 1.7 times as fast per step at n = 4096 (27.2 -> 15.9 ms for the
four terms of a 4-direction set). Measured against double precision
(``experiments/bench_tables.py --compare-warm --pairs 3 --precisions double single``, n = 4096,
150 warm steps): final rate loss within 1 %, band energy along every line as low, edge variance
-3..+14 % (cold 200-step sets with keys 1-4 spread over 1.70-2.08e-7, +-10 %, on the pair
(16, 146) where single precision measured 1.93e-7: ``--compare-warm --pairs 1 --cold-keys 1 2 3
4 --precisions double single``). Tables that exist keep the precision they were built with."""


def _existing_synthesis(out: Path, direction_count: int) -> dict | None:
    """The synthesis settings of the table at ``out``, or None (no table, or a damaged one:
    :func:`create_table` reports what is wrong with it)."""
    if (out / "table.json").exists():
        try:
            return dict(_t.open_table(out, direction_count=direction_count).settings["synthesis"])
        except (ValueError, KeyError):
            pass
    return None


def build(n: int, direction_count: int = 3, *, out=None, seed: int = 0, sets=None, batch: int = 1,
          devices=None, checkpoint_every: int = 25, show_progress: bool = True,
          warm_start: bool | None = None, **synthesis_options) -> dict:
    """Synthesize the canonical sets of the ``direction_count``-direction table for ``n`` points.

    Args:
        n: points per set.
        direction_count: 3 (axes + one extra direction, 46 sets) or 4 (two extra, 4,141 sets).
        out: table directory (default ``tables.cache_dir()/d{direction_count}_n{n}``). An
            existing table
            there must have the same settings (n, direction_count, seed, synthesis options), else
            ``ValueError``; its finished sets are verified and kept, damaged ones rebuilt.
        seed: integer seed; set ``i`` uses ``fold_in(key(seed), i)``.
        sets: build only these canonical extra-direction tuples (default: all).
        batch: sets per optimizer loop. 1: :func:`anisosample.synthesize` per set (checkpoints
            every ``checkpoint_every`` steps). ``B > 1``: :func:`anisosample.synthesis.
            synthesize_batch` on fixed groups of ``B`` consecutive sets with the same number of
            directions (its sets' terms share the cores each step; a group is the unit of
            resumption and is redone whole if any of its sets is missing; set ``b`` of the group
            starting at canonical index ``i`` uses ``split(fold_in(key(seed), i), B)[b]``).
            ``batch`` is part of the table's settings (it changes the sets' keys).
        devices: the devices (default ``jax.local_devices()``): ``batch=1`` spreads sets over
            them, one thread each; ``batch > 1`` splits each group over all of them (the
            same bits as a one-device build).
        checkpoint_every: synthesis checkpoint interval in steps (resume granularity).
        warm_start: a 4-direction table only: start each set ``(a, b)`` from the set for ``a``
            of the complete 3-direction table for ``n`` (:func:`warm_source`, :func:`warm_points`)
            with :data:`WARM_STEPS` steps at :data:`WARM_LEARNING_RATE` unless ``steps`` /
            ``learning_rate`` are given; no such table: cold. Part of the table's settings.
            ``None`` (default): what an existing table at ``out`` chose, else warm for
            ``direction_count=4`` (as the on-demand lookups build), so a table built here serves
            them.
            A new 4-direction table also runs its transforms in single precision
            (:data:`FOUR_DIRECTION_PRECISION`) unless ``nufft_precision`` is given.
        synthesis_options: passed to :func:`anisosample.synthesize` (``recipe``, ``steps``, ...).

    Returns a summary dict (``path``, ``built``, ``skipped``, ``seconds`` per built set,
    ``complete``).
    """
    n = check_int("n", n, minimum=2)
    direction_count = _t.check_direction_count(direction_count)
    seed = check_int("seed", seed, minimum=0)
    checkpoint_every = check_int("checkpoint_every", checkpoint_every, minimum=1)
    batch = check_int("batch", batch, minimum=1)
    for name in synthesis_options:
        if name not in _synth_options():
            raise TypeError(f"build() got an unexpected keyword argument {name!r}; synthesis "
                            f"options are {', '.join(_synth_options())}")
    synth = {k: v for k, v in synthesis_options.items() if v is not None}
    if batch > 1:
        synth["batch"] = batch
    prefix = _prefix.check_table_prefix(synth.get("prefix"))
    seq = check_int("sequence_from", synth.get("sequence_from", 0), minimum=0)
    out = Path(out) if out is not None else _t.cache_table_path(direction_count, n, prefix, seq)
    existing = _existing_synthesis(out, direction_count)  # an existing table keeps its own choices
    if seq:  # a sequence table's steps, learning rate and frequency options: its own (a table
        # built before a default existed keeps going without it), else the sequence defaults
        from .synthesis import SEQUENCE_DEFAULTS

        for name, default in SEQUENCE_DEFAULTS.items():
            if name in synth:
                continue
            if existing is None:
                synth[name] = dict(default) if isinstance(default, dict) else default
            elif name in existing:
                synth[name] = existing[name]
    if warm_start is None:
        warm_start = direction_count == 4 if existing is None else "warm_start" in existing
    if not isinstance(warm_start, bool):
        raise TypeError(f"warm_start must be True, False or None, got {warm_start!r}")
    if direction_count == 4 and "nufft_precision" not in synth:
        if existing is None:
            synth["nufft_precision"] = FOUR_DIRECTION_PRECISION
        elif "nufft_precision" in existing:  # a table from before the option has none
            synth["nufft_precision"] = existing["nufft_precision"]
    src = (warm_source(n, exclude=out, prefix=prefix, sequence_from=seq)
           if warm_start and direction_count == 4 else None)
    if src is not None:
        synth["warm_start"] = {"table": _t.table_name(3, n, prefix, seq),
                               "fingerprint": src.settings["fingerprint"]}
        synth.setdefault("steps", WARM_STEPS)
        synth.setdefault("learning_rate", WARM_LEARNING_RATE)
    all_sets = _t.canonical_sets(direction_count)
    index = {e: i for i, e in enumerate(all_sets)}
    if sets is None:
        todo = list(all_sets)
    else:
        todo = []
        for e in sets:
            e = tuple(int(a) for a in np.atleast_1d(e))
            if e not in index:
                raise ValueError(f"sets must hold canonical extra directions of a "
                                 f"{direction_count}-direction table (see "
                                 f"tables.canonical_sets({direction_count})), got {list(e)}")
            if e not in todo:
                todo.append(e)
    table = create_table(out, n, direction_count, seed=seed, synthesis=synth)

    # Work units: one set (batch 1) or a fixed group of sets (batch B). Hosts split the units
    # (jax.distributed); each host spreads its share over its local devices, one thread each.
    todo = sorted(todo, key=index.__getitem__)
    if batch == 1:
        units = [[e] for e in todo]
    else:
        units = []
        for count in sorted({len(_t.set_directions(e)) for e in todo}):
            same = [e for e in todo if len(_t.set_directions(e)) == count]
            units += [same[i:i + batch] for i in range(0, len(same), batch)]
    pid, pcount = jax.process_index(), jax.process_count()
    mine = [u for i, u in enumerate(units) if i % pcount == pid]
    done_units = [u for u in mine if all(_set_ok(table, e) for e in u)]
    remaining = [u for u in mine if u not in done_units]
    devices = list(devices) if devices is not None else jax.local_devices()
    if not devices:
        raise ValueError("devices must hold at least one device")

    seconds: dict[str, float] = {}
    errors: list[BaseException] = []
    work: queue.Queue = queue.Queue()
    for u in remaining:
        work.put(u)
    bar = _progress(total=sum(map(len, mine)), initial=sum(map(len, done_units)),
                    desc=f"table d{direction_count} n={n} ({len(devices)} device(s))",
                    disable=None if show_progress else True)
    lock = threading.Lock()

    def worker(device):
        while not errors:
            try:
                u = work.get_nowait()
            except queue.Empty:
                return
            try:
                if batch == 1:
                    sec = [_build_one(table, index[u[0]], u[0], device, checkpoint_every,
                                      show_progress and len(remaining) == 1)]
                else:
                    sec = _build_group(table, [index[e] for e in u], u, device,
                                       checkpoint_every)
            except BaseException as exc:  # noqa: BLE001 -- re-raised in the main thread
                errors.append(exc)
                return
            with lock:
                for e, t in zip(u, sec, strict=True):
                    seconds[_t.set_name(e)] = t
                bar.update(len(u))

    try:
        if batch > 1:  # one group at a time, split over all the devices
            worker(devices)
        elif len(devices) == 1 or len(remaining) <= 1:
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
    _remove_empty_checkpoints(table)
    if errors:
        raise errors[0]
    complete = _finalize(_t.open_table(out), all_sets)
    return {
        "path": str(out),
        "built": [_t.set_name(e) for u in remaining for e in u],
        "skipped": [_t.set_name(e) for u in done_units for e in u],
        "seconds": seconds,
        "devices": [str(d) for d in devices],
        "complete": complete,
    }


def build_set(n: int, direction_count: int, extra, *, out, show_progress: bool = True,
              **build_options) -> dict:
    """Build one missing canonical set on demand (what :func:`anisosample.tables.ensure` does).

    An existing table at ``out`` is finished with its own settings (seed, batch, synthesis
    options, warm start); given ``build_options`` must then match them (else ``ValueError``).
    A new table gets ``build_options`` and, for ``direction_count=4``, ``warm_start=True`` unless
    ``build_options`` say otherwise. One set builds with its own progress bar.
    """
    out = Path(out)
    if (out / "table.json").exists() and not build_options:
        tab = _t.open_table(out, n=n, direction_count=direction_count)
        opts = dict(tab.settings["synthesis"])
        batch = opts.pop("batch", 1)
        opts.pop("warm_start", None)  # the table's own choice (build's default)
        return build(n, direction_count, out=out, sets=[tuple(extra)], seed=tab.settings["seed"],
                     batch=batch, show_progress=show_progress, **build_options, **opts)
    return build(n, direction_count, out=out, sets=[tuple(extra)], show_progress=show_progress,
                 **build_options)
