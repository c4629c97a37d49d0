"""Baseline 2D samplers, the toroidal shift and the Singh-Jarosz shear.

Every sampler is a callable ``sampler(key, n) -> (n, 2)`` float32 in ``[0, 1)^2``, reachable by
name through :func:`get`. Randomness comes only from the key: the same key gives the same bits.

Coordinates of the digital constructions (sobol-owen, pmj02, pmj02bn) are built as 32-bit
fixed-point integers and converted to float32 by *truncation* (``(X >> 8) * 2^-24``), never by
rounding, so strata survive the conversion and no coordinate becomes 1.0. Jittered and CMJ form
``s / count + u / count`` in float32 and clamp it inside its stratum (:func:`_in_stratum`).

References: Kensler 2013 (CMJ); Burley 2020 (hash-based Owen scrambling); Christensen, Kensler,
Kilpatrick 2018 (pmj02, pmj02bn); Helmer, Christensen, Kensler 2021 (stochastic generation of
(t, s) sequences, which we use to construct pmj02); Cranley and Patterson 1976; Singh and Jarosz
2017 (shearing anisotropic patterns).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from ._names import BASELINES, BUILTIN_SAMPLER_FACTORIES
from ._types import Key, Points
from ._validate import ONE_MINUS_EPSILON, check_int, check_key, check_points

__all__ = [
    "BASELINES",
    "Sampler",
    "get",
    "names",
    "register",
    "random",
    "jittered",
    "cmj",
    "sobol_owen",
    "pmj02",
    "pmj02bn",
    "toroidal_shift",
    "shear",
    "grid_shape",
]


MAX_LOG2_N = 24
"""Nets are exact up to 2^24 points: float32 carries 24 bits of each coordinate."""


# --- the sampler type and the registry -------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class Sampler:
    """A named sampler ``(key, n) -> (n, 2)``.

    ``jittable`` says whether ``fn`` can be traced by ``jax.jit``/``jax.vmap`` over keys (with
    ``n`` static); NumPy constructions (pmj02, pmj02bn) cannot, but are cached.
    ``power_of_two`` says whether the construction's guarantees (nets) need ``n = 2^m``.
    """

    name: str
    fn: Callable[[jax.Array, int], jax.Array]
    jittable: bool = True
    power_of_two: bool = False

    def __call__(self, key: Key, n: int) -> Points:
        key = check_key("key", key)
        n = check_int("n", n, minimum=1, maximum=2**MAX_LOG2_N)
        return self.fn(key, n)


_REGISTRY: dict[str, Callable[..., Sampler]] = {}


def register(name: str, factory: Callable[..., Sampler]) -> None:
    """Make ``get(name, **options)`` return ``factory(**options)``.

    Users add their own samplers this way; the name must not be taken (by a registered sampler
    or a built-in one, :data:`anisosample._names.BUILTIN_SAMPLER_FACTORIES`).
    """
    if not isinstance(name, str) or not name:
        raise ValueError(f"name must be a non-empty string, got {name!r}")
    if name in _REGISTRY or name in BUILTIN_SAMPLER_FACTORIES:
        raise ValueError(f"a sampler named {name!r} is already registered")
    _REGISTRY[name] = factory


def _factory(name: str) -> Callable[..., Sampler] | None:
    """The factory of ``name``: registered, or a built-in one made above this module
    (``aligned``: ``BUILTIN_SAMPLER_FACTORIES``), imported on first use; None if unknown."""
    if name not in _REGISTRY and name in BUILTIN_SAMPLER_FACTORIES:
        import importlib

        module, function = BUILTIN_SAMPLER_FACTORIES[name].split(":")
        _REGISTRY[name] = getattr(importlib.import_module(module), function)
    return _REGISTRY.get(name)


def names() -> list[str]:
    """The registered sampler names (the built-in ones included)."""
    return sorted({*_REGISTRY, *BUILTIN_SAMPLER_FACTORIES})


def get(name: str, **options) -> Sampler:
    """The sampler called ``name`` (see :func:`names`), configured with ``options``.

    ``get("sheared", base="pmj02bn", direction_deg=30.0)`` is the Singh-Jarosz sheared baseline.
    """
    factory = _factory(name) if isinstance(name, str) else None
    if factory is None:
        raise ValueError(f"unknown sampler {name!r}; known samplers: {', '.join(names())}")
    return factory(**options)


def _no_options(sampler: Sampler) -> Callable[..., Sampler]:
    def factory(**options) -> Sampler:
        if options:
            raise TypeError(f"sampler {sampler.name!r} takes no options, got {sorted(options)}")
        return sampler

    return factory


# --- fixed point helpers -----------------------------------------------------------------------


def _u32_to_unit_float32(bits):
    """Truncating uint32 -> float32 in [0, 1 - 2^-24]: keeps every stratum of width >= 2^-24."""
    return (bits >> 8).astype(jnp.float32) * jnp.float32(2.0**-24)


def _np_u32_to_unit_float32(bits: np.ndarray) -> np.ndarray:
    return (bits >> np.uint32(8)).astype(np.float32) * np.float32(2.0**-24)


def grid_shape(n: int) -> tuple[int, int]:
    """The most square factorization ``n = nx * ny`` with ``nx <= ny``.

    Used by ``jittered`` and ``cmj`` so that every one of the n points has a stratum of its own.
    For a square ``n`` this is ``sqrt(n) x sqrt(n)``; for ``n = 2^(2k+1)`` it is
    ``2^k x 2^(k+1)``; for a prime ``n`` it degenerates to ``1 x n`` (stratified along y only).
    """
    n = check_int("n", n, minimum=1)
    nx = math.isqrt(n)
    while n % nx:
        nx -= 1
    return nx, n // nx


# --- random, jittered, CMJ --------------------------------------------------------------------


def _in_stratum(s, u, count: int):
    """``(s + u) / count`` in float32, inside the stratum ``[s/count, (s+1)/count)``.

    ``s`` integer stratum indices, ``u`` uniform in ``[0, 1)``. Forming ``s + u`` first loses the
    low bits of ``u`` and rounds ``s + u`` up to ``s + 1`` for ``u`` near 1 (any ``s >= 1``),
    which put the point in the next stratum; ``s / count + u / count`` keeps full float32
    resolution, and a clamp keeps the result inside the stratum. XLA's float32 division on CPU
    is off by up to one ulp, so for a ``count`` that is not a power of two (where ``s / count``
    is inexact) the clamp bounds step two ulps inwards; then the guarantee holds wherever a
    stratum spans more than four float32 values (``count <= 2^22``). Power-of-two counts are
    exact. The result is at most ``1 - 2^-24``.
    """
    sf = s.astype(jnp.float32)
    lo = sf / count
    hi = jnp.nextafter((sf + 1.0) / count, jnp.float32(0.0))
    if count & (count - 1):  # inexact quotients: two more ulps of margin on each side
        up, down = jnp.float32(1.0), jnp.float32(0.0)
        lo = jnp.where(s > 0, jnp.nextafter(jnp.nextafter(lo, up), up), lo)
        hi = jnp.nextafter(jnp.nextafter(hi, down), down)
    return jnp.minimum(jnp.minimum(jnp.maximum(lo + u / count, lo), hi), ONE_MINUS_EPSILON)


@functools.partial(jax.jit, static_argnums=1)
def _random(key, n):
    return jax.random.uniform(key, (n, 2), dtype=jnp.float32)


@functools.partial(jax.jit, static_argnums=1)
def _jittered(key, n):
    nx, ny = grid_shape(n)
    xi = jax.random.uniform(key, (ny, nx, 2), dtype=jnp.float32)
    i = jnp.broadcast_to(jnp.arange(nx, dtype=jnp.int32)[None, :], (ny, nx))
    j = jnp.broadcast_to(jnp.arange(ny, dtype=jnp.int32)[:, None], (ny, nx))
    x = _in_stratum(i, xi[..., 0], nx)
    y = _in_stratum(j, xi[..., 1], ny)
    return jnp.stack([x.reshape(-1), y.reshape(-1)], axis=-1)


@functools.partial(jax.jit, static_argnums=1)
def _cmj(key, n):
    """Kensler 2013: one point per cell of an m x q grid and per fine x- and y-stratum.

    Correlated shuffle: one permutation of the columns' y-substrata shared by all columns and
    one of the rows' x-substrata shared by all rows. Computed in integers, then truncated.
    """
    m, q = grid_shape(n)  # m columns, q rows, n = m q
    k_px, k_py, k_j, k_order = jax.random.split(key, 4)
    perm_x = jax.random.permutation(k_px, m).astype(jnp.uint32)  # pi_x over columns i
    perm_y = jax.random.permutation(k_py, q).astype(jnp.uint32)  # pi_y over rows j
    i = jnp.tile(jnp.arange(m, dtype=jnp.uint32), q)
    j = jnp.repeat(jnp.arange(q, dtype=jnp.uint32), m)
    fine_x = i * q + perm_y[j]  # x-stratum index in [0, n)
    fine_y = j * m + perm_x[i]  # y-stratum index in [0, n)
    # uniform jitter inside the fine stratum
    jitter = jax.random.uniform(k_j, (n, 2), dtype=jnp.float32)
    x = _in_stratum(fine_x, jitter[:, 0], n)
    y = _in_stratum(fine_y, jitter[:, 1], n)
    pts = jnp.stack([x, y], axis=-1)
    order = jax.random.permutation(k_order, n)  # decorrelate sample order (Kensler Sec. 4)
    return pts[order]


# --- Owen-scrambled Sobol' (Burley 2020) -------------------------------------------------------


def _reverse_bits32(x):
    x = ((x >> 1) & 0x55555555) | ((x & 0x55555555) << 1)
    x = ((x >> 2) & 0x33333333) | ((x & 0x33333333) << 2)
    x = ((x >> 4) & 0x0F0F0F0F) | ((x & 0x0F0F0F0F) << 4)
    x = ((x >> 8) & 0x00FF00FF) | ((x & 0x00FF00FF) << 8)
    return (x >> 16) | (x << 16)


def _laine_karras_improved(x, seed):
    """Laine-Karras style hash: output bit k depends only on input bits <= k (and the seed).

    The improved constants are those of pbrt-v4's FastOwenScrambler (after Vegdahl).
    """
    x = x ^ (x * jnp.uint32(0x3D20ADEA))
    x = x + seed
    x = x * ((seed >> 16) | jnp.uint32(1))
    x = x ^ (x * jnp.uint32(0x05526C56))
    x = x ^ (x * jnp.uint32(0x53A22864))
    return x


def nested_uniform_scramble(x, seed):
    """Owen's nested uniform scramble of 32-bit fixed-point values (Burley 2020, Sec. 3).

    Bit reversal turns the Laine-Karras property (bit k depends on lower bits) into Owen's (bit k
    depends on higher bits, the prefix). ``x`` and ``seed`` are uint32.
    """
    return _reverse_bits32(_laine_karras_improved(_reverse_bits32(x), seed))


def hash_u32(x):
    """A 32-bit avalanche hash (lowbias32 by C. Wellons) to turn key bits into seeds."""
    x = x ^ (x >> 16)
    x = x * jnp.uint32(0x7FEB352D)
    x = x ^ (x >> 15)
    x = x * jnp.uint32(0x846CA68B)
    return x ^ (x >> 16)


def _hash_combine(seed, v):
    return seed ^ (v + (seed << 6) + (seed >> 2))


def _sobol_pascal_columns() -> np.ndarray:
    """Generator matrix columns of Sobol' dimension 1 (Pascal matrix mod 2), MSB first."""
    cols = np.zeros(32, dtype=np.uint32)
    c = np.uint32(0x80000000)
    for j in range(32):
        cols[j] = c
        c = np.uint32(c ^ (c >> np.uint32(1)))
    return cols


_PASCAL = _sobol_pascal_columns()


def sobol_2d_bits(index):
    """Unscrambled Sobol' dimensions 0 and 1 as uint32 fixed point, for uint32 ``index``."""
    x = _reverse_bits32(index)
    y = jnp.zeros_like(index)
    for j in range(32):
        y = y ^ jnp.where((index >> j) & 1, jnp.uint32(_PASCAL[j]), jnp.uint32(0))
    return x, y


@functools.partial(jax.jit, static_argnums=1)
def _sobol_owen(key, n):
    """Shuffled, Owen-scrambled Sobol' (Burley 2020, Sec. 4): every 2^m prefix is a (0,m,2)-net."""
    seed = hash_u32(jax.random.bits(key, (), dtype=jnp.uint32))
    index = nested_uniform_scramble(jnp.arange(n, dtype=jnp.uint32), seed)
    x, y = sobol_2d_bits(index)
    x = nested_uniform_scramble(x, hash_u32(_hash_combine(seed, jnp.uint32(0))))
    y = nested_uniform_scramble(y, hash_u32(_hash_combine(seed, jnp.uint32(1))))
    return jnp.stack([_u32_to_unit_float32(x), _u32_to_unit_float32(y)], axis=-1)


# --- pmj02 and pmj02bn (stochastic generation, Helmer et al. 2021) ----------------------------

# For the sample j = 2^k + i (0 <= i < 2^k), dimension d pairs with the earlier sample
# i ^ _PMJ02_XORS[d][k] and takes the sibling of its stratum at resolution 2^(k+1). These xor
# values generate the pmj02 sequence of Christensen et al. 2018 (Helmer et al. 2021, Sec. 5;
# values as published with their reference code). The tests check the (0, m, 2)-net property
# of every power-of-two prefix, which is what they guarantee.
_PMJ02_XORS = np.array(
    [
        [
            0x0,
            0x0,
            0x2,
            0x6,
            0x6,
            0xE,
            0x36,
            0x4E,
            0x16,
            0x2E,
            0x276,
            0x6CE,
            0x716,
            0xC2E,
            0x3076,
            0x40CE,
            0x116,
            0x22E,
            0x20676,
            0x60ECE,
            0x61716,
            0xE2C2E,
            0x367076,
            0x4EC0CE,
        ],
        [
            0x0,
            0x1,
            0x3,
            0x3,
            0x7,
            0x1B,
            0x27,
            0xB,
            0x17,
            0x13B,
            0x367,
            0x38B,
            0x617,
            0x183B,
            0x2067,
            0x8B,
            0x117,
            0x1033B,
            0x30767,
            0x30B8B,
            0x71617,
            0x1B383B,
            0x276067,
            0xB808B,
        ],
    ],
    dtype=np.int64,
)

PMJ02BN_CANDIDATES = 10
"""Best-candidate count for pmj02bn (as in Christensen et al. 2018)."""


def _pmj02_fixed_point(bits: np.ndarray, log2_n: int, candidates: int) -> np.ndarray:
    """Build 2^log2_n points of pmj02 as uint32 fixed point, level by level.

    ``bits``: uint32 random words of shape (2^log2_n, candidates, 2), the sub-stratum jitter.
    With ``candidates > 1`` the blue-noise variant keeps, for each new point, the candidate
    farthest (toroidal distance) from the points already placed (Mitchell's best candidate, as
    in pmj02bn). Within a level, new points are placed in sub-batches that see all earlier
    batches; the first levels are exactly sequential.
    """
    from scipy.spatial import cKDTree

    n = 1 << log2_n
    pts = np.zeros((n, 2), dtype=np.uint32)
    pts[0] = bits[0, 0]
    for k in range(log2_n):
        count = 1 << k  # new points j = count + i
        shift = np.uint32(32 - (k + 1))
        i = np.arange(count)
        cand = np.empty((count, candidates, 2), dtype=np.uint32)
        for d in range(2):
            partner = pts[i ^ _PMJ02_XORS[d, k], d]
            stratum = (partner >> shift) ^ np.uint32(1)
            fine = bits[count + i, :, d] >> np.uint32(k + 1)
            cand[:, :, d] = (stratum[:, None] << shift) | fine
        if candidates == 1:
            pts[count : 2 * count] = cand[:, 0]
            continue
        batch = max(1, count // 32)
        for start in range(0, count, batch):
            placed = pts[: count + start].astype(np.float64) * 2.0**-32
            tree = cKDTree(placed, boxsize=1.0)
            c = cand[start : start + batch]
            dist, _ = tree.query(c.reshape(-1, 2).astype(np.float64) * 2.0**-32, k=1)
            best = np.argmax(dist.reshape(c.shape[0], candidates), axis=1)
            pts[count + start : count + start + c.shape[0]] = c[np.arange(c.shape[0]), best]
    return pts


_PMJ_CACHE_MAX_LOG2_N = 20
"""Sets up to 2^20 points (8 MB each, 32 of them at most) are cached; larger ones are rebuilt."""


def _pmj02_build(key_data: bytes, key_impl: str, log2_n: int, candidates: int) -> np.ndarray:
    key = jax.random.wrap_key_data(
        jnp.asarray(np.frombuffer(key_data, dtype=np.uint32)), impl=key_impl
    )
    bits = np.asarray(jax.random.bits(key, (1 << log2_n, candidates, 2), dtype=jnp.uint32))
    return _np_u32_to_unit_float32(_pmj02_fixed_point(bits, log2_n, candidates))


_pmj02_cached = functools.lru_cache(maxsize=32)(_pmj02_build)


def _pmj(key, n, candidates):
    if isinstance(key, jax.core.Tracer):
        raise TypeError("key is traced (jit/vmap), but the pmj02 constructions run in NumPy "
                        "(Sampler.jittable is False): call them outside jit and vmap, or shift "
                        "their set (toroidal_shift) inside")
    if not jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key):
        key = jax.random.wrap_key_data(key)
    log2_n = max(0, (n - 1).bit_length())
    impl = str(jax.random.key_impl(key))
    data = np.asarray(jax.random.key_data(key)).tobytes()
    build = _pmj02_cached if log2_n <= _PMJ_CACHE_MAX_LOG2_N else _pmj02_build
    return jnp.asarray(build(data, impl, log2_n, candidates)[:n])


def _pmj02(key, n):
    return _pmj(key, n, 1)


def _pmj02bn(key, n):
    return _pmj(key, n, PMJ02BN_CANDIDATES)


random = Sampler("random", _random)
jittered = Sampler("jittered", _jittered)
cmj = Sampler("cmj", _cmj)
sobol_owen = Sampler("sobol-owen", _sobol_owen, power_of_two=True)
pmj02 = Sampler("pmj02", _pmj02, jittable=False, power_of_two=True)
pmj02bn = Sampler("pmj02bn", _pmj02bn, jittable=False, power_of_two=True)

for _s in (random, jittered, cmj, sobol_owen, pmj02, pmj02bn):
    register(_s.name, _no_options(_s))


# --- toroidal shift and shear -------------------------------------------------------------------


def wrap_unit(x):
    """x mod 1 in float32, clamped below 1 (mod of a tiny negative number rounds to 1.0)."""
    return jnp.minimum(x - jnp.floor(x), ONE_MINUS_EPSILON)


@jax.jit
def _shift(key, points):
    t = jax.random.uniform(key, (2,), dtype=points.dtype)
    return wrap_unit(points + t[None, :])


def toroidal_shift(key: Key, points) -> Points:
    """Cranley-Patterson rotation: ``(x + t) mod 1`` with one uniform ``t`` for the whole set.

    Keeps the power spectrum (``P_{S+t} = P_S``) and makes the pattern homogeneous (W Sec. 2).
    Nets are not nets after a shift.
    """
    key = check_key("key", key)
    points = check_points("points", points)
    return _shift(key, jnp.asarray(points, dtype=jnp.float32))


@jax.jit
def _shear(points, theta_rad):
    x, y = points[:, 0], points[:, 1]
    horizontal = jnp.abs(jnp.cos(theta_rad)) >= jnp.abs(jnp.sin(theta_rad))
    s = -jnp.tan(theta_rad)  # x' = x + s y moves the (k, 0) axis to direction theta
    t = -jnp.cos(theta_rad) / jnp.sin(jnp.where(horizontal, 1.0, theta_rad))  # -cot theta
    xh = wrap_unit(x + jnp.where(horizontal, s, 0.0) * y)
    yv = wrap_unit(y + jnp.where(horizontal, 0.0, t) * x)
    return jnp.stack([jnp.where(horizontal, xh, x), jnp.where(horizontal, y, yv)], axis=-1)


def shear(points, direction_deg: float) -> Points:
    """Singh & Jarosz 2017: re-aim one low-energy axis of a 2-direction pattern at a direction.

    For spectral directions within 45 degrees of the x axis a horizontal shear
    ``x' = (x - tan(theta) y) mod 1`` moves the pattern's 0-degree low-energy axis to theta and
    keeps 90 degrees; otherwise a vertical shear ``y' = (y - cot(theta) x) mod 1`` moves the
    90-degree axis and keeps 0. Fourier shear theorem: ``P'(a, b) = P(a, b + a s)``.
    """
    points = check_points("points", points)
    if isinstance(direction_deg, bool) or not isinstance(direction_deg, int | float | np.number):
        raise TypeError(f"direction_deg must be a number in [0, 180), got {direction_deg!r}")
    if not 0.0 <= float(direction_deg) < 180.0:
        raise ValueError(f"direction_deg must lie in [0, 180), got {direction_deg}")
    theta = jnp.float32(math.radians(float(direction_deg)))
    return _shear(jnp.asarray(points, dtype=jnp.float32), theta)


def _sheared_factory(*, base: str = "pmj02bn", direction_deg: float) -> Sampler:
    if base not in BASELINES:
        raise ValueError(f"base must be one of {list(BASELINES)}, got {base!r}")
    inner = get(base)
    shear(np.zeros((1, 2), np.float32), direction_deg)  # validate direction_deg now, not per call

    def fn(key, n):
        return shear(inner(key, n), direction_deg)

    return Sampler(
        f"sheared-{base}@{direction_deg:g}", fn, jittable=False, power_of_two=inner.power_of_two
    )


register("sheared", _sheared_factory)
