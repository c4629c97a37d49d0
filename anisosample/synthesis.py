"""Point synthesis with anisotropic spectra: one recipe, one optimizer loop, one result (W Sec. 4).

``synthesize(key, n, directions_deg, *, recipe="rate", **options) -> SynthesisResult``; the
points, float32 ``(n, 2)`` in ``[0, 1)^2``, are ``result.points`` (``np.asarray(result)`` gives
them too). The optimistix shape: the problem first (key, n, directions), every option in one
frozen :class:`Recipe`, one loop (:func:`_iterate`) serving a single set and a batch of sets
(:func:`synthesize_batch`), and one result type, :class:`SynthesisResult`.

Two recipes (``RECIPES``), both minimising a loss of the point positions with Adam (Kingma & Ba;
a small pure-function implementation, :func:`anisosample.optimizer.adam_step`; the loop as an
objective, an optimizer and a differentiable ``lax.scan`` runtime: :mod:`anisosample.optimizer`),
initialised from a stratified set:

``"rate"`` (default; the design that reaches the rate, issue 4 finding c)
    :func:`~anisosample.losses.linear_spectrum_loss` on the ``"rate"`` frequency design
    (wedges of length ``n^0.8`` along every direction given, a disk of radius ``sqrt(n)``,
    weights ``W(v) = sum_d 1/(|v|^2 (1 + s_d^2))`` for the aligned edges and for edges off by
    +-0.25..+-1 deg, ``frequencies.ROBUST_OFFSETS_DEG``, from ``frequencies.ROBUST_MIN_N`` =
    1024 points up), no sliced-Wasserstein term, Adam with
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

Speed: a set's loss is data (:class:`_Objective`: the spectrum terms of
:func:`anisosample.losses.spectrum_terms`, one per type-1 box), so a step is one compiled
value-and-gradient per box *shape* and one compiled Adam step: a set whose box shapes were seen
before in the process (every later set of a table, every later on-demand lookup with shared
shapes) compiles nothing, and the terms of a step run on the cores in parallel (one FINUFFT
thread each), summed in their fixed order.

Same key, same bits: every step runs the same compiled functions on the same state whether or
not the run is checkpointed or resumed, and every NUFFT runs on one thread
(:data:`anisosample.spectrum.NUFFT_THREADS`), so a run is reproducible byte for byte across
processes and thread counts, a resumed run equals an uninterrupted one, and set ``b`` of a batch
equals ``synthesize(split(key, B)[b], ...)``. Long runs show a progress bar and save a
checkpoint every ``checkpoint_every`` steps when ``checkpoint=`` names a ``.npz`` file.
:func:`save_result` writes a result with its record (n, directions, recipe, frequency design,
loss history, key, package version).
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import functools
import hashlib
import math
import os
import threading
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from . import frequencies as _freq
from . import io as _io
from . import losses as _losses
from . import optimizer as _optimizer
from . import prefix as _prefix
from . import spectrum as _spectrum
from ._validate import (
    ONE_MINUS_EPSILON,
    check_choice,
    check_devices,
    check_directions_deg,
    check_int,
    check_key,
    check_points,
    check_positive_float,
)
from .optimizer import adam_update as adam_update  # kept here for old callers
from .progress import progress as _progress

__all__ = ["RECIPES", "BOUNDARIES", "Recipe", "make_recipe", "recipe_defaults",
           "SynthesisResult", "loop_status", "synthesize", "synthesize_batch",
           "synthesize_sequence",
           "sequence_levels", "loss_value", "SEQUENCE_WEIGHTS", "SEQUENCE_STEPS",
           "SEQUENCE_LEARNING_RATE", "SEQUENCE_FREQUENCY_OPTIONS", "SEQUENCE_DEFAULTS",
           "adam_update", "save_result", "load_result", "load_or_synthesize", "max_directions",
           "usable_cpus", "usable_cores"]

RECIPES = ("rate", "paper")
SEQUENCE_STEPS = 3000
"""Optimizer steps of a sequence (:func:`synthesize_sequence`, sequence tables) unless given: the
nested losses need far more than a set's 200. Measured at N = 4096 against the mean of three
standalone sets (``experiments/beyond_sequences.py``'s measure, 16384 shifts), one sequence per
setting at the rate 1.5, worst prefix ratio 256..4096: 1.22 / 1.37 (extra directions 81 / 166)
at 600 steps, 1.18 / 1.24 at 1500; on the experiment's four directions 1.29 at 1500 steps and
1.24 at 3000 (every prefix within 1.25x of a standalone set; the slope over the prefixes 0.01-0.04
flatter, as the small prefixes gain most); at the rate 0.5, 600 steps had been no worse than
1200 (512 shifts: mean ratio 1.21 / 1.22), and 200 steps worse (1.31).
Applied where a sequence is asked for (:func:`synthesize_sequence`, a new sequence table's
settings), not by :func:`make_recipe`: ``steps`` is one of a named recipe's defaults, which table
fingerprints record as such, so a recipe-level default would give a table built before it (such
as the first shipped ``d3_n4096_seq256``, 200 steps) sets of another step count under the same
fingerprint."""
SEQUENCE_LEARNING_RATE = 1.5
"""The learning rate of a sequence (:func:`synthesize_sequence`, new sequence tables) unless
given, in units of the full sequence's point spacing (a set's default is 0.5). Measured at
N = 4096, 600 steps, extra directions 81 and 96, each prefix's edge variance over the mean of
three standalone sets (16384 shifts; the sets' own max/min spread 1.02-1.09): the worst prefix
ratio was 1.34 / 1.41 at 0.5, 1.26 / 1.24 at 1.0, 1.22 / 1.23 at 1.5 and 1.30 / 1.22 at 2.0."""
SEQUENCE_FREQUENCY_OPTIONS = {"robust_axis_weight": _freq.AXIS_WEIGHT_4}
"""The frequency options of a sequence (:func:`synthesize_sequence`, new sequence tables) unless
``frequency_options`` is given (then those alone): the axes weigh
:data:`anisosample.frequencies.AXIS_WEIGHT_4` in the nested prefixes of
:data:`anisosample.frequencies.ROBUST_MIN_N` points and more, where the robust offsets weigh
each extra direction nine times, at every direction count (a 4-direction design's default;
3-direction sets keep weight 1, the shipped set tables' design). Measured with
``experiments/beyond_sequences.py --scale small`` (2026-12-07; 16384 toroidal shifts of each
prefix on the half-plane perpendicular to its extra direction, against the mean of three
standalone sets; the same sets, keys and machine for both designs), extra directions 134 / 85 /
166 / 79 degrees, these options against ``frequency_options={}`` (weight 1 at every prefix, the
default before): slope over 256..4096 -1.70 / -1.67 / -1.69 / -1.70 against -1.71 / -1.60 /
-1.65 / -1.64; variance at 4096 over pmj02bn's 0.16 / 0.44 / 0.26 / 0.32 against 0.16 / 0.52 /
0.30 / 0.37; worst prefix over a standalone set 1.18 against 1.31; worst band energy 0.036
against 0.071. The axes' weight 3 at every prefix instead (``axis_weight``, two of the four
directions run) reached -1.71 at 85 degrees but cost the 512-point prefixes 1.37 and 1.43
times a standalone set's variance (85 and 134 degrees); weight 9 moved the four directions'
slopes by -0.03..+0.01, within one sequence's key-to-key spread. The shipped
``d3_n4096_seq256`` is built with these options (every prefix of its 45 off-axis sequences has a
lower edge variance than in the table before them, 0.84-0.90x in the geometric mean)."""
SEQUENCE_DEFAULTS = {"steps": SEQUENCE_STEPS, "learning_rate": SEQUENCE_LEARNING_RATE,
                     "frequency_options": SEQUENCE_FREQUENCY_OPTIONS}
"""What a sequence takes unless given, where a sequence is asked for (:func:`synthesize_sequence`,
a new sequence table): the one list both apply."""
SEQUENCE_WEIGHTS = ("equal", "size")
"""Named weights of the nested prefixes' losses in a sequence (:func:`synthesize_sequence`):
``"equal"`` (each prefix's normalized loss counts once) or ``"size"`` (prefix ``n_k`` weighs
``n_k / N``: the full sequence first). ``sequence_weights`` may also be explicit: one positive
weight per nested prefix (:func:`sequence_levels`), smallest first."""
BOUNDARIES = ("wrap", "clip")

_DEFAULTS = {
    "rate": dict(steps=200, learning_rate=0.5, final_lr_fraction=0.01, b1=0.9, b2=0.9,
                 adam_eps=1e-30, c=0.0, boundary="wrap", design="rate", nufft_eps=1e-7),
    "paper": dict(steps=1000, learning_rate=0.1, final_lr_fraction=0.01, b1=0.9, b2=0.999,
                  adam_eps=1e-8, c=100.0, boundary="clip", design="paper", nufft_eps=1e-7),
}
_POSITIVE = ("learning_rate", "final_lr_fraction", "b1", "b2", "adam_eps", "nufft_eps")
OPTIONS = ("steps", "learning_rate", "final_lr_fraction", "b1", "b2", "adam_eps", "c",
           "spectrum_weight", "boundary", "design", "frequency_options", "init", "method",
           "nufft_eps", "nufft_precision", "prefix", "sequence_from", "sequence_weights")
"""Every synthesis option a :class:`Recipe` holds (besides the recipe's name)."""


def _level_weights(weights):
    """``Recipe.sequence_weights``: a name, or explicit weights as a tuple of floats."""
    if isinstance(weights, str):
        return weights
    if isinstance(weights, np.ndarray | list | tuple):
        try:
            return tuple(float(w) for w in np.asarray(weights, dtype=float).reshape(-1))
        except (TypeError, ValueError):
            pass
    return weights  # refused by the check, with the parameter's name


def _freeze(options) -> tuple:
    if options is None:
        return ()
    if isinstance(options, tuple):
        options = dict(options)
    if not isinstance(options, dict):
        raise TypeError(f"frequency_options must be a dict, got {type(options).__name__}")
    return tuple(sorted((str(k), tuple(v) if isinstance(v, list) else v)
                        for k, v in options.items()))


class Recipe(eqx.Module):
    """Every option of a synthesis run, frozen: the one record that results and tables
    fingerprint (:meth:`record`). Make one with :func:`make_recipe` (a named recipe's defaults
    plus overrides); constructing it directly validates the same way.

    ``learning_rate`` is in units of the mean point spacing ``1/sqrt(n)`` and decays
    exponentially to ``final_lr_fraction`` of itself over ``steps``; ``c >= 0`` weighs the SW
    term and ``spectrum_weight`` the spectrum term (W Eq. 10; 0 drops a term, W Fig. 3);
    ``design`` and ``frequency_options`` choose the frequency set
    (:func:`anisosample.frequencies.design`); ``init`` names the sampler of the initial set;
    ``method``, ``nufft_eps`` and ``nufft_precision`` (``"double"``, or ``"single"``: the type-1
    transforms in float32, :data:`anisosample.losses.PRECISIONS`; the 4-direction tables'
    choice) are the spectrum engine's (:mod:`anisosample.spectrum`). ``prefix`` (W Sec. 7;
    :mod:`anisosample.prefix`): ``"none"``, ``"dihedral-<m>"`` or ``"pmj02bn-<m>"``: the set's
    first ``m`` points are that fixed isotropic prefix, bit for bit, and only the others move.
    ``sequence_from`` (0: a set; a power of two: a progressive sequence, W Sec. 7; see
    :func:`synthesize_sequence`) and ``sequence_weights`` (:data:`SEQUENCE_WEIGHTS`) make every
    nested power-of-two prefix from ``sequence_from`` up an aligned set.
    """

    name: str = eqx.field(static=True, default="rate")
    steps: int = eqx.field(static=True, default=200)
    learning_rate: float = eqx.field(static=True, default=0.5)
    final_lr_fraction: float = eqx.field(static=True, default=0.01)
    b1: float = eqx.field(static=True, default=0.9)
    b2: float = eqx.field(static=True, default=0.9)
    adam_eps: float = eqx.field(static=True, default=1e-30)
    c: float = eqx.field(static=True, default=0.0)
    spectrum_weight: float = eqx.field(static=True, default=1.0)
    boundary: str = eqx.field(static=True, default="wrap")
    design: str = eqx.field(static=True, default="rate")
    frequency_options: tuple = eqx.field(static=True, default=(), converter=_freeze)
    init: str = eqx.field(static=True, default="jittered")
    method: str = eqx.field(static=True, default="auto")
    nufft_eps: float = eqx.field(static=True, default=1e-7)
    nufft_precision: str = eqx.field(static=True, default="double")
    prefix: str = eqx.field(static=True, default="none")
    sequence_from: int = eqx.field(static=True, default=0)
    sequence_weights: str | tuple = eqx.field(static=True, default="equal",
                                              converter=_level_weights)

    def __check_init__(self):
        from . import samplers

        check_choice("recipe", self.name, RECIPES)
        check_int("steps", self.steps, minimum=1)
        for name in _POSITIVE:
            check_positive_float(name, getattr(self, name))
        check_positive_float("c", self.c, allow_zero=True)
        check_positive_float("spectrum_weight", self.spectrum_weight, allow_zero=True)
        if self.spectrum_weight == 0 and self.c == 0:
            raise ValueError("spectrum_weight and c must not both be 0 (nothing to minimise)")
        check_choice("boundary", self.boundary, BOUNDARIES)
        check_choice("design", self.design, _freq.DESIGNS)
        if self.init not in samplers.names():
            raise ValueError(f"init must be one of {samplers.names()}, got {self.init!r}")
        check_choice("method", self.method, _spectrum.METHODS)
        check_choice("nufft_precision", self.nufft_precision, _losses.PRECISIONS)
        _prefix.check_prefix("prefix", self.prefix)
        check_int("sequence_from", self.sequence_from, minimum=0)
        if self.sequence_from and (self.sequence_from < 2
                                   or self.sequence_from & (self.sequence_from - 1)):
            raise ValueError("sequence_from must be 0 (a set) or a power of two >= 2 (the "
                             f"smallest nested prefix of a sequence), got {self.sequence_from}")
        if isinstance(self.sequence_weights, tuple) and all(
                isinstance(x, float) for x in self.sequence_weights):
            w = self.sequence_weights
            if not w or not all(math.isfinite(x) and x > 0 for x in w):
                raise ValueError("sequence_weights must be one of "
                                 f"{', '.join(map(repr, SEQUENCE_WEIGHTS))} or one positive, "
                                 f"finite weight per nested prefix, got {list(w)}")
        elif isinstance(self.sequence_weights, str):
            check_choice("sequence_weights", self.sequence_weights, SEQUENCE_WEIGHTS)
        else:
            raise TypeError("sequence_weights must be a name "
                            f"({', '.join(map(repr, SEQUENCE_WEIGHTS))}) or a sequence of "
                            f"floats, got {type(self.sequence_weights).__name__}")

    def record(self) -> dict:
        """The JSON-able record of every option (stored with results, fingerprinted by tables).
        ``prefix`` and ``sequence_*`` appear only when set, so the records (and table
        fingerprints) of plain sets are what they were before the options existed."""
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        for name, default in (("prefix", "none"), ("sequence_from", 0)):
            if out[name] == default:
                del out[name]
        if self.prefix != "none":  # the points behind the name, not only the name
            out["prefix_sha256"] = _prefix.prefix_checksum(self.prefix)
        if not self.sequence_from:
            del out["sequence_weights"]
        out["recipe"] = out.pop("name")
        out["frequency_options"] = dict(self.frequency_options)
        return _io.to_jsonable(out)

    def options(self) -> dict:
        """The options as keyword arguments of :func:`make_recipe` / :func:`synthesize`."""
        rec = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        rec["recipe"] = rec.pop("name")
        rec["frequency_options"] = dict(self.frequency_options)
        return rec


def make_recipe(recipe: str | Recipe = "rate", **options) -> Recipe:
    """A :class:`Recipe`: the named recipe's defaults (``"rate"`` or ``"paper"``) with
    ``options`` (any of :data:`OPTIONS`; ``None`` keeps the default) applied; or ``recipe``
    itself, with ``options`` replacing its fields."""
    unknown = sorted(set(options) - set(OPTIONS))
    if unknown:
        raise TypeError(f"unexpected synthesis option(s) {unknown}; the options are "
                        f"{', '.join(OPTIONS)}")
    given = {k: v for k, v in options.items() if v is not None}
    if given.get("sequence_from") and "init" not in given and not isinstance(recipe, Recipe):
        given["init"] = "pmj02bn"  # a sequence starts progressive: every power-of-two head
    if "method" in given:
        given["method"] = _spectrum.check_method(given["method"])
    if isinstance(recipe, Recipe):
        base = recipe.options()
        name = base.pop("recipe")
    else:
        name = check_choice("recipe", recipe, RECIPES)
        base = dict(_DEFAULTS[name])
    return Recipe(name=name, **{**base, **given})


def recipe_defaults(recipe: str) -> dict:
    """The options a named recipe uses unless overridden (see :class:`Recipe`)."""
    return dict(_DEFAULTS[check_choice("recipe", recipe, RECIPES)])


def max_directions(n: int) -> int:
    """The most spectral directions a set of ``n`` points is synthesized for:
    ``max(4, floor(sqrt(n) / 2))`` (W's tables use 3 and 4). Every direction's wedge takes
    frequencies the ``2 n`` coordinates must darken, so the reachable depth falls as directions
    are added: the rate loss (white noise = 1) after the default 200 steps, evenly spaced
    directions, key 0, measured at n = 64: 0.026 (3 directions), 0.047 (4), 0.070 (8),
    0.088 (12), 0.10 (18), 0.11 (36); at n = 256: 0.011 (3), 0.019 (4), 0.023 (8), 0.027
    (12), 0.042 (18). The bound keeps a request within the range where every direction still
    gets dark, and names the count instead of quietly returning a set that is not."""
    return max(4, int(math.isqrt(check_int("n", n, minimum=2)) // 2))


class SynthesisResult(eqx.Module):
    """What :func:`synthesize` (one set) and :func:`synthesize_batch` (``B`` sets) return: an
    ``equinox.Module`` (a pytree: the arrays and the status are leaves, the rest static).

    Attributes:
        points: float32 ``(n, 2)`` (batch: ``(B, n, 2)``) in ``[0, 1)^2``; ``np.asarray(result)``
            is the same array.
        history: the loss before each step and after the last, ``(steps + 1,)`` (``(B, ...)``).
        final_loss: the loss of the returned points (batch: ``(B,)``).
        result: the loop's status, optimistix's ``RESULTS`` (batch: one per set):
            ``successful`` when every loss in ``history`` is finite, else
            ``nonlinear_divergence``. Adam runs its fixed ``recipe.steps``, so there is no
            "max steps reached": the step count is the recipe's, not a failure.
        recipe: the :class:`Recipe` that made them.
        n, directions_deg: the problem (batch: a list of direction tuples).
        key: the key's data as a list of ints (batch: the key the sets' keys were split from).
        frequency_design: the frequency set's parameters (batch: one dict per set).
        frequency_count: its size (batch: one per set).
    """

    points: jax.Array
    history: np.ndarray | jax.Array
    final_loss: float | np.ndarray | jax.Array
    result: optx.RESULTS
    recipe: Recipe = eqx.field(static=True)
    n: int = eqx.field(static=True)
    directions_deg: tuple | list = eqx.field(static=True)
    key: list = eqx.field(static=True)
    frequency_design: dict | list = eqx.field(static=True)
    frequency_count: int | list = eqx.field(static=True)

    def __array__(self, dtype=None, copy=None):
        return np.asarray(self.points, dtype=dtype)

    @property
    def successful(self):
        """``result == optimistix.RESULTS.successful`` (batch: one bool per set)."""
        return self.result == optx.RESULTS.successful

    @property
    def info(self) -> dict:
        """The record as a dict (what :func:`save_result` stores)."""
        return {
            "n": self.n,
            "directions_deg": list(self.directions_deg),
            "recipe": self.recipe.name,
            "options": self.recipe.record(),
            "key": self.key,
            "frequency_design": self.frequency_design,
            "frequency_count": self.frequency_count,
            "history": np.asarray(self.history).tolist(),
            "final_loss": np.asarray(self.final_loss).tolist(),
        }


def loop_status(history) -> optx.RESULTS:
    """The status of a synthesis loop from its loss ``history`` (``(steps + 1,)``, or
    ``(B, steps + 1)`` for one status per set): ``RESULTS.successful`` when every loss is
    finite, else ``RESULTS.nonlinear_divergence`` (the points left the region where the loss
    is defined, e.g. overflowed)."""
    if isinstance(history, jax.core.Tracer):
        finite = jnp.all(jnp.isfinite(history), axis=-1)
    else:  # in float64: a large finite loss must not overflow to inf in float32
        finite = jnp.asarray(np.all(np.isfinite(np.asarray(history, np.float64)), axis=-1))
    pick = lambda ok: optx.RESULTS.where(ok, optx.RESULTS.successful,  # noqa: E731
                                         optx.RESULTS.nonlinear_divergence)
    return jax.vmap(pick)(finite) if finite.ndim else pick(finite)


class _Objective(eqx.Module):
    """One set's loss ``a L_spec + c L_SW`` (W Eq. 10; ``a = 0`` or ``c = 0`` drops a term, as in
    W Fig. 3) as data: the spectrum terms (:func:`anisosample.losses.spectrum_terms`, scaled
    by ``a``) and the SW directions and targets. Nothing of the set is static but the terms'
    box shapes, so sets whose boxes have the same shapes share the compiled functions."""

    terms: tuple
    sw: tuple | None
    c: float = eqx.field(static=True)
    heads: tuple = ()  # (n_k, term) of a sequence's nested prefixes x[:n_k], n_k < n


def sequence_levels(n: int, sequence_from: int) -> list[int]:
    """The nested prefix sizes a sequence of ``n`` points is optimized for: every power of two
    from ``sequence_from`` below ``n``, and ``n`` (``[n]`` for a set, ``sequence_from = 0``)."""
    if not sequence_from:
        return [n]
    out, k = [], sequence_from
    while k < n:
        out.append(k)
        k *= 2
    return [*out, n]


def _level_weight(recipe: Recipe, nk: int, n: int) -> float:
    w = recipe.sequence_weights
    if isinstance(w, tuple):
        return w[sequence_levels(n, recipe.sequence_from).index(nk)]
    return 1.0 if w == "equal" else nk / n


def _objective(fset, directions_deg, recipe: Recipe, n: int) -> _Objective:
    """One set's loss as data; a sequence (``recipe.sequence_from``) adds the loss of every
    nested prefix (:func:`sequence_levels`) on its own frequency design, weighted by
    ``recipe.sequence_weights``: ``L = sum_k w_k L_{n_k}(x[:n_k])``."""
    a, c = recipe.spectrum_weight, recipe.c
    terms, heads = (), ()
    levels = sequence_levels(n, recipe.sequence_from)
    with jax.enable_x64(True):  # the loop runs in float64
        if a > 0:
            make = (_losses.linear_spectrum_loss_terms if recipe.name == "rate"
                    else _losses.spectrum_loss_terms)

            def level_terms(fs, nk):
                return make(fs, nk, scale=a * _level_weight(recipe, nk, n),
                            method=recipe.method, eps=recipe.nufft_eps,
                            precision=recipe.nufft_precision)

            terms = level_terms(fset, n)
            heads = tuple((nk, t) for nk in levels[:-1]
                          for t in level_terms(_freq.design(nk, directions_deg, recipe.design,
                                                            **dict(recipe.frequency_options)),
                                               nk))
        sw = _losses.sliced_wasserstein_targets(directions_deg, n) if c > 0 else None
    return _Objective(terms, sw, float(c), heads)


# One compiled function per spectrum term shape (shared by every set, single or batched), one
# for the SW term and one for the Adam step: a set of an already-seen size compiles nothing.
_term_value_and_grad = jax.jit(jax.value_and_grad(_losses.term_value))


@functools.partial(jax.jit, static_argnums=0)
def _head_value_and_grad(nk, x, term):
    """A nested prefix's term: its value on ``x[:nk]`` and the gradient on all of ``x``."""
    return jax.value_and_grad(lambda y: _losses.term_value(y[:nk], term))(x)


@functools.partial(jax.jit, static_argnums=0)
def _sw_value_and_grad(c, x, d, tgt):
    return jax.value_and_grad(lambda y: c * _losses.sliced_wasserstein_value(y, d, tgt))(x)


@functools.partial(jax.jit, static_argnums=0)
def _adam_step(hyper, x, m, v, t, vals, grads):
    """Sum the terms' values and gradients (in their order) and take one step
    (:func:`anisosample.optimizer.adam_step`: Adam at the decayed learning rate, a prefix held
    still, a sequence's per-point scale, wrap or clip): ``(x, m, v, t + 1, loss before it)``."""
    lr0, decay, b1, b2, eps, wrap, fixed, seq_from = hyper
    val = functools.reduce(jnp.add, vals)
    g = functools.reduce(jnp.add, grads)
    x, m, v, t = _optimizer.adam_step(x, g, m, v, t, lr0=lr0, decay=decay, b1=b1, b2=b2,
                                      eps=eps, wrap=wrap, fixed=fixed, sequence_from=seq_from)
    return x, m, v, t, val


def _jobs(obj: _Objective, x) -> list:
    """The independent pieces of one set's loss and gradient: one per spectrum term (and SW)."""
    jobs = [(_term_value_and_grad, (x, term)) for term in obj.terms]
    jobs += [(functools.partial(_head_value_and_grad, nk), (x, term)) for nk, term in obj.heads]
    if obj.sw is not None:
        jobs.append((functools.partial(_sw_value_and_grad, obj.c), (x, *obj.sw)))
    return jobs


_POOL: list = []
_POOL_LOCK = threading.Lock()


def usable_cpus() -> list[int]:
    """The CPUs this process may run on, sorted (its affinity where the OS tells, else all of
    ``os.cpu_count()``)."""
    try:
        return sorted(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return list(range(max(1, os.cpu_count() or 1)))


def usable_cores() -> int:
    """How many CPUs this process may run on (:func:`usable_cpus`): the size of the synthesis
    thread pool, so a process pinned to one core (``anisosample tables build --processes P``)
    runs one term at a time."""
    return len(usable_cpus())


def _pool():
    """The worker threads the terms of a step run on (one per usable core): each term is its
    own compiled FINUFFT computation on one thread, so the cores work on different terms and the
    bits do not depend on which thread ran which (the terms are summed in their order)."""
    with _POOL_LOCK:
        if not _POOL:
            _POOL.append(concurrent.futures.ThreadPoolExecutor(
                max_workers=usable_cores(), thread_name_prefix="anisosample"))
        return _POOL[0]


def _run_job(fn, args):
    # the config is per thread: float64, on the device the set lives on
    (device,) = args[0].devices()
    with jax.enable_x64(True), jax.default_device(device):
        return jax.block_until_ready(fn(*args))


def _evaluate(objectives, xs) -> list:
    """``(values, gradients)`` of every set's terms, the sets' terms spread over the cores."""
    jobs = [_jobs(obj, x) for obj, x in zip(objectives, xs, strict=True)]
    flat = [j for js in jobs for j in js]
    if len(flat) == 1:
        res = [_run_job(*flat[0])]
    else:
        res = list(_pool().map(lambda j: _run_job(*j), flat))
    out, k = [], 0
    for js in jobs:
        part = res[k:k + len(js)]
        k += len(js)
        out.append((tuple(r[0] for r in part), tuple(r[1] for r in part)))
    return out


def loss_value(points, fset, directions_deg, recipe: Recipe) -> float:
    """The loss the synthesis loop minimizes, at ``points`` ``(n, 2)``: ``recipe``'s terms on
    the frequency design ``fset`` (:func:`anisosample.frequencies.design`) for
    ``directions_deg``, plus, for a sequence (``recipe.sequence_from``), every nested prefix's
    weighted loss (:func:`sequence_levels`). Computed as the loop does (float64, its terms in
    their order)."""
    directions_deg = tuple(float(d) for d in directions_deg)
    with jax.enable_x64(True):
        x = jnp.asarray(points, jnp.float64)
        if x.ndim != 2 or x.shape[1] != 2:
            raise ValueError(f"points must have shape (n, 2), got {x.shape}")
        obj = _objective(fset, directions_deg, recipe, x.shape[0])
        values, _ = _evaluate([obj], [x])[0]
        return float(functools.reduce(jnp.add, values))


def _hyper(recipe: Recipe, n: int) -> tuple:
    opt = _optimizer.Adam.from_recipe(recipe, n)
    return (*opt.schedule(), opt.b1, opt.b2, opt.eps, opt.boundary == "wrap", opt.fixed,
            opt.sequence_from)


def _resolve_prefix(prefix, options: dict):
    """``synthesize``'s ``prefix=``: ``None`` (the recipe's), a spec string (goes to the recipe)
    or explicit ``(m, 2)`` points (the recipe gets their
    :func:`~anisosample.prefix.explicit_prefix_name`). Returns
    the explicit points (float32) or ``None``."""
    if prefix is None:
        return None
    if isinstance(prefix, str):
        options["prefix"] = prefix
        return None
    pts = np.asarray(check_points("prefix", prefix), np.float32)
    options["prefix"] = _prefix.explicit_prefix_name(pts)
    return pts


def _check_prefix_fits(rec: Recipe, n: int) -> None:
    """The recipe's parts that depend on ``n``: the prefix's size and explicit sequence
    weights (one per nested prefix)."""
    m = _prefix.prefix_size(rec.prefix)
    if m and 4 * m > n:
        raise ValueError(f"prefix has {m} points, more than n/4 = {n / 4:g} for n={n}: a prefix "
                         "holds 1 to n/4 points (the rest must be free to shape the spectrum)")
    if rec.sequence_from and isinstance(rec.sequence_weights, tuple):
        levels = sequence_levels(n, rec.sequence_from)
        if len(rec.sequence_weights) != len(levels):
            raise ValueError(f"sequence_weights must hold one weight per nested prefix {levels} "
                             f"(n={n}, sequence_from={rec.sequence_from}), got "
                             f"{len(rec.sequence_weights)}")


def _start_with_prefix(x0: np.ndarray, rec: Recipe, explicit) -> np.ndarray:
    m = _prefix.prefix_size(rec.prefix)
    if m == 0:
        return x0
    pts = explicit if explicit is not None else _prefix.prefix_points(rec.prefix)
    # a sequence: the prefix displaces points of the smallest nested prefix that holds it, so
    # every nested prefix keeps its share of the initial (progressive) set
    h = next(k for k in sequence_levels(len(x0), rec.sequence_from) if k >= m)
    return np.concatenate([_prefix.place_prefix(x0[:h], pts), x0[h:]])


def _run_chunk(objectives, state, hyper, chunk: int, last: bool):
    """``chunk`` optimizer steps on ``B`` sets: the state is one ``(x, m, v)`` triple of
    ``(n, 2)`` arrays per set and a shared step count; set ``b`` follows the gradient of its
    own objective. Every set runs the same compiled functions on its own data, so batched and
    single synthesis give the same bits. Returns the new state, the losses before each step
    ``(chunk, B)`` and, for the ``last`` chunk, the losses of the end state ``(B,)`` (else
    ``None``: the next chunk's first step evaluates that state anyway)."""
    sets, t = state
    hist = []
    for _ in range(chunk):
        out, vals = [], []
        evals = _evaluate(objectives, [x for x, _, _ in sets])
        for (tv, tg), (x, m, v) in zip(evals, sets, strict=True):
            x, m, v, t_next, val = _adam_step(hyper, x, m, v, t, tv, tg)
            out.append((x, m, v))
            vals.append(val)
        sets, t = tuple(out), t_next
        hist.append(vals)
    end = None
    if last:
        end = np.asarray(jnp.stack([functools.reduce(jnp.add, tv) for tv, _ in
                                    _evaluate(objectives, [x for x, _, _ in sets])]))
    return (sets, t), np.asarray(jnp.asarray(hist)), end


def _to_float32_unit(x) -> np.ndarray:
    x = np.asarray(x, np.float64)
    x = x - np.floor(x)
    return np.minimum(x.astype(np.float32), ONE_MINUS_EPSILON)


def _key_record(key) -> list[int]:
    if jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key):
        key = jax.random.key_data(key)
    return [int(k) for k in np.asarray(key).reshape(-1)]


_BYTES_PER_POINT = 512  # float64 x, m, v, gradient and the transforms' work arrays per point


def _check_size(n: int, directions_deg) -> None:
    """Refuse a size whose state and frequency set would not fit in half the memory, and more
    directions than :func:`max_directions` allows, before anything is allocated."""
    k = len(directions_deg)
    if k > max_directions(n):
        raise ValueError(
            f"directions_deg holds {k} directions, too many for n={n} points: at most "
            f"{max_directions(n)} (max(4, sqrt(n) / 2)); use fewer directions or more points")
    freqs = math.pi * n / 2 + 4 * k * n**0.8  # the rate design's disk and wedges, generously
    need = _BYTES_PER_POINT * n + 64 * freqs
    have = _spectrum.memory_bytes()
    if need > have // 2:
        raise ValueError(
            f"n={n} needs about {need / 2**30:.1f} GiB for the optimizer state and its "
            f"{freqs:.3g} frequencies, more than half of this machine's {have / 2**30:.1f} GiB;"
            " choose a smaller n")


def _read_checkpoint(path: Path, meta: dict, shape: tuple, steps: int):
    """The state saved at ``path``, checked against this run (settings, shape, finiteness,
    step range): ``(x, m, v, step, history)`` or a ``ValueError`` naming the file."""
    arrays, old = _io.load_npz(path)  # a damaged or foreign file: ValueError naming it
    same = {k: old.get(k) for k in meta}
    if same != _io.to_jsonable(meta):
        raise ValueError(f"checkpoint {path} was made with other settings; delete it or "
                         "choose another path")
    missing = [k for k in ("x", "m", "v", "step", "history") if k not in arrays]
    if missing:
        raise ValueError(f"checkpoint {path} lacks {missing}; delete it")
    for name in ("x", "m", "v"):
        a = arrays[name]
        if a.shape != shape or a.dtype != np.float64:
            raise ValueError(f"checkpoint {path}: {name} must be float64 of shape {shape}, got "
                             f"{a.dtype} {a.shape}; delete it")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"checkpoint {path}: {name} contains NaN or Inf; delete it")
    step = arrays["step"]
    if step.shape != () or not np.issubdtype(step.dtype, np.integer):
        raise ValueError(f"checkpoint {path}: step must be an integer, got {step!r}")
    step = int(step)
    if not 0 <= step < steps:
        raise ValueError(f"checkpoint {path}: step {step} is outside [0, steps={steps}); "
                         "delete it")
    hist = np.asarray(arrays["history"], np.float64)
    if hist.shape[0] != step or not np.all(np.isfinite(hist)):
        raise ValueError(f"checkpoint {path}: its loss history does not match step {step}")
    return arrays["x"], arrays["m"], arrays["v"], step, hist


def _iterate(objectives, x_init: np.ndarray, recipe: Recipe, n: int, *, meta: dict,
             checkpoint=None, checkpoint_every: int = 50, callback=None, bar_desc: str = "",
             show_progress: bool = True, single: bool = True):
    """The one optimizer loop: Adam on the stacked sets ``x_init`` ``(B, n, 2)`` (float64),
    ``checkpoint_every`` steps per chunk (:func:`_run_chunk`), checkpointed and resumed, with
    progress.
    Returns ``(x (B, n, 2), history (B, steps + 1), final (B,))``."""
    steps = recipe.steps
    b = x_init.shape[0]
    with jax.enable_x64(True):
        x, m, v = x_init, np.zeros_like(x_init), np.zeros_like(x_init)
        done = 0
        hist = np.zeros((0, b))
        shape = x_init.shape[1:] if single else x_init.shape
        if checkpoint is not None and Path(checkpoint).exists():
            x, m, v, done, h = _read_checkpoint(Path(checkpoint), meta, shape, steps)
            if single:
                x, m, v = x[None], m[None], v[None]
            hist = h.reshape(done, b)
        state = (tuple((jnp.asarray(x[i]), jnp.asarray(m[i]), jnp.asarray(v[i]))
                       for i in range(b)), jnp.asarray(done, jnp.int64))
        hyper = _hyper(recipe, n)
        bar = _progress(total=steps, initial=done, desc=bar_desc,
                        disable=None if show_progress else True)

        def stacked(j):
            return np.stack([np.asarray(s[j]) for s in state[0]])

        try:
            while done < steps:
                k = min(checkpoint_every, steps - done)
                state, vals, final = _run_chunk(objectives, state, hyper, k, done + k >= steps)
                hist = np.concatenate([hist, vals])
                done = int(state[1])
                bar.update(k)
                bar.set_postfix(loss=f"{float(hist[-1].max()):.3e}")
                if checkpoint is not None and done < steps:
                    sq = (lambda a: a[0]) if single else (lambda a: a)
                    _io.save_npz(checkpoint, {"x": sq(stacked(0)), "m": sq(stacked(1)),
                                              "v": sq(stacked(2)), "step": np.int64(done),
                                              "history": hist[:, 0] if single else hist},
                                 meta, overwrite=True)
                if callback is not None:
                    callback(done, float(hist[-1, 0]) if single else hist[-1].copy())
        finally:
            bar.close()
        final = np.asarray(final)
        x = stacked(0)
    if checkpoint is not None and Path(checkpoint).exists():
        Path(checkpoint).unlink()
    return x, np.concatenate([hist, final[None]]).T, final


def _initial_points(key, n, init):
    from . import samplers

    return np.asarray(samplers.get(init)(key, n), np.float64)


def synthesize(key, n: int, directions_deg, *, recipe: str | Recipe = "rate",
               initial_points=None, prefix=None, checkpoint: str | Path | None = None,
               checkpoint_every: int = 50, show_progress: bool = True, callback=None,
               return_info: bool = False, **options) -> SynthesisResult:
    """Synthesize ``n`` points whose spectrum is dark along the spectral ``directions_deg``.

    Args:
        key: JAX PRNG key (the initial stratified set).
        n: number of points, ``>= 2``.
        directions_deg: spectral directions in ``[0, 180)`` (include 0 and 90 for the axes, as W
            always does), distinct, at most :func:`max_directions` of them.
        recipe: ``"rate"`` (default, reaches the rate), ``"paper"`` (W Eqs. 10-15) or a
            :class:`Recipe`.
        options: any of :data:`OPTIONS` overriding the recipe (``steps``, ``learning_rate``,
            ``c``, ``boundary``, ``init``, ``method`` ``"auto" | "direct" | "nufft1" |
            "nufft3"``, ``frequency_options``, ``b1``, ``b2``, ``adam_eps``,
            ``final_lr_fraction``, ``nufft_eps``; see :class:`Recipe`).
        initial_points: start from these ``(n, 2)`` points in ``[0, 1)^2`` instead of the
            recipe's ``init`` sampler (a warm start; the key is then unused, and the points'
            SHA-256 is part of the record).
        prefix: fixed first points (W Sec. 7): ``None`` (the recipe's, default none), a spec
            ``"dihedral-<m>"`` / ``"pmj02bn-<m>"`` (:mod:`anisosample.prefix`) or explicit
            ``(m, 2)`` points in ``[0, 1)^2``, ``1 <= m <= n / 4``. The result's first ``m``
            points are the prefix bit for bit (float32); the other ``n - m`` are optimized so
            that the whole set has the aligned spectrum (they start from the ``init`` set with
            the point nearest each prefix point removed,
            :func:`~anisosample.prefix.place_prefix`).
        checkpoint: ``.npz`` path; saved every ``checkpoint_every`` steps, resumed if present
            (a checkpoint of other settings, shape or a step past ``steps`` is refused).
        callback: ``callback(step, loss)`` after each chunk (may raise to stop).
        return_info: kept for old callers: return ``(points, result.info)`` instead.

    Returns:
        a :class:`SynthesisResult` (``result.points``: ``(n, 2)`` float32 in ``[0, 1)^2``).
    """
    key = check_key("key", key)
    n = check_int("n", n, minimum=2)
    directions_deg = check_directions_deg("directions_deg", directions_deg)
    explicit = _resolve_prefix(prefix, options)
    rec = make_recipe(recipe, **options)
    _check_prefix_fits(rec, n)
    checkpoint_every = check_int("checkpoint_every", checkpoint_every, minimum=1)
    _check_size(n, directions_deg)
    fset = _freq.design(n, directions_deg, rec.design, **dict(rec.frequency_options))
    meta = {"n": n, "directions_deg": list(directions_deg), "recipe": rec.name,
            "options": rec.record(), "frequency_design": fset.params, "key": _key_record(key)}
    if initial_points is None:
        x0 = _initial_points(key, n, rec.init)
    else:
        x0 = np.asarray(check_points("initial_points", initial_points), np.float64)
        if x0.shape != (n, 2):
            raise ValueError(f"initial_points must have shape ({n}, 2), got {x0.shape}")
        meta["initial_points_sha256"] = hashlib.sha256(x0.astype("<f8").tobytes()).hexdigest()
    x0 = _start_with_prefix(x0, rec, explicit)
    x, hist, final = _iterate([_objective(fset, directions_deg, rec, n)], x0[None], rec, n,
                              meta=meta,
                              checkpoint=checkpoint, checkpoint_every=checkpoint_every,
                              callback=callback, bar_desc=f"synthesize n={n}",
                              show_progress=show_progress)
    result = SynthesisResult(
        points=jnp.asarray(_to_float32_unit(x[0])), history=hist[0],
        final_loss=float(final[0]), result=loop_status(hist[0]), recipe=rec, n=n,
        directions_deg=tuple(directions_deg), key=meta["key"], frequency_design=fset.params,
        frequency_count=len(fset))
    return (result.points, result.info) if return_info else result


def synthesize_sequence(key, n: int = 4096, directions_deg=(0.0, 90.0, 45.0), *,
                        prefix=None, sequence_from: int = 256,
                        sequence_weights: str | tuple | list | np.ndarray | None = None,
                        steps: int | None = None,
                        learning_rate: float | None = None, **options) -> SynthesisResult:
    """A progressive aligned sequence (W Sec. 7: "generate points in a sampling sequence to
    allow for progressive rendering"): ``result.points`` is one ``(n, 2)`` sequence whose every
    power-of-two prefix of at least ``sequence_from`` points (and the whole) is an aligned set
    for ``directions_deg``.

    The loss is the sum over the nested prefixes ``n_k`` (:func:`sequence_levels`) of the
    recipe's loss of ``x[:n_k]`` on ``n_k``'s own frequency design, each normalized so that
    white noise scores 1 and weighted by ``sequence_weights`` (``"equal"``, the default: every
    prefix is a set a renderer may stop at, so each counts once; ``"size"``: ``n_k / n``; or
    one explicit weight per nested prefix, smallest first).
    Point ``i`` steps in units of the spacing of the first prefix that holds it, so early
    points move on their own scale. The initial sequence is progressive (a sequence's recipe
    takes ``init="pmj02bn"`` unless told otherwise: every power-of-two head is stratified).
    It runs in the one loop of :func:`synthesize` (checkpoints, resume, progress, same key same
    bits) and takes its options (``steps``, ``learning_rate`` and ``frequency_options``:
    :data:`SEQUENCE_STEPS`, :data:`SEQUENCE_LEARNING_RATE` and
    :data:`SEQUENCE_FREQUENCY_OPTIONS` unless given; a recipe given as a :class:`Recipe` keeps
    its own only if they are passed); ``prefix`` as there (placed among the first nested prefix
    that holds it).
    """
    if sequence_weights is not None:
        options["sequence_weights"] = sequence_weights
    given = {"steps": steps, "learning_rate": learning_rate}
    options.update({k: SEQUENCE_DEFAULTS[k] if v is None else v for k, v in given.items()})
    if options.get("frequency_options") is None:
        options["frequency_options"] = dict(SEQUENCE_FREQUENCY_OPTIONS)
    n = check_int("n", n, minimum=2)
    sequence_from = check_int("sequence_from", sequence_from, minimum=2)
    if sequence_from > n:
        raise ValueError(f"sequence_from must be at most n={n}, got {sequence_from}")
    return synthesize(key, n, directions_deg, prefix=prefix, sequence_from=sequence_from,
                      **options)


def synthesize_batch(key, n: int, direction_sets, *, recipe: str | Recipe = "rate",
                     initial_points=None, prefix=None, devices=None,
                     checkpoint: str | Path | None = None,
                     checkpoint_every: int = 50, show_progress: bool = True,
                     return_info: bool = False, **options) -> SynthesisResult:
    """``B`` sets at once through the same loop as :func:`synthesize`: ``direction_sets`` is a
    list of ``B`` direction lists of equal length; ``result.points`` is ``(B, n, 2)``. Set ``b``
    starts from ``jax.random.split(key, B)[b]`` and equals ``synthesize(that key, n,
    direction_sets[b], ...)`` bit for bit: each set keeps its own frequency plan (the
    lattice-aligned type-1 grids batch too), and each step evaluates every set's terms on the
    cores at once (:func:`_run_chunk`).

    ``devices``: split the sets into one contiguous slice per device; each device runs the loop
    on its slice in its own thread (XLA releases the GIL), and the results are the same bits as
    on one device. On the CPU, try it with ``XLA_FLAGS=--xla_force_host_platform_device_count=2``.
    ``checkpoint`` (one device): as in :func:`synthesize`, for the whole batch.
    ``initial_points``: ``(B, n, 2)`` warm starts instead of the ``init`` sampler.
    ``prefix``: as in :func:`synthesize`, one prefix for every set.
    """
    key = check_key("key", key)
    n = check_int("n", n, minimum=2)
    if isinstance(direction_sets, str) or not hasattr(direction_sets, "__len__"):
        raise TypeError("direction_sets must be a list of direction lists")
    sets = [check_directions_deg(f"direction_sets[{i}]", d) for i, d in enumerate(direction_sets)]
    if not sets:
        raise ValueError("direction_sets must hold at least one direction set")
    if len({len(d) for d in sets}) != 1:
        raise ValueError("direction_sets must all have the same number of directions, got "
                         f"{[len(d) for d in sets]}")
    explicit = _resolve_prefix(prefix, options)
    rec = make_recipe(recipe, **options)
    _check_prefix_fits(rec, n)
    checkpoint_every = check_int("checkpoint_every", checkpoint_every, minimum=1)
    for d in sets:
        _check_size(n, d)
    devs = check_devices("devices", devices) or [None]  # None: the default device
    if checkpoint is not None and len(devs) > 1:
        raise ValueError("checkpoint needs devices=None (one device)")
    b = len(sets)
    keys = jax.random.split(key, b)
    fsets = [_freq.design(n, d, rec.design, **dict(rec.frequency_options)) for d in sets]
    if initial_points is None:
        x_init = np.stack([_initial_points(k, n, rec.init) for k in keys])
    else:
        x_init = np.asarray(initial_points, np.float64)
        if x_init.shape != (b, n, 2):
            raise ValueError(f"initial_points must have shape ({b}, {n}, 2), got {x_init.shape}")
        for i in range(b):
            check_points(f"initial_points[{i}]", x_init[i])
    x_init = np.stack([_start_with_prefix(x, rec, explicit) for x in x_init])
    slices = np.array_split(np.arange(b), len(devs))
    out: dict[int, tuple] = {}
    errors: list[BaseException] = []

    def run(i, idx, device):
        meta = {"n": n, "direction_sets": [list(sets[j]) for j in idx], "recipe": rec.name,
                "options": rec.record(), "frequency_design": [fsets[j].params for j in idx],
                "key": _key_record(key), "indices": [int(j) for j in idx]}
        if initial_points is not None:
            meta["initial_points_sha256"] = hashlib.sha256(
                x_init[idx].astype("<f8").tobytes()).hexdigest()
        try:
            with jax.default_device(device) if device is not None else _nullcontext():
                out[i] = _iterate([_objective(fsets[j], sets[j], rec, n) for j in idx],
                                  x_init[idx], rec, n, meta=meta, checkpoint=checkpoint,
                                  checkpoint_every=checkpoint_every, single=False,
                                  bar_desc=f"synthesize_batch {len(idx)} x n={n}",
                                  show_progress=show_progress and i == 0)
        except BaseException as exc:  # noqa: BLE001 -- re-raised in the calling thread
            errors.append(exc)

    work = [(i, idx, d) for i, (idx, d) in enumerate(zip(slices, devs, strict=True)) if len(idx)]
    if len(work) == 1:
        run(*work[0])
    else:
        threads = [threading.Thread(target=run, args=w, daemon=True) for w in work]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    if errors:
        raise errors[0]
    x = np.concatenate([out[i][0] for i, _, _ in work])
    hist = np.concatenate([out[i][1] for i, _, _ in work])
    final = np.concatenate([out[i][2] for i, _, _ in work])
    result = SynthesisResult(
        points=jnp.asarray(_to_float32_unit(x)), history=hist, final_loss=final,
        result=loop_status(hist), recipe=rec, n=n, directions_deg=[tuple(d) for d in sets],
        key=_key_record(key), frequency_design=[fs.params for fs in fsets],
        frequency_count=[len(fs) for fs in fsets])
    return (result.points, result.info) if return_info else result


class _nullcontext:
    def __enter__(self):
        return None

    def __exit__(self, *exc):
        return False


# --- results on disk --------------------------------------------------------------------------


def save_result(path, result, info=None, *, overwrite: bool = False) -> Path:
    """Write a :class:`SynthesisResult` (or old-style ``points, info``) to ``.npz``."""
    if isinstance(result, SynthesisResult):
        points, info = result.points, result.info
    else:
        points, info = result, dict(info or {})
    history = np.asarray(info.get("history", []), np.float64)
    meta = {k: v for k, v in info.items() if k != "history"}
    return _io.save_npz(path, {"points": np.asarray(points), "loss_history": history}, meta,
                        overwrite=overwrite)


def load_result(path):
    """Inverse of :func:`save_result`: ``(points, metadata)``."""
    arrays, meta = _io.load_npz(path)
    if "points" not in arrays:
        raise ValueError(f"{path} holds no 'points' array (not a saved synthesis result)")
    return jnp.asarray(arrays["points"]), dict(meta, history=arrays.get("loss_history"))


def load_or_synthesize(path, key, n: int, directions_deg, **options) -> SynthesisResult:
    """The result saved at ``path`` if it was made with the same settings (the same
    :meth:`Recipe.record`, n, directions, key and frequency design), else synthesize it
    (checkpointed beside ``path``, so an interrupted run resumes) and save it there.

    Experiments use this to reuse finished sets on rerun.
    """
    path = Path(path)
    key = check_key("key", key)
    directions_deg = check_directions_deg("directions_deg", directions_deg)
    options = {k: v for k, v in options.items() if k != "return_info"}
    recipe = options.pop("recipe", "rate")
    run = {k: options.pop(k) for k in ("checkpoint_every", "show_progress", "callback")
           if k in options}
    rec = make_recipe(recipe, **options)
    if path.exists():
        pts, meta = load_result(path)
        fset = _freq.design(n, directions_deg, rec.design, **dict(rec.frequency_options))
        if (meta.get("n") == n and meta.get("directions_deg") == list(directions_deg)
                and meta.get("key") == _key_record(key) and meta.get("options") == rec.record()
                and meta.get("frequency_design") == _io.to_jsonable(fset.params)):
            hist = np.asarray(meta.get("history"), np.float64)
            return SynthesisResult(
                points=pts, history=hist, final_loss=float(meta.get("final_loss", hist[-1])),
                result=loop_status(hist), recipe=rec, n=n,
                directions_deg=tuple(directions_deg), key=meta["key"],
                frequency_design=meta["frequency_design"],
                frequency_count=int(meta.get("frequency_count", len(fset))))
    ckpt = path.with_name(path.stem + ".ckpt.npz")
    result = synthesize(key, n, directions_deg, recipe=rec, checkpoint=ckpt, **run)
    save_result(path, result, overwrite=True)
    return result
