"""Multiple importance sampling weights (Veach & Guibas 1995), evaluated with Alg. 2 pdfs.

``n_f, p_f``: the sample count and pdf of the technique that drew the sample; ``n_g, p_g`` the
competing technique's, both evaluated at the *same* point (hence the need for invertible warps,
H Sec. 3.1). Both pdfs 0 -> weight 0; an overflowing ``(n_f p_f)^2`` -> weight 1 (pbrt-v4);
never NaN.
"""

from __future__ import annotations

import jax.numpy as jnp


def balance_heuristic(n_f, p_f, n_g, p_g):
    """``n_f p_f / (n_f p_f + n_g p_g)``."""
    f, g = n_f * jnp.asarray(p_f, jnp.float32), n_g * jnp.asarray(p_g, jnp.float32)
    s = f + g
    w = jnp.where(s > 0, f / jnp.where(s > 0, s, 1.0), 0.0)
    return jnp.where(jnp.isinf(f), 1.0, w)


def power_heuristic(n_f, p_f, n_g, p_g, beta: float = 2.0):
    """``(n_f p_f)^beta / ((n_f p_f)^beta + (n_g p_g)^beta)``.

    The one power heuristic of the package: the renderer's MIS (light sample and BSDF sample,
    :mod:`anisosample.render.integrator`) and every experiment use it.
    """
    f = n_f * jnp.asarray(p_f, jnp.float32)
    g = n_g * jnp.asarray(p_g, jnp.float32)
    if beta == 2:  # the usual exponent (Veach's): two multiplies instead of pow
        f, g = f * f, g * g
    else:
        f, g = f**beta, g**beta
    s = f + g
    w = jnp.where(s > 0, f / jnp.where(s > 0, s, 1.0), 0.0)
    return jnp.where(jnp.isinf(f), 1.0, w)
