"""A bounding volume hierarchy over the planar primitives, built on the host, traversed in JAX.

Build (:func:`build_bvh`, NumPy): top down with the binned surface area heuristic (Wald 2007,
"On fast construction of SAH-based bounding volume hierarchies"; pbrt-v4 Sec. 7.3.2): each node's
primitives are binned by centroid into :data:`BINS` bins along the longest axis of their centroid
bounds, and the node is split at the bin boundary that minimises ``A_L N_L + A_R N_R`` (the SAH
cost up to constants). Every node of one tree level is split at once, so each level is a few
vectorised passes over the primitives (a million triangles build in seconds). Identical centroids
fall back to an object-median split. A node of at most :data:`LEAF_SIZE` primitives is a leaf:
traversal tests a leaf's :data:`LEAF_SIZE` slots as one vector, so a smaller leaf costs nothing
less. Every traversal step gathers those slots' rows, interior node or leaf, so the size trades
gathered rows against steps: one device, 64^2 x 16 spp, best of 3 (load 1.0), LEAF_SIZE 2 / 4 /
8 ms per image: 9,800-triangle mesh 161 / 150-158 / 176-183, 99k-triangle mesh 220 / 218-222 /
234.

Layout (binary tree, flattened): ``node[i] = (child 0, child 1, start, count)``; node ``i`` is a
leaf when ``count > 0`` (its primitives are ``start .. start + count - 1`` of the reordered
rows), else an interior node whose children have their boxes stored in the parent (``box[i]``:
one read gives both).
Boxes are padded by a small multiple of the scene scale so that the float32 slab test never
culls a primitive that the primitive test would hit (the traversal's results equal brute force).

Traversal (:func:`closest_hit`, :func:`any_hit`): a ``lax.while_loop`` over one ray (callers
vmap), a current node and a fixed-size stack whose depth is the tree's (static): at an interior
node the ray's slab test (Kay & Kajiya 1986) of both child boxes continues at the nearer hit child
and pushes the farther; a leaf tests its primitives with the same plane test as the brute-force
kernel (:func:`plane_test`) and pops. Closest hit keeps the nearest
``t`` (ties to the lowest primitive index, as ``argmin`` over all primitives does); any hit stops
at the first primitive inside the segment (shadow rays).

Vmapped, a while loop runs every ray of the batch until its slowest is done: on 4096 camera-like
rays into a 9,800-triangle mesh the traversal takes 19 steps on average and 61 at most. So a
vmap of :func:`closest_hit` or :func:`any_hit` (``jax.custom_batching.custom_vmap``; nested
vmaps flatten into one) runs :func:`_traverse_queue` instead: :data:`LANES` lanes step their rays
and a lane whose ray is done takes the next one from the batch. Each ray takes the same steps,
so the results are the same bits. One device, light sampling, best of 3: the 9,800-triangle mesh
at 64^2 x 16 spp 536 -> 184 ms, the 99k-triangle one at 128^2 x 64 spp 9.6 -> 3.6-3.8 s
(lanes 1024-8192 within noise of each other, 16384 slower). Two steps per refill (finished rays
masked) were no faster: 164 ms against 146 for the 99k-triangle mesh at 64^2 x 16 spp.

A step reads its node and its leaf rows as slices (``lax.dynamic_slice``) and its stack through
masks: a vmapped index into ``count``, ``start``, ``child``, ``rows[start + lane]`` or
``stack[sp]`` becomes an XLA gather or scatter of single elements, which XLA:CPU runs as a
generic loop. On 4096 lanes into the 99k-triangle mesh (no YNNPACK, as the render kernels
compile), ns per lane-step, best of 15 over 200 steps, load 0.8-1.3: gathers 46-67 (two
modes), slices and masks 39-40; the render of the mesh at 128^2 x 64 spp over both CPU devices
0.72 -> 0.92 M samples/s (load 1.4-1.8), the same image bits. Unrolling the leaf's minimum over
its four slots instead of ``argmin`` was slower (49-50 ns).

Tried and not kept (2026-12-07, ad-hoc script, the same image bits): packet traversal, where
``P`` consecutive rays (one pixel's samples) share one node and stack, descend where any of
them hits a box (nearer child by its nearest ray) and test a leaf's slots densely over the
``P`` rays, with packets fed from a queue like the rays here. One device, the 99k-triangle mesh
at 64^2 x 16 spp, best of 3 (load about 1.1): this queue 0.192 s; packets of 8 / 16 / 16 / 32 /
64 rays with 512 / 256 / 64 / 64 / 64 packets in flight 0.183 / 0.199 / 0.242 / 0.274 / 0.364 s.
A packet visits the union of its rays' nodes, and the steps' fixed work (a leaf's rows, the
stack, the queue's refill) did not shrink enough to pay for it.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

BINS = 16  # SAH bins per node
LEAF_SIZE = 4  # primitives per leaf slot block (was 8 before the ray queue)
# Scenes with at least this many planar primitives get a BVH (SceneBuilder.build's default);
# below it testing every primitive is faster. Measured 2026-12-06 on the 2-core reference CPU
# (one device, load 0.8-1.8), light sampling 128^2 x 64 spp of a sphere mesh on a floor, ns per
# sample, brute force at render's chunk for it (4096 samples above render._kernel.BRUTE_WIDE
# primitives) / the BVH (65536, leaves of 8): 48 tris 127 / 940, 288: 566 / 1637, 840: 1363 /
# 1827, 1224: 2066 / 1972, 2400: 4836 / 2133 (/tmp script over bench_render.write_mesh_scene;
# the queue of _traverse_queue moved the crossover down from about 2500). Brute force was
# compiled without YNNPACK there; with it, as now above render._kernel.BRUTE_YNN primitives,
# 960 triangles at 64^2 x 16 spp took 1261-1386 ns per sample instead of 1631-1633.
# With per-tile culling (render/culling.py), 64^2 x 16 spp, best of 3 (bench_render.py --prims,
# load about 1): brute force / BVH 1368 tris 1282 / 1858, 1848: 1906 / 1927, 2808: 5205 / 2010
# (no culling above culling.MAX_PRIMITIVES): the crossover moved from 1200 to about 1850.
# With the traversal's slices and masks (2026-12-07, an AMD EPYC, same table, best of 5, load
# 1.4-1.7): 840 tris 944 / 1064, 1224: 1593 / 1140, 1520: 2503 / 1268, so about 1000 now.
THRESHOLD = 1000
LANES = 4096  # traversal lanes fed from the ray queue (_traverse_queue)
_NO_PRIM = np.int32(np.iinfo(np.int32).max)
_PAD = 2.0**-16  # box padding, relative to the largest coordinate magnitude


class BVH(eqx.Module):
    """A flattened binary BVH over a scene's planar primitives (see the module docstring)."""

    box: Float[Array, "n 12"]  # interior nodes: both children's boxes, [child, min/max, xyz]
    node: Int[Array, "n 4"]  # (child 0, child 1, start, count): leaves have count > 0 and their
    # primitives in rows start .. start + count - 1; interior nodes count 0
    rows: Float[Array, "p 13"]  # plane-test rows (builder._plane_rows) in leaf order, padded
    prim: Int[Array, " p"]  # the scene's primitive index of each row
    depth: int = eqx.field(static=True, default=1)  # stack size for traversal

    @property
    def num_nodes(self) -> int:
        return int(self.node.shape[0])


def _segments(starts: np.ndarray, counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Concatenated ranges ``start[k] .. start[k] + count[k] - 1`` and the segment of each."""
    seg = np.repeat(np.arange(len(counts)), counts)
    first = np.cumsum(counts) - counts
    pos = np.arange(int(counts.sum())) - first[seg] + starts[seg]
    return pos, seg


def _area(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    e = np.maximum(hi - lo, 0.0)
    return e[..., 0] * e[..., 1] + e[..., 1] * e[..., 2] + e[..., 2] * e[..., 0]


def build_tree(lo: np.ndarray, hi: np.ndarray, leaf_size: int = LEAF_SIZE, bins: int = BINS):
    """Binned-SAH tree over boxes ``lo, hi`` (``(p, 3)``): ``(order, bounds, start, count,
    child, depth)`` with ``order`` the primitives in leaf order and ``bounds`` ``(n, 2, 3)``.

    Node 0 is the root; a node is a leaf iff ``child[i, 0] < 0``.
    """
    lo = np.asarray(lo, np.float64)
    hi = np.asarray(hi, np.float64)
    p = lo.shape[0]
    cent = 0.5 * (lo + hi)
    lo_t, hi_t = np.ascontiguousarray(lo.T), np.ascontiguousarray(hi.T)
    order = np.arange(p)
    n_start, n_count, n_bounds, n_child = [0], [p], [], []
    active = np.array([0])  # nodes of the current level
    level_bounds = np.stack([lo.min(axis=0), hi.max(axis=0)])[None]  # their boxes
    depth = 0
    while active.size:
        depth += 1
        starts = np.asarray(n_start)[active]
        counts = np.asarray(n_count)[active]
        n_bounds.append(level_bounds)
        n_child.append(np.full((len(active), 2), -1, np.int64))
        split = counts > leaf_size
        if not split.any():
            break
        # Split the nodes with more than leaf_size primitives.
        nodes = active[split]
        starts, counts = starts[split], counts[split]
        pos, seg = _segments(starts, counts)
        prims = order[pos]
        k = len(nodes)
        offs = np.cumsum(counts) - counts
        c = cent[prims]
        clo = np.minimum.reduceat(c, offs)
        chi = np.maximum.reduceat(c, offs)
        ext = chi - clo
        axis = np.argmax(ext, axis=1)
        ca = c[np.arange(len(c)), axis[seg]]
        lo_a, ex_a = clo[np.arange(k), axis], ext[np.arange(k), axis]
        scale = np.where(ex_a > 0, bins / np.where(ex_a > 0, ex_a, 1.0), 0.0)
        b = np.clip(((ca - lo_a[seg]) * scale[seg]).astype(np.int64), 0, bins - 1)
        key = seg * bins + b
        cnt = np.bincount(key, minlength=k * bins).reshape(k, bins)
        bl = np.full((3, k * bins), np.inf)
        bh = np.full((3, k * bins), -np.inf)
        for ax in range(3):  # 1-D ufunc.at is several times faster than on rows
            np.minimum.at(bl[ax], key, lo_t[ax, prims])
            np.maximum.at(bh[ax], key, hi_t[ax, prims])
        bl, bh = bl.T.reshape(k, bins, 3), bh.T.reshape(k, bins, 3)
        # Prefix (left of boundary j+1) and suffix (right) sweeps over the bins.
        ll = np.minimum.accumulate(bl, axis=1)[:, :-1]
        lh = np.maximum.accumulate(bh, axis=1)[:, :-1]
        rl = np.minimum.accumulate(bl[:, ::-1], axis=1)[:, ::-1][:, 1:]
        rh = np.maximum.accumulate(bh[:, ::-1], axis=1)[:, ::-1][:, 1:]
        nl = np.cumsum(cnt, axis=1)[:, :-1]
        nr = counts[:, None] - nl
        cost = np.where((nl > 0) & (nr > 0),
                        _area(ll, lh) * nl + _area(rl, rh) * nr, np.inf)
        best = np.argmin(cost, axis=1)
        ok = np.isfinite(cost[np.arange(k), best])
        # Stable partition inside each segment; nodes without a SAH split take the median.
        rank = np.arange(len(seg)) - offs[seg]
        left = np.where(ok[seg], b <= best[seg], rank < (counts // 2)[seg])
        nleft = np.bincount(seg, weights=left, minlength=k).astype(np.int64)
        cl = np.cumsum(left) - left
        lrank = cl - cl[offs][seg]  # rank among the left ones of the segment
        new = np.where(left, lrank, nleft[seg] + (rank - lrank))
        order[starts[seg] + new] = prims
        # The children's boxes: the bins' sweeps at the split (min and max are exact, so these
        # equal the boxes of their primitives); median splits measure theirs.
        kids = np.empty((k, 2, 2, 3))
        ar = np.arange(k)
        kids[:, 0, 0], kids[:, 0, 1] = ll[ar, best], lh[ar, best]
        kids[:, 1, 0], kids[:, 1, 1] = rl[ar, best], rh[ar, best]
        if not ok.all():
            med = np.flatnonzero(~ok)
            cs = np.stack([starts[med], starts[med] + nleft[med]], 1).reshape(-1)
            cc = np.stack([nleft[med], counts[med] - nleft[med]], 1).reshape(-1)
            mp = order[_segments(cs, cc)[0]]
            mo = np.cumsum(cc) - cc
            kids[med, :, 0] = np.minimum.reduceat(lo[mp], mo).reshape(-1, 2, 3)
            kids[med, :, 1] = np.maximum.reduceat(hi[mp], mo).reshape(-1, 2, 3)
        level_bounds = kids.reshape(2 * k, 2, 3)
        # Children.
        base = len(n_start)
        ids = base + np.arange(2 * k)
        n_start.extend(np.stack([starts, starts + nleft], 1).reshape(-1).tolist())
        n_count.extend(np.stack([nleft, counts - nleft], 1).reshape(-1).tolist())
        level_child = n_child[-1]
        level_child[np.flatnonzero(split)] = ids.reshape(k, 2)
        active = ids
    bounds = np.concatenate(n_bounds)
    child = np.concatenate(n_child)
    start = np.asarray(n_start, np.int64)
    count = np.asarray(n_count, np.int64)
    return order, bounds, start, count, child, depth


def build_bvh(rows: np.ndarray, lo: np.ndarray, hi: np.ndarray, scale: float,
              leaf_size: int = LEAF_SIZE) -> BVH:
    """A :class:`BVH` over primitives with plane-test rows ``rows`` (``(13, p)``, the scene's
    ``tri_soa``) and bounding boxes ``lo, hi`` (``(p, 3)``); ``scale`` is the largest coordinate
    magnitude of the scene (box padding)."""
    order, bounds, start, count, child, depth = build_tree(lo, hi, leaf_size)
    pad = _PAD * max(float(scale), 1e-30)
    bounds = bounds + np.array([-pad, pad])[None, :, None]
    leaf = child[:, 0] < 0
    box = np.zeros((len(count), 2, 2, 3))
    box[~leaf] = bounds[child[~leaf]]
    rows = np.asarray(rows, np.float64).T[order]
    dummy = np.zeros((leaf_size, 13))
    dummy[:, 7] = 1.0  # never a hit (as builder._plane_rows' degenerate rows)
    node = np.concatenate([np.where(leaf[:, None], 0, child),
                           np.where(leaf, start, 0)[:, None], np.where(leaf, count, 0)[:, None]], 1)
    return BVH(
        box=jnp.asarray(box.reshape(-1, 12), jnp.float32),
        node=jnp.asarray(node, jnp.int32),
        rows=jnp.asarray(np.concatenate([rows, dummy]), jnp.float32),
        prim=jnp.asarray(np.concatenate([order, np.zeros(leaf_size, np.int64)]), jnp.int32),
        depth=int(depth),
    )


def plane_test(r, o, d):
    """Plane-based ray test against primitives with rows ``r`` (13 arrays, builder._plane_rows):
    distances (inf where missed; no ``tmin``/``tmax`` yet) and coordinates ``(b1, b2)``.

    Triangles hit where ``b1, b2 >= 0, b1 + b2 <= 1``; parallelograms (row 12 = 1) where
    ``0 <= b1, b2 <= 1``. Brute force (:func:`anisosample.render.geometry.intersect`) and the
    BVH's leaves both call this, so that they agree bit for bit.
    """
    denom = d[0] * r[0] + d[1] * r[1] + d[2] * r[2]
    ok = denom != 0
    t = (r[3] - (o[0] * r[0] + o[1] * r[1] + o[2] * r[2])) / jnp.where(ok, denom, 1.0)
    qx, qy, qz = o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]
    b1 = qx * r[4] + qy * r[5] + qz * r[6] - r[7]
    b2 = qx * r[8] + qy * r[9] + qz * r[10] - r[11]
    hit = ok & (b1 >= 0) & (b2 >= 0) & (jnp.where(r[12] > 0, jnp.maximum(b1, b2), b1 + b2) <= 1)
    return jnp.where(hit, t, jnp.float32(jnp.inf)), b1, b2


def _slab(box, o, inv_d, tmin, tmax):
    """Entry distances into the two boxes ``box`` (``(2, 2, 3)``) and whether each is hit."""
    t0 = (box[:, 0] - o[None]) * inv_d[None]
    t1 = (box[:, 1] - o[None]) * inv_d[None]
    tn = jnp.maximum(jnp.max(jnp.minimum(t0, t1), axis=-1), tmin)
    tf = jnp.minimum(jnp.min(jnp.maximum(t0, t1), axis=-1), tmax)
    return tn, tn <= tf


def _inv_dir(d):
    tiny = jnp.float32(1e-20)
    return 1.0 / jnp.where(jnp.abs(d) > tiny, d, jnp.where(d >= 0, tiny, -tiny))


def _start(bvh: BVH):
    """A traversal's initial state ``(node, sp, stack, best_t, best_prim, b1, b2)``."""
    return (jnp.int32(0), jnp.int32(0), jnp.zeros(bvh.depth + 1, jnp.int32),
            jnp.float32(jnp.inf), _NO_PRIM, jnp.float32(0), jnp.float32(0))


def _active(state, any_hit: bool):
    """Whether a traversal state has work left (any hit: and has found nothing yet)."""
    go = state[0] >= 0
    return go & ~jnp.isfinite(state[3]) if any_hit else go


def _row(a, i, size: int):
    """Rows ``i .. i + size - 1`` of ``a`` (a slice; ``i`` is clamped into range)."""
    return jax.lax.dynamic_slice_in_dim(a, i, size)


def _step(bvh: BVH, ray, state):
    """One node of one ray's traversal: a leaf's plane tests, or an interior node's slab tests
    and the stack; ``ray`` is ``(o, d, inv_d, tmin, tmax)``."""
    o, d, inv_d, tmin, tmax = ray
    node, sp, stack, best_t, best_p, b1s, b2s = state
    lane = jnp.arange(LEAF_SIZE, dtype=jnp.int32)
    inf = jnp.float32(jnp.inf)
    # Slices of contiguous rows, not gathers of single elements: XLA:CPU emits a generic loop
    # per gathered element (the whole step took 1.15-1.7x as long so; module docstring).
    ch0, ch1, first, cnt = _row(bvh.node, node, 1)[0]
    leaf = cnt > 0
    # Leaf: the plane test on its LEAF_SIZE slots (the unused ones masked).
    r = _row(bvh.rows, first, LEAF_SIZE).T
    t, b1, b2 = plane_test(r, o, d)
    pid = _row(bvh.prim, first, LEAF_SIZE)
    t = jnp.where(leaf & (lane < cnt) & (t > tmin) & (t < tmax), t, inf)
    j = jnp.argmin(jnp.where(t == jnp.min(t), pid, _NO_PRIM))
    tj, pj = t[j], pid[j]
    better = jnp.isfinite(tj) & ((tj < best_t) | ((tj == best_t) & (pj < best_p)))
    best_t = jnp.where(better, tj, best_t)
    best_p = jnp.where(better, pj, best_p)
    b1s = jnp.where(better, b1[j], b1s)
    b2s = jnp.where(better, b2[j], b2s)
    # Interior: both children's boxes (culled beyond the nearest hit so far).
    tn, hit = _slab(_row(bvh.box, node, 1).reshape(2, 2, 3), o, inv_d, tmin,
                    jnp.minimum(tmax, best_t))
    hit = hit & ~leaf
    ch = (ch0, ch1)
    near_first = tn[0] <= tn[1]
    near = jnp.where(near_first, ch[0], ch[1])
    far = jnp.where(near_first, ch[1], ch[0])
    both = hit[0] & hit[1]
    one = jnp.where(hit[0], ch[0], ch[1])
    # The stack's top and push as masks over its slots, not a gather and a scatter.
    slots = jnp.arange(stack.shape[0], dtype=jnp.int32)
    top = jnp.sum(jnp.where(slots == sp - 1, stack, 0))
    popped = jnp.where(sp > 0, top, -1)
    nxt = jnp.where(both, near, jnp.where(hit[0] | hit[1], one, popped))
    stack = jnp.where(both & (slots == sp), far, stack)
    sp = jnp.where(both, sp + 1, jnp.where(hit[0] | hit[1], sp, jnp.maximum(sp - 1, 0)))
    return nxt, sp, stack, best_t, best_p, b1s, b2s


def _result(state):
    t, p = state[3], state[4]
    return t, jnp.where(jnp.isfinite(t), p, 0), state[5], state[6]


def _ray(o, d, tmin, tmax):
    return (o, d, _inv_dir(d), jnp.asarray(tmin, jnp.float32), jnp.asarray(tmax, jnp.float32))


def _traverse(bvh: BVH, o, d, tmin, tmax, any_hit: bool):
    """One ray's traversal: a ``lax.while_loop`` over :func:`_step`."""
    ray = _ray(o, d, tmin, tmax)
    state = jax.lax.while_loop(lambda s: _active(s, any_hit), lambda s: _step(bvh, ray, s),
                               _start(bvh))
    return _result(state)


def _traverse_queue(bvh: BVH, o, d, tmin, tmax, any_hit: bool):
    """The traversal of ``R`` rays (``o``, ``d`` ``(R, 3)``, ``tmin``, ``tmax`` ``(R,)``) on
    :data:`LANES` lanes fed from a queue: a lane whose ray is done writes its result and takes
    the next ray, so that the loop runs about ``R x mean steps / LANES`` iterations instead of
    the slowest ray's steps over all ``R`` (a vmapped while loop runs every ray until the last
    is done). Each ray takes the steps of :func:`_traverse`: the same results."""
    n = o.shape[0]
    lanes = min(LANES, n)
    ray_of = jax.vmap(_ray)
    step = jax.vmap(lambda ray, st: _step(bvh, ray, st))
    active = jax.vmap(lambda st: _active(st, any_hit))
    start = jax.vmap(lambda _: _start(bvh))(jnp.arange(lanes))

    def select(mask, a, b):
        return jax.tree.map(lambda x, y: jnp.where(mask.reshape((-1,) + (1,) * (x.ndim - 1)),
                                                   x, y), a, b)

    def take(ids):
        return ray_of(o[ids], d[ids], tmin[ids], tmax[ids])

    def body(c):
        rid, ray, st, nxt, out = c
        # Every lane with a ray is active here (a lane whose ray finished took the next one, or
        # none); idle lanes (rid < 0) step on garbage that nothing reads.
        st = step(ray, st)
        done = (rid >= 0) & ~active(st)
        res = jax.vmap(_result)(st)
        out = tuple(a.at[jnp.where(done, rid, n)].set(v, mode="drop")
                    for a, v in zip(out, res, strict=True))
        free = done | (rid < 0)
        new = nxt + jnp.cumsum(free.astype(jnp.int32)) - 1
        got = free & (new < n)
        ids = jnp.where(got, new, 0)
        ray = select(got, take(ids), ray)
        # A new ray's stack is empty (sp = 0): its old entries are never read.
        st = select(got, start[:2] + st[2:3] + start[3:], st)
        rid = jnp.where(got, new, jnp.where(done, -1, rid))
        return rid, ray, st, jnp.minimum(nxt + jnp.sum(free), n), out

    out = (jnp.zeros(n, jnp.float32), jnp.zeros(n, jnp.int32), jnp.zeros(n, jnp.float32),
           jnp.zeros(n, jnp.float32))
    rid = jnp.arange(lanes, dtype=jnp.int32)
    init = (rid, take(rid), start, jnp.int32(lanes), out)
    return jax.lax.while_loop(lambda c: jnp.any(c[0] >= 0), body, init)[-1]


def _vmappable(fun, batched_fun):
    """``fun(bvh, o, d, tmin, tmax)`` whose ``vmap`` calls ``batched_fun`` with the same
    arguments, the unbatched rays' broadcast along the new axis (``custom_vmap``); with a
    batched BVH it vmaps ``fun`` itself."""

    @jax.custom_batching.custom_vmap
    def f(bvh, o, d, tmin, tmax):
        return fun(bvh, o, d, tmin, tmax)

    @f.def_vmap
    def _(size, batched, bvh, *rays):
        if any(jax.tree.leaves(batched[0])):
            axes = tuple(jax.tree.map(lambda b: 0 if b else None, x) for x in batched)
            return jax.vmap(fun, in_axes=axes)(bvh, *rays), (True,) * 4
        rays = [x if b else jnp.broadcast_to(x, (size,) + x.shape)
                for x, b in zip(rays, batched[1:], strict=True)]
        return batched_fun(bvh, *rays), (True,) * 4

    return f


def _batched(any_hit: bool):
    """:func:`_traverse_queue` over ``(R,)`` rays as a function whose ``vmap`` flattens the new
    axis into the rays (nested vmaps of a render: pixels x samples)."""

    def flat(bvh, *rays):
        size, r = rays[0].shape[:2]
        out = queue(bvh, *(x.reshape((size * r,) + x.shape[2:]) for x in rays))
        return tuple(x.reshape((size, r) + x.shape[1:]) for x in out)

    queue = _vmappable(lambda bvh, *rays: _traverse_queue(bvh, *rays, any_hit), flat)
    return queue


_BATCHED = {a: _batched(a) for a in (False, True)}
# One ray (:func:`_traverse`), whose vmap runs the queue.
_ONE_RAY = {a: _vmappable(lambda bvh, *rays, a=a: _traverse(bvh, *rays, a), _BATCHED[a])
            for a in (False, True)}


def closest_hit(bvh: BVH, o, d, tmin=0.0, tmax=jnp.inf):
    """Nearest planar primitive with ``tmin < t < tmax`` along ``o + t d``: ``(t, prim, b1,
    b2)`` with ``t = inf`` and ``prim = 0`` on a miss (as brute force's ``argmin``)."""
    return _ONE_RAY[False](bvh, o, d, jnp.float32(tmin), jnp.float32(tmax))


def any_hit(bvh: BVH, o, d, tmin, tmax):
    """Whether any planar primitive has ``tmin < t < tmax`` (stops at the first found)."""
    return jnp.isfinite(_ONE_RAY[True](bvh, o, d, jnp.float32(tmin), jnp.float32(tmax))[0])
