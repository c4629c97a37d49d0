"""The variance engine: estimator variance over randomizations, sweeps over n, slope fits.

The estimator of a point set ``S`` is ``I_N = mean_j f(x_j)`` (W Eq. 1). Its variance is taken
over *randomizations* of the pattern, chosen explicitly with ``randomization``:

* ``"shift"`` -- one fixed pattern (or ``patterns`` fixed patterns) moved by independent
  toroidal shifts ``(x + t) mod 1`` (Cranley-Patterson; W Sec. 5.4 decorrelates its precomputed
  sets this way). For a fixed set this is exactly ``sum_{v != 0} P_S(v) P_f(v)`` (W Eq. 5;
  Pilleboue et al. 2015; :func:`anisosample.metrics.predicted_variance`). The only sensible
  choice for deterministic or precomputed sets (optimized sets, tables) and for slow
  constructions (pmj02, pmj02bn).
* ``"fresh"`` -- a new pattern per realization from a new key (new jitter, new Owen scramble,
  new permutation): the sampler's own randomization, what a renderer does per pixel.
* ``"fresh+shift"`` -- both: the homogenized pattern for which W Eq. 5 holds with the expected
  spectrum ``<P_S>`` (fresh patterns of a non-homogeneous sampler such as jittered are not
  shift-invariant, fourier_variance.md Sec. 2).
* ``"auto"`` -- ``"fresh"`` for samplers that can be traced (``sampler.jittable``), ``"shift"``
  otherwise (NumPy constructions, fixed point sets, unknown callables).

Accuracy (DESIGN "Accuracy"): each realization's estimate is accumulated as centred float32
deviations ``f(x_j) - c`` summed in blocks of 256 and then over blocks, and the variance is
formed in float64 from centred values; at ``n = 2^16`` the result matches a float64 reference to
well under 1 % (tests/test_variance.py). Speed: realizations are evaluated in chunks (``vmap``
inside ``lax.map``) inside one ``jit``, so memory is bounded by ``chunk_elements``.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable, Mapping, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.stats

from . import samplers as _samplers
from ._validate import check_choice, check_devices, check_int, check_key, check_points
from .progress import progress as _progress_bar

__all__ = [
    "RANDOMIZATIONS",
    "VarianceEstimate",
    "SlopeFit",
    "ConvergenceResult",
    "realization_estimates",
    "estimator_variance",
    "estimate_variance",
    "variance_from_estimates",
    "fit_slope",
    "convergence",
]

RANDOMIZATIONS = ("auto", "shift", "fresh", "fresh+shift")

_BLOCK = 256
"""Block length of the two-level float32 sum of deviations (pairwise-like error growth)."""

DEFAULT_CHUNK_ELEMENTS = 2**19
"""Integrand evaluations per chunk of realizations (a few MB of float32 temporaries: the chunk
stays in cache, which measured faster than larger chunks)."""


# --- the jitted kernels ---------------------------------------------------------------------------


def _shifted_xy(x, y, tx, ty):
    """``(x + t) mod 1`` per coordinate, stacked last: kept as two planes (structure of arrays)
    until the integrand, which lets XLA fuse shift, wrap and integrand into one vectorized loop
    (several times faster on the CPU than shifting interleaved ``(..., 2)`` points)."""
    wrap = _samplers.wrap_unit  # the toroidal shift's own wrap (one definition of "mod 1, below 1")
    return jnp.stack([wrap(x + tx), wrap(y + ty)], axis=-1)


def _block_mean(v, n: int):
    """Mean over the last axis of centred float32 values: sums of 256-blocks, then of blocks."""
    pad = (-n) % _BLOCK
    if pad:
        v = jnp.concatenate([v, jnp.zeros(v.shape[:-1] + (pad,), v.dtype)], axis=-1)
    v = v.reshape(v.shape[:-1] + (-1, _BLOCK))
    return jnp.sum(jnp.sum(v, axis=-1), axis=-1) / jnp.float32(n)


def _evaluate(f, x, c):
    v = jnp.asarray(f(x))
    if v.shape != x.shape[:-1]:
        raise ValueError(
            f"the integrand must map points of shape (..., 2) to (...), got {v.shape} from "
            f"{x.shape}"
        )
    return _block_mean(v.astype(jnp.float32) - c, x.shape[-2])


@eqx.filter_jit
def _shifted_deviations(f, points, shifts, c, chunk: int):
    """``mean_j f((x_j + t_r) mod 1) - c`` for every shift ``t_r`` (``(R, 2)``, R % chunk = 0)."""

    px, py = points[None, :, 0], points[None, :, 1]

    def body(t):  # t: (chunk, 2)
        return _evaluate(f, _shifted_xy(px, py, t[:, 0:1], t[:, 1:2]), c)

    out = jax.lax.map(body, shifts.reshape(-1, chunk, 2))
    return out.reshape(-1)


@functools.partial(jax.jit, static_argnums=(0, 1))
def _fresh_points(sampler, n: int, keys):
    """A stack of fresh patterns ``sampler.fn(key_r, n)``, vmapped over the keys.

    Kept apart from the integrand's kernel so that its (costly) compilation is shared by every
    integrand measured with the same sampler, n and chunk.
    """
    return jax.vmap(lambda k: sampler.fn(k, n))(keys)


@eqx.filter_jit
def _stacked_deviations(f, points, shifts, c):
    """Deviations of a stack of point sets ``(C, n, 2)``, each shifted by its ``t``."""
    x = _shifted_xy(points[..., 0], points[..., 1], shifts[:, 0:1], shifts[:, 1:2])
    return _evaluate(f, x, c)


# --- argument handling --------------------------------------------------------------------------


def _resolve_sampler(sampler, n: int):
    """A sampler name, Sampler, callable ``(key, n)`` or a fixed ``(n, 2)`` point set."""
    if isinstance(sampler, str):
        return _samplers.get(sampler), None
    if hasattr(sampler, "shape"):
        pts = check_points("sampler", sampler)
        if pts.shape[0] != n:
            raise ValueError(
                f"n must equal the number of points of the given set ({pts.shape[0]}), got {n}"
            )
        return None, jnp.asarray(pts, dtype=jnp.float32)
    if not callable(sampler):
        raise TypeError(
            "sampler must be a sampler name, a callable (key, n) -> (n, 2) or an (n, 2) point "
            f"set, got {type(sampler).__name__}"
        )
    return sampler, None


MAX_REALIZATIONS = 2**30
"""The most realizations one variance estimate takes (their shifts alone are 8 GiB)."""


def _check_pattern(points, n: int):
    """A set a user's sampler made: ``(n, 2)``, finite, in ``[0, 1)^2``."""
    pts = check_points("the sampler's points", points)
    if pts.shape[0] != n:
        raise ValueError(f"the sampler must return (n, 2) = ({n}, 2) points, got shape "
                         f"{tuple(pts.shape)}")
    return pts


def _check_n_for(sampler, n: int) -> None:
    if getattr(sampler, "power_of_two", False) and n & (n - 1):
        name = getattr(sampler, "name", "this sampler")
        raise ValueError(
            f"n must be a power of two for sampler {name!r} (its net guarantees hold at 2^m), "
            f"got {n}"
        )


def _choose_randomization(randomization: str, sampler, fixed) -> str:
    check_choice("randomization", randomization, RANDOMIZATIONS)
    jittable = isinstance(sampler, _samplers.Sampler) and sampler.jittable
    if randomization == "auto":
        return "fresh" if jittable else "shift"
    if fixed is not None and randomization != "shift":
        raise ValueError(
            f"randomization must be 'shift' or 'auto' for a fixed point set, got {randomization!r}"
        )
    return randomization


def _off(progress: bool):
    return True if not progress else None  # None: tqdm follows ANISOSAMPLE_PROGRESS


def _chunk_size(n: int, realizations: int, chunk_elements: int) -> int:
    """Realizations per chunk: at most ``chunk_elements`` evaluations. Not a function of the
    devices: a ray-casting integrand's last bit can follow the chunk's shape (XLA's vector
    width), so the devices share whole chunks of the one-device size."""
    return max(1, min(realizations, chunk_elements // n))


def _local_devices(devices) -> list:
    """``[None]`` (the default device) or the checked ``devices``, all of this process."""
    devs = check_devices("devices", devices)
    if devs is None:
        return [None]
    me = jax.process_index()
    if any(d.process_index != me for d in devs):
        raise ValueError(f"devices must be this process's devices (process {me}), got {devs}")
    return devs


def _placed(tree, device):
    """``tree`` with its arrays on ``device`` (``None``: left where they are), so that a jitted
    call on them runs there."""
    if device is None:
        return tree
    arrays, rest = eqx.partition(tree, eqx.is_array)
    return eqx.combine(jax.device_put(arrays, device), rest)


def _pad_rows(a, rows: int):
    if a.shape[0] == rows:
        return a
    reps = rows - a.shape[0]
    return jnp.concatenate([a, jnp.broadcast_to(a[:1], (reps,) + a.shape[1:])], axis=0)


def realization_estimates(
    f: Callable,
    sampler,
    n: int,
    key,
    realizations: int,
    *,
    randomization: str = "auto",
    patterns: int = 1,
    center: float | None = None,
    chunk_elements: int = DEFAULT_CHUNK_ELEMENTS,
    progress: bool = False,
    devices=None,
) -> np.ndarray:
    """The ``realizations`` estimates ``I_N`` (float64 NumPy array), one per randomization.

    ``sampler``: a name (``samplers.names()``), a sampler ``(key, n) -> (n, 2)``, or a fixed
    ``(n, 2)`` point set (shift only). ``patterns``: with ``"shift"``, the number of independent
    base patterns, each moved by ``realizations / patterns`` shifts. ``center``: the value the
    float32 deviations are taken from (default: the estimate of the first pattern; the exact
    integral is best). ``devices``: local devices (e.g. ``jax.devices()``) that the chunks of
    ``chunk_elements // n`` realizations are dealt out to, in turn (``render``'s ``devices``
    for the variance engine; one chunk runs on the first device alone); default: the default
    device. The estimates are the same bits on any devices: a chunk is the same computation
    wherever it runs. They do not depend on ``chunk_elements`` beyond float32 rounding (to
    the bit for analytic integrands; a ray-casting integrand's last bit can follow the chunk's
    shape).
    """
    n = check_int("n", n, minimum=1)
    realizations = check_int("realizations", realizations, minimum=2, maximum=MAX_REALIZATIONS)
    patterns = check_int("patterns", patterns, minimum=1)
    chunk_elements = check_int("chunk_elements", chunk_elements, minimum=1)
    key = check_key("key", key)
    devs = _local_devices(devices)
    if not callable(f):
        raise TypeError(f"f must be a callable integrand over (..., 2), got {type(f).__name__}")
    sampler, fixed = _resolve_sampler(sampler, n)
    if sampler is not None:
        _check_n_for(sampler, n)
    mode = _choose_randomization(randomization, sampler, fixed)
    if patterns != 1 and mode != "shift":
        raise ValueError(f"patterns applies to randomization 'shift' only, got {mode!r}")
    if realizations % patterns:
        raise ValueError(
            f"realizations must be a multiple of patterns ({patterns}), got {realizations}"
        )
    k_pat, k_shift = jax.random.split(key)
    shifts = jax.random.uniform(k_shift, (realizations, 2), dtype=jnp.float32)

    if mode == "shift":
        if fixed is not None:
            if patterns != 1:
                raise ValueError("patterns must be 1 for a fixed point set")
            bases = [fixed]
        else:
            bases = [
                jnp.asarray(sampler(k, n), dtype=jnp.float32)
                for k in jax.random.split(k_pat, patterns)
            ]
    else:
        bases = [
            jnp.asarray(sampler(jax.random.split(k_pat, realizations)[0], n), dtype=jnp.float32)
        ]
    user_made = sampler is not None and not isinstance(sampler, _samplers.Sampler)
    if user_made:  # a user's callable: its sets must be point sets of n points
        for b in bases:
            _check_pattern(b, n)
    if center is None:
        center = float(np.mean(np.asarray(f(bases[0]), dtype=np.float64)))
    c = jnp.float32(center)
    per = realizations // patterns
    chunk = _chunk_size(n, per if mode == "shift" else realizations, chunk_elements)
    devs = devs[: -(-(per if mode == "shift" else realizations) // chunk)]  # one chunk or more
    on = [(d, _placed(f, d), _placed(c, d)) for d in devs]  # the integrand on each device

    out = []
    if mode == "shift":
        bar = _progress_bar(total=patterns, desc="patterns", disable=_off(progress))
        for p, base in enumerate(bases):
            t = shifts[p * per : (p + 1) * per]
            rows = -(-per // (chunk * len(devs))) * chunk  # per device, whole chunks
            t = _pad_rows(t, rows * len(devs))
            parts = [  # dispatched to every device before any result is read
                _shifted_deviations(fd, _placed(base, d), _placed(t[i * rows : (i + 1) * rows], d),
                                    cd, chunk)
                for i, (d, fd, cd) in enumerate(on)
            ]
            out.append(np.concatenate([np.asarray(x, dtype=np.float64) for x in parts])[:per])
            bar.update(1)
        bar.close()
    else:
        use_shift = mode == "fresh+shift"
        t = shifts if use_shift else jnp.zeros_like(shifts)
        keys = jax.random.split(k_pat, realizations)
        jittable = isinstance(sampler, _samplers.Sampler) and sampler.jittable
        if jittable:
            rows = -(-realizations // chunk) * chunk
            keys, t = _pad_rows(keys, rows), _pad_rows(t, rows)
            parts = []
            for j, i in enumerate(range(0, rows, chunk)):
                d, fd, cd = on[j % len(on)]
                pts = _fresh_points(sampler, n, _placed(keys[i : i + chunk], d))
                parts.append(_stacked_deviations(fd, pts, _placed(t[i : i + chunk], d), cd))
            dev = np.concatenate([np.asarray(x, dtype=np.float64) for x in parts])
            out.append(dev[:realizations])
        else:  # NumPy constructions or unknown callables: make the sets in Python, evaluate stacked
            bar = _progress_bar(total=realizations, desc="patterns", disable=_off(progress))
            for j, start in enumerate(range(0, realizations, chunk)):
                stop = min(start + chunk, realizations)
                d, fd, cd = on[j % len(on)]
                pts = jnp.stack(
                    [
                        _check_pattern(jnp.asarray(sampler(keys[r], n), dtype=jnp.float32), n)
                        if user_made else jnp.asarray(sampler(keys[r], n), dtype=jnp.float32)
                        for r in range(start, stop)
                    ]
                )
                out.append(_stacked_deviations(fd, _placed(pts, d), _placed(t[start:stop], d),
                                               cd))
                bar.update(stop - start)
            bar.close()
            out = [np.asarray(x, dtype=np.float64) for x in out]
    return float(center) + np.concatenate(out)


# --- variance and its interval ------------------------------------------------------------------


class VarianceEstimate(eqx.Module):
    """A variance with its standard error and confidence interval.

    ``variance``: unbiased sample variance of the estimates (``exact=None``) or their mean
    squared error about ``exact``. ``std_error`` uses the sample fourth moment (no normality
    assumption); the interval is ``variance * exp(+-z std_error / variance)`` (log-normal).
    """

    variance: float
    std_error: float
    ci_low: float
    ci_high: float
    mean: float
    n: int = eqx.field(static=True)
    realizations: int = eqx.field(static=True)
    randomization: str = eqx.field(static=True)
    confidence: float = eqx.field(static=True)

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


def variance_from_estimates(
    estimates,
    exact: float | None = None,
    *,
    n: int = 0,
    randomization: str = "",
    confidence: float = 0.95,
) -> VarianceEstimate:
    """Variance, standard error and interval from per-realization estimates (float64)."""
    x = np.asarray(estimates, dtype=np.float64).reshape(-1)
    r = x.size
    if r < 2:
        raise ValueError(f"realizations must be >= 2, got {r}")
    if not np.all(np.isfinite(x)):
        raise ValueError("the integrand produced NaN or Inf estimates")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must lie in (0, 1), got {confidence}")
    mean = float(np.mean(x))
    if exact is None:
        d = x - mean
        var = float(np.sum(d * d) / (r - 1))
        m4 = float(np.mean(d**4))
        se2 = (m4 - var * var * (r - 3) / (r - 1)) / r
    else:
        d = x - float(exact)
        sq = d * d
        var = float(np.mean(sq))
        se2 = float(np.var(sq, ddof=1)) / r
    se = math.sqrt(max(se2, 0.0))
    z = float(scipy.stats.norm.ppf(0.5 + confidence / 2))
    if var > 0:
        spread = math.exp(z * se / var)
        lo, hi = var / spread, var * spread
    else:
        lo = hi = 0.0
    return VarianceEstimate(var, se, lo, hi, mean, n, r, randomization, confidence)


def _known_integral(f) -> float | None:
    """``f.integral`` when the integrand knows it (a good centre for the deviations)."""
    try:
        value = float(getattr(f, "integral", None))
    except (TypeError, ValueError, NotImplementedError):
        return None
    return value if math.isfinite(value) else None


def estimate_variance(
    f: Callable,
    sampler,
    n: int,
    key,
    realizations: int,
    exact: float | None = None,
    *,
    randomization: str = "auto",
    patterns: int = 1,
    confidence: float = 0.95,
    chunk_elements: int = DEFAULT_CHUNK_ELEMENTS,
    progress: bool = False,
    devices=None,
) -> VarianceEstimate:
    """Like :func:`estimator_variance`, with the standard error and a confidence interval."""
    if exact is not None:
        exact = float(exact)
        if not math.isfinite(exact):
            raise ValueError(f"exact must be finite, got {exact}")
    center = exact if exact is not None else _known_integral(f)
    est = realization_estimates(
        f,
        sampler,
        n,
        key,
        realizations,
        randomization=randomization,
        patterns=patterns,
        center=center,
        chunk_elements=chunk_elements,
        progress=progress,
        devices=devices,
    )
    sampler_obj, fixed = _resolve_sampler(sampler, n)
    mode = _choose_randomization(randomization, sampler_obj, fixed)
    return variance_from_estimates(est, exact, n=n, randomization=mode, confidence=confidence)


def estimator_variance(
    f: Callable,
    sampler,
    n: int,
    key,
    realizations: int = 1024,
    exact: float | None = None,
    *,
    randomization: str = "auto",
    patterns: int = 1,
    chunk_elements: int = DEFAULT_CHUNK_ELEMENTS,
    devices=None,
) -> float:
    """``Var(I_N)`` of ``I_N = mean_j f(x_j)`` over ``realizations`` randomizations (W Eq. 5's
    left-hand side), as a float.

    ``exact``: the true integral, if known (e.g. ``f.integral``); then the mean squared error
    about it is returned (the estimators are unbiased, so it estimates the same variance with one
    more degree of freedom). ``randomization``: ``"auto"``, ``"shift"``, ``"fresh"`` or
    ``"fresh+shift"`` (see the module docstring). ``devices``: local devices the chunks of
    realizations are dealt out to (:func:`realization_estimates`; the same result). Raises
    ``ValueError`` for ``realizations < 2`` and for ``n`` that is not a power of two with a net
    sampler (sobol-owen, pmj02, pmj02bn).
    """
    return estimate_variance(
        f,
        sampler,
        n,
        key,
        realizations,
        exact,
        randomization=randomization,
        patterns=patterns,
        chunk_elements=chunk_elements,
        devices=devices,
    ).variance


# --- convergence sweeps and slope fits ------------------------------------------------------------


class SlopeFit(eqx.Module):
    """``log Var = intercept + slope log n`` by weighted least squares.

    Weights are ``1 / se(log Var)^2`` from each variance's standard error. The slope's standard
    error is inflated by ``sqrt(chi2 / dof)`` when the points scatter more than their errors say
    (model error: the curve is not exactly a power law), and the interval uses Student's t with
    ``k - 2`` degrees of freedom.
    """

    slope: float
    intercept: float
    std_error: float
    ci_low: float
    ci_high: float
    confidence: float = eqx.field(static=True)

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


def fit_slope(ns, variances, std_errors=None, *, confidence: float = 0.95) -> SlopeFit:
    """Fit the log-log convergence slope of ``variances`` over ``ns`` with its interval."""
    ns = np.asarray(ns, dtype=np.float64).reshape(-1)
    v = np.asarray(variances, dtype=np.float64).reshape(-1)
    if ns.shape != v.shape or ns.size < 2:
        raise ValueError(
            f"ns and variances must have the same length >= 2, got {ns.size} and {v.size}"
        )
    if not (np.all(np.isfinite(v)) and np.all(np.isfinite(ns))):
        raise ValueError("ns and variances must be finite for a log-log fit")
    if np.any(v <= 0) or np.any(ns <= 0):
        raise ValueError("ns and variances must be positive for a log-log fit")
    if len(np.unique(ns)) < 2:
        raise ValueError(f"ns must hold at least 2 different sizes, got {ns.tolist()}")
    if not 0.0 < float(confidence) < 1.0:
        raise ValueError(f"confidence must lie in (0, 1), got {confidence}")
    x, y = np.log(ns), np.log(v)
    if std_errors is None:
        w = np.ones_like(y)
    else:
        se = np.asarray(std_errors, dtype=np.float64).reshape(-1) / v
        w = 1.0 / np.maximum(se, 1e-12) ** 2
    a = np.stack([np.ones_like(x), x], axis=-1)
    cov = np.linalg.inv(a.T @ (w[:, None] * a))
    beta = cov @ (a.T @ (w * y))
    k = x.size
    dof = k - 2
    resid = y - a @ beta
    chi2 = float(np.sum(w * resid**2))
    scale = 1.0
    if std_errors is None:
        scale = math.sqrt(chi2 / dof) if dof > 0 else float("inf")
    elif dof > 0:
        scale = max(1.0, math.sqrt(chi2 / dof))
    se_slope = math.sqrt(cov[1, 1]) * scale
    q = float(scipy.stats.t.ppf(0.5 + confidence / 2, dof)) if dof > 0 else float("inf")
    if std_errors is not None and scale == 1.0:  # known errors explain the scatter: normal
        q = float(scipy.stats.norm.ppf(0.5 + confidence / 2))
    return SlopeFit(
        float(beta[1]),
        float(beta[0]),
        se_slope,
        float(beta[1] - q * se_slope),
        float(beta[1] + q * se_slope),
        confidence,
    )


class ConvergenceResult(eqx.Module):
    """Per sampler: the variance estimates over ``ns`` and the fitted slope."""

    ns: tuple[int, ...] = eqx.field(static=True)
    estimates: dict[str, tuple[VarianceEstimate, ...]]
    fits: dict[str, SlopeFit]

    def variances(self, name: str) -> np.ndarray:
        return np.array([e.variance for e in self.estimates[name]])

    def as_dict(self) -> dict:
        return {
            "ns": list(self.ns),
            "samplers": {
                name: {
                    "variance": [e.variance for e in ests],
                    "std_error": [e.std_error for e in ests],
                    "ci_low": [e.ci_low for e in ests],
                    "ci_high": [e.ci_high for e in ests],
                    "randomization": ests[0].randomization,
                    "realizations": ests[0].realizations,
                    "fit": self.fits[name].as_dict(),
                }
                for name, ests in self.estimates.items()
            },
        }


def _fixed_sets_by_size(label, sampler, ns) -> dict[int, jax.Array] | None:
    """``{n: (n, 2) set}`` when ``sampler`` is fixed sets, one per size (a mapping by size or a
    list of sets), checked to cover ``ns``; ``None`` for names and callables."""
    if isinstance(sampler, Mapping):
        items = list(sampler.items())
    elif isinstance(sampler, list | tuple) and not isinstance(sampler, str):
        items = [(None, s) for s in sampler]
    else:
        return None
    if not items:
        raise ValueError(f"sampler {label!r} holds no point sets")
    sets: dict[int, jax.Array] = {}
    for i, (size, pts) in enumerate(items):
        pts = check_points(f"sampler {label!r}: set {size if size is not None else i}", pts)
        m = int(pts.shape[0])
        if size is not None and int(size) != m:
            raise ValueError(f"sampler {label!r}: the set under key {size} has {m} points")
        if m in sets:
            raise ValueError(f"sampler {label!r} holds two sets of n = {m}; give one set per "
                             "size (a convergence run shifts each one)")
        sets[m] = jnp.asarray(pts, dtype=jnp.float32)
    missing = [m for m in ns if m not in sets]
    if missing:
        raise ValueError(f"sampler {label!r} has fixed sets of n = {sorted(sets)}, none of n = "
                         f"{missing}; ns must be sizes it holds")
    return sets


def convergence(
    f: Callable,
    samplers: Sequence[str] | Mapping[str, object],
    ns: Sequence[int],
    key,
    realizations: int = 1024,
    *,
    exact: float | None = None,
    randomization: str | Mapping[str, str] = "auto",
    patterns: int | Mapping[str, int] = 1,
    fit_min_n: int = 1,
    confidence: float = 0.95,
    progress: bool = False,
    devices=None,
) -> ConvergenceResult:
    """Sweep ``n`` over ``ns`` for each sampler and fit ``Var ~ n^slope`` (W Figs. 6, 11).

    ``samplers``: names, or a mapping ``label -> sampler``: a name, a callable ``(key, n)``, or
    *fixed sets, one per size* -- a mapping ``{n: (n, 2) points}`` or a list of ``(n_i, 2)``
    sets (a user's own sets, e.g. ``io.load_point_sets(path)``), which must hold a set of every
    size in ``ns`` and are randomized by toroidal shifts (``randomization`` ``"shift"`` or
    ``"auto"``, one pattern). ``randomization`` and ``patterns`` may be
    per-label mappings; ``patterns`` applies to the samplers randomized by ``"shift"``.
    The same key is used for every n and sampler (common random numbers).
    Only ``n >= fit_min_n`` enter the fit (skip the pre-asymptotic regime). ``devices``: local
    devices each estimate's realizations are dealt out to (:func:`realization_estimates`).
    """
    key = check_key("key", key)
    _local_devices(devices)
    ns = tuple(check_int("ns", m, minimum=1) for m in ns)
    if len(ns) < 2:
        raise ValueError(f"ns must hold at least 2 sizes for a slope, got {list(ns)}")
    if isinstance(samplers, str):
        samplers = [samplers]
    table = dict(samplers) if isinstance(samplers, Mapping) else {s: s for s in samplers}
    if not table:
        raise ValueError("samplers must name at least one sampler")
    fit_ns = [m for m in ns if m >= fit_min_n]
    if len(fit_ns) < 2:
        raise ValueError(f"fit_min_n leaves fewer than 2 sizes to fit, got {fit_min_n}")
    if not callable(f):
        raise TypeError(f"f must be a callable integrand over (..., 2), got {type(f).__name__}")
    # the arguments every estimate checks, checked before the progress bar starts
    check_int("realizations", realizations, minimum=2, maximum=MAX_REALIZATIONS)
    for opt, name in ((patterns, "patterns"),):
        for value in (opt.values() if isinstance(opt, Mapping) else (opt,)):
            check_int(name, value, minimum=1)
    for label in table:
        for opt, name in ((randomization, "randomization"), (patterns, "patterns")):
            if isinstance(opt, Mapping) and label not in opt:
                raise ValueError(f"{name} has no entry for sampler {label!r}")
    fixed = {label: _fixed_sets_by_size(label, smp, ns) for label, smp in table.items()}

    def option(opt, label):
        return opt[label] if isinstance(opt, Mapping) else opt

    estimates: dict[str, tuple[VarianceEstimate, ...]] = {}
    fits: dict[str, SlopeFit] = {}
    bar = _progress_bar(total=len(table) * len(ns), desc="convergence", disable=_off(progress))
    for label, smp in table.items():
        row = []
        mode = option(randomization, label)
        pats = option(patterns, label)
        sets = fixed[label]
        if sets is not None:
            _choose_randomization(mode, None, sets[ns[0]])  # "shift" or "auto" only
            pats = 1  # one fixed set per size
        elif _choose_randomization(mode, *_resolve_sampler(smp, ns[0])) != "shift":
            pats = 1  # patterns counts fixed sets; fresh randomizations have none
        for m in ns:
            row.append(
                estimate_variance(
                    f,
                    smp if sets is None else sets[m],
                    m,
                    key,
                    realizations,
                    exact,
                    randomization=mode,
                    patterns=pats,
                    confidence=confidence,
                    devices=devices,
                )
            )
            bar.update(1)
        estimates[label] = tuple(row)
        sel = [i for i, m in enumerate(ns) if m >= fit_min_n]
        fits[label] = fit_slope(
            [ns[i] for i in sel],
            [row[i].variance for i in sel],
            [row[i].std_error for i in sel],
            confidence=confidence,
        )
    bar.close()
    return ConvergenceResult(ns, estimates, fits)
