"""The Warp protocol and composition (H Sec. 3.1, Eqs. 2-6, Algorithms 1 and 2).

A warp maps one point of its input domain (a primary-sample-space point ``u`` in ``[0, 1]^2``)
to one point of its output domain. **Every method takes and returns a single point**; batches are
made by the caller with ``jax.vmap(warp.sample)(u)`` (or the helpers :func:`sample_batch`,
:func:`pdf_batch`, :func:`inverse_batch`). This keeps ``jax.jacfwd(warp.sample)`` meaningful and
lets one test battery cover every warp.

The triplet (STYLE: pbrt-v4 ``SampleBilinear``/``BilinearPDF``/``InvertBilinearSample``):

* ``sample(u) -> x``: ``u`` of shape ``(2,)`` in ``[0, 1]^2``; ``x`` of shape ``(out_dim,)``.
* ``pdf(x) -> ()``: the density of ``x = sample(u)`` for uniform ``u``, with respect to the warp's
  output ``measure`` (H Table 1's ``J_w`` evaluated at the output point); ``0`` off the support,
  never NaN.
* ``inverse(x) -> u``: the PSS point that ``sample`` maps to ``x``. Points off the support are
  mapped to the nearest PSS point (clamped into ``[0, 1]^2``); their ``pdf`` is ``0``.
"""

from __future__ import annotations

import abc
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp

from .._types import Array, ArrayLike, Float
from .._validate import check_points


def check_point(name: str, x, dim: int) -> jax.Array:
    """Shape check before tracing: one point of shape ``(dim,)`` (vmap for batches)."""
    shape = getattr(x, "shape", None)
    if shape is None:
        x = jnp.asarray(x, dtype=jnp.float32)
        shape = x.shape
    if tuple(shape) != (dim,):
        raise ValueError(
            f"{name} must be a single point of shape ({dim},) (use jax.vmap for batches),"
            f" got shape {tuple(shape)}"
        )
    x = jnp.asarray(x)
    if not jnp.issubdtype(x.dtype, jnp.floating):
        x = x.astype(jnp.float32)
    return x


class AbstractWarp(eqx.Module):
    """A bijective map from ``[0, 1]^2`` onto a 2D domain with its density and inverse.

    Subclasses set the class variables ``out_dim`` (2 for the unit square and the disk, 3 for
    directions and points on surfaces) and ``measure`` (what ``pdf`` is a density with respect to:
    ``"area [0,1]^2"``, ``"area disk"``, ``"solid angle"`` or ``"area"``).
    """

    out_dim: ClassVar[int] = 2
    measure: ClassVar[str] = "area [0,1]^2"

    @abc.abstractmethod
    def sample(self, u: Float[Array, "2"]) -> Float[Array, " d"]:
        """Warp one PSS point ``u`` of shape ``(2,)`` to the output domain."""

    @abc.abstractmethod
    def pdf(self, x: Float[Array, " d"]) -> Float[Array, ""]:
        """Density of the output point ``x`` w.r.t. ``measure`` (0 off the support)."""

    @abc.abstractmethod
    def inverse(self, x: Float[Array, " d"]) -> Float[Array, "2"]:
        """The PSS point ``u`` with ``sample(u) == x`` (clamped into ``[0, 1]^2``)."""

    def sample_and_pdf(self, u: Float[Array, "2"]) -> tuple[Float[Array, " d"], Float[Array, ""]]:
        """``(x, pdf(x))`` for ``x = sample(u)``; compositions use H Algorithm 1 here."""
        x = self.sample(u)
        return x, self.pdf(x)


class Compose(AbstractWarp):
    """``w = w_m o ... o w_1``: ``warps[0]`` acts first on ``u`` (H Eqs. 3-6).

    ``sample_and_pdf`` is H Algorithm 1 (the pdf is the product of each warp's ``J_w`` at its own
    output); ``pdf`` is H Algorithm 2 (invert in reverse order, multiplying the ``J_w`` on the
    way), which needs every warp, the base technique included, to be invertible.
    All warps but the last must map ``[0, 1]^2`` to ``[0, 1]^2``.
    """

    warps: tuple[AbstractWarp, ...]

    def __init__(self, *warps: AbstractWarp):
        if len(warps) == 1 and isinstance(warps[0], tuple | list):
            warps = tuple(warps[0])
        if not warps:
            raise ValueError("compose needs at least one warp, got none")
        for i, w in enumerate(warps):
            if not isinstance(w, AbstractWarp):
                raise TypeError(f"warps[{i}] must be a Warp, got {type(w).__name__}")
        for i, w in enumerate(warps[:-1]):
            if w.out_dim != 2 or w.measure != "area [0,1]^2":
                raise ValueError(
                    f"warps[{i}] ({type(w).__name__}) must map [0,1]^2 to [0,1]^2 to be followed"
                    f" by another warp; its output measure is {w.measure!r}"
                )
        self.warps = tuple(warps)

    @property
    def out_dim(self) -> int:  # type: ignore[override]
        return self.warps[-1].out_dim

    @property
    def measure(self) -> str:  # type: ignore[override]
        return self.warps[-1].measure

    def sample(self, u):
        x = check_point("u", u, 2)
        for w in self.warps:
            x = w.sample(x)
        return x

    def sample_and_pdf(self, u):
        # H Algorithm 1.
        x = check_point("u", u, 2)
        pdf = jnp.ones((), x.dtype)
        for w in self.warps:
            x, j = w.sample_and_pdf(x)  # J_w at the warp's own output
            pdf = pdf * j
        return x, pdf

    def pdf(self, x):
        # H Algorithm 2.
        x = check_point("x", x, self.out_dim)
        pdf = jnp.ones((), jnp.float32)
        for w in reversed(self.warps):
            pdf = pdf * w.pdf(x)
            x = w.inverse(x)
        return jnp.where(pdf > 0, pdf, 0.0).astype(jnp.float32)

    def inverse(self, x):
        x = check_point("x", x, self.out_dim)
        for w in reversed(self.warps):
            x = w.inverse(x)
        return x


def compose(*warps: AbstractWarp) -> Compose:
    """``compose(w1, ..., wm)``: the warp ``wm o ... o w1`` (``w1`` acts first on ``u``)."""
    return Compose(*warps)


def sample_batch(warp: AbstractWarp, u: Float[ArrayLike, "n 2"]) -> tuple[Array, Array]:
    """``(x, pdf)`` for a batch ``u`` of shape ``(n, 2)`` (``vmap`` of ``sample_and_pdf``).

    ``u`` must lie in ``[0, 1]^2`` and be finite: a ``ValueError`` otherwise (checked once here,
    before the compiled batch; a warp would clamp such ``u`` to the square's border, or map NaN
    to a finite point, without saying so); traced ``u`` inside the program, with the same
    message (``_validate.refuse_traced``).
    """
    if not isinstance(warp, AbstractWarp):
        raise TypeError(f"warp must be a warp (AbstractWarp), got {type(warp).__name__}")
    u = check_points("u", u, closed=True)
    return _sample_batch(warp, u)


@eqx.filter_jit
def _sample_batch(warp, u):
    return jax.vmap(warp.sample_and_pdf)(u)


@eqx.filter_jit
def pdf_batch(warp: AbstractWarp, x: Float[Array, "n d"]) -> Float[Array, " n"]:
    """``pdf`` over a batch of output points (``vmap``)."""
    return jax.vmap(warp.pdf)(x)


@eqx.filter_jit
def inverse_batch(warp: AbstractWarp, x: Float[Array, "n d"]) -> Float[Array, "n 2"]:
    """``inverse`` over a batch of output points (``vmap``)."""
    return jax.vmap(warp.inverse)(x)
