"""Cooperative CPU blocks (Warp's wp.config.enable_cpu_blocks, docs/tiles.md): with the setting
on, a CPU launch with block_dim from 2 to 1024 runs each block's threads as lanes that meet at
tile ops. wp.tile(x) gathers every lane's x (scalars, vectors), untile gives each lane its own,
tile stacks take every lane's push, t[i] op= v combines every lane's v, a tile store or atomic
add is done once per block (not once per lane), gradients of gathered values reach each lane,
the launch's last block may be short, and wp.block_dim() is the block's size. Checked on fresh
random data against NumPy. Attacks: block_dim above 1024; lanes that leave the kernel early or
take different branches around tile ops (no hang, the daemon goes on); the largest block
(1024 lanes) with tiles on every lane's stack; the setting off: one thread per block; a kernel
without tiles sees the launch's block_dim in wp.block_dim(), and a forged block_dim never
reaches it outside Warp's range."""
import numpy as np
import pytest

import weft as wp

B = 16


@pytest.fixture(autouse=True)
def cpu_blocks(device, monkeypatch):
    if device != "cpu":
        pytest.skip("cooperative blocks are a CPU launch mode")
    monkeypatch.setattr(wp.config, "enable_cpu_blocks", True)


@wp.kernel
def gather_lanes(x: wp.array[float], tiles: wp.array[float], sums: wp.array[float], own: wp.array[float],
                 dims: wp.array[int]):
    i = wp.tid()
    t = wp.tile(x[i] * 2.0)
    wp.tile_store(tiles, t, offset=(i // B) * B)
    wp.tile_atomic_add(sums, wp.tile_sum(t), offset=i // B)
    own[i] = wp.untile(t * 3.0)
    dims[i] = wp.block_dim()


def test_tile_gathers_every_lane_and_stores_once(rng):
    n = 3 * B + 5                       # the last block has 5 lanes
    xs = (rng.standard_normal(n) * 10.0 ** rng.integers(-3, 4, n)).astype(np.float32)
    x = wp.array(xs)
    tiles = wp.zeros(4 * B, dtype=float)
    sums = wp.zeros(4, dtype=float)
    own = wp.zeros(n, dtype=float)
    dims = wp.zeros(n, dtype=int)
    wp.launch(gather_lanes, dim=n, inputs=[x, tiles, sums, own, dims], block_dim=B)
    ref = np.zeros(4 * B)
    ref[:n] = xs.astype(np.float64) * 2.0
    np.testing.assert_allclose(tiles.numpy(), ref, rtol=1e-6)
    # each block's sum added once (a tile_atomic_add per lane would add it B times)
    np.testing.assert_allclose(sums.numpy(), ref.reshape(4, B).sum(axis=1), rtol=1e-5, atol=1e-4)
    np.testing.assert_allclose(own.numpy(), xs.astype(np.float64) * 6.0, rtol=1e-6)
    assert dims.numpy().tolist() == [B] * n


@wp.kernel
def gather_vectors(v: wp.array[wp.vec3], out: wp.array2d[float], back: wp.array[wp.vec3]):
    i = wp.tid()
    t = wp.tile(v[i])                   # shape (3, B): lane l's components in column l
    wp.tile_store(out, t, offset=(0, (i // B) * B))
    back[i] = wp.untile(t)


def test_vector_tiles_hold_a_column_per_lane(rng):
    n = 2 * B
    vs = rng.standard_normal((n, 3)).astype(np.float32)
    out = wp.zeros((3, n), dtype=float)
    back = wp.zeros(n, dtype=wp.vec3)
    wp.launch(gather_vectors, dim=n, inputs=[wp.array(vs, dtype=wp.vec3), out, back], block_dim=B)
    np.testing.assert_array_equal(out.numpy(), vs.T)
    np.testing.assert_array_equal(back.numpy(), vs)


@wp.kernel
def stack_lanes(keep: wp.array[int], slots: wp.array[int], counts: wp.array[int], popped: wp.array[int]):
    _b, j = wp.tid()
    s = wp.tile_stack(capacity=24, dtype=int)
    slots[j] = wp.tile_stack_push(s, j * 10 + 7, keep[j] != 0)
    counts[j] = wp.tile_stack_count(s)
    val, slot = wp.tile_stack_pop(s)
    if slot >= 0:
        popped[slot] = val
    counts[B * 2 + j] = wp.tile_stack_count(s)


def test_tile_stacks_take_every_lanes_push(rng):
    lanes = 2 * B
    keep = (rng.random(lanes) < 0.8).astype(np.int32)
    keep[:3] = 1
    slots = wp.full(lanes, -5, dtype=int)
    counts = wp.zeros(4 * B, dtype=int)
    popped = wp.full(24, -1, dtype=int)
    wp.launch_tiled(stack_lanes, dim=[1], inputs=[wp.array(keep), slots, counts, popped], block_dim=lanes)
    pushers = np.flatnonzero(keep)
    pushed = min(len(pushers), 24)            # the stack holds 24: later pushes get -1
    expect_slots = np.full(lanes, -1)
    expect_slots[pushers[:pushed]] = np.arange(pushed)
    assert slots.numpy().tolist() == expect_slots.tolist()
    assert counts.numpy()[:lanes].tolist() == [pushed] * lanes
    # every lane pops one: all values come off, the count ends at zero
    assert sorted(popped.numpy()[:pushed].tolist()) == sorted((pushers[:pushed] * 10 + 7).tolist())
    assert counts.numpy()[2 * B:].tolist() == [0] * lanes


@wp.kernel
def combine_lanes(a: wp.array[wp.uint32], f: wp.array[float], bits: wp.array[wp.uint32], sums: wp.array[float],
                  marks: wp.array[float]):
    i = wp.tid()
    j = i % B
    t = wp.tile_zeros(shape=4, dtype=wp.uint32)
    t[0] = wp.uint32(0xFFFFFFFF)
    t[0] &= ~(wp.uint32(1) << wp.uint32(j))        # every lane clears its bit
    t[1] |= a[i]
    t[2] ^= a[i]
    s = wp.tile_zeros(shape=2, dtype=float)
    s[1] += f[i]
    s[0] -= f[i]
    m = wp.tile_zeros(shape=B, dtype=float)
    m[B - 1 - j] = float(j) + 0.5                  # each lane writes its own element
    if j == 0:
        bits[(i // B) * 3 + 0] = t[0]
        bits[(i // B) * 3 + 1] = t[1]
        bits[(i // B) * 3 + 2] = t[2]
    wp.tile_store(sums, s, offset=(i // B) * 2)
    wp.tile_store(marks, m, offset=(i // B) * B)


def test_element_updates_combine_every_lane(rng):
    blocks = 3
    n = blocks * B
    a = rng.integers(0, 2**32, n, dtype=np.uint64).astype(np.uint32)
    f = rng.standard_normal(n).astype(np.float32)
    bits = wp.zeros(blocks * 3, dtype=wp.uint32)
    sums = wp.zeros(blocks * 2, dtype=float)
    marks = wp.zeros(blocks * B, dtype=float)
    wp.launch(combine_lanes, dim=n, inputs=[wp.array(a), wp.array(f), bits, sums, marks], block_dim=B)
    got = bits.numpy().reshape(blocks, 3)
    for b in range(blocks):
        blk = a[b * B:(b + 1) * B]
        assert got[b, 0] == np.uint32(0xFFFFFFFF & ~((1 << B) - 1))
        assert got[b, 1] == np.bitwise_or.reduce(blk)
        assert got[b, 2] == np.bitwise_xor.reduce(blk)
    ref = f.astype(np.float64).reshape(blocks, B).sum(axis=1)
    np.testing.assert_allclose(sums.numpy().reshape(blocks, 2)[:, 1], ref, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(sums.numpy().reshape(blocks, 2)[:, 0], -ref, rtol=1e-5, atol=1e-5)
    assert marks.numpy().reshape(blocks, B).tolist() == [[B - 1 - k + 0.5 for k in range(B)]] * blocks


@wp.kernel
def from_lane(out: wp.array[float]):
    i = wp.tid()
    t = wp.tile_from_thread(shape=(B,), value=float(i) * 1.5 + 1.0, thread_idx=5)
    out[i] = wp.tile_extract(t, i % B) + float(i % B)


def test_tile_from_thread_broadcasts_one_lane():
    out = wp.zeros(2 * B, dtype=float)
    wp.launch(from_lane, dim=2 * B, inputs=[out], block_dim=B)
    expect = [(b * B + 5) * 1.5 + 1.0 + k for b in range(2) for k in range(B)]
    assert out.numpy().tolist() == expect


@wp.kernel
def lane_loss(x: wp.array[float], w: wp.array[float], loss: wp.array[float]):
    i = wp.tid()
    t = wp.tile(x[i] * x[i])
    ws = wp.tile_load(w, shape=B)
    wp.tile_atomic_add(loss, wp.tile_sum(t * ws))


def test_gradients_reach_each_lane_once(rng):
    n = 2 * B
    xs = rng.standard_normal(n).astype(np.float32)
    wsn = rng.standard_normal(B).astype(np.float32)
    x = wp.array(xs, requires_grad=True)
    w = wp.array(wsn, requires_grad=True)
    loss = wp.zeros(1, dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(lane_loss, dim=n, inputs=[x, w, loss], block_dim=B)
    tape.backward(loss)
    x64, w64 = xs.astype(np.float64), wsn.astype(np.float64)
    ref_loss = (x64.reshape(2, B) ** 2 * w64).sum()
    np.testing.assert_allclose(loss.numpy()[0], ref_loss, rtol=1e-5)
    np.testing.assert_allclose(x.grad.numpy(), 2.0 * x64 * np.tile(w64, 2), rtol=1e-5, atol=1e-6)
    # w is loaded by every lane of both blocks: its gradient is each block's once
    np.testing.assert_allclose(w.grad.numpy(), (x64.reshape(2, B) ** 2).sum(axis=0), rtol=1e-5, atol=1e-6)


@wp.kernel
def diverging(x: wp.array[float], out: wp.array[float]):
    i = wp.tid()
    if i % 3 == 0:
        return                           # a third of the lanes leave before the tile ops
    t = wp.tile(x[i])
    if i % 2 == 0:
        t = wp.tile(x[i] + 1.0)          # only some lanes: the lanes fall out of step
    wp.tile_store(out, t, offset=(i // B) * B)


def test_lanes_that_leave_or_diverge_finish(rng):
    n = 4 * B
    x = wp.array(rng.standard_normal(n).astype(np.float32))
    out = wp.zeros(n, dtype=float)
    wp.launch(diverging, dim=n, inputs=[x, out], block_dim=B)
    wp.synchronize()                     # returns: no lane waits forever
    got = out.numpy()
    assert np.all(got[::3] == 0.0) and np.all(np.isfinite(got))
    # the daemon serves the next launch as usual
    wp.launch(gather_lanes, dim=B, inputs=[x, wp.zeros(B, dtype=float), wp.zeros(1, dtype=float),
                                           wp.zeros(B, dtype=float), wp.zeros(B, dtype=int)], block_dim=B)
    wp.synchronize()


@wp.kernel
def big_block(x: wp.array[float], out: wp.array[float]):
    i = wp.tid()
    t = wp.tile(x[i])
    big = wp.tile_zeros(shape=(32, 32), dtype=float) + wp.tile_sum(t)[0]
    out[i] = wp.untile(t) + wp.tile_sum(big)[0] * 0.0 + big[i % 32, 3]


def test_the_largest_block_runs(rng):
    n = 2048
    xs = rng.standard_normal(n).astype(np.float32)
    out = wp.zeros(n, dtype=float)
    wp.launch(big_block, dim=n, inputs=[wp.array(xs), out], block_dim=1024)
    block_sums = xs.astype(np.float64).reshape(2, 1024).sum(axis=1)
    np.testing.assert_allclose(out.numpy(), xs + np.repeat(block_sums, 1024), rtol=1e-4, atol=1e-3)
    with pytest.raises(ValueError, match=r"block_dim must be at most 1024 on CPU, got 2048"):
        wp.launch(big_block, dim=n, inputs=[wp.array(xs), out], block_dim=2048)


def test_without_the_setting_a_block_is_one_thread(rng, monkeypatch):
    monkeypatch.setattr(wp.config, "enable_cpu_blocks", False)
    n = B
    xs = rng.standard_normal(n).astype(np.float32)
    own = wp.zeros(n, dtype=float)
    dims = wp.zeros(n, dtype=int)
    sums = wp.zeros(1, dtype=float)
    # one thread per block: wp.tile(x) has one element, so the store at offset 0 writes 1
    wp.launch(gather_vectors_one, dim=n, inputs=[wp.array(xs), own, dims, sums], block_dim=B)
    np.testing.assert_allclose(own.numpy(), xs.astype(np.float64) * 2.0, rtol=1e-6)
    assert dims.numpy().tolist() == [1] * n
    np.testing.assert_allclose(sums.numpy()[0], xs.astype(np.float64).sum() * 2.0, rtol=1e-5, atol=1e-5)


@wp.kernel
def gather_vectors_one(x: wp.array[float], own: wp.array[float], dims: wp.array[int], sums: wp.array[float]):
    i = wp.tid()
    t = wp.tile(x[i] * 2.0)
    own[i] = wp.untile(t)
    dims[i] = wp.block_dim()
    wp.tile_atomic_add(sums, wp.tile_sum(t))


@wp.kernel
def lane_draws(seed: int, xi: wp.array[int], xf: wp.array[float]):
    i, _lane = wp.tid()
    rng = wp.rand_init(seed, i)
    wp.tile_store(xi, wp.tile_randi(shape=2 * B, rng=rng), offset=i * 2 * B)
    wp.tile_store(xf, wp.tile_randf(shape=2 * B, rng=rng, min=-3.0, max=5.0), offset=i * 2 * B)


@wp.kernel
def one_thread_draws(seed: int, xi: wp.array[int], xf: wp.array[float]):
    i, t = wp.tid()
    rng = wp.rand_init(seed, i) + wp.uint32(t)
    a = wp.tile_randi(shape=2, rng=rng)           # lane t's stream: its first two draws
    b = wp.tile_randf(shape=2, rng=rng, min=-3.0, max=5.0)
    xi[i * 2 * B + t] = a[0]
    xi[i * 2 * B + t + B] = a[1]
    xf[i * 2 * B + t] = b[0]
    xf[i * 2 * B + t + B] = b[1]


def test_random_tiles_draw_one_stream_per_lane(rng, monkeypatch):
    seed = int(rng.integers(0, 2**31))
    xi, xf = wp.zeros(4 * B, dtype=int), wp.zeros(4 * B, dtype=float)
    wp.launch_tiled(lane_draws, dim=[2], inputs=[seed, xi, xf], block_dim=B)
    monkeypatch.setattr(wp.config, "enable_cpu_blocks", False)
    ri, rf = wp.zeros(4 * B, dtype=int), wp.zeros(4 * B, dtype=float)
    wp.launch(one_thread_draws, dim=[2, B], inputs=[seed, ri, rf])
    assert xi.numpy().tolist() == ri.numpy().tolist()
    assert xf.numpy().tolist() == rf.numpy().tolist()
    assert np.all((xf.numpy() >= -3.0) & (xf.numpy() < 5.0)) and len(set(xi.numpy().tolist())) > 3 * B


@wp.kernel
def tiled_bvh_hits(bvh: wp.uint64, lower: wp.vec3, upper: wp.vec3, hits: wp.array[int], rounds: wp.array[int]):
    query = wp.tile_bvh_query_aabb(bvh, lower, upper)
    n = int(0)
    while wp.tile_query_valid(query):
        found = wp.untile(wp.tile_bvh_query_next(query))    # one item per lane
        if found >= 0:
            wp.atomic_add(hits, found, 1)
        n += 1
    wp.atomic_max(rounds, 0, n)


def test_tiled_bvh_queries_give_each_lane_an_item(rng):
    count = 300
    lowers = rng.random((count, 3)).astype(np.float32) * 10.0
    uppers = lowers + rng.random((count, 3)).astype(np.float32) * 2.0
    bvh = wp.Bvh(wp.array(lowers, dtype=wp.vec3), wp.array(uppers, dtype=wp.vec3))
    lo, hi = np.array([2.0, 2.0, 2.0], np.float32), np.array([7.0, 7.0, 7.0], np.float32)
    hits = wp.zeros(count, dtype=int)
    rounds = wp.zeros(1, dtype=int)
    wp.launch_tiled(tiled_bvh_hits, dim=[1], inputs=[bvh.id, wp.vec3(*lo), wp.vec3(*hi), hits, rounds], block_dim=B)
    overlap = np.all((lowers <= hi) & (uppers >= lo), axis=1)
    assert hits.numpy().tolist() == overlap.astype(int).tolist()     # each item once, by one lane
    # B items per round: the lanes share the walk
    assert rounds.numpy()[0] == (int(overlap.sum()) + B - 1) // B + 1


@wp.kernel
def wide_tiles(x: wp.array2d[float], out: wp.array2d[float]):
    t = wp.tile_load(x, shape=(128, 256))        # 128 KiB per lane, twice that with adjoints
    wp.tile_store(out, t * 2.0)


def test_blocks_whose_tiles_take_too_much_memory_are_refused():
    x = wp.zeros((128, 256), dtype=float)
    out = wp.zeros((128, 256), dtype=float)
    wp.launch_tiled(wide_tiles, dim=[1], inputs=[x, out], block_dim=8)      # 8 lanes: fine
    with pytest.raises(Exception, match=r"cooperative CPU blocks of 1024 threads.*per block \(at most 268435456\)"):
        wp.launch_tiled(wide_tiles, dim=[1], inputs=[x, out], block_dim=1024)
    wp.launch_tiled(wide_tiles, dim=[1], inputs=[x, out], block_dim=8)      # the session goes on
    wp.synchronize()


@wp.kernel
def print_tile(x: wp.array[float]):
    i = wp.tid()
    wp.print(wp.tile(x[i]))


def test_a_tile_prints_once_per_block(capfd):
    x = wp.array(np.arange(2 * 4, dtype=np.float32))
    capfd.readouterr()
    wp.launch(print_tile, dim=8, inputs=[x], block_dim=4)
    wp.synchronize()
    out = capfd.readouterr().out
    assert out.count("tile(shape=(4)") == 2, out
    assert "[0 1 2 3]" in out and "[4 5 6 7]" in out, out


def test_a_launch_with_another_block_dim_than_compiled_is_refused(monkeypatch):
    """The daemon checks block_dim against the lanes the kernel was compiled for: a client
    that compiles for 16 lanes and launches with 8 gets an error, the session goes on."""
    import importlib

    launch_mod = importlib.import_module("weft._kernel.launch")
    plan = launch_mod._launch_plan
    monkeypatch.setattr(launch_mod, "_launch_plan", lambda k, d, rt, lanes=1: plan(k, d, rt, B))
    monkeypatch.setattr(launch_mod, "cpu_lanes", lambda device, block_dim: 8)
    x = wp.array(np.ones(B, dtype=np.float32))
    with pytest.raises(Exception, match=r"compiled for CPU blocks of 16 threads .* launched with block_dim 8"):
        wp.launch(gather_lanes, dim=B, inputs=[x, wp.zeros(B, dtype=float), wp.zeros(1, dtype=float),
                                               wp.zeros(B, dtype=float), wp.zeros(B, dtype=int)], block_dim=8)
        wp.synchronize()
    monkeypatch.undo()
    monkeypatch.setattr(wp.config, "enable_cpu_blocks", True)
    own = wp.zeros(B, dtype=float)
    wp.launch(gather_lanes, dim=B, inputs=[x, wp.zeros(B, dtype=float), wp.zeros(1, dtype=float), own,
                                           wp.zeros(B, dtype=int)], block_dim=B)
    assert own.numpy().tolist() == [6.0] * B


@wp.kernel
def block_size_without_tiles(x: wp.array[float], out: wp.array[float], dims: wp.array[int]):
    i = wp.tid()
    out[i] = x[i] * float(wp.block_dim())
    dims[i] = wp.block_dim()


def test_block_dim_of_a_kernel_without_tiles_is_the_launchs(rng, monkeypatch):
    # Warp's rule: with the setting on, wp.block_dim() is the launch's block_dim even where the
    # module has no tiles (weft then runs its threads one at a time, not as lanes)
    n = 200
    xs = rng.standard_normal(n).astype(np.float32)
    for block_dim, on, expected in ((64, True, 64), (1024, True, 1024), (None, True, 1), (64, False, 1)):
        monkeypatch.setattr(wp.config, "enable_cpu_blocks", on)
        out, dims = wp.zeros(n, dtype=float), wp.zeros(n, dtype=int)
        wp.launch(block_size_without_tiles, dim=n, inputs=[wp.array(xs), out, dims], block_dim=block_dim)
        assert set(dims.numpy().tolist()) == {expected}
        np.testing.assert_array_equal(out.numpy(), xs * np.float32(expected))


def test_a_forged_block_dim_never_reaches_a_kernel_without_lanes(rng, monkeypatch):
    """A client that sends any block_dim for a CPU launch of a kernel compiled without lanes:
    wp.block_dim() stays within Warp's range (1 outside 2..1024), the session goes on."""
    import importlib

    launch_mod = importlib.import_module("weft._kernel.launch")
    plan = launch_mod._launch_plan
    n = 50
    xs = rng.standard_normal(n).astype(np.float32)
    for forged in (5000, 2**31 - 1, 2**32 - 1):
        monkeypatch.setattr(launch_mod, "_launch_plan", lambda k, d, rt, lanes=1: plan(k, d, rt, 1))
        monkeypatch.setattr(launch_mod, "cpu_lanes", lambda device, block_dim, f=forged: f)
        out, dims = wp.zeros(n, dtype=float), wp.zeros(n, dtype=int)
        wp.launch(block_size_without_tiles, dim=n, inputs=[wp.array(xs), out, dims], block_dim=64)
        assert set(dims.numpy().tolist()) == {1}
        monkeypatch.undo()
    monkeypatch.setattr(wp.config, "enable_cpu_blocks", True)
    dims = wp.zeros(n, dtype=int)
    wp.launch(block_size_without_tiles, dim=n, inputs=[wp.array(xs), wp.zeros(n, dtype=float), dims], block_dim=32)
    assert set(dims.numpy().tolist()) == {32}
