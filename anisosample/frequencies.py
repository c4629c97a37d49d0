"""Integer frequency sets to suppress along chosen spectral directions (W Sec. 4.1, Fig. 5).

A spectral direction ``theta`` (degrees, ``[0, 180)``) is the direction of the frequency vectors
``d = (cos theta, sin theta)``; an edge running at ``theta + 90`` puts its energy there.  For each
direction we suppress a *wedge* of integer frequencies around the ray ``t d`` (``t > 0``):

    Lambda(d) = { v in Z^2 \\ {0} :  0 < t <= length,  |s| <= max(width, t tan(angle)) },
    t = v . d,   s = v . d_perp,   d_perp = (-sin theta, cos theta).

``length`` sets how far the suppression reaches (the convergence rate: a ray suppressed out to
``|v| ~ n^a`` gives variance ``~ n^-(1+a)`` on an edge, ``fourier_variance.md`` Sec. 5), ``width``
and ``angle`` set the robustness to a misaligned edge (an edge off by ``delta`` puts its energy
on a ray that leaves a band of half-width ``w`` at ``|v| ~ w / tan(delta)``).  Because the power
spectrum is even, only one of ``v`` and ``-v`` is kept; ``v = 0`` never is.

Two documented designs (:func:`design`):

``"rate"`` (the default of :func:`anisosample.synthesize`)
    wedges of length ``n^0.8``, half-width ``max(1.5, t tan 2deg)`` along *every* direction given
    (axes included), plus an isotropic disk ``|v| <= sqrt(n)``, weighted by
    ``W(v) = sum_d 1 / (|v|^2 (1 + s_d^2))`` — the weights follow the energy of an edge's
    spectrum (``|v|^-2`` on its ray) and fall off across the ray — plus, for each non-axis
    direction, the same weight for edges misaligned by ``ROBUST_OFFSETS_DEG`` (+-0.25, +-0.5,
    +-0.75, +-1 deg; :func:`edge_weights` ``offsets_deg``).  The loss then sums the W Eq. 5
    variances of the aligned edge and of eight misaligned ones (W Sec. 7 proposes choosing the
    frequencies by evaluating the variance on test integrands), so a set made for ``theta``
    keeps the rate on edges up to 1 deg off (tables round to integer degrees; direction
    estimates err by about a degree).  Measured over ``n = 2^8..2^14`` (one set per n, edge at
    30 deg, ``results/w_fig6/robust_dense``): slope -1.75 aligned, -1.76..-1.78 at +-0.25,
    +-0.5, +-0.75, +-1 deg, -1.69..-1.70 between the lines (+-0.125, +-0.375), -1.60 at
    +-1.5 and -1.47 at +-2; without the offsets (``offsets_deg=()``): -1.81 aligned, -1.64 at
    +-0.5, -1.59 at +-1 (``results/w_fig6/robust_old``).  Lines every 0.125 deg
    (``offsets_deg=[k / 8 for k in range(-8, 9) if k]``, ``results/w_fig6/robust_dense125``) close
    the dips: -1.76..-1.78 at every delta in [-1, 1], aligned -1.77, one edge at
    30/67/12/145 deg -1.77/-1.78/-1.80/-1.77 (not the default only because the shipped tables
    were built with the 0.25 spacing).  The axes get no offsets: the square's border is
    exactly axis-aligned; with two or more directions besides the axes, each axis weighs
    :data:`AXIS_WEIGHT_4` times its edge (else the offsets leave the axes bright).
``"paper"``
    W Sec. 4.1 / 6.1 as far as the paper states it: wedges of length ``3 sqrt(n)`` and half-width
    ``max(1, t tan 2deg)``, uniform weights.  This reproduces the paper's counts closely
    (4,014 frequencies for ``n = 2^12`` and directions 0, 90, 30 vs the paper's 4,303).

Each set is partitioned into one group per direction (every frequency goes to the direction
whose ray it is closest to in angle, oriented so that ``t >= 0``); the spectrum of a group is
evaluated by a type-3 NUFFT in coordinates rotated to its direction, so its cost grows with the
wedge's length instead of its bounding box (:mod:`anisosample.losses`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ._validate import (
    check_choice,
    check_directions_deg,
    check_int,
    check_positive_float,
    renamed_keywords,
)

DESIGNS = ("rate", "paper")
ROBUST_OFFSETS_DEG = (-1.0, -0.75, -0.5, -0.25, 0.25, 0.5, 0.75, 1.0)
ROBUST_MIN_N = 1024
"""The ``"rate"`` design adds the :data:`ROBUST_OFFSETS_DEG` weights for ``n >= ROBUST_MIN_N``
only; smaller sets get the aligned-only weights. From the fits of the robustness study
(``results/w_fig6/robust_dense`` against ``robust_old``: one edge at 30 degrees, edges
misaligned by -2..2 degrees, n = 2^8..2^14, 2048 shifts), the robust set's variance over the
aligned-only set's at n = 256 / 512 / 1024 / 4096: aligned 1.08 / 1.12 / 1.16 / 1.24, at +-0.5
degrees 1.16 / 1.06 / 0.97 / 0.82 (mean of both signs), at +-1 degree 1.14 / 1.01 / 0.89 /
0.70 (table in docs/reproduction.md, W Fig. 6's robustness): below 1024 points the offsets
lose at every misalignment within 2 degrees, from 1024 up they win where an estimate errs by
half a degree or more. In the renderer at 256 spp the aligned-only table gave 0.87 of
pmj02bn's edge-pixel variance where the robust one gave 1.23 (the shipped n = 256 table,
b1d4f52), and W Fig. 8's dof window 15 (per-pixel directions, probes apart, 16 keys, ad-hoc
script) 0.494 against 0.529; on all of W Fig. 8 at 256 spp the aligned-only sets gained on
cornell, dof and pillars and lost on blinds and attic (docs/reproduction.md, W Fig. 8)."""


AXIS_WEIGHT_4 = 3.0
"""The ``"rate"`` design's ``axis_weight`` (:func:`edge_weights`) for sets with two or more
directions besides the axes, from :data:`ROBUST_MIN_N` points up, where the robust offsets give
each of those directions nine edges' weight and each axis one: the optimizer then left the axes
bright. Measured (2026-12-07, ad-hoc scripts, one set per key, 4096 toroidal shifts per
variance): 4-direction sets at 1024 points, band energy (:func:`anisosample.diagnostics.
band_energy`, white noise 1) along 0 / 90 with axis weight 1 / 3 / 9: extra directions 47 and
148 0.177, 0.151 / 0.050, 0.056 / 0.018, 0.013, extra 19 and 77 0.123, 0.081 / 0.033, 0.024 /
0.011, 0.011, while along the extra directions 0.002 / 0.004-0.005 / 0.008-0.010. The corner
integrand whose edges are perpendicular to the extra directions (``integrands.edges``), its
edges aligned / 0.5 / 1 degree off, variance over pmj02bn's, mean of two keys, at 1024 and 4096
points: (47, 148) 0.282, 0.284, 0.301 / 0.212, 0.209, 0.216 / 0.195, 0.194, 0.208 and 0.202,
0.201, 0.218 / 0.154, 0.157, 0.172 / 0.151, 0.152, 0.174; (19, 77) 0.384, 0.357, 0.368 / 0.298,
0.290, 0.303 / 0.285, 0.281, 0.297 and 0.244, 0.228, 0.282 / 0.195, 0.186, 0.235 / 0.196, 0.195,
0.240; (8, 130) at 1024 0.305, 0.291, 0.301 / 0.240, 0.242, 0.257 / 0.247, 0.244, 0.261. 3 cuts
the variance by 15-28 % against 1; against 9 it is up to 8 % higher (one pair at 1024 points)
and up to 5 % lower (at 4096 and misaligned), and keeps more of the extra lines' darkness.
3-direction sets keep weight 1 (the shipped tables' design), although 3 gains there too: the
half-plane perpendicular to the extra direction, aligned / 0.5 / 1 degree off, mean of three
keys, variance with weight 3 over weight 1 at 1024 and 4096 points: 12 degrees 0.86, 0.89, 0.89
and 0.90, 0.89, 0.89; 30 degrees 0.94, 0.92, 0.97 and 0.97, 0.99, 1.00; 60 degrees 0.92, 0.92,
0.93 and 1.00, 0.98, 1.00; 85 degrees 0.88, 0.86, 0.86 and 0.82, 0.88, 0.84 (85 degrees,
variance over pmj02bn's at 1024 / 2048 / 4096 points, weight 1 against 3 from 1024: 0.513,
0.455, 0.463 against 0.450, 0.399, 0.381, slope over 256-4096 -1.60 against -1.68; 80 degrees
0.416, 0.362, 0.307 against 0.347, 0.308, 0.268, -1.64 against -1.71). Adopting it there means
rebuilding the shipped 3-direction tables and rerunning the records that synthesize sets from
1024 points."""


@dataclass(frozen=True, eq=False)
class FrequencySet:
    """A half-set of integer frequencies, split into per-direction groups, with weights.

    Attributes:
        freqs: ``(m, 2)`` int32, groups concatenated in order; only one of ``v``, ``-v``.
        weights: ``(m,)`` float64, positive.
        group_directions_deg: the direction each group is evaluated in (rotation angle).
        group_sizes: number of frequencies in each group.
        params: the design's parameters (stored with synthesized sets).
    """

    freqs: np.ndarray
    weights: np.ndarray
    group_directions_deg: tuple[float, ...]
    group_sizes: tuple[int, ...]
    params: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.freqs.shape[0])

    def groups(self):
        """Yield ``(direction_deg, freqs_g, weights_g)`` for each non-empty group."""
        start = 0
        for theta, size in zip(self.group_directions_deg, self.group_sizes, strict=True):
            if size:
                yield theta, self.freqs[start : start + size], self.weights[start : start + size]
            start += size


def _unit(theta_deg: float) -> tuple[np.ndarray, np.ndarray]:
    th = math.radians(theta_deg)
    return np.array([math.cos(th), math.sin(th)]), np.array([-math.sin(th), math.cos(th)])


def wedge(direction_deg: float, length: float, width: float = 1.0, angle_deg: float = 0.0):
    """Integer ``v`` with ``0 < v.d <= length`` and ``|v.d_perp| <= max(width, (v.d) tan angle)``.

    ``angle_deg = 0`` gives the paper's straight band (``point_synthesis.md`` Sec. 2).
    Returns ``(m, 2)`` int32 (possibly empty); cost grows with the wedge's area only.
    """
    (direction_deg,) = check_directions_deg("direction_deg", direction_deg)
    length = check_positive_float("length", length)
    width = check_positive_float("width", width, allow_zero=True)
    if not 0.0 <= angle_deg < 45.0:
        raise ValueError(f"angle_deg must lie in [0, 45), got {angle_deg}")
    d, dp = _unit(direction_deg)
    tan_a = math.tan(math.radians(angle_deg))
    hmax = max(width, length * tan_a)
    # Walk the lattice along the dominant axis of d; per row, the candidates lie in an interval
    # around the ray (a conservative bound), filtered exactly afterwards.
    major = 0 if abs(d[0]) >= abs(d[1]) else 1
    minor = 1 - major
    dm = d[major]
    kmax = int(math.ceil(abs(dm) * length + hmax)) + 1
    k = np.arange(-kmax, kmax + 1)
    centre = k * d[minor] / dm
    t_row = np.abs(k) / abs(dm)
    half = (np.maximum(width, np.minimum(t_row + hmax, length) * tan_a) + 1.0) / abs(dm)
    lo = np.floor(centre - half).astype(np.int64)
    hi = np.ceil(centre + half).astype(np.int64)
    counts = hi - lo + 1
    kk = np.repeat(k, counts)
    offs = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    mm = np.repeat(lo, counts) + offs
    v = np.empty((kk.size, 2), np.int64)
    v[:, major] = kk
    v[:, minor] = mm
    t = v @ d
    s = v @ dp
    eps = 1e-9
    keep = (t > eps) & (t <= length + eps) & (np.abs(s) <= np.maximum(width, t * tan_a) + eps)
    return v[keep].astype(np.int32)


def disk(radius: float):
    """Integer ``v != 0`` with ``|v| <= radius``, one of each ``+-v`` pair. ``(m, 2)`` int32."""
    radius = check_positive_float("radius", radius)
    r = int(math.floor(radius))
    g = np.arange(-r, r + 1)
    v = np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2)
    v = v[(v[:, 0] ** 2 + v[:, 1] ** 2) <= radius**2 + 1e-9]
    return canonical_half(v)


def canonical_half(freqs) -> np.ndarray:
    """Map each ``v`` to the representative of ``{v, -v}`` with ``v_y > 0`` or ``v_y = 0, v_x > 0``;
    drop ``v = 0`` and duplicates. Returns sorted ``(m, 2)`` int32."""
    v = np.asarray(freqs, dtype=np.int64).reshape(-1, 2)
    flip = (v[:, 1] < 0) | ((v[:, 1] == 0) & (v[:, 0] < 0))
    v = np.where(flip[:, None], -v, v)
    v = v[np.any(v != 0, axis=1)]
    return np.unique(v, axis=0).astype(np.int32)


def edge_weights(freqs, directions_deg, spread_deg: float = 0.0,
                 core_deg: float = 0.0, offsets_deg=(), axis_weight: float = 1.0) -> np.ndarray:
    """``W(v) = sum_d 1 / (|v|^2 (1 + s_d^2))`` with ``s_d = v . d_perp`` (issue 4 design c).

    An edge along spectral direction ``d`` has ``P_f ~ |v|^-2`` on its ray and a lattice-scale
    spread across it; W weights each frequency by the energy a slightly misaligned edge could
    put there.  ``spread_deg > 0`` divides ``s`` by ``max(1, |v.d| tan(spread))``, so the
    weight stays high across the width a ray misaligned by ``spread_deg`` sweeps (robustness).

    ``core_deg > 0`` gives each non-axis direction (not 0 or 90: the square's border is exactly
    axis-aligned) a flat core: ``s`` is replaced by ``max(0, |s| - |v.d| tan(core))``, the
    distance from the core's boundary.  An edge misaligned by ``delta <= core`` has its ray at
    ``|s| = t sin(delta)`` (``t = |v.d|``), inside the core, where it gets the full weight
    ``1/|v|^2`` of an aligned edge; outside the core the ``1/(1 + s'^2)`` falloff of the
    edge's own spectrum follows (the robustness requirement of issue 4).

    ``offsets_deg`` (e.g. ``(-1, -0.5, 0.5, 1)``) adds, for each non-axis direction, the weight
    of an edge at ``theta + o`` for each offset ``o``: ``1/(|v|^2 (1 + s_o^2))`` with ``s_o``
    measured from that edge's ray, so the loss is the sum of the (W Eq. 5) variances of the
    aligned edge and of the edges misaligned by each offset.

    ``axis_weight`` multiplies the weight of each axis (0 and 90; the offsets give the other
    directions ``1 + len(offsets_deg)`` edges' weight, the axes one): :data:`AXIS_WEIGHT_4`
    for sets of four or more directions.
    """
    spread_deg = check_positive_float("spread_deg", spread_deg, allow_zero=True)
    core_deg = check_positive_float("core_deg", core_deg, allow_zero=True)
    axis_weight = check_positive_float("axis_weight", axis_weight)
    if spread_deg >= 45.0 or core_deg >= 45.0:
        raise ValueError(f"spread_deg and core_deg must lie in [0, 45), got {spread_deg}, "
                         f"{core_deg}")
    v = np.asarray(freqs, dtype=np.float64)
    r2 = np.sum(v * v, axis=1)
    w = np.zeros(v.shape[0])
    tan_b = math.tan(math.radians(spread_deg))
    tan_c = math.tan(math.radians(core_deg))
    for theta in directions_deg:
        d, dp = _unit(theta)
        s = v @ dp
        if spread_deg > 0:  # measure s in units of the band a ray off by spread_deg reaches
            s = s / np.maximum(1.0, np.abs(v @ d) * tan_b)
        if core_deg > 0 and theta not in (0.0, 90.0):  # distance from the flat core
            s = np.maximum(0.0, np.abs(s) - np.abs(v @ d) * tan_c)
        if theta in (0.0, 90.0):
            w += axis_weight / (r2 * (1.0 + s * s))
            continue
        w += 1.0 / (r2 * (1.0 + s * s))
        for off in offsets_deg:
            _, dpo = _unit(theta + off)
            so = v @ dpo
            w += 1.0 / (r2 * (1.0 + so * so))
    return w


def _group(freqs: np.ndarray, weights: np.ndarray, directions_deg, params) -> FrequencySet:
    """Assign each frequency to the direction whose ray (axially) is closest in angle; orient it
    so that ``v . d >= 0``; concatenate the groups."""
    v = np.asarray(freqs, np.int64)
    ang = np.degrees(np.arctan2(v[:, 1], v[:, 0])) % 180.0
    dirs = np.asarray(directions_deg, np.float64)
    diff = np.abs((ang[:, None] - dirs[None, :] + 90.0) % 180.0 - 90.0)
    owner = np.argmin(diff, axis=1)
    out_f, out_w, sizes = [], [], []
    for g, theta in enumerate(dirs):
        sel = owner == g
        d, _ = _unit(theta)
        vg = v[sel]
        sign = np.where(vg @ d < 0, -1, 1)
        out_f.append(vg * sign[:, None])
        out_w.append(weights[sel])
        sizes.append(int(sel.sum()))
    return FrequencySet(
        freqs=np.concatenate(out_f).astype(np.int32),
        weights=np.concatenate(out_w).astype(np.float64),
        group_directions_deg=tuple(float(t) for t in dirs),
        group_sizes=tuple(sizes),
        params=dict(params),
    )


def custom_set(freqs, directions_deg, weights=None) -> FrequencySet:
    """A :class:`FrequencySet` from your own frequencies (grouped by ``directions_deg``)."""
    directions_deg = check_directions_deg("directions_deg", directions_deg)
    f = np.asarray(freqs)
    if not (np.issubdtype(f.dtype, np.integer) or np.issubdtype(f.dtype, np.floating)):
        raise TypeError(f"freqs must be an (m, 2) array of integers, got dtype {f.dtype}")
    if f.size and (not np.all(np.isfinite(f)) or np.any(f != np.round(f))):
        raise ValueError("freqs must hold integer frequency vectors (v_x, v_y), got "
                         f"fractional or non-finite values such as {f[f != np.round(f)][:3]}")
    rows = canonical_half_rows(freqs)
    if weights is None:
        w = np.ones(rows.shape[0])
    else:
        w = np.asarray(weights, np.float64).reshape(-1)
        if w.shape[0] != rows.shape[0]:
            raise ValueError(f"weights must have one entry per frequency ({rows.shape[0]}),"
                             f" got {w.shape[0]}")
        if not np.all(np.isfinite(w)) or np.any(w < 0):
            raise ValueError("weights must be finite and >= 0")
    nonzero = np.any(rows != 0, axis=1)
    if not np.any(nonzero):
        raise ValueError("freqs must hold at least one non-zero frequency, got none")
    v, first = np.unique(rows[nonzero], axis=0, return_index=True)
    w = w[nonzero][first]
    return _group(v.astype(np.int32), w, directions_deg, {"design": "custom"})


def canonical_half_rows(freqs) -> np.ndarray:
    """Row-wise canonical representative (no dedup, zeros kept), for associating weights."""
    v = np.asarray(freqs, dtype=np.int64).reshape(-1, 2)
    flip = (v[:, 1] < 0) | ((v[:, 1] == 0) & (v[:, 0] < 0))
    return np.where(flip[:, None], -v, v)


@renamed_keywords(kind="name")
def design(
    n: int,
    directions_deg,
    name: str = "rate",
    *,
    length: float | None = None,
    width: float | None = None,
    angle_deg: float | None = None,
    disk_radius: float | None = None,
    weight_spread_deg: float | None = None,
    core_deg: float | None = None,
    offsets_deg=None,
    axis_weight: float | None = None,
    robust_axis_weight: float | None = None,
) -> FrequencySet:
    """The frequency set (and weights) for ``n`` points and the given spectral directions.

    ``name="rate"``: wedges of length ``n^0.8``, half-width ``max(1.5, t tan 2deg)``, disk of
    radius ``sqrt(n)``, weights :func:`edge_weights` with ``offsets_deg=ROBUST_OFFSETS_DEG``
    for ``n >= ROBUST_MIN_N`` (:data:`ROBUST_MIN_N`), the aligned-only weights of issue 4
    design c below (pass ``offsets_deg`` to choose either at any ``n``); with the offsets and
    two or more directions besides the axes, the axes weigh :data:`AXIS_WEIGHT_4`.
    ``name="paper"``: wedges of length ``3 sqrt(n)``, half-width ``max(1, t tan 2deg)``, no
    disk, uniform weights (W Sec. 4.1).  Any of ``length``, ``width``, ``angle_deg``,
    ``disk_radius`` (0 for none) overrides the design's value; ``weight_spread_deg``,
    ``core_deg``, ``offsets_deg`` and ``axis_weight`` (default 1; :data:`AXIS_WEIGHT_4` for
    4-direction sets) are passed to :func:`edge_weights` (``"rate"`` only).
    ``robust_axis_weight``: the axes' weight from :data:`ROBUST_MIN_N` points only, where the
    offsets are on (default :data:`AXIS_WEIGHT_4` with two or more directions besides the axes,
    else 1; below :data:`ROBUST_MIN_N` the axes weigh 1); ``axis_weight``, if given, is the
    axes' weight at every ``n`` instead.
    """
    n = check_int("n", n, minimum=2)
    directions_deg = check_directions_deg("directions_deg", directions_deg)
    name = check_choice("name", name, DESIGNS)
    if name == "rate":
        robust = n >= ROBUST_MIN_N
        extra = [t for t in directions_deg if t not in (0.0, 90.0)]
        heavy = AXIS_WEIGHT_4 if len(extra) >= 2 else 1.0
        if robust_axis_weight is not None:
            heavy = check_positive_float("robust_axis_weight", robust_axis_weight)
        p = {"length": n**0.8, "width": 1.5, "angle_deg": 2.0, "disk_radius": math.sqrt(n),
             "offsets_deg": list(ROBUST_OFFSETS_DEG) if robust else [],
             "axis_weight": heavy if robust else 1.0}
    else:
        p = {"length": 3.0 * math.sqrt(n), "width": 1.0, "angle_deg": 2.0, "disk_radius": 0.0}
    for key, val in (("length", length), ("width", width), ("angle_deg", angle_deg),
                     ("disk_radius", disk_radius), ("weight_spread_deg", weight_spread_deg),
                     ("core_deg", core_deg), ("axis_weight", axis_weight)):
        if val is not None:
            p[key] = check_positive_float(key, val,
                                          allow_zero=key not in ("length", "axis_weight"))
    if p.get("core_deg", 0.0) >= 45.0:
        raise ValueError(f"core_deg must lie in [0, 45), got {p['core_deg']}")
    if offsets_deg is not None:
        offs = np.asarray(offsets_deg, np.float64).reshape(-1)
        if not np.all(np.isfinite(offs)) or np.any(np.abs(offs) >= 45.0) or np.any(offs == 0):
            raise ValueError(f"offsets_deg must be non-zero angles in (-45, 45), got {offsets_deg}")
        p["offsets_deg"] = [float(o) for o in offs]
    parts = [wedge(t, p["length"], p["width"], p["angle_deg"]) for t in directions_deg]
    if p["disk_radius"] >= 1.0:
        parts.append(disk(p["disk_radius"]))
    v = canonical_half(np.concatenate(parts))
    if v.shape[0] == 0:
        raise ValueError(f"the frequency set for n={n} and these parameters is empty: {p}")
    for opt in ("weight_spread_deg", "core_deg", "offsets_deg"):
        if not p.get(opt):  # 0: the plain weights (kept out of the record)
            p.pop(opt, None)
    if p.get("axis_weight") == 1.0:  # the plain weights (kept out of the record)
        p.pop("axis_weight")
    w = (edge_weights(v, directions_deg, p.get("weight_spread_deg", 0.0),
                      p.get("core_deg", 0.0), p.get("offsets_deg", ()),
                      p.get("axis_weight", 1.0))
         if name == "rate" else np.ones(v.shape[0]))
    params = {"design": name, "n": n, "directions_deg": list(directions_deg), **p,
              "weights": "edge" if name == "rate" else "uniform", "size": int(v.shape[0])}
    return _group(v, w, directions_deg, params)
