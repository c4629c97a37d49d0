"""Direct illumination and depth of field, with each pixel's 2D integrand exposed (W Eq. 8).

One sample of pixel ``q`` is a function of four 2D points: the film position inside the pixel,
the lens sample, the light sample and (with MIS) the BSDF sample. :func:`radiance` evaluates it.
The options (``dimension``, ``technique``, ``light_warp``, ``mis``, ``pixel_center``,
``square_aperture``) are one record, :class:`~anisosample.render.options.IntegratorOptions`,
checked once and resolved for the scene by :func:`anisosample.render.render` and
:func:`pixel_integrand`; every function here takes it. The *integrand dimension* is the one the
sampler under study drives; the others are either fixed (pixel centre, lens centre) or
independent uniform random numbers:

* ``dimension="light"``: ``x`` is the light sample; ``f_q(x) = L_e + f_r L_e G V / p(x)`` at the
  primary hit (Veach's area form, the pixel's direct illumination estimated with one light
  sample; W Sec. 6.2 Cornell box / breakfast room / attic, H Sec. 4).
* ``dimension="lens"``: ``x`` is the aperture sample of the thin lens; the primary hit is
  connected deterministically to the point lights (W Sec. 6.2 depth of field).

With ``pixel_center=True`` (W's setting) the film position is the pixel centre and
:func:`pixel_integrand` is a true 2D function of ``x``. With ``pixel_center=False`` (default)
the film position is drawn from the key: uniform in the pixel for a box-filtered film, from the
pixel's reconstruction filter for a gaussian one (filter importance sampling,
:mod:`anisosample.render.film`; Mitsuba's splatted image in expectation).

MIS (``mis=True``): one light sample and one BSDF sample combined with the power heuristic
(Veach & Guibas 1995, :func:`anisosample.warps.power_heuristic`; H renders with one light and
one BSDF sample). Mitsuba's ``direct`` integrator with ``emitter_samples = bsdf_samples = 1``
computes the same estimator. On ``dimension="lens"`` (point lights only) it is applied too and
changes no bit: the BSDF sample reaches no emitter (:mod:`anisosample.render.options`).

Light warps (``light_warp``, :mod:`anisosample.render.light_warps`, H Sec. 4): one shading frame
per sample. Every ray leaves from the offset point ``offset_origin(p, n, wi)`` on the viewer's
side; the light's warp chain is fitted there, the light sample is drawn from there, and the BSDF
sample's light pdf is H Algorithm 2 through the same chain from the same point.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..warps import power_heuristic
from ._kernel import kernel
from ._vec import dot
from .bsdf import eval_bsdf, pdf_bsdf, sample_bsdf
from .camera import generate_ray
from .culling import film_view, pixel_view, with_culling
from .film import film_offsets
from .geometry import intersect, occluded, offset_origin
from .light_warps import Receiver
from .lights import emitted, light_pdf, sample_light
from .options import IntegratorOptions
from .scene import LUMINANCE, THINLENS, Scene


def hashed_uniforms(key, n: int) -> Float[Array, "n 2"]:
    """``n`` independent uniform 2D points from one key: a counter hashed with lowbias32.

    One threefry draw seeds the pixel; each coordinate is then ``hash(seed ^ hash(counter))``,
    two multiply-xorshift rounds instead of threefry's twenty. Used for the dimensions a render
    does not study (film position, the other of lens/light, the BSDF sample), as Mitsuba's
    independent sampler uses PCG32 rather than a cryptographic generator.
    """
    from ..samplers import hash_u32

    seed = jax.random.bits(key, (), jnp.uint32)
    bits = hash_u32(seed ^ hash_u32(jnp.arange(2 * n, dtype=jnp.uint32)))
    return ((bits >> 8).astype(jnp.float32) * jnp.float32(2.0**-24)).reshape(n, 2)


def radiance(
    scene: Scene,
    film: Float[Array, "2"],
    lens: Float[Array, "2"],
    light: Float[Array, "2"],
    bsdf_u: Float[Array, "2"],
    options: IntegratorOptions | None = None,
    view=None,
) -> Float[Array, "3"]:
    """One sample of the radiance through film point ``film`` (``[0, 1]^2``, row 0 on top),
    with ``options``' technique, light warp, MIS and aperture (its dimension and film rule are
    the callers': :func:`sample_function`, :func:`pixel_samples`; None: the defaults).
    ``view``: the film tile's candidate primitives for the primary and the shadow ray
    (:func:`anisosample.render.culling.pixel_view`; None: every primitive)."""
    options = IntegratorOptions() if options is None else options
    technique, light_warp, mis = options.technique, options.light_warp, options.mis
    o, d = generate_ray(scene.camera, film, lens, square_aperture=options.square_aperture)
    hit = intersect(scene, o, d, subset=None if view is None else view.primary)
    wi = -d
    mats = scene.materials
    # Emission seen directly (front side only, Mitsuba's area emitter).
    front = dot(hit.n, wi) > 0
    see_light = hit.valid & (hit.light >= 0) & front
    L = jnp.where(see_light, emitted(scene, jnp.maximum(hit.light, 0), hit.uv), 0.0)
    # One shading frame: every ray leaves from here (the BSDFs reflect only, to wi's side).
    rec = Receiver(origin=offset_origin(scene, hit.p, hit.n, wi), n=hit.n, wi=wi,
                   material=hit.material)

    # Light sampling.
    ls = sample_light(scene, light, rec, technique, light_warp)
    v = ls.p - rec.origin
    d2 = jnp.maximum(dot(v, v), 1e-30)
    wo = v * jax.lax.rsqrt(d2)
    cos_l = jnp.where(ls.delta, 1.0, dot(ls.n, -wo))
    f = eval_bsdf(mats, hit.material, hit.n, wi, wo)
    visible = ~occluded(scene, rec.origin, ls.p, subset=None if view is None else view.shadow)
    ok = hit.valid & (cos_l > 0) & (ls.pdf > 0) & visible & jnp.any(f > 0)
    contrib = f * ls.radiance * (cos_l / (d2 * jnp.where(ls.pdf > 0, ls.pdf, 1.0)))
    if mis:
        pdf_l_sa = ls.pdf * d2 / jnp.maximum(cos_l, 1e-30)
        pdf_b = pdf_bsdf(mats, hit.material, hit.n, wi, wo)
        contrib = contrib * jnp.where(ls.delta, 1.0, power_heuristic(1, pdf_l_sa, 1, pdf_b))
    L = L + jnp.where(ok, contrib, 0.0)

    if mis:
        wb, pdf_b = sample_bsdf(mats, hit.material, hit.n, wi, bsdf_u)
        h2 = intersect(scene, rec.origin, wb)
        cos2 = dot(h2.n, -wb)
        lit = hit.valid & h2.valid & (h2.light >= 0) & (cos2 > 0) & (pdf_b > 0)
        prim = jnp.maximum(h2.light, 0)
        pdf_l = light_pdf(scene, prim, h2.p, rec, technique, light_warp)  # H Alg. 2, same chain
        pdf_l_sa = pdf_l * h2.t**2 / jnp.maximum(cos2, 1e-30)
        fb = eval_bsdf(mats, hit.material, hit.n, wi, wb)
        wgt = power_heuristic(1, pdf_b, 1, pdf_l_sa)
        cb = fb * emitted(scene, prim, h2.uv) * (wgt / jnp.where(pdf_b > 0, pdf_b, 1.0))
        L = L + jnp.where(lit, cb, 0.0)
    return L


def sample_function(scene: Scene, options: IntegratorOptions):
    """``g(x, film, other, bsdf_u, view=None) -> rgb``: one sample of :func:`radiance` where
    ``x`` drives ``options.dimension`` (resolved; the other dimension's sample is ``other``;
    ``view`` the pixel's candidate primitives)."""

    def g(x, film, other, bsdf_u, view=None):
        if options.dimension == "light":
            lens = other if scene.camera.projection == THINLENS else jnp.full(2, 0.5, jnp.float32)
            light = x
        else:
            lens, light = x, other
        return radiance(scene, film, lens, light, bsdf_u, options, view)

    return g


class PixelIntegrand(eqx.Module):
    """``f_q(x)`` of one pixel: a callable over ``x`` of shape ``(..., 2)`` returning ``(...)``.

    The value is the luminance (or one RGB channel) of the one-sample estimate of the pixel with
    ``x`` as its light or lens sample: the image estimator is ``mean_j f_q(x_j)`` (W Eq. 8),
    exactly :func:`anisosample.variance.estimator_variance`'s estimator. Everything except ``x``
    is fixed: the film position at the pixel centre (or at ``film`` if given), the lens at its
    centre, no BSDF sample.

    ``options``: the :class:`~anisosample.render.options.IntegratorOptions` of the integrand,
    resolved for the scene (:meth:`~anisosample.render.options.IntegratorOptions.integrand`:
    ``mis`` off, ``pixel_center`` on: a 2D integrand has one sampling technique); its
    ``light_warp`` is the light technique's warp chain fitted at each shading point
    (:mod:`anisosample.render.light_warps`; ``"none"``: the base ``technique`` alone).
    ``warp`` (optional): a further primary-sample-space warp ``w`` from
    :mod:`anisosample.warps` (``[0,1)^2 -> [0,1)^2``, e.g. a fitted ``Bilinear`` or a
    ``compose`` of them) applied in front of that, H Eqs. 2-6: the integrand becomes
    ``f_q(w(x)) / J_w(w(x))``, whose mean is the same pixel value.
    """

    scene: Scene
    film: Float[Array, "2"]
    weights: Float[Array, "3"]
    options: IntegratorOptions = eqx.field(static=True)
    warp: eqx.Module | None = None

    def rgb(self, x: Float[Array, "... 2"]) -> Float[Array, "... 3"]:
        x = jnp.asarray(x, jnp.float32)
        flat = x.reshape(-1, 2)
        n = flat.shape[0]
        if isinstance(x, jax.core.Tracer) or n == 0:
            out = _integrand_rgb(self, flat, film_view(self.scene, self.film))
        else:
            # Concrete input: blocks of three fixed sizes, so that three compilations serve
            # every size: as many of the large as fit, then the middle, the last one padded.
            pad = (-n) % (_BLOCK if n > 256 else 256)
            xs = jnp.concatenate([flat, jnp.full((pad, 2), 0.5, jnp.float32)])
            big = (n + pad) // _CALL_BLOCK * _CALL_BLOCK
            starts = [(i, _CALL_BLOCK) for i in range(0, big, _CALL_BLOCK)]
            starts += [(i, min(_BLOCK, n + pad)) for i in range(big, n + pad, _BLOCK)]
            view = _film_view(self.scene, self.film)  # gathered once, outside the kernel
            out = jnp.concatenate([_integrand_rgb(self, xs[i:i + size], view, _CALL_BLOCK)
                                   for i, size in starts])[:n]
        return out.reshape(*x.shape[:-1], 3)

    def __call__(self, x: Float[Array, "... 2"]) -> Float[Array, "..."]:
        return jnp.tensordot(self.rgb(x), self.weights, axes=1)


_film_view = eqx.filter_jit(film_view)  # one dispatch, not one per eager gather
_BLOCK = 4096  # points per vmapped block of a traced call: keeps its working set small
# Points per call of a concrete evaluation: cornell's integrand at 2^20 points, 179 ms in
# blocks of 4096, 89 ms of 16384, 66 ms of 65536, the same bits (one device, load 1.5).
_CALL_BLOCK = 65536


@kernel(jit=eqx.filter_jit)
def _integrand_rgb(f: PixelIntegrand, flat, view, block: int = _BLOCK):
    """``f.rgb`` at the points ``flat`` ``(n, 2)``: vmapped, over blocks of ``block`` points
    (static) under ``lax.map`` where ``n`` is larger."""
    g = sample_function(f.scene, f.options)
    half = jnp.full(2, 0.5, jnp.float32)

    def point(xi):
        if f.warp is None:
            return g(xi, f.film, half, half, view)
        y = f.warp.sample(xi)
        jac = f.warp.pdf(y)
        val = g(y, f.film, half, half, view)
        return jnp.where(jac > 0, val / jnp.where(jac > 0, jac, 1.0), 0.0)

    one = jax.vmap(point)
    n = flat.shape[0]
    if n <= block:
        return one(flat)
    pad = (-n) % block
    xs = jnp.concatenate([flat, jnp.full((pad, 2), 0.5, jnp.float32)]).reshape(-1, block, 2)
    return jax.lax.map(one, xs).reshape(-1, 3)[:n]


def pixel_integrand(
    scene: Scene,
    pixel: tuple[int, int],
    *,
    options: IntegratorOptions | None = None,
    dimension: str = "auto",
    technique: str = "area",
    light_warp: str = "none",
    channel: str = "luminance",
    film: tuple[float, float] | None = None,
    square_aperture: bool = False,
    warp=None,
    culling: bool = False,
) -> PixelIntegrand:
    """The 2D integrand ``f_q`` of pixel ``pixel = (column, row)`` (row 0 at the image top).

    ``options``: an :class:`~anisosample.render.options.IntegratorOptions` (a render's own,
    say), or the keywords ``dimension``, ``technique``, ``light_warp`` (one of
    :data:`~anisosample.render.light_warps.LIGHT_WARPS`, the light technique's warp chain
    fitted at the shading point, H Sec. 4) and ``square_aperture`` that make one -- not both.
    The integrand takes :meth:`~anisosample.render.options.IntegratorOptions.integrand` of it
    (no MIS, film at the pixel centre). ``channel``: ``"luminance"`` (Rec. 709 weights),
    ``"r"``, ``"g"`` or ``"b"``. ``film`` overrides the film position inside ``[0, 1]^2``
    (default: the pixel centre). ``warp``: a primary-sample-space warp composed in front of
    the light/lens technique (see :class:`PixelIntegrand`). ``culling=True``: its rays test only
    the planar primitives its film position's tile can meet (:mod:`anisosample.render.culling`;
    the same values). Off by default: it pays for large evaluations (one device, 2^20 points,
    load about 1: blinds' integrand 89 -> 63 ms, cornell's 61 -> 58 ms), not for the many small
    ones of the per-pixel estimation (W Fig. 9's cornell at small scale took 195 s with it on).
    """
    from .._validate import check_choice, check_int

    options = options_of(options, dimension=dimension, technique=technique,
                         light_warp=light_warp, square_aperture=square_aperture)
    options = options.for_scene(scene).integrand()
    col = check_int("pixel[0] (column)", pixel[0], minimum=0, maximum=scene.width - 1)
    row = check_int("pixel[1] (row)", pixel[1], minimum=0, maximum=scene.height - 1)
    check_choice("channel", channel, ("luminance", "r", "g", "b"))
    if not isinstance(culling, (bool, np.bool_)):
        raise TypeError(f"culling must be True or False, got {culling!r}")
    weights = {"luminance": LUMINANCE, "r": (1, 0, 0), "g": (0, 1, 0), "b": (0, 0, 1)}[channel]
    if film is None:
        film = ((col + 0.5) / scene.width, (row + 0.5) / scene.height)
    return PixelIntegrand(
        scene=with_culling(scene, bool(culling)),
        film=jnp.asarray(film, jnp.float32),
        weights=jnp.asarray(weights, jnp.float32),
        options=options,
        warp=warp,
    )


_KEYWORD_DEFAULTS = IntegratorOptions()


def options_of(options: IntegratorOptions | None = None, **keywords) -> IntegratorOptions:
    """``options``, or the record the keywords make (the user-facing functions take either,
    not both: a keyword away from its default beside ``options`` is a ``ValueError``)."""
    if options is None:
        return IntegratorOptions(**keywords)
    if not isinstance(options, IntegratorOptions):
        raise TypeError(f"options must be a render.IntegratorOptions, got "
                        f"{type(options).__name__}")
    given = sorted(k for k, v in keywords.items() if not _is_default(k, v))
    if given:
        raise ValueError(f"give options= or the keywords {given}, not both (the record "
                         f"holds them: options.replace({given[0]}=...))")
    return options


def _is_default(name: str, value) -> bool:
    default = getattr(_KEYWORD_DEFAULTS, name)
    if name == "dimension" and value is None:
        return True
    return type(value) in (type(default), np.bool_) and value == default


@kernel(static_argnames=("options",))
def render_chunk(scene: Scene, points, key, pixels, *, options: IntegratorOptions):
    """Mean over the ``spp`` points of each pixel in ``pixels`` (flat indices): ``(..., 3)``.

    Each pixel gets its own toroidal shift of the shared point set (W Sec. 5.4) and its own
    independent random numbers for the other dimensions, all from ``fold_in(key, pixel)``.
    ``options``: the render's record, resolved for ``scene``.
    """
    from ..samplers import toroidal_shift

    g = sample_function(scene, options)

    def one_pixel(q):
        x = toroidal_shift(pixel_shift_key(key, q), points)
        rgb = pixel_samples(scene, g, x, key, q, points.shape[0], 0, options)
        return jnp.mean(rgb, axis=0)

    if pixels.ndim == 1:
        return jax.vmap(one_pixel)(pixels)
    # (blocks, chunk): lax.map over cache-sized chunks keeps the working set small.
    return jax.lax.map(jax.vmap(one_pixel), pixels)


def pixel_shift_key(key, q):
    """The key of pixel ``q``'s toroidal shift (W Sec. 5.4) in a render keyed ``key``."""
    return jax.random.split(jax.random.fold_in(key, q), 4)[0]


def pixel_samples(scene: Scene, g, x, key, q, spp: int, start: int,
                  options: IntegratorOptions) -> Float[Array, "k 3"]:
    """Samples ``start .. start + k - 1`` of pixel ``q``'s ``spp``-sample estimate, ``x``
    ``(k, 2)`` their (shifted) points in the studied dimension: the film position, the other
    dimension's and the BSDF's random numbers are the same counters of the pixel's streams
    (``fold_in(key, q)``) whatever the split, so a pixel rendered in parts (a prefix, then the
    rest of its set: :mod:`anisosample.render.pixel_aligned`) gets the bits it gets whole.
    ``options`` (resolved) says which of them the configuration draws. The rays test the
    pixel's candidate primitives (:func:`~anisosample.render.culling.pixel_view`) where the
    scene carries them."""
    k = x.shape[0]
    w, h = scene.width, scene.height
    _, k_film, k_other, k_bsdf = jax.random.split(jax.random.fold_in(key, q), 4)

    def stream(kk):
        return jax.lax.dynamic_slice_in_dim(hashed_uniforms(kk, spp), start, k)

    col = (q % w).astype(jnp.float32)
    row = (q // w).astype(jnp.float32)
    if options.pixel_center:
        pos = jnp.broadcast_to(jnp.stack([col, row]) + 0.5, (k, 2))
    else:  # uniform in the pixel (box) or from its reconstruction filter (render/film.py)
        cam = scene.camera
        pos = film_offsets(cam.rfilter, cam.rfilter_stddev, stream(k_film), col, row, w, h)
    film = pos / jnp.asarray([[w, h]], jnp.float32)
    # Draw only the random numbers this configuration uses.
    half = jnp.full((k, 2), 0.5, jnp.float32)
    # (dimension "lens" implies point lights only: no light sample is needed.)
    need_other = options.dimension == "light" and scene.camera.projection == THINLENS
    other = stream(k_other) if need_other else half
    bsdf_u = stream(k_bsdf) if options.mis else half
    view = pixel_view(scene, q)  # gathered inside the samples' loop: faster than a loop input
    return jax.vmap(g, in_axes=(0, 0, 0, 0, None))(x, film, other, bsdf_u, view)

