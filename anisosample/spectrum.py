"""Power spectra of point sets (W Eq. 6): the one engine.

``F_S(v) = (1/N) sum_j exp(-2 pi i v . x_j)`` and ``P_S(v) = |F_S(v)|^2`` for integer ``v``, so
``P_S(0) = 1`` and white noise has ``<P_S(v)> = 1/N``. Plots show ``N P_S`` (white noise -> 1).

One engine evaluates ``P_S`` for everything in the package (:func:`power_spectrum`, the losses of
:mod:`anisosample.losses`, the expected spectra and profiles of :mod:`anisosample.metrics`,
:mod:`anisosample.diagnostics`; pictures: :mod:`anisosample.plot`):
:func:`grouped_power_spectrum` on a :class:`~anisosample.frequencies.FrequencySet`, one group
(frequencies near one direction) at a time, by one of three methods (:data:`METHODS`):

``"direct"``  the sum itself, chunked over frequencies (the reference; O(n m)). The phase
              ``v . x`` is reduced modulo 1 before it is scaled by ``2 pi``; in float32 it is
              formed from an exact high part and a small low part of ``x``
              (:func:`_phase_fraction`), so it stays accurate for ``|v| < 2^24``;
``"nufft1"``  type-1 NUFFTs (jax-finufft; adjoint: type 2) on a few small grids per group: the
              group is cut into runs along its direction, each run gets the bounding box of its
              frequencies in a unimodular integer basis ``v = M u`` whose first vector follows
              the direction (``exp(-2 pi i v.x) = exp(-2 pi i u.(M^T x mod 1))`` holds exactly
              for integer ``u``), centred by a phase on the strengths. The grids of a group
              total 1.5-2.6 times its frequency count (n = 2^16 at 0, 90 and 30 degrees) and
              only the ``n`` points are spread: the fast path for long wedges. Bases other than
              the identity need float64 (``M^T x`` multiplies the rounding error by ``|M|``);
``"nufft3"``  a type-3 NUFFT at exactly the requested frequencies, in coordinates rotated to the
              group's direction (``v.x = (R v).(R x)``), so a long thin wedge has a small
              bounding box.

``"auto"`` (the default everywhere) picks per group: the direct sum when ``n m <= 2^21``, else
``nufft1`` when its grids total at most ``8 m`` points (every wedge, disk or grid), else
``nufft3``. The old name ``"nufft"`` is refused with its new one, ``"nufft1"``.

Accuracy policy (one for every caller, :func:`default_eps`): NUFFT tolerance ``1e-6`` in float32
and ``1e-10`` in float64 unless a caller passes ``eps`` (synthesis uses ``1e-7``); every CPU
FINUFFT call runs on :data:`NUFFT_THREADS` threads (deterministic, :func:`finufft_opts`). The
synthesis terms may run their type-1 transforms in float32 instead
(:data:`anisosample.losses.PRECISIONS`, at ``eps >= 1e-6``): the 4-direction tables' choice.

The losses take the same transforms as data (:func:`anisosample.losses.spectrum_terms`): they
plan with :func:`group_plan` and evaluate with the two primitives :func:`box_power` (``P_S`` on
a type-1 box's whole grid, the basis and centre as data) and :func:`power_at` (``P_S`` at given
frequencies by one method).

Every method has a custom VJP with the closed-form gradient (``point_synthesis.md`` Sec. 2)
``dP(v)/dx_j = (4 pi / n) Im(conj(F(v)) exp(-2 pi i v.x_j)) v``, so the backward pass of any
function of ``P`` is one adjoint transform ``sum_v a_v exp(-2 pi i v.x_j)`` with
``a_v = (dL/dP_v) conj(F_v) v`` -- again a NUFFT (or a direct sum), never an ``m x n`` matrix
held in memory. Points that are not finite are refused before they reach XLA or FINUFFT (a
``ValueError`` for concrete arrays, ``equinox.error_if`` under ``jit`` and ``grad``).
"""

from __future__ import annotations

import functools
import math
import os
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._validate import (
    check_choice,
    check_frequencies,
    check_int,
    check_points,
    check_positive_float,
)
from .frequencies import FrequencySet

__all__ = [
    "METHODS",
    "NUFFT_THREADS",
    "default_eps",
    "finufft_opts",
    "memory_bytes",
    "power_spectrum",
    "power_spectrum_autodiff",
    "power_spectrum_grid",
    "grouped_power_spectrum",
    "power_spectrum_rotated",
    "power_at",
    "box_power",
    "as_points",
    "check_method",
    "group_plan",
    "nufft1_plan",
    "box_area",
    "check_box_memory",
    "rotation",
    "Box",
    "frequency_grid",
    "white_noise_level",
]

METHODS = ("auto", "direct", "nufft1", "nufft3")
_RENAMED = {"nufft": "nufft1"}  # old method names, refused with the new one named

_DIRECT_MAX_WORK = 2**21  # n * m up to which "auto" takes the direct sum
_DIRECT_CHUNK_WORK = 2**21  # chunk * n elements per step of the direct sum
_MAX_FREQ = 1 << 24  # float32 holds every integer frequency below this exactly
_MAX_SEGMENTS = 8
# A transform's cost beyond its grid, in grid points per point spread: one term (type 1 and its
# two-strength type-2 VJP) took about 1.8 ms + 0.08 us per grid point at n = 4096 (box shapes
# 113x177 .. 289x209, eps 1e-7, one thread), so a call costs what ~5.5 n grid points cost.
_CALL_COST = 6.0


def white_noise_level(n: int) -> float:
    """``<P_S(v)>`` of ``n`` independent uniform points: ``1 / n``."""
    return 1.0 / check_int("n", n, minimum=1)


def frequency_grid(radius: int) -> np.ndarray:
    """All integer frequencies of the centred ``(2r+1)^2`` grid as ``(m, 2)`` int32, ``(v_x, v_y)``.

    Ordered so that ``.reshape(2r+1, 2r+1, 2)[i, j] == (j - r, i - r)``: rows are ``v_y``.
    """
    r = check_int("radius", radius, minimum=1)
    _check_grid_memory(r)
    k = np.arange(-r, r + 1, dtype=np.int32)
    vx, vy = np.meshgrid(k, k, indexing="xy")
    return np.stack([vx.reshape(-1), vy.reshape(-1)], axis=-1)


def memory_bytes() -> int:
    """Physical memory of this machine in bytes (16 GiB where the OS does not say); size checks
    refuse work that needs more than half of it before allocating."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return 16 << 30


_GRID_BYTES_PER_FREQ = 48  # int32 pair + index + complex128 grid value + output + gather


def _check_grid_memory(radius: int) -> None:
    """Refuse a centred grid whose arrays would not fit in half the memory, before allocating."""
    side = 2 * radius + 1
    need = side * side * _GRID_BYTES_PER_FREQ
    have = memory_bytes()
    if need > have // 2:
        raise ValueError(
            f"radius={radius} asks for a {side} x {side} spectrum grid: about {need / 2**30:.1f}"
            f" GiB, more than half of this machine's {have / 2**30:.1f} GiB of memory; "
            f"use radius <= {int((math.sqrt(have // 2 / _GRID_BYTES_PER_FREQ) - 1) // 2)}"
        )


# --- the accuracy policy and the FINUFFT options --------------------------------------------------


def default_eps(dtype) -> float:
    """The NUFFT tolerance when a caller gives none: ``1e-6`` (float32), ``1e-10`` (float64)."""
    return 1e-10 if dtype == jnp.float64 else 1e-6


NUFFT_THREADS = 1
"""OpenMP threads of every CPU FINUFFT call. FINUFFT's multithreaded spreader (types 1 and 3)
adds the threads' subgrids into the fine grid in whatever order they finish, so with more than
one thread the same call gives different bits from run to run (n = 1024, 300 synthesis steps:
coordinates differ by 3e-5). One thread makes every transform a fixed sequence of operations:
same key, same bits across runs, thread counts and resumes (DESIGN). Interpolation (type 2) is
order-independent but its FFT's plan depends on the thread count, so it runs on one thread too.
On a GPU, cuFINUFFT's options apply (its atomics make it nondeterministic there)."""


def finufft_opts(eps, *, upsampfac=None):
    """The FINUFFT options of every call: :data:`NUFFT_THREADS` threads on the CPU and, for
    type 1/2 grids, ``upsampfac`` where the CPU library supports it (``eps >= 1e-9``)."""
    from jax_finufft.options import Opts

    if jax.default_backend() != "cpu":
        return None
    up = upsampfac if upsampfac is not None and eps >= 1e-9 else 0.0
    return Opts(nthreads=NUFFT_THREADS, upsampfac=up)



# --- the direct sum -------------------------------------------------------------------------------


def _phase_fraction(points, v):
    """``v . x`` modulo 1 (up to an integer), accurate in float32 for large integer ``v``.

    ``x = x_hi + x_lo`` with ``x_hi = k / 1024`` (a truncation, ``k < 1024``) and
    ``0 <= x_lo < 2^-10``. Since ``1024 x_hi`` is an integer, ``v x_hi = (v mod 1024) x_hi`` modulo
    1, a product of two 10-bit numbers that float32 holds exactly, so its fraction is exact for
    every ``|v| < 2^24``; ``v x_lo`` (``|v x_lo| < |v| / 1024``) is rounded once and reduced
    modulo 1 too, so the phase error grows only like ``|v| 2^-34``.
    """
    scale = jnp.asarray(1024.0, points.dtype)
    hi = jnp.floor(points * scale) / scale
    lo = points - hi
    v_mod = v - scale * jnp.floor(v / scale)  # in [0, 1024), exact
    prod_hi = v_mod[:, None, :] * hi[None, :, :]  # (c, n, 2), exact
    prod_lo = v[:, None, :] * lo[None, :, :]
    return jnp.sum((prod_hi - jnp.floor(prod_hi)) + (prod_lo - jnp.floor(prod_lo)), axis=-1)


def _phase(x, vc):
    """``-2 pi (v . x mod 1)`` for a chunk of frequencies ``vc`` ``(c, 2)``: ``(c, n)``."""
    if x.dtype == jnp.float64:
        ph = vc @ x.T
        ph = ph - jnp.round(ph)  # reduce mod 1 before scaling by 2 pi (fourier_variance Sec. 6)
    else:
        ph = _phase_fraction(x, vc)
    return -2.0 * jnp.pi * ph


def _chunks(v, n):
    m = v.shape[0]
    # no chunk larger than the set: padding a 300-frequency group to 2048 was 6.8x the work
    c = int(min(2048, max(8, _DIRECT_CHUNK_WORK // max(n, 1)), max(m, 1)))
    pad = (-m) % c
    return jnp.pad(v, ((0, pad), (0, 0))).reshape(-1, c, 2), pad, c


def _direct_forward(x, v):
    """``n F(v)`` for integer ``v`` (float array), chunked over frequencies."""
    vp, _, _ = _chunks(v, x.shape[0])

    def one(vc):
        ang = _phase(x, vc)
        return jax.lax.complex(jnp.sum(jnp.cos(ang), axis=1), jnp.sum(jnp.sin(ang), axis=1))

    return jax.lax.map(one, vp).reshape(-1)[: v.shape[0]]


def _direct_adjoint(x, v, a):
    """``sum_v a_v exp(-2 pi i v.x_j)`` for ``a``: ``(k, m)`` complex -> ``(k, n)``."""
    vp, pad, c = _chunks(v, x.shape[0])
    ap = jnp.pad(a, ((0, 0), (0, pad))).reshape(a.shape[0], -1, c).transpose(1, 0, 2)

    def body(acc, inp):
        vc, ac = inp
        ang = _phase(x, vc)
        e = jax.lax.complex(jnp.cos(ang), jnp.sin(ang))  # (c, n)
        return acc + ac @ e, None

    acc0 = jnp.zeros((a.shape[0], x.shape[0]), dtype=_cdtype(x.dtype))
    acc, _ = jax.lax.scan(body, acc0, (vp, ap))
    return acc


def _cdtype(dtype):
    return jnp.complex128 if dtype == jnp.float64 else jnp.complex64


def rotation(theta_deg: float, dtype=jnp.float32):
    """The 2x2 rotation taking direction ``theta_deg`` to the x axis (the type-3 coordinates)."""
    th = math.radians(theta_deg)
    return jnp.asarray([[math.cos(th), math.sin(th)], [-math.sin(th), math.cos(th)]], dtype)


# --- type-3 NUFFT in rotated coordinates ----------------------------------------------------------


def _nufft3_forward(x, v, r, eps):
    from jax_finufft import nufft3

    xr = (x - 0.5) @ r.T * (2.0 * jnp.pi)  # centring only changes the phase of F, not P
    vr = v @ r.T
    c = jnp.ones(x.shape[0], dtype=_cdtype(x.dtype))
    return nufft3(c, xr[:, 0], xr[:, 1], vr[:, 0], vr[:, 1], iflag=-1, eps=eps,
                  opts=finufft_opts(eps))


def _nufft3_adjoint(x, v, a, r, eps):
    from jax_finufft import nufft3

    xr = (x - 0.5) @ r.T
    vr = v @ r.T * (2.0 * jnp.pi)
    return nufft3(a, vr[:, 0], vr[:, 1], xr[:, 0], xr[:, 1], iflag=-1, eps=eps,
                  opts=finufft_opts(eps))


# --- type-1 NUFFT on lattice-aligned grids --------------------------------------------------------


class Box(NamedTuple):
    """One type-1 grid: integer frequencies ``v = M u`` with ``u - c`` in ``[-r, r]^2``.

    ``M`` (row-major ``m``) is unimodular (integer, ``|det| = 1``), so ``x' = M^T x mod 1`` is
    again a point set on the torus and ``exp(-2 pi i v.x) = exp(-2 pi i u.x')``: a wedge along a
    direction close to the lattice vector ``a = M e_1`` becomes a thin axis-aligned strip in
    ``u``. The centre ``c`` is a phase modulation of the strengths, so a half-plane wedge does
    not pay for the empty half of a box centred on 0.
    """

    m: tuple[int, int, int, int]
    c: tuple[int, int]
    r: tuple[int, int]


def _unimodular_bases(theta_deg: float, lattice: bool) -> list[np.ndarray]:
    """Candidate ``M`` (columns ``a, b``): the identity and, if ``lattice``, one basis per
    continued-fraction convergent ``p/q`` of the direction's slope, ``a = (q, p)`` (or
    ``(p, q)`` past 45 degrees), ``b`` the previous convergent made as orthogonal to ``a`` as
    integer shifts ``b + j a`` allow (convergents give ``|det(a, b)| = 1``)."""
    out = [np.eye(2, dtype=np.int64)]
    if not lattice:
        return out
    th = math.radians(theta_deg)
    d = (math.cos(th), math.sin(th))
    swap = abs(d[1]) > abs(d[0])
    slope = d[0] / d[1] if swap else d[1] / d[0]
    (p0, q0), (p1, q1) = (1, 0), (math.floor(slope), 1)
    frac = slope - math.floor(slope)
    while q1 <= 256:
        a, b = np.array([q1, p1]), np.array([q0, p0])
        if swap:
            a, b = a[::-1], b[::-1]
        b = b - round(float(b @ a) / float(a @ a)) * a
        m = np.stack([a, b], axis=1)
        if abs(round(np.linalg.det(m))) == 1:
            out.append(m)
        if frac < 1e-12:
            break
        frac = 1.0 / frac
        k = math.floor(frac)
        frac -= k
        (p0, q0), (p1, q1) = (p1, q1), (k * p1 + p0, k * q1 + q0)
    return out


def nufft1_plan(fg: np.ndarray, theta_deg: float, n: int, lattice: bool):
    """Split a group into at most 8 runs along its direction, each with its own :class:`Box`
    under one unimodular basis, minimising the total grid size plus ``6 n`` per transform (a
    call's measured cost, :data:`_CALL_COST`).
    Returns ``(order, [(start, stop, box), ...])``: segment ``k`` holds ``fg[order[start:stop]]``.
    The boxes of the rate design's groups total 1.5-2.6 times their frequency count at
    n = 2^16 (0, 90, 30 degrees; one centred box around the 30-degree group in the standard
    basis would be about 26 times)."""
    th = math.radians(theta_deg)
    order = np.argsort(fg @ np.array([math.cos(th), math.sin(th)]), kind="stable")
    v = fg[order].astype(np.int64)
    m = len(v)
    best = None
    for mat in _unimodular_bases(theta_deg, lattice):
        inv = np.round(np.linalg.inv(mat)).astype(np.int64)
        u = v @ inv.T
        for k in range(1, min(_MAX_SEGMENTS, m) + 1):
            cuts = np.linspace(0, m, k + 1).round().astype(np.int64)
            lo = np.minimum.reduceat(u, cuts[:-1], axis=0)
            hi = np.maximum.reduceat(u, cuts[:-1], axis=0)
            c = (lo + hi) // 2
            r = np.maximum(hi - c, c - lo)
            cost = float(np.sum(np.prod(2 * r + 1, axis=1))) + _CALL_COST * n * k
            if best is None or cost < best[0]:
                best = (cost, mat, cuts, c, r)
    _, mat, cuts, c, r = best
    segs = [(int(cuts[i]), int(cuts[i + 1]),
             Box(tuple(int(e) for e in mat.reshape(-1)), (int(c[i, 0]), int(c[i, 1])),
                 (int(r[i, 0]), int(r[i, 1]))))
            for i in range(len(cuts) - 1)]
    return order, segs


def box_area(segs) -> int:
    """Total grid points of a :func:`nufft1_plan`'s boxes."""
    return sum((2 * b.r[0] + 1) * (2 * b.r[1] + 1) for _, _, b in segs)


def check_box_memory(segs, m: int) -> None:
    """Refuse a :func:`nufft1_plan` for ``m`` frequencies whose grids would take more than half
    the memory, before allocating."""
    if box_area(segs) * _GRID_BYTES_PER_FREQ > memory_bytes() // 2:
        raise ValueError(f"method='nufft1' needs type-1 grids of {box_area(segs)} points for "
                         f"{m} frequencies here, more than half the memory; use "
                         "method='auto' or 'nufft3'")


def _grid_setup(x, basis, centre, half, eps, single=False):
    """The box's points ``2 pi (M^T x mod 1 - 1/2)``, the centre's phase per point, the grid
    shape and the FINUFFT options; ``single``: the points and phases formed in ``x``'s
    precision, then rounded to float32 / complex64 for the transforms."""
    xp = x @ basis.astype(x.dtype)  # x'_j = M^T x_j
    xp = xp - jnp.floor(xp)
    ph = xp @ centre.astype(x.dtype)
    ph = -2.0 * jnp.pi * (ph - jnp.round(ph))
    shift = jax.lax.complex(jnp.cos(ph), jnp.sin(ph))
    shape = (2 * half[0] + 1, 2 * half[1] + 1)
    xs = (xp - 0.5) * (2.0 * jnp.pi)
    # sigma = 1.25 shrinks the fine grid 2.6x; type 1/2 only spread the n points, so the wider
    # kernel it needs costs little. CPU FINUFFT supports it down to eps ~ 1e-9; on a GPU the
    # library's own choice stands.
    if single:
        xs, shift = xs.astype(jnp.float32), shift.astype(jnp.complex64)
    return xs, shift, shape, finufft_opts(eps, upsampfac=1.25)


def _nufft1_setup(x, v, box: Box, eps):
    """Points on the box's lattice, the centre's phase per point, grid indices, NUFFT options
    (:func:`_grid_setup` with the box's basis and centre as constants)."""
    m = np.asarray(box.m, np.float64).reshape(2, 2)
    xs, shift, shape, opts = _grid_setup(x, jnp.asarray(m, x.dtype), jnp.asarray(box.c, x.dtype),
                                         box.r, eps)
    inv = np.round(np.linalg.inv(m))
    u = jnp.round(v @ jnp.asarray(inv.T, v.dtype)).astype(jnp.int32)
    idx = (u[:, 0] - box.c[0] + box.r[0], u[:, 1] - box.c[1] + box.r[1])
    return xs, shift, idx, shape, opts


def _nufft1_forward(x, v, box: Box, eps):
    """``n F(v)`` by a type-1 NUFFT onto the box's grid, then a gather."""
    from jax_finufft import nufft1

    xs, shift, idx, shape, opts = _nufft1_setup(x, v, box, eps)
    grid = nufft1(shape, shift, xs[:, 0], xs[:, 1], iflag=-1, eps=eps, opts=opts)
    return grid[idx]


def _nufft1_adjoint(x, v, a, box: Box, eps):
    """``sum_v a_v exp(-2 pi i v.x_j)`` by a scatter onto the box's grid and a type-2 NUFFT."""
    from jax_finufft import nufft2

    xs, shift, idx, shape, opts = _nufft1_setup(x, v, box, eps)
    grid = jnp.zeros((a.shape[0], *shape), a.dtype).at[:, idx[0], idx[1]].add(a)
    return nufft2(grid, xs[:, 0], xs[:, 1], iflag=-1, eps=eps, opts=opts) * shift[None, :]


# --- P_S with the closed-form VJP -----------------------------------------------------------------


@functools.partial(jax.custom_vjp, nondiff_argnums=(3, 4))
def _power(x, v, r, how, eps):
    """``P_S`` at frequencies ``v`` (float, integer-valued) by ``how``: ``"direct"``,
    ``"nufft3"`` (rotation ``r``) or a :class:`Box` (type 1)."""
    return _power_fwd(x, v, r, how, eps)[0]


def _power_fwd(x, v, r, how, eps):
    n = x.shape[0]
    if how == "direct":
        fn = _direct_forward(x, v)
    elif isinstance(how, Box):
        fn = _nufft1_forward(x, v, how, eps)
    else:
        fn = _nufft3_forward(x, v, r, eps)
    f = fn / n
    p = jnp.real(f) ** 2 + jnp.imag(f) ** 2
    return p, (x, v, r, f)


def _power_bwd(how, eps, res, g):
    x, v, r, f = res
    n = x.shape[0]
    a = (g.astype(f.dtype) * jnp.conj(f))[None, :] * v.T.astype(f.dtype)  # (2, m)
    if how == "direct":
        s = _direct_adjoint(x, v, a)
    elif isinstance(how, Box):  # the grid's phase convention cancels as for type 3
        s = _nufft1_adjoint(x, v, a, how, eps)
    else:
        s = _nufft3_adjoint(x, v, a, r, eps)  # centring cancels in conj(F) e_j
    grad = (4.0 * jnp.pi / n) * jnp.imag(s).T.astype(x.dtype)
    return grad, jnp.zeros_like(v), jnp.zeros_like(r)


_power.defvjp(_power_fwd, _power_bwd)
# One compiled program per shape and plan: called outside jit (power_spectrum on concrete
# points, its gradient), the custom VJP's forward and backward otherwise ran op by op, each
# operation a small program compiled on first use. Inside jit it is inlined.
_power = jax.jit(_power, static_argnums=(3, 4))


def check_method(method) -> str:
    """One of :data:`METHODS`, or a ``ValueError`` (an old name, ``"nufft"``, names its new one,
    ``"nufft1"``)."""
    if isinstance(method, str) and method in _RENAMED:
        raise ValueError(f"method={method!r} is now called {_RENAMED[method]!r}; the methods are "
                         f"{', '.join(map(repr, METHODS))}")
    return check_choice("method", method, METHODS)


def group_plan(method: str, n: int, fg: np.ndarray, theta_deg: float, dtype):
    """``(how, order, segments)`` for one group of frequencies ``fg`` along ``theta_deg``.

    ``auto``: the direct sum for ``n m <= 2^21``, else type-1 grids (:func:`nufft1_plan`) when
    their boxes total at most ``8 m`` (wedges, disks and grids along any direction: about
    ``2 m``), else the rotated type-3 NUFFT. Unimodular bases other than the identity are only
    used in float64."""
    method = check_method(method)
    m = fg.shape[0]
    if method == "auto" and n * m <= _DIRECT_MAX_WORK:
        return "direct", None, None
    if method in ("auto", "nufft1"):
        order, segs = nufft1_plan(fg, theta_deg, n, lattice=dtype == jnp.float64)
        if method == "nufft1" or box_area(segs) <= 8 * m:
            return "nufft1", order, segs
        return "nufft3", None, None
    return method, None, None


def _finite(points):
    """Refuse non-finite points before XLA or FINUFFT sees them (FINUFFT's spreader indexes its
    grid with them: a NaN crashes the process)."""
    if isinstance(points, jax.core.Tracer):
        return eqx.error_if(points, ~jnp.all(jnp.isfinite(points)),
                            "points contain NaN or Inf (P_S needs finite points in [0, 1)^2)")
    if not bool(np.all(np.isfinite(np.asarray(points)))):
        raise ValueError("points contain NaN or Inf (P_S needs finite points in [0, 1)^2)")
    return points


def _group_power(points, fg: np.ndarray, theta_deg: float, method: str, eps: float):
    """``P_S`` of one group in its own order, by :func:`group_plan`'s choice."""
    n = points.shape[0]
    how, order, segs = group_plan(method, n, fg, theta_deg, points.dtype)
    rot = rotation(theta_deg, points.dtype)
    if how != "nufft1":
        return _power(points, jnp.asarray(fg, points.dtype), rot, how, eps)
    check_box_memory(segs, fg.shape[0])
    vs = fg[order]
    p = jnp.concatenate([_power(points, jnp.asarray(vs[a:b], points.dtype), rot, box, eps)
                         for a, b, box in segs])
    # The barrier keeps XLA from constant-folding this gather's transpose when the loss is
    # linear in P (a constant cotangent scattered by constant indices: seconds at 2^16).
    return p[jax.lax.optimization_barrier(jnp.asarray(np.argsort(order), jnp.int32))]


def as_points(points):
    """``points`` (checked: ``(n, 2)`` floats in ``[0, 1)^2``) as the engine takes them: a JAX
    array of float32 or float64, refused if not finite (a ``ValueError``, ``equinox.error_if``
    under ``jit``)."""
    check_points("points", points)
    pts = jnp.asarray(points)
    if pts.dtype not in (jnp.float32, jnp.float64):
        pts = pts.astype(jnp.float32)
    return _finite(pts)


def power_at(points, freqs, rot, how, eps) -> jax.Array:
    """``P_S`` at frequencies ``freqs`` (a float array of integer values) by ``how``:
    ``"direct"``, ``"nufft3"`` (in the coordinates of the rotation ``rot``, :func:`rotation`) or
    a :class:`Box` (type 1), with the closed-form VJP; traceable (``points`` a float array,
    refused if not finite). The primitive behind :func:`power_spectrum` and the losses' list
    terms."""
    return _power(_finite(points), freqs, rot, how, eps)


def box_power(points, basis, centre, half, eps, single=False) -> jax.Array:
    """``P_S(M u)`` on a type-1 box's whole grid ``u - centre in [-half, half]^2`` (``M`` =
    ``basis``, a unimodular integer matrix as a float array; ``half`` static), by one type-1
    NUFFT with a one-type-2 VJP; ``single``: the transforms in float32. Traceable; ``points``
    refused if not finite. The primitive of the losses' grid terms, where ``basis`` and
    ``centre`` are data."""
    return _grid_power(_finite(points), basis, centre, half, eps, single)


def grouped_power_spectrum(points, fset: FrequencySet, *, method: str = "auto", eps=None):
    """``P_S`` on every frequency of ``fset`` (its order), differentiable w.r.t. ``points``.

    Each group (the frequencies nearest one direction) is evaluated by ``method`` (see the
    module docstring; ``"auto"`` chooses per group, :func:`group_plan`). ``eps``: the NUFFT
    tolerance (default :func:`default_eps`).
    """
    pts = as_points(points)
    if not isinstance(fset, FrequencySet):
        raise TypeError(f"fset must be a frequencies.FrequencySet, got {type(fset).__name__}")
    method = check_method(method)
    eps = default_eps(pts.dtype) if eps is None else check_positive_float("eps", eps)
    return jnp.concatenate([_group_power(pts, fg, theta, method, eps)
                            for theta, fg, _ in fset.groups()])


# --- P_S on a type-1 box's whole grid (the losses' terms) ------------------------------------


@functools.partial(jax.custom_vjp, nondiff_argnums=(3, 4, 5))
def _grid_power(x, basis, centre, half, eps, single=False):
    """``P_S(M u)`` on a box's whole grid (type 1; VJP: one type-2 of two strengths), in
    ``x``'s precision (``single``: the transforms in float32)."""
    return _grid_power_fwd(x, basis, centre, half, eps, single)[0]


def _grid_power_fwd(x, basis, centre, half, eps, single=False):
    from jax_finufft import nufft1

    xs, shift, shape, opts = _grid_setup(x, basis, centre, half, eps, single)
    f = nufft1(shape, shift, xs[:, 0], xs[:, 1], iflag=-1, eps=eps, opts=opts)
    f = f.astype(_cdtype(x.dtype)) / x.shape[0]
    return jnp.real(f) ** 2 + jnp.imag(f) ** 2, (x, basis, centre, f)


def _grid_power_bwd(half, eps, single, res, g):
    from jax_finufft import nufft2

    x, basis, centre, f = res
    n = x.shape[0]
    b = basis.astype(f.real.dtype)
    u1 = centre[0].astype(b.dtype) + jnp.arange(-half[0], half[0] + 1, dtype=b.dtype)
    u2 = centre[1].astype(b.dtype) + jnp.arange(-half[1], half[1] + 1, dtype=b.dtype)
    vx = b[0, 0] * u1[:, None] + b[0, 1] * u2[None, :]  # v = M u on the grid
    vy = b[1, 0] * u1[:, None] + b[1, 1] * u2[None, :]
    a = g.astype(f.dtype) * jnp.conj(f)
    xs, shift, _, opts = _grid_setup(x, basis, centre, half, eps, single)
    strengths = jnp.stack([a * vx.astype(a.dtype), a * vy.astype(a.dtype)])
    s = nufft2(strengths.astype(shift.dtype), xs[:, 0], xs[:, 1], iflag=-1, eps=eps, opts=opts)
    grad = (4.0 * jnp.pi / n) * jnp.imag(s * shift[None, :]).T.astype(x.dtype)
    return grad, jnp.zeros_like(basis), jnp.zeros_like(centre)


_grid_power.defvjp(_grid_power_fwd, _grid_power_bwd)


def _principal_angle(freqs: np.ndarray) -> float:
    """Direction (degrees, axial) of the frequencies' principal axis through 0."""
    f = freqs.astype(np.float64)
    _, vecs = np.linalg.eigh(f.T @ f)
    a = vecs[:, -1]
    return math.degrees(math.atan2(a[1], a[0])) % 180.0


def power_spectrum_autodiff(points, freqs) -> jax.Array:
    """``P_S(v) = |(1/n) sum_j exp(-2 pi i v . x_j)|^2`` (W Eq. 4) by the direct sum with plain
    autodiff (no custom VJP): differentiable to any order, in the points and in the (float)
    frequencies, under ``jit``, ``vmap`` and ``lax.scan`` -- what
    :func:`anisosample.optimizer.minimize` differentiates through. ``O(n m)`` memory; for large
    sets use :func:`power_spectrum`. Traced inputs are not checked."""
    if not isinstance(points, jax.core.Tracer):
        check_points("points", points)
    x = jnp.asarray(points)
    v = jnp.asarray(freqs, x.dtype)
    ph = (2.0 * jnp.pi) * (x @ v.T)
    c, s = jnp.mean(jnp.cos(ph), 0), jnp.mean(jnp.sin(ph), 0)
    return c * c + s * s


def power_spectrum(points, freqs, *, method: str = "auto", eps=None):
    """``P_S(v)`` of a point set at integer frequencies (W Eq. 6): ``(m,)`` values.

    Args:
        points: ``(n, 2)`` in ``[0, 1)^2`` (float32, or float64 under ``jax.enable_x64``).
        freqs: ``(m, 2)`` integer frequency vectors ``(v_x, v_y)`` with ``|v_x|, |v_y| < 2^24``.
        method: ``"auto"``, ``"direct"``, ``"nufft1"`` (type 1 on lattice-aligned grids) or
            ``"nufft3"`` (type 3 in rotated coordinates), the frequencies taken as one group
            along their principal axis. All agree to ~1e-6 (float32) or ~1e-10
            (float64) relative to ``P_S(0) = 1``, and all are differentiable in ``points``.
        eps: NUFFT tolerance (default :func:`default_eps`).
    """
    method = check_method(method)
    pts = as_points(points)
    freqs = check_frequencies("freqs", freqs)
    eps = default_eps(pts.dtype) if eps is None else check_positive_float("eps", eps)
    if isinstance(freqs, jax.core.Tracer):  # no plan for traced frequencies: the direct sum
        if method not in ("auto", "direct"):
            raise ValueError(f"method={method!r} needs concrete freqs; traced freqs take "
                             "method='direct'")
        v = jnp.asarray(freqs).astype(pts.dtype)
        return _power(pts, v, rotation(0.0, pts.dtype), "direct", eps)
    f = np.asarray(freqs, np.int64)
    if np.abs(f).max() >= _MAX_FREQ:
        raise ValueError(f"freqs must satisfy |v_x|, |v_y| < 2^24, got up to {np.abs(f).max()}")
    return _group_power(pts, f, _principal_angle(f), method, eps)


def power_spectrum_rotated(points, freqs, direction_deg=0.0, *, method="nufft3", eps=None):
    """``P_S(v)`` for ``freqs`` ``(m, 2)`` as one group along ``direction_deg`` (the type-3 NUFFT
    rotated to that direction, or any other method); differentiable w.r.t. ``points``."""
    pts = as_points(points)
    f = np.asarray(check_frequencies("freqs", freqs), np.int64)
    eps = default_eps(pts.dtype) if eps is None else check_positive_float("eps", eps)
    return _group_power(pts, f, float(direction_deg), check_method(method), eps)


def power_spectrum_grid(points, radius: int, *, method: str = "auto"):
    """``P_S`` on the centred grid of half-width ``radius``: ``grid[i, j] = P_S(j - r, i - r)``.

    Rows are ``v_y`` and columns ``v_x``, as in DESIGN's grids (``imshow(origin="lower")``).
    Past ``n (2r+1)^2 = 2^21`` (``"auto"``) one type-1 grid holds the whole spectrum.
    """
    r = check_int("radius", radius, minimum=1)
    method = check_method(method)
    pts = as_points(points)
    _check_grid_memory(r)
    side = 2 * r + 1
    if method == "nufft1" or (method == "auto" and pts.shape[0] * side * side > _DIRECT_MAX_WORK):
        # the grid is one identity box: no plan search, no gather permutation
        box = Box((1, 0, 0, 1), (0, 0), (r, r))
        v = jnp.asarray(frequency_grid(r), pts.dtype)
        vals = _power(pts, v, rotation(0.0, pts.dtype), box, default_eps(pts.dtype))
    else:
        vals = power_spectrum(pts, frequency_grid(r), method=method)
    return vals.reshape(side, side)
