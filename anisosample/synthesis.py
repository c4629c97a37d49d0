"""Point synthesis with anisotropic spectra: the optimizer loop (W Sec. 4, Eqs. 9-15).

``synthesize(key, n, directions_deg, *, recipe="rate", ...) -> (n, 2)`` float32 in ``[0, 1)^2``.

Two recipes (``RECIPES``), both minimising a loss of the point positions with Adam (Kingma & Ba;
a small pure-function implementation, :func:`adam_update`), initialised from a stratified set:

``"rate"`` (default; the design that reaches the rate, issue 4 finding c)
    :func:`~anisosample.losses.linear_spectrum_loss` on the ``"rate"`` frequency design
    (wedges of length ``n^0.8`` along every direction given, a disk of radius ``sqrt(n)``,
    weights ``W(v) = sum_d 1/(|v|^2 (1 + s_d^2))`` for the aligned edges and for edges off by
    +-0.25..+-1 deg, ``frequencies.ROBUST_OFFSETS_DEG``), no sliced-Wasserstein term, Adam with
    ``b2 = 0.9`` and a tiny epsilon, float64, positions wrapped on the torus.
``"paper"`` (W's recipe as published)
    :func:`~anisosample.losses.spectrum_loss` (Eq. 11, uniform weights, target 0) on the
    ``"paper"`` design (wedges of length ``3 sqrt(n)``) plus ``c`` times the sliced Wasserstein
    loss (Eqs. 12-15) along the same directions; standard Adam; positions clipped to the square.
    The paper's ``c`` is in its supplemental (not available); ``c = 100`` balances our scaled
    terms (measured at n = 256, directions 0/90/30, 300 steps: spectrum loss 0.017 alone ->
    0.057 with SW; n L_SW 0.0063 without SW -> 0.00058 with it; SW alone reaches 0.00022).

Boundary handling: the spectrum loss is periodic, so ``"wrap"`` (``x mod 1``) leaves it exact
and never piles points on the border; the SW target assumes the square (not the torus), so a
point wrapping from 1 to 0 would jump across the whole projected distribution: the paper recipe
therefore ``"clip"``s to ``[0, 1 - 2^-53]``.  Both can be chosen with ``boundary=``.

Long runs show a progress bar, save a checkpoint every ``checkpoint_every`` steps when
``checkpoint=`` names a ``.npz`` file, and resume from it (bit-identical to an uninterrupted
run: the same compiled step runs on the same state).  :func:`save_result` writes the set with
its metadata (n, directions, frequency design, loss history, key, package version).
"""

from __future__ import annotations

import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from . import frequencies as _freq
from . import io as _io
from . import losses as _losses
from . import spectrum as _spectrum
from ._validate import (
    ONE_MINUS_EPSILON,
    check_choice,
    check_directions_deg,
    check_int,
    check_key,
    check_positive_float,
)
from .progress import progress as _progress

RECIPES = ("rate", "paper")
BOUNDARIES = ("wrap", "clip")

_DEFAULTS = {
    "rate": dict(
        steps=200,
        learning_rate=0.5,
        final_lr_fraction=0.01,
        b1=0.9,
        b2=0.9,
        adam_eps=1e-30,
        c=0.0,
        boundary="wrap",
        design="rate",
        nufft_eps=1e-7,
    ),
    "paper": dict(
        steps=1000,
        learning_rate=0.1,
        final_lr_fraction=0.01,
        b1=0.9,
        b2=0.999,
        adam_eps=1e-8,
        c=100.0,
        boundary="clip",
        design="paper",
        nufft_eps=1e-7,
    ),
}


def recipe_defaults(recipe: str) -> dict:
    """The options a recipe uses unless overridden (``learning_rate`` is in units of the mean
    point spacing ``1/sqrt(n)``; it decays exponentially to ``final_lr_fraction`` of itself)."""
    return dict(_DEFAULTS[check_choice("recipe", recipe, RECIPES)])


def adam_update(grad, state, step, *, lr, b1, b2, eps):
    """One Adam step (Kingma & Ba 2015, Alg. 1) on an array; ``state = (m, v)``, ``step >= 1``."""
    m, v = state
    m = b1 * m + (1 - b1) * grad
    v = b2 * v + (1 - b2) * grad * grad
    mhat = m / (1 - b1**step)
    vhat = v / (1 - b2**step)
    return -lr * mhat / (jnp.sqrt(vhat) + eps), (m, v)


def _make_loss(fset, directions_deg, c, recipe, method, eps, a=1.0):
    """``a L_spec + c L_SW`` (W Eq. 10; ``a = 0`` or ``c = 0`` drops a term, as in W Fig. 3)."""
    spec = _losses.linear_spectrum_loss if recipe == "rate" else _losses.spectrum_loss

    def loss(x):
        val = jnp.zeros((), x.dtype)
        if a > 0:
            val = val + a * spec(x, fset, method=method, eps=eps)
        if c > 0:
            val = val + c * _losses.sliced_wasserstein_loss(x, directions_deg)
        return val

    return loss


def _make_chunk(loss, n, steps, opts, chunk):
    """A jitted function running ``chunk`` optimizer steps from a state (lax.scan)."""
    lr0 = opts["learning_rate"] / math.sqrt(n)
    decay = opts["final_lr_fraction"] ** (1.0 / max(steps - 1, 1))
    b1, b2, eps = opts["b1"], opts["b2"], opts["adam_eps"]
    wrap = opts["boundary"] == "wrap"
    hi = 1.0 - 2.0**-53

    def one(state, _):
        x, m, v, t = state
        val, g = jax.value_and_grad(loss)(x)
        tf = (t + 1).astype(x.dtype)
        lr = lr0 * decay ** t.astype(x.dtype)
        dx, (m, v) = adam_update(g, (m, v), tf, lr=lr, b1=b1, b2=b2, eps=eps)
        x = x + dx
        x = x - jnp.floor(x) if wrap else jnp.clip(x, 0.0, hi)
        return (x, m, v, t + 1), val

    @jax.jit
    def run(state):
        return jax.lax.scan(one, state, None, length=chunk)

    return run


def _initial_points(key, n, init):
    from . import samplers

    if init not in samplers.names():
        raise ValueError(f"init must be one of {samplers.names()}, got {init!r}")
    return samplers.get(init)(key, n)


def _to_float32_unit(x) -> np.ndarray:
    x = np.asarray(x, np.float64)
    x = x - np.floor(x)
    return np.minimum(x.astype(np.float32), ONE_MINUS_EPSILON)


def _key_record(key) -> list[int]:
    if jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key):
        key = jax.random.key_data(key)
    return [int(k) for k in np.asarray(key).reshape(-1)]


def synthesize(
    key,
    n: int,
    directions_deg,
    *,
    recipe: str = "rate",
    steps: int | None = None,
    learning_rate: float | None = None,
    c: float | None = None,
    spectrum_weight: float = 1.0,
    boundary: str | None = None,
    init: str = "jittered",
    method: str = "auto",
    frequency_options: dict | None = None,
    checkpoint: str | Path | None = None,
    checkpoint_every: int = 50,
    show_progress: bool = True,
    callback=None,
    return_info: bool = False,
    **adam_options,
):
    """Synthesize ``n`` points whose spectrum is dark along the spectral ``directions_deg``.

    Args:
        key: JAX PRNG key (the initial stratified set).
        n: number of points, ``>= 2``.
        directions_deg: spectral directions in ``[0, 180)`` (include 0 and 90 for the axes, as W
            always does), distinct.
        recipe: ``"rate"`` (default, reaches the rate) or ``"paper"`` (W Eqs. 10-15).
        steps, learning_rate, c, boundary: override the recipe's value (see
            :func:`recipe_defaults`); ``c >= 0`` weighs the SW term (W Eq. 10).
        spectrum_weight: weight of the spectrum term (0 leaves SW alone, W Fig. 3 b).
        init: a sampler name for the initial set (default ``"jittered"``).
        method: spectrum evaluation, ``"auto" | "direct" | "nufft1" | "nufft3"`` (see
            :mod:`anisosample.losses`; ``auto`` takes the lattice-aligned type-1 grids).
        frequency_options: overrides for :func:`anisosample.frequencies.design`.
        checkpoint: ``.npz`` path; saved every ``checkpoint_every`` steps, resumed if present.
        callback: ``callback(step, loss)`` after each chunk (may raise to stop).
        return_info: also return a dict (loss history, options, frequency design).
        adam_options: ``b1``, ``b2``, ``adam_eps``, ``final_lr_fraction``, ``nufft_eps`` (the
            NUFFT tolerance; 1e-7 keeps ``P_S`` accurate to ~1e-6 of white noise).

    Returns:
        ``(n, 2)`` float32 in ``[0, 1)^2`` (and ``info`` if asked).
    """
    key = check_key("key", key)
    n = check_int("n", n, minimum=2)
    directions_deg = check_directions_deg("directions_deg", directions_deg)
    recipe = check_choice("recipe", recipe, RECIPES)
    opts = recipe_defaults(recipe)
    for name, val in adam_options.items():
        if name not in ("b1", "b2", "adam_eps", "final_lr_fraction", "nufft_eps"):
            raise TypeError(f"synthesize() got an unexpected keyword argument {name!r}")
        opts[name] = check_positive_float(name, val)
    if steps is not None:
        opts["steps"] = check_int("steps", steps, minimum=1)
    if learning_rate is not None:
        opts["learning_rate"] = check_positive_float("learning_rate", learning_rate)
    if c is not None:
        opts["c"] = check_positive_float("c", c, allow_zero=True)
    opts["spectrum_weight"] = check_positive_float("spectrum_weight", spectrum_weight,
                                                   allow_zero=True)
    if opts["spectrum_weight"] == 0 and opts["c"] == 0:
        raise ValueError("spectrum_weight and c must not both be 0 (nothing to minimise)")
    if boundary is not None:
        opts["boundary"] = check_choice("boundary", boundary, BOUNDARIES)
    method = _spectrum.check_method(method)
    checkpoint_every = check_int("checkpoint_every", checkpoint_every, minimum=1)
    fset = _freq.design(n, directions_deg, opts["design"], **(frequency_options or {}))
    steps = opts["steps"]
    meta = {
        "n": n,
        "directions_deg": list(directions_deg),
        "recipe": recipe,
        "options": opts,
        "init": init,
        "method": method,
        "frequency_design": fset.params,
        "key": _key_record(key),
    }

    x_init = np.asarray(_initial_points(key, n, init), np.float64)
    with jax.enable_x64(True):
        x0 = jnp.asarray(x_init, jnp.float64)
        state = (x0, jnp.zeros_like(x0), jnp.zeros_like(x0), jnp.asarray(0, jnp.int64))
        history: list[float] = []
        if checkpoint is not None and Path(checkpoint).exists():
            arrays, old = _io.load_npz(checkpoint)
            same = {
                k: old.get(k)
                for k in (
                    "n",
                    "directions_deg",
                    "recipe",
                    "options",
                    "key",
                    "init",
                    "frequency_design",
                )
            }
            want = {k: _io._to_jsonable(meta[k]) for k in same}
            if same != want:
                raise ValueError(
                    f"checkpoint {checkpoint} was made with other settings;"
                    " delete it or choose another path"
                )
            state = (
                jnp.asarray(arrays["x"]),
                jnp.asarray(arrays["m"]),
                jnp.asarray(arrays["v"]),
                jnp.asarray(int(arrays["step"]), jnp.int64),
            )
            history = [float(h) for h in arrays["history"]]
        loss = _make_loss(fset, directions_deg, opts["c"], recipe, method, opts["nufft_eps"],
                          opts["spectrum_weight"])
        done = int(state[3])
        runners = {}
        bar = _progress(
            total=steps,
            initial=done,
            desc=f"synthesize n={n}",
            disable=None if show_progress else True,
        )
        try:
            while done < steps:
                k = min(checkpoint_every, steps - done)
                if k not in runners:
                    runners[k] = _make_chunk(loss, n, steps, opts, k)
                state, vals = runners[k](state)
                history.extend(np.asarray(vals).tolist())
                done = int(state[3])
                bar.update(k)
                bar.set_postfix(loss=f"{history[-1]:.3e}")
                if checkpoint is not None and done < steps:
                    _io.save_npz(
                        checkpoint,
                        {
                            "x": state[0],
                            "m": state[1],
                            "v": state[2],
                            "step": done,
                            "history": np.asarray(history),
                        },
                        meta,
                        overwrite=True,
                    )
                if callback is not None:
                    callback(done, history[-1])
        finally:
            bar.close()
        final = float(loss(state[0]))
    points = _to_float32_unit(state[0])
    if checkpoint is not None and Path(checkpoint).exists():
        Path(checkpoint).unlink()
    if return_info:
        info = dict(meta, history=history + [final], final_loss=final, frequency_count=len(fset))
        return jnp.asarray(points), info
    return jnp.asarray(points)


def save_result(path, points, info, *, overwrite: bool = False) -> Path:
    """Write a synthesized set and its ``info`` (from ``return_info=True``) to ``.npz``."""
    history = np.asarray(info.get("history", []), np.float64)
    meta = {k: v for k, v in info.items() if k != "history"}
    return _io.save_npz(
        path, {"points": np.asarray(points), "loss_history": history}, meta, overwrite=overwrite
    )


def load_result(path):
    """Inverse of :func:`save_result`: ``(points, metadata)``."""
    arrays, meta = _io.load_npz(path)
    return jnp.asarray(arrays["points"]), dict(meta, history=arrays.get("loss_history"))


def _expected_options(recipe, options) -> dict:
    opts = recipe_defaults(recipe)
    for k in ("steps", "learning_rate", "c", "boundary", "b1", "b2", "adam_eps",
              "final_lr_fraction", "nufft_eps"):
        if options.get(k) is not None:
            opts[k] = options[k]
    opts["spectrum_weight"] = options.get("spectrum_weight", 1.0)
    return opts


def load_or_synthesize(path, key, n: int, directions_deg, **options):
    """Load the set saved at ``path`` if it was made with the same settings, else synthesize it
    (checkpointed beside ``path``, so an interrupted run resumes) and save it there.

    Returns ``(points, info)``.  Experiments use this to reuse finished sets on rerun.
    """
    path = Path(path)
    key = check_key("key", key)
    directions_deg = check_directions_deg("directions_deg", directions_deg)
    recipe = options.get("recipe", "rate")
    if path.exists():
        pts, meta = load_result(path)
        want = _io._to_jsonable(_expected_options(recipe, options))
        if (meta.get("n") == n and meta.get("directions_deg") == list(directions_deg)
                and meta.get("key") == _key_record(key) and meta.get("recipe") == recipe
                and meta.get("options") == want
                and meta.get("frequency_design") == _io._to_jsonable(_freq.design(
                    n, directions_deg, want["design"],
                    **(options.get("frequency_options") or {})).params)):
            return pts, meta
    options = dict(options)
    options.pop("return_info", None)
    ckpt = path.with_name(path.stem + ".ckpt.npz")
    pts, info = synthesize(key, n, directions_deg, checkpoint=ckpt, return_info=True, **options)
    save_result(path, pts, info, overwrite=True)
    return pts, info


def _padded_groups(fsets, dtype):
    """Stack the per-direction groups of several frequency sets, padding each group to the
    largest size with zero-weight copies of its first frequency (so the loss is unchanged)."""
    k = len(fsets[0].group_sizes)
    out = []
    for g in range(k):
        groups = [list(fs.groups())[g] for fs in fsets]
        m = max(len(fg) for _, fg, _ in groups)
        vs, ws, rs = [], [], []
        for theta, fg, wg in groups:
            pad = m - len(fg)
            vs.append(np.concatenate([fg, np.repeat(fg[:1], pad, axis=0)]).astype(np.float64))
            ws.append(np.concatenate([wg, np.zeros(pad)]))
            rs.append(np.asarray(_spectrum.rotation(theta, jnp.float64)))
        out.append((jnp.asarray(np.stack(vs), dtype), jnp.asarray(np.stack(ws), dtype),
                    jnp.asarray(np.stack(rs), dtype)))
    return out


def _check_devices(devices) -> list:
    if devices is None:
        return [None]  # the default device (respects jax.default_device)
    devs = list(devices)
    if not devs:
        raise ValueError("devices must hold at least one device")
    for i, d in enumerate(devs):
        if not isinstance(d, jax.Device):
            raise TypeError(f"devices[{i}] must be a jax.Device, got {type(d).__name__}")
    if len(set(devs)) != len(devs):
        raise ValueError(f"devices must be distinct, got {devs}")
    return devs


def synthesize_batch(key, n: int, direction_sets, *, recipe: str = "rate",
                     steps: int | None = None, learning_rate: float | None = None,
                     c: float | None = None, init: str = "jittered", method: str = "nufft3",
                     devices=None, show_progress: bool = True, return_info: bool = False,
                     **adam_options):
    """Several sets at once: ``direction_sets`` is a list of ``B`` direction lists of equal
    length; returns ``(B, n, 2)``.  One optimizer loop, the loss ``vmap``ped over the sets
    (frequency groups padded to a common size with zero weights), so a batch costs one
    compilation and runs as batched type-3 NUFFTs (the sets' directions differ, so the
    lattice-aligned grids of :func:`synthesize` do not batch).  Set ``b`` starts from
    ``jax.random.split(key, B)[b]`` and equals ``synthesize(that key, n, direction_sets[b])``
    up to rounding.  No checkpoints (use :func:`synthesize` for long single runs).

    ``devices``: shard the sets over these devices with ``jax.shard_map`` on a one-axis
    ``jax.sharding.Mesh`` (``"sets"``); each device runs the loop on its own slice of the batch
    (the sets do not interact, so no collectives). ``B`` is padded to a multiple of the device
    count with copies of the last set, which are dropped. Default: the default device only. On
    the CPU, try it with ``XLA_FLAGS=--xla_force_host_platform_device_count=2``."""
    key = check_key("key", key)
    n = check_int("n", n, minimum=2)
    recipe = check_choice("recipe", recipe, RECIPES)
    sets = [check_directions_deg("direction_sets[i]", d) for d in direction_sets]
    if not sets:
        raise ValueError("direction_sets must hold at least one direction set")
    if len({len(d) for d in sets}) != 1:
        raise ValueError("direction_sets must all have the same number of directions, got "
                         f"{[len(d) for d in sets]}")
    method = check_choice("method", method, ("direct", "nufft3"))
    devs = _check_devices(devices)
    opts = recipe_defaults(recipe)
    for name, val in adam_options.items():
        if name not in ("b1", "b2", "adam_eps", "final_lr_fraction", "nufft_eps"):
            raise TypeError(f"synthesize_batch() got an unexpected keyword argument {name!r}")
        opts[name] = check_positive_float(name, val)
    if steps is not None:
        opts["steps"] = check_int("steps", steps, minimum=1)
    if learning_rate is not None:
        opts["learning_rate"] = check_positive_float("learning_rate", learning_rate)
    if c is not None:
        opts["c"] = check_positive_float("c", c, allow_zero=True)
    b = len(sets)
    keys = jax.random.split(key, b)
    x_init = np.stack([np.asarray(_initial_points(k, n, init), np.float64) for k in keys])
    fsets = [_freq.design(n, d, opts["design"]) for d in sets]
    pad = -b % len(devs)  # copies of the last set so that every device gets as many sets
    x_init = np.concatenate([x_init, np.repeat(x_init[-1:], pad, axis=0)])
    fsets_padded = fsets + [fsets[-1]] * pad
    sets_padded = sets + [sets[-1]] * pad
    eps = opts["nufft_eps"]
    spec_sq = recipe == "paper"
    cw = opts["c"]
    with jax.enable_x64(True):
        groups = _padded_groups(fsets_padded, jnp.float64)
        th = jnp.asarray(np.deg2rad(np.asarray(sets_padded)), jnp.float64)  # (B, k)
        u = jnp.asarray((np.arange(n) + 0.5) / n - 0.5, jnp.float64)

        def loss_one(x, grp, theta):
            num = jnp.zeros((), x.dtype)
            den = jnp.zeros((), x.dtype)
            for v, w, r in grp:
                p = _spectrum._power(x, v, r, method, eps)
                num = num + jnp.sum(w * (p * p * n if spec_sq else p))
                den = den + jnp.sum(w)
            val = n * num / den
            if cw > 0:  # sliced Wasserstein (W Eqs. 12-15) with traced directions
                d = jnp.stack([jnp.cos(theta), jnp.sin(theta)], 1)
                tgt = _losses.square_projection_quantile(jnp.rad2deg(theta)[:, None], u[None])
                srt = jnp.sort((x - 0.5) @ d.T, axis=0).T
                val = val + cw * jnp.mean(jnp.sum((srt - tgt) ** 2, axis=1))
            return val

        def total(xb, grps, ths):
            if method == "direct":
                vals = jax.vmap(loss_one)(xb, grps, ths)
            else:  # jax-finufft 1.3.1's batching rule fails under jax 0.10 (no
                # batching.not_mapped): map over the sets inside the same jit instead
                vals = jax.lax.map(lambda a: loss_one(*a), (xb, grps, ths))
            return jnp.sum(vals), vals

        lr0 = opts["learning_rate"] / math.sqrt(n)
        decay = opts["final_lr_fraction"] ** (1.0 / max(opts["steps"] - 1, 1))
        wrap = opts["boundary"] == "wrap"

        def run(state, grps, ths, length):
            def one(st, _):
                x, m, v, t = st
                (_, vals), g = jax.value_and_grad(total, has_aux=True)(x, grps, ths)
                lr = lr0 * decay ** t.astype(x.dtype)
                dx, (m, v) = adam_update(g, (m, v), (t + 1).astype(x.dtype), lr=lr,
                                         b1=opts["b1"], b2=opts["b2"], eps=opts["adam_eps"])
                x = x + dx
                x = x - jnp.floor(x) if wrap else jnp.clip(x, 0.0, 1.0 - 2.0**-53)
                return (x, m, v, t + 1), vals

            return jax.lax.scan(one, state, None, length=length)

        def final_values(xb, grps, ths):
            return total(xb, grps, ths)[1]

        if len(devs) > 1:
            from jax.sharding import Mesh
            from jax.sharding import PartitionSpec as P

            mesh = Mesh(np.asarray(devs), ("sets",))
            per_set, rep = P("sets"), P()

            def sharded(fn, in_specs, out_specs):
                # check_vma=False: the NUFFT custom calls carry no varying-axis rules; the sets
                # are independent, so every output is exactly its shard's.
                return jax.jit(jax.shard_map(fn, mesh=mesh, in_specs=in_specs,
                                             out_specs=out_specs, check_vma=False))

            make_runner = lambda k: sharded(  # noqa: E731
                lambda st, g, t: run(st, g, t, k),
                ((per_set, per_set, per_set, rep), per_set, per_set),
                ((per_set, per_set, per_set, rep), P(None, "sets")))
            final_fn = sharded(final_values, (per_set, per_set, per_set), per_set)
        else:
            make_runner = lambda k: jax.jit(lambda st, g, t: run(st, g, t, k))  # noqa: E731
            final_fn = jax.jit(final_values)

        chunk = 25
        runners = {}
        x0 = jnp.asarray(x_init)
        if len(devs) == 1 and devs[0] is not None:
            x0 = jax.device_put(x0, devs[0])
        state = (x0, jnp.zeros_like(x0), jnp.zeros_like(x0), jnp.asarray(0, jnp.int64))
        history = []
        bar = _progress(total=opts["steps"], desc=f"synthesize_batch {b} x n={n}"
                        + (f" on {len(devs)} devices" if len(devs) > 1 else ""),
                        disable=None if show_progress else True)
        done = 0
        while done < opts["steps"]:
            k = min(chunk, opts["steps"] - done)
            if k not in runners:
                runners[k] = make_runner(k)
            state, vals = runners[k](state, groups, th)
            history.append(np.asarray(vals)[:, :b])
            done += k
            bar.update(k)
        bar.close()
        final = np.asarray(final_fn(state[0], groups, th))[:b]
        state = (np.asarray(state[0])[:b],) + tuple(state[1:])
    pts = jnp.asarray(np.stack([_to_float32_unit(x) for x in np.asarray(state[0])]))
    if return_info:
        hist = np.concatenate(history + [final[None]], axis=0).T
        return pts, {"n": n, "direction_sets": [list(d) for d in sets], "recipe": recipe,
                     "options": opts, "history": hist, "final_loss": final,
                     "frequency_design": [fs.params for fs in fsets]}
    return pts
