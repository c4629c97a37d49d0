"""The light sources of ``h_shading_points`` (a triangle and a twisted bilinear patch above
shading points with normal +z), their float64 references and the warps that sample them; shared
by ``h_shading_points`` and ``beyond_differentiable_tuning``."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

import anisosample.warps as W

TRIANGLE = np.array([[-0.5, -0.3, 0.8], [0.7, -0.2, 1.1], [0.0, 0.6, 0.5]])
# corners[i, j] = p_ij at (u, v) = (i, j): a twisted, non-planar patch with one short edge
# (p00-p01), the case where uniform parametric sampling suffers (H Sec. 4.2).
PATCH = np.array([[[-0.6, -0.5, 0.9], [-0.5, -0.3, 0.95]], [[0.8, -0.4, 0.6], [0.3, 0.9, 1.3]]])
NORMAL = np.array([0.0, 0.0, 1.0])


# --- references (float64 NumPy, independent of the warps) -------------------------------------


def lambert_irradiance(points):
    out = []
    for p in points:
        d = TRIANGLE - p
        d = d / np.linalg.norm(d, axis=1, keepdims=True)
        total = 0.0
        for i in range(3):
            a, b = d[i], d[(i + 1) % 3]
            cr = np.cross(a, b)
            total += np.arctan2(np.linalg.norm(cr), a @ b) * (NORMAL @ cr) / np.linalg.norm(cr)
        out.append(abs(total) / 2)
    return np.array(out)


def patch_irradiance(points, order=96):
    t, w = np.polynomial.legendre.leggauss(order)
    t, w = (t + 1) / 2, w / 2
    U, V = np.meshgrid(t, t, indexing="ij")
    c = PATCH
    pt = ((1 - U) * (1 - V))[..., None] * c[0, 0] + (U * (1 - V))[..., None] * c[1, 0]
    pt += ((1 - U) * V)[..., None] * c[0, 1] + (U * V)[..., None] * c[1, 1]
    du = (1 - V)[..., None] * (c[1, 0] - c[0, 0]) + V[..., None] * (c[1, 1] - c[0, 1])
    dv = (1 - U)[..., None] * (c[0, 1] - c[0, 0]) + U[..., None] * (c[1, 1] - c[1, 0])
    nrm = np.cross(du, dv)
    area = np.linalg.norm(nrm, axis=-1)
    nl = nrm / area[..., None]
    ww = np.outer(w, w)
    out = []
    for p in points:
        d = pt - p
        r2 = np.sum(d * d, -1)
        dn = d / np.sqrt(r2)[..., None]
        f = np.maximum(dn @ NORMAL, 0) * np.abs(np.sum(dn * nl, -1)) / r2 * area
        out.append(np.sum(ww * f))
    return np.array(out)


# --- methods: (shading point) -> warp, and the integrand on the warp's output -----------------

_N = jnp.asarray(NORMAL, jnp.float32)


def _cos(w):
    return jnp.maximum(jnp.dot(w, _N), 0.0)


def triangle_methods():
    verts = jnp.asarray(TRIANGLE, jnp.float32)

    def base(p):
        return W.SphericalTriangle(verts, p)

    def pw(family):
        return lambda p: W.compose(W.fit_pointwise(family, _cos, [base(p)]), base(p))

    def ls(family):
        def make(p):
            init = W.fit_pointwise(family, _cos, [base(p)])
            return W.compose(W.fit_least_squares(family, _cos, [base(p)], init=init), base(p))

        return make

    return {
        "uniform solid angle": base,
        "+ bilinear (point-wise)": pw(W.Bilinear),
        "+ biquadratic (point-wise)": pw(W.Biquadratic),
        "+ bilinear (least squares)": ls(W.Bilinear),
        "+ biquadratic (least squares)": ls(W.Biquadratic),
        "Arvo 2001 (exact)": lambda p: W.CosineSphericalTriangle(verts, p, _N),
        "tabulated 32x32": lambda p: W.compose(W.fit_tabulated(_cos, [base(p)]), base(p)),
    }, (lambda p: _cos)


def patch_factors(p):
    patch = W.BilinearPatch(jnp.asarray(PATCH, jnp.float32))

    def geometry(x):  # 1/r^2 * cos at the light
        d = x - p
        r2 = jnp.sum(d * d)
        uv = patch.inverse(x)
        du, dv = patch.partials(uv)
        nl = jnp.cross(du, dv)
        nl = nl / jnp.linalg.norm(nl)
        return jnp.abs(jnp.dot(d, nl)) / (r2 * jnp.sqrt(r2))

    def cos_r(x):
        d = x - p
        return jnp.maximum(jnp.dot(d, _N), 0.0) / jnp.linalg.norm(d)

    def f(x):
        return geometry(x) * cos_r(x)

    return patch, geometry, cos_r, f


def patch_three_warp(p):
    """H Sec. 4.2's three-warp chain at shading point ``p`` (the library's
    ``warps.patch_three_warp``): the bilinear approximate-area warp, a biquadratic fitted to the
    geometric factor behind it, one fitted to the receiver's cosine."""
    return W.patch_three_warp(W.BilinearPatch(jnp.asarray(PATCH, jnp.float32)), p, _N)
