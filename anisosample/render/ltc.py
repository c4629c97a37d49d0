"""GGX linearly transformed cosines (Heitz et al. 2016), fitted by the library, for light sampling.

Heitz, Dupuy, Hill & Neubelt 2016 approximate the GGX lobe ``f(w) = rho(w_i, w) cos(theta)``
(Fresnel 1) seen from ``w_i`` by a linearly transformed cosine ``D`` (``warps.ltc``) with
``M = [[a, 0, b], [0, c, 0], [d, 0, 1]]`` in the frame whose x axis is ``w_i``'s projection on
the surface (their Sec. 4: isotropic lobes need four parameters), tabulated over the roughness
``alpha`` and the view angle. The table here is fitted by :func:`fit_ggx_table`, not copied
(and shipped as the library's own fit, :data:`SHIPPED`, so that a process does not spend the
fit's ~10 s on its first GGX render; :func:`write_ggx_table` remakes it):

* per cell, the parameters ``(log a, b, log c, d)`` minimise the variance of ``f / D`` under
  sampling from ``D``, ``int f^2 / D`` (with ``f`` normalised by its albedo), estimated on a fixed
  set of directions (a ``probes x probes`` grid through the GGX visible-normal sampler and as
  many cosine-distributed ones, weighted by their mixture density), by optimistix'
  Levenberg-Marquardt on the residuals ``f / sqrt(K q D)``; Heitz et al. minimise an L3 error
  with Nelder-Mead instead;
* cells are solved from rough to smooth (``alpha = 1`` down to :data:`ALPHA_MIN`), each started
  at the previous one's solution (as Heitz et al. do), in one ``lax.scan`` per view angle; a
  step that does not lower the objective is not taken.

The renderer (``light_warp="ltc"``) samples ``D`` restricted to the light's polygon exactly
(``warps.LTCPolygon``: Peters 2021's projected-solid-angle sampling of ``M^-1 P``), so the light
sample follows the BSDF-times-cosine lobe *and* the light's extent; the BSDF sample covers what
``D`` misses, under MIS. Materials other than GGX conductors use ``M = I``: the clamped cosine
(the projected-solid-angle technique).
"""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float

from .._validate import check_int
from ..metrics import midpoint_grid
from .bsdf import ggx_d, ggx_g1, sample_ggx_vndf
from .scene import CONDUCTOR

ALPHA_MIN = 0.05
"""The smoothest roughness of the table; smoother lobes use its row (still unbiased)."""
THETA_MAX_DEG = 85.0
"""The most grazing view angle of the table; beyond it the last column is used."""


class LTCTable(eqx.Module):
    """Fitted GGX LTC parameters ``params[i, j] = (log a, b, log c, d)`` at view angle
    ``theta[i]`` (radians, uniform in ``[0, THETA_MAX_DEG]``) and roughness ``alpha[j]``
    (uniform from 1 down to :data:`ALPHA_MIN`); ``albedo`` the lobe's integral; ``objective``
    the fitted ``int f^2 / D`` (1 is a perfect fit) and ``vndf`` the same for visible-normal
    sampling, on the same probe directions."""

    theta: Float[Array, " nt"]
    alpha: Float[Array, " na"]
    params: Float[Array, "nt na 4"]
    albedo: Float[Array, "nt na"]
    objective: Float[Array, "nt na"]
    vndf: Float[Array, "nt na"]


def ggx_lobe(wi, wo, alpha):
    """The lobe the LTC tables fit: GGX ``rho cos`` with Fresnel 1 for unit ``wi`` and ``wo``
    in the local frame (``z`` the normal), and the density of sampling ``wo`` by visible
    normals (Heitz 2014); both 0 unless ``wi`` and ``wo`` are above the surface.
    Returns ``(f, pdf)``."""
    h = wi + wo
    h = h / jnp.maximum(jnp.sqrt(jnp.sum(h * h)), 1e-30)
    d = ggx_d(h, alpha)
    ok = (wi[2] > 0) & (wo[2] > 0)
    f = d * ggx_g1(wi, h, alpha) * ggx_g1(wo, h, alpha) / (4 * jnp.maximum(wi[2], 1e-20))
    vis = ggx_g1(wi, h, alpha) * jnp.maximum(jnp.dot(wi, h), 0.0) * d / jnp.maximum(wi[2], 1e-20)
    q = vis / (4 * jnp.maximum(jnp.dot(wo, h), 1e-20))
    return jnp.where(ok, f, 0.0), jnp.where(ok, q, 0.0)


def matrix(p):
    """``M`` of the parameters ``(log a, b, log c, d)`` and its inverse (closed form)."""
    a, b, c, d = jnp.exp(p[..., 0]), p[..., 1], jnp.exp(p[..., 2]), p[..., 3]
    z, one = jnp.zeros_like(a), jnp.ones_like(a)
    m = jnp.stack([jnp.stack([a, z, b], -1), jnp.stack([z, c, z], -1),
                   jnp.stack([d, z, one], -1)], -2)
    det = a - b * d  # of the xz block [[a, b], [d, 1]]
    det = jnp.where(jnp.abs(det) > 1e-12, det, 1e-12)
    m_inv = jnp.stack([jnp.stack([one / det, z, -b / det], -1), jnp.stack([z, one / c, z], -1),
                       jnp.stack([-d / det, z, a / det], -1)], -2)
    return m, m_inv


def ltc_density(m_inv, w):
    """Heitz et al. 2016 Eq. 2: ``D_o(w_o) |det M^-1| / |M^-1 w|^3`` for a unit ``w``."""
    q = m_inv @ w
    n = jnp.sqrt(jnp.sum(q * q))
    return jnp.maximum(q[2] / n, 0.0) / jnp.pi * jnp.abs(jnp.linalg.det(m_inv)) / n**3


def _probe_directions(wi, alpha, u):
    m = jax.vmap(lambda x: sample_ggx_vndf(wi, alpha, x))(u)
    w1 = 2 * jnp.sum(m * wi[None, :], -1)[:, None] * m - wi[None, :]
    r, ph = jnp.sqrt(u[:, 0]), 2 * jnp.pi * u[:, 1]
    w2 = jnp.stack([r * jnp.cos(ph), r * jnp.sin(ph), jnp.sqrt(jnp.maximum(1 - u[:, 0], 0))], -1)
    w = jnp.concatenate([w1, w2])
    f, q_vndf = jax.vmap(lambda x: ggx_lobe(wi, x, alpha))(w)
    q = 0.5 * q_vndf + 0.5 * jnp.maximum(w[:, 2], 0.0) / jnp.pi
    return w, f, q, q_vndf


def _fit_cell(theta, alpha, p0, u, max_steps):
    wi = jnp.stack([jnp.sin(theta), 0.0, jnp.cos(theta)])
    w, f, q, q_vndf = _probe_directions(wi, alpha, u)
    k = w.shape[0]
    good = q > 0
    qs = jnp.where(good, q, 1.0)
    albedo = jnp.mean(jnp.where(good, f / qs, 0.0))
    fn = f / albedo
    weight = jnp.where(good, 1.0 / jnp.sqrt(k * qs), 0.0)

    def residuals(p, _):
        _, m_inv = matrix(p)
        dens = jax.vmap(lambda x: ltc_density(m_inv, x))(w)
        return fn * weight / jnp.sqrt(dens + 1e-10)  # sum of squares: int f^2 / D

    sol = optx.least_squares(residuals, optx.LevenbergMarquardt(rtol=1e-5, atol=1e-7), p0,
                             max_steps=max_steps, throw=False)
    obj = lambda p: jnp.sum(residuals(p, None) ** 2)  # noqa: E731
    p = jnp.where(obj(sol.value) <= obj(p0), sol.value, p0)
    vndf = jnp.mean(jnp.where(good & (q_vndf > 0), fn**2 / jnp.where(q_vndf > 0, q_vndf, 1.0)
                              / qs, 0.0))
    return p, albedo, obj(p), vndf


def fit_ggx_table(n_theta: int = 16, n_alpha: int = 16, *, probes: int = 32,
                  max_steps: int = 200, rows=None) -> LTCTable:
    """Fit the GGX LTC table (see the module docstring); about 10 s for 16 x 16 on two cores,
    compilation included. ``rows`` (indices into the ``n_theta`` view angles, default all)
    fits only those view angles: each is fitted on its own, so they are the whole table's rows
    up to float rounding (the test of the shipped table refits a few)."""
    n_theta = check_int("n_theta", n_theta, minimum=2)
    n_alpha = check_int("n_alpha", n_alpha, minimum=2)
    probes = check_int("probes", probes, minimum=2)
    max_steps = check_int("max_steps", max_steps, minimum=1)
    theta = np.radians(np.linspace(0.0, THETA_MAX_DEG, n_theta))
    if rows is not None:
        rows = np.asarray(rows)
        if rows.ndim != 1 or rows.size == 0 or not np.issubdtype(rows.dtype, np.integer):
            raise TypeError(f"rows must be a non-empty 1-D sequence of integers, got {rows!r}")
        if rows.min() < 0 or rows.max() >= n_theta:
            raise ValueError(f"rows must lie in [0, {n_theta - 1}] (n_theta={n_theta}), got "
                             f"{rows.tolist()}")
        theta = theta[rows]
    theta = jnp.asarray(theta, jnp.float32)
    alpha = jnp.asarray(np.linspace(1.0, ALPHA_MIN, int(n_alpha)), jnp.float32)
    u = jnp.asarray(midpoint_grid(int(probes), indexing="ij").reshape(-1, 2))

    @jax.jit
    def column(th):
        def step(p, a):
            out = _fit_cell(th, a, p, u, max_steps)
            return out[0], out

        return jax.lax.scan(step, jnp.zeros(4, jnp.float32), alpha)[1]

    params, albedo, objective, vndf = jax.vmap(column)(theta)
    return LTCTable(theta=theta, alpha=alpha, params=params, albedo=albedo,
                    objective=objective, vndf=vndf)


SHIPPED = Path(__file__).parents[1] / "data" / "ltc" / "ggx.npz"
"""The renderer's table, :func:`fit_ggx_table` with its defaults, written by
:func:`write_ggx_table` (a test refits rows of it)."""


_LEAVES = tuple(f.name for f in dataclasses.fields(LTCTable))  # what the .npz holds


def write_ggx_table(path=SHIPPED) -> Path:
    """Fit the table with :func:`fit_ggx_table`'s defaults and save its leaves to ``path``
    (``.npz``; refuses to overwrite an existing file other than the shipped one)."""
    path = Path(path)
    if path.exists() and path.resolve() != SHIPPED.resolve():
        raise FileExistsError(f"path {path} exists; remove it first")
    table = _fit_default()
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, **{k: np.asarray(getattr(table, k)) for k in _LEAVES})
    return path


def _fit_default() -> LTCTable:
    # Eager even inside a trace. (Its bits differ from a plain eager call's at float32
    # rounding; the renderer has always used this one.)
    with jax.ensure_compile_time_eval():
        return fit_ggx_table()


@functools.cache
def _ggx_table_numpy() -> LTCTable:
    # Cached as NumPy leaves: a jax array made inside the trace that first asks for the table
    # would be that trace's tracer, leaked into every later trace.
    with jax.ensure_compile_time_eval():
        if SHIPPED.exists():
            with np.load(SHIPPED) as shipped:
                table = LTCTable(**{k: jnp.asarray(shipped[k], jnp.float32) for k in _LEAVES})
        else:
            table = _fit_default()
    return jax.tree.map(lambda x: np.asarray(x), table)


def ggx_table() -> LTCTable:
    """The renderer's table (16 x 16): read from :data:`SHIPPED` (the library's own fit; the
    fit takes about 10 s per process), else fitted on first use, eagerly (also when first asked
    for inside a trace); its leaves are made jax arrays in the caller's trace."""
    return jax.tree.map(jnp.asarray, _ggx_table_numpy())


def lookup(table: LTCTable, alpha, cos_theta):
    """``M^-1`` at roughness ``alpha`` and view cosine ``cos_theta``, bilinear in the table's
    parameters (clamped to its range)."""
    nt, na = table.theta.shape[0], table.alpha.shape[0]
    th = jnp.arccos(jnp.clip(cos_theta, 0.0, 1.0))
    x = jnp.clip(th / table.theta[-1] * (nt - 1), 0.0, nt - 1.0)
    a0, a1 = table.alpha[0], table.alpha[-1]
    y = jnp.clip((alpha - a0) / (a1 - a0) * (na - 1), 0.0, na - 1.0)
    i0 = jnp.clip(jnp.floor(x).astype(jnp.int32), 0, nt - 2)
    j0 = jnp.clip(jnp.floor(y).astype(jnp.int32), 0, na - 2)
    fx, fy = x - i0.astype(x.dtype), y - j0.astype(y.dtype)
    p = table.params
    v = ((1 - fx) * (1 - fy) * p[i0, j0] + fx * (1 - fy) * p[i0 + 1, j0]
         + (1 - fx) * fy * p[i0, j0 + 1] + fx * fy * p[i0 + 1, j0 + 1])
    return matrix(v)[1]


def frame(n, wi):
    """Rows ``(x, y, n)``: x the projection of ``wi`` on the surface (any tangent if none)."""
    t = wi - jnp.dot(wi, n) * n
    ln = jnp.sqrt(jnp.sum(t * t))
    alt = jnp.where(jnp.abs(n[0]) < 0.9, jnp.array([1.0, 0, 0]), jnp.array([0.0, 1, 0]))
    alt = alt - jnp.dot(alt, n) * n
    t = jnp.where(ln > 1e-6, t / jnp.maximum(ln, 1e-30),
                  alt / jnp.sqrt(jnp.maximum(jnp.sum(alt * alt), 1e-30)))
    return jnp.stack([t, jnp.cross(n, t), n])


def m_inv_for(materials, mat, n, wi) -> Float[Array, "3 3"]:
    """The renderer's ``M^-1`` for material ``mat`` seen from ``wi``: the fitted GGX lobe for
    conductors, the identity (the clamped cosine) otherwise."""
    table = ggx_table()
    m_inv = lookup(table, materials.alpha[mat], jnp.dot(n, wi))
    return jnp.where(materials.material[mat] == CONDUCTOR, m_inv, jnp.eye(3, dtype=jnp.float32))
