"""Frequency sets: membership against a brute-force filter of the whole lattice, half-set and
grouping invariants, the documented designs."""

import math

import numpy as np
import pytest

from anisosample import frequencies as fr


def _brute_wedge(theta, length, width, angle):
    r = int(length + width) + 2
    g = np.arange(-r, r + 1)
    v = np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2)
    th = math.radians(theta)
    t = v @ np.array([math.cos(th), math.sin(th)])
    s = v @ np.array([-math.sin(th), math.cos(th)])
    keep = (t > 1e-9) & (t <= length + 1e-9) & (
        np.abs(s) <= np.maximum(width, t * math.tan(math.radians(angle))) + 1e-9)
    return {tuple(x) for x in v[keep]}


@pytest.mark.parametrize("theta", [0.0, 17.0, 30.0, 45.0, 67.0, 90.0, 123.5, 179.0])
@pytest.mark.parametrize("shape", [(40.0, 1.0, 0.0), (60.0, 1.5, 2.0), (25.0, 0.0, 10.0)])
def test_wedge_equals_brute_force(theta, shape):
    got = fr.wedge(theta, *shape)
    assert got.dtype == np.int32
    assert {tuple(x) for x in got} == _brute_wedge(theta, *shape)
    assert len({tuple(x) for x in got}) == len(got)


def test_disk_half_set():
    v = fr.disk(10.0)
    s = {tuple(x) for x in v}
    assert (0, 0) not in s
    assert all((-a, -b) not in s for a, b in s)
    full = sum(1 for a in range(-10, 11) for b in range(-10, 11) if 0 < a * a + b * b <= 100)
    assert 2 * len(v) == full


@pytest.mark.parametrize("name", ["rate", "paper"])
@pytest.mark.parametrize("dirs", [(0.0, 90.0, 30.0), (0.0, 90.0, 67.0, 140.0)])
def test_design_invariants(name, dirs):
    n = 1024
    fs = fr.design(n, dirs, name)
    v = fs.freqs.astype(np.int64)
    canon = fr.canonical_half(v)
    assert len(canon) == len(v)  # one of each +-v, no zero
    assert np.all(fs.weights > 0)
    assert sum(fs.group_sizes) == len(fs)
    for theta, fg, _ in fs.groups():
        th = math.radians(theta)
        assert np.all(fg @ np.array([math.cos(th), math.sin(th)]) >= -1e-9)
    # every wedge frequency of every direction is in the set (up to sign)
    p = fs.params
    have = {tuple(x) for x in canon}
    for theta in dirs:
        w = fr.canonical_half(fr.wedge(theta, p["length"], p["width"], p["angle_deg"]))
        assert {tuple(x) for x in w} <= have


def test_design_parameters_are_functions_of_n():
    a = fr.design(256, [0.0, 90.0, 30.0]).params
    b = fr.design(4096, [0.0, 90.0, 30.0]).params
    assert a["length"] == pytest.approx(256**0.8) and b["length"] == pytest.approx(4096**0.8)
    assert b["disk_radius"] == pytest.approx(64.0)
    assert fr.design(4096, [0.0, 90.0, 30.0], "paper").params["length"] == pytest.approx(192.0)
    # the paper's frequency count for 2^12 is 4,303 (3 directions); ours is within 10 %
    assert abs(len(fr.design(4096, [0.0, 90.0, 30.0], "paper")) - 4303) < 430


def test_edge_weights_closed_form():
    v = np.array([[3, 0], [3, 1], [0, 2]])
    w = fr.edge_weights(v, [0.0])
    np.testing.assert_allclose(w, [1 / 9, 1 / (10 * 2), 1 / (4 * 5)])


def test_bad_input():
    with pytest.raises(ValueError, match="n must be >= 2"):
        fr.design(1, [0.0])
    with pytest.raises(ValueError, match="directions_deg"):
        fr.design(64, [0.0, 180.0])
    with pytest.raises(ValueError, match="directions_deg"):
        fr.design(64, [10.0, 10.0])
    with pytest.raises(ValueError, match="name must be one of"):
        fr.design(64, [0.0], "fancy")
    with pytest.raises(TypeError, match=r"design\(\) takes name= where it took kind="):
        fr.design(64, [0.0], kind="paper")
    with pytest.raises(ValueError, match="empty"):
        fr.design(64, [0.0], "paper", length=0.5, width=0.0)
    with pytest.raises(ValueError, match="at least one"):
        fr.custom_set(np.zeros((1, 2), int), [0.0])
    with pytest.raises(ValueError, match="angle_deg"):
        fr.wedge(0.0, 10.0, 1.0, 50.0)


def test_edge_weights_spread():
    v = np.array([[10, 1], [100, 3]])
    w = fr.edge_weights(v, [0.0], spread_deg=2.0)
    s2 = 3 / (100 * math.tan(math.radians(2.0)))
    np.testing.assert_allclose(w, [1 / (101 * 2), 1 / (10009 * (1 + s2 * s2))])
    assert "weight_spread_deg" not in fr.design(256, [0.0, 90.0]).params
    assert fr.design(256, [0.0, 90.0], weight_spread_deg=1.0).params["weight_spread_deg"] == 1.0


@pytest.mark.parametrize("theta", [12.0, 30.0, 67.0, 145.0])
def test_edge_weights_core_holds_misaligned_rays(theta):
    """core_deg: a ray misaligned by delta <= core gets an aligned ray's weight 1/|v|^2 (its
    points are inside the core); beyond the core the weight falls with the distance from the
    core's boundary, 1/(1 + s'^2), and it never exceeds the aligned weight."""
    core = 1.0
    t = np.array([5.0, 50.0, 500.0, 5000.0])
    for delta in (-1.0, -0.5, 0.0, 0.3, 1.0):
        th = math.radians(theta + delta)
        v = t[:, None] * np.array([math.cos(th), math.sin(th)])
        w = fr.edge_weights(v, [theta], core_deg=core)
        np.testing.assert_allclose(w, 1.0 / t**2, rtol=1e-9)
    for delta in (1.5, -2.0, 3.0):
        th = math.radians(theta + delta)
        v = t[:, None] * np.array([math.cos(th), math.sin(th)])
        # independent geometry: distance from v to the nearer of the core's two boundary rays,
        # measured across the direction (perpendicular offset minus the core's half-width)
        along = t * math.cos(math.radians(delta))
        across = t * abs(math.sin(math.radians(delta)))
        s_out = across - along * math.tan(math.radians(core))
        np.testing.assert_allclose(fr.edge_weights(v, [theta], core_deg=core),
                                   1.0 / (t**2 * (1.0 + s_out**2)), rtol=1e-9)
        assert np.all(fr.edge_weights(v, [theta], core_deg=core) < 1.0 / t**2)


def test_edge_weights_core_spares_axes_and_zero_is_plain():
    rng = np.random.default_rng(3)
    v = rng.integers(-300, 300, size=(500, 2))
    v = v[np.any(v != 0, axis=1)]
    # the square's border is exactly axis-aligned: no core on 0 and 90
    np.testing.assert_array_equal(fr.edge_weights(v, [0.0, 90.0], core_deg=1.5),
                                  fr.edge_weights(v, [0.0, 90.0]))
    np.testing.assert_array_equal(fr.edge_weights(v, [0.0, 90.0, 30.0], core_deg=0.0),
                                  fr.edge_weights(v, [0.0, 90.0, 30.0]))
    # a core only raises weights
    assert np.all(fr.edge_weights(v, [0.0, 90.0, 30.0], core_deg=1.0)
                  >= fr.edge_weights(v, [0.0, 90.0, 30.0]))


def test_design_core_option():
    plain = fr.design(1024, [0.0, 90.0, 30.0], core_deg=0.0)
    cored = fr.design(1024, [0.0, 90.0, 30.0], core_deg=1.0)
    assert "core_deg" not in plain.params and cored.params["core_deg"] == 1.0
    np.testing.assert_array_equal(plain.freqs, cored.freqs)
    assert np.all(cored.weights >= plain.weights) and np.any(cored.weights > plain.weights)
    for bad in (-1.0, 45.0, float("nan")):
        with pytest.raises(ValueError, match="core_deg"):
            fr.design(256, [0.0, 90.0, 30.0], core_deg=bad)


def test_edge_weights_offsets_are_extra_edges():
    """offsets_deg: the weight is that of the aligned edge plus one edge at theta + o for each
    offset (the loss sums their W Eq. 5 variances); the axes get no offsets."""
    rng = np.random.default_rng(5)
    v = rng.integers(-400, 400, size=(400, 2))
    v = v[np.any(v != 0, axis=1)]
    offs = (-1.0, -0.5, 0.5, 1.0)
    for theta in (12.0, 30.0, 145.0):
        want = fr.edge_weights(v, [theta]) + sum(fr.edge_weights(v, [theta + o]) for o in offs)
        np.testing.assert_allclose(fr.edge_weights(v, [theta], offsets_deg=offs), want,
                                   rtol=1e-12)
    np.testing.assert_array_equal(fr.edge_weights(v, [0.0, 90.0], offsets_deg=offs),
                                  fr.edge_weights(v, [0.0, 90.0]))
    # an edge misaligned by an offset gets (at least) an aligned edge's weight on its own ray
    t = np.array([10.0, 100.0, 1000.0])
    th = math.radians(30.5)
    ray = t[:, None] * np.array([math.cos(th), math.sin(th)])
    assert np.all(fr.edge_weights(ray, [30.0], offsets_deg=offs) >= 1.0 / t**2)


def test_design_offsets_option():
    fs = fr.design(1024, [0.0, 90.0, 30.0], offsets_deg=[-1, -0.5, 0.5, 1])
    assert fs.params["offsets_deg"] == [-1.0, -0.5, 0.5, 1.0]
    for bad in ([0.0, 1.0], [50.0], [float("inf")]):
        with pytest.raises(ValueError, match="offsets_deg"):
            fr.design(256, [0.0, 90.0, 30.0], offsets_deg=bad)


def test_axis_weight_scales_the_axes_alone():
    """axis_weight multiplies the weight of the axis directions only: the weights are the
    axes' (each computed alone) times the factor plus the other directions' with their
    offsets; 1 gives the same bits as no option, and the design records it only when it is not
    1 (so tables' fingerprints stay as they were)."""
    rng = np.random.default_rng(6)
    v = rng.integers(-300, 300, size=(300, 2))
    v = v[np.any(v != 0, axis=1)]
    offs = fr.ROBUST_OFFSETS_DEG
    axes = fr.edge_weights(v, [0.0]) + fr.edge_weights(v, [90.0])
    extra = fr.edge_weights(v, [40.0, 120.0], offsets_deg=offs)
    got = fr.edge_weights(v, [0.0, 40.0, 90.0, 120.0], offsets_deg=offs, axis_weight=3.0)
    np.testing.assert_allclose(got, 3.0 * axes + extra, rtol=1e-12)
    np.testing.assert_array_equal(
        fr.edge_weights(v, [0.0, 40.0, 90.0], offsets_deg=offs, axis_weight=1.0),
        fr.edge_weights(v, [0.0, 40.0, 90.0], offsets_deg=offs))
    four = [0.0, 90.0, 40.0, 120.0]
    plain = fr.design(1024, four, axis_weight=1.0)
    heavy = fr.design(1024, four)  # the default with two extra directions and the offsets
    assert "axis_weight" not in plain.params and heavy.params["axis_weight"] == fr.AXIS_WEIGHT_4
    np.testing.assert_array_equal(heavy.freqs, plain.freqs)
    np.testing.assert_allclose(
        heavy.weights, plain.weights + (fr.AXIS_WEIGHT_4 - 1.0) * (
            fr.edge_weights(heavy.freqs, [0.0]) + fr.edge_weights(heavy.freqs, [90.0])),
        rtol=1e-12)
    # one extra direction, or no offsets (below ROBUST_MIN_N): the axes weigh 1, as before
    assert "axis_weight" not in fr.design(1024, [0.0, 90.0, 40.0]).params
    assert "axis_weight" not in fr.design(512, four).params
    assert fr.design(1024, [0.0, 90.0, 40.0], axis_weight=2.0).params["axis_weight"] == 2.0
    for bad in (0.0, -2.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="axis_weight"):
            fr.design(1024, [0.0, 90.0, 30.0], axis_weight=bad)


def test_robust_axis_weight_acts_from_robust_min_n_only():
    """robust_axis_weight is the axes' weight where the robust offsets are on: from
    ROBUST_MIN_N points the design equals axis_weight given explicitly, below it the plain
    design (bit for bit); its default is the 4-direction design's AXIS_WEIGHT_4 and weight 1
    for one extra direction; axis_weight, given too, applies at every n."""
    three, four = [0.0, 90.0, 85.0], [0.0, 90.0, 47.0, 148.0]
    for n in (fr.ROBUST_MIN_N, 2 * fr.ROBUST_MIN_N):
        got = fr.design(n, three, robust_axis_weight=3.0)
        want = fr.design(n, three, axis_weight=3.0)
        np.testing.assert_array_equal(got.weights, want.weights)
        assert got.params["axis_weight"] == 3.0
        np.testing.assert_array_equal(fr.design(n, four, robust_axis_weight=fr.AXIS_WEIGHT_4)
                                      .weights, fr.design(n, four).weights)
    below = fr.ROBUST_MIN_N // 2
    np.testing.assert_array_equal(fr.design(below, three, robust_axis_weight=3.0).weights,
                                  fr.design(below, three).weights)
    assert "axis_weight" not in fr.design(below, three, robust_axis_weight=3.0).params
    assert fr.design(below, three, robust_axis_weight=3.0, axis_weight=2.0).params[
        "axis_weight"] == 2.0
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="robust_axis_weight"):
            fr.design(1024, three, robust_axis_weight=bad)


def test_rate_design_defaults_to_robust_offsets():
    v = fr.design(1024, [0.0, 90.0, 30.0])
    assert v.params["offsets_deg"] == list(fr.ROBUST_OFFSETS_DEG)
    assert fr.ROBUST_OFFSETS_DEG == (-1.0, -0.75, -0.5, -0.25, 0.25, 0.5, 0.75, 1.0)
    canon = fr.canonical_half_rows(v.freqs)
    np.testing.assert_allclose(v.weights, fr.edge_weights(canon, [0.0, 90.0, 30.0],
                                                          offsets_deg=fr.ROBUST_OFFSETS_DEG))
    plain = fr.design(1024, [0.0, 90.0, 30.0], offsets_deg=())
    assert "offsets_deg" not in plain.params
    np.testing.assert_allclose(plain.weights, fr.edge_weights(canon, [0.0, 90.0, 30.0]))


def test_rate_design_below_robust_min_n_is_aligned_only():
    assert fr.ROBUST_MIN_N == 1024
    small = fr.design(512, [0.0, 90.0, 30.0])
    assert "offsets_deg" not in small.params
    canon = fr.canonical_half_rows(small.freqs)
    np.testing.assert_allclose(small.weights, fr.edge_weights(canon, [0.0, 90.0, 30.0]))
    robust = fr.design(512, [0.0, 90.0, 30.0], offsets_deg=fr.ROBUST_OFFSETS_DEG)
    assert robust.params["offsets_deg"] == list(fr.ROBUST_OFFSETS_DEG)
    assert not np.allclose(robust.weights, small.weights)
