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
    """``(n_f p_f)^beta / ((n_f p_f)^beta + (n_g p_g)^beta)``."""
    f = (n_f * jnp.asarray(p_f, jnp.float32)) ** beta
    g = (n_g * jnp.asarray(p_g, jnp.float32)) ** beta
    s = f + g
    w = jnp.where(s > 0, f / jnp.where(s > 0, s, 1.0), 0.0)
    return jnp.where(jnp.isinf(f), 1.0, w)
