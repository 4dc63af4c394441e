"""Graph capture (weft/graph.py) on every test device: wp.ScopedCapture / capture_begin /
capture_end record instead of running, wp.capture_launch replays with the arguments fixed at
capture; zeros/full made inside a capture are reset by each replay; a tape recorded inside a
capture replays its backward (a gradient-descent step captured whole matches a float64
reference); a graph keeps the arrays it names; capture_if/capture_while; errors in replayed
commands carry the captured launch's file:line; a tampered graph command is refused by the
daemon like any command; a host wait inside a capture is Warp's error and the capture goes on."""
import gc
import inspect
import re

import numpy as np
import pytest

import weft as wp


@wp.kernel
def axpy(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):
    i = wp.tid()
    y[i] = y[i] + a * x[i]


@wp.kernel
def sum_squares(x: wp.array(dtype=float), loss: wp.array(dtype=float)):
    i = wp.tid()
    wp.atomic_add(loss, 0, x[i] * x[i] * x[i] * x[i])


@wp.kernel
def descend(x: wp.array(dtype=float), g: wp.array(dtype=float), rate: float):
    i = wp.tid()
    x[i] = x[i] - rate * g[i]


@wp.kernel
def count_down(counter: wp.array(dtype=wp.int32), hits: wp.array(dtype=float)):
    counter[0] = counter[0] - 1
    hits[0] = hits[0] + 1.0


@wp.kernel
def read_at(x: wp.array(dtype=float), index: int, out: wp.array(dtype=float)):
    out[0] = x[index]


def test_capture_records_and_replays_with_fixed_arguments(rng, device):
    n = 1000
    x_np = rng.standard_normal(n).astype(np.float32) * np.float32(1e3)
    y0 = rng.standard_normal(n).astype(np.float32)
    x = wp.array(x_np)
    y = wp.array(y0)
    a = float(rng.uniform(0.5, 2.0))
    with wp.ScopedCapture() as capture:
        wp.launch(axpy, n, inputs=[x, y, a])
        wp.launch(axpy, n, inputs=[x, y, -0.25 * a])
    assert wp.get_device().is_capturing is False
    np.testing.assert_array_equal(y.numpy(), y0)          # nothing ran while capturing
    graph = capture.graph
    assert isinstance(graph, wp.Graph) and len(graph.commands) == 2
    replays = 5
    for _ in range(replays):
        wp.capture_launch(graph)
    expected = y0.astype(np.float64)
    for _ in range(replays):
        expected = expected + np.float32(a) * x_np.astype(np.float64)
        expected = expected + np.float32(-0.25 * a) * x_np.astype(np.float64)
    # float32 accumulation of 10 terms of |a x| <= ~2e3: a few ulps of the running sum
    np.testing.assert_allclose(y.numpy(), expected, rtol=0, atol=1e-3 * np.abs(expected).max())


def test_capture_begin_end_and_misuse(device):
    x = wp.zeros(4)
    wp.capture_begin()
    try:
        assert wp.get_device().is_capturing
        with pytest.raises(RuntimeError, match="already in progress"):
            wp.capture_begin()
        x.fill_(3.0)
    finally:
        graph = wp.capture_end()
    assert not wp.get_device().is_capturing
    np.testing.assert_array_equal(x.numpy(), 0.0)
    wp.capture_launch(graph)
    np.testing.assert_array_equal(x.numpy(), 3.0)
    with pytest.raises(RuntimeError, match="not active"):
        wp.capture_end()
    with pytest.raises(TypeError, match="wp.Graph"):
        wp.capture_launch("graph")
    assert wp.is_conditional_graph_supported() is True      # host-side conditions
    # Warp's capture modes: each records the same (weftd captures in RELAXED); others refused.
    assert [m.value for m in wp.CaptureMode] == [0, 1, 2]
    for mode in (wp.CaptureMode.GLOBAL, wp.CaptureMode.THREAD_LOCAL, wp.CaptureMode.RELAXED, 2):
        with wp.ScopedCapture(capture_mode=mode) as capture:
            x.fill_(float(int(mode)) + 5.0)
        wp.capture_launch(capture.graph)
        np.testing.assert_array_equal(x.numpy(), float(int(mode)) + 5.0)
    for bad in (3, -1, "RELAXED", True):
        with pytest.raises(ValueError, match="capture_mode must be"):
            wp.capture_begin(capture_mode=bad)
    assert not wp.get_device().is_capturing


def test_host_waits_inside_a_capture_are_refused_and_the_capture_goes_on(device):
    x = wp.zeros(4)
    with wp.ScopedCapture() as capture:
        x.fill_(2.0)
        for wait in (wp.synchronize, lambda: wp.synchronize_device(device)):
            with pytest.raises(RuntimeError, match="Cannot synchronize device.* while graph capture is active"):
                wait()
    wp.synchronize()                       # outside the capture: a host wait again
    np.testing.assert_array_equal(x.numpy(), 0.0)
    wp.capture_launch(capture.graph)
    np.testing.assert_array_equal(x.numpy(), 2.0)


def test_zeros_made_in_a_capture_start_from_zero_at_each_replay(rng, device):
    values = rng.standard_normal(64).astype(np.float32)
    x = wp.array(values)
    with wp.ScopedCapture() as capture:
        acc = wp.zeros(1)
        ones = wp.full(64, 1.5)
        wp.launch(sum_squares, 64, inputs=[x, acc])
        wp.launch(axpy, 64, inputs=[ones, x, 0.0])
    expected = float(np.sum(values.astype(np.float64) ** 4))
    for _ in range(3):
        wp.capture_launch(capture.graph)
        assert acc.numpy()[0] == pytest.approx(expected, rel=1e-5)


def test_a_captured_training_step_with_a_tape_matches_float64(rng, device):
    n = 256
    x0 = rng.uniform(-1.5, 1.5, n).astype(np.float32)
    x = wp.array(x0, requires_grad=True)
    loss = wp.zeros(1, requires_grad=True)
    rate = 0.01
    tape = wp.Tape()
    with wp.ScopedCapture() as capture:
        with tape:
            wp.launch(sum_squares, n, inputs=[x, loss])
        tape.backward(loss)
        wp.launch(descend, n, inputs=[x, x.grad, rate])
        tape.zero()
    np.testing.assert_array_equal(x.numpy(), x0)
    steps = 20
    ref = x0.astype(np.float64)
    for _ in range(steps):
        loss.zero_()
        wp.capture_launch(capture.graph)
        ref = ref - rate * 4.0 * ref ** 3
    # float32 steps of a contraction: errors stay at float32 rounding of |x| <= 1.5
    np.testing.assert_allclose(x.numpy(), ref, rtol=0, atol=2e-5)
    np.testing.assert_array_equal(x.grad.numpy(), 0.0)   # the captured tape.zero() ran last


def test_a_graph_keeps_the_arrays_it_names(rng, device):
    rt = wp._runtime.get_runtime()
    values = rng.standard_normal(32).astype(np.float32)
    out = wp.zeros(1)

    def capture_with_temporary():
        temp = wp.array(values)
        with wp.ScopedCapture() as capture:
            wp.launch(read_at, 1, inputs=[temp, 7, out])
        return capture.graph

    graph = capture_with_temporary()
    gc.collect()
    wp.capture_launch(graph)
    assert out.numpy()[0] == values[7]
    held = set(graph._retained)
    assert held and held <= set(rt._graph_handles)
    del graph
    gc.collect()
    assert not held & set(rt._graph_handles)
    assert not held & rt._graph_freed


def test_capture_if_and_capture_while_outside_a_capture(device):
    counter = wp.array([3], dtype=wp.int32)
    hits = wp.zeros(1)
    wp.capture_while(counter, lambda: wp.launch(count_down, 1, inputs=[counter, hits]))
    assert counter.numpy()[0] == 0 and hits.numpy()[0] == 3.0
    taken = []
    wp.capture_if(counter, on_true=lambda: taken.append("true"),
                  on_false=lambda: taken.append("false"))
    assert taken == ["false"]
    with wp.ScopedCapture() as body:
        wp.launch(count_down, 1, inputs=[counter, hits])
    counter.fill_(1)
    wp.capture_if(counter, on_true=body.graph)
    assert counter.numpy()[0] == 0 and hits.numpy()[0] == 4.0
    with pytest.raises(TypeError, match="int32"):
        wp.capture_if(hits, on_true=body.graph)
    with pytest.raises(TypeError, match="int32"):
        with wp.ScopedCapture():
            wp.capture_while(hits, body.graph)


def test_capture_while_and_capture_if_inside_a_capture(rng, device):
    """Inside a capture the branches and the loop body are captured as graphs and the
    condition is read each time the graph runs, after the work before it (a host step): the
    counter a captured fill sets is counted down by the body, which also sorts."""
    n = 256
    counter = wp.zeros(1, dtype=wp.int32)
    hits = wp.zeros(1)
    keys = wp.zeros(2 * n, dtype=wp.int32)
    values = wp.zeros(2 * n, dtype=wp.int32)
    flag = wp.zeros(1, dtype=wp.int32)
    taken = wp.zeros(2)

    def body():
        wp.utils.radix_sort_pairs(keys, values, n)
        wp.launch(count_down, 1, inputs=[counter, hits])

    with wp.ScopedCapture() as capture:
        counter.fill_(3)
        wp.capture_while(counter, while_body=body)
        wp.capture_if(flag, on_true=lambda: taken.fill_(1.0), on_false=lambda: taken.fill_(-1.0))
    np.testing.assert_array_equal(hits.numpy(), 0.0)        # nothing ran while capturing
    for round_ in range(2):
        keys_np = rng.integers(-10_000, 10_000, n).astype(np.int32)
        keys.assign(np.concatenate([keys_np, np.zeros(n, np.int32)]))
        flag.fill_(round_)
        wp.capture_launch(capture.graph)
        assert counter.numpy()[0] == 0 and hits.numpy()[0] == 3.0 * (round_ + 1)
        np.testing.assert_array_equal(keys.numpy()[:n], np.sort(keys_np, kind="stable"))
        np.testing.assert_array_equal(taken.numpy(), 1.0 if round_ else -1.0)


def test_a_replayed_bounds_error_names_the_captured_line(device):
    x = wp.zeros(8)
    out = wp.zeros(1)
    with wp.ScopedCapture() as capture:
        line = inspect.currentframe().f_lineno + 1
        wp.launch(read_at, 1, inputs=[x, 100, out])
    with pytest.raises(Exception) as err:
        wp.capture_launch(capture.graph)
        wp.synchronize()
    message = str(err.value)
    assert "out of bounds" in message or "bounds" in message
    assert re.search(rf"test_graph_capture\.py:{line}\b", message), message
    out.fill_(2.0)          # the session goes on
    assert out.numpy()[0] == 2.0


def _graph_command(op, graph_id, device="", commands=()):
    from weft.v1 import exec_pb2
    return exec_pb2.Command(graph=exec_pb2.GraphCommand(op=op, graph_id=graph_id, device=device,
                                                        commands=list(commands)))


def test_graph_commands_are_checked_like_any_command(device):
    """Raw GraphCommands as a hostile client sends them: a graph naming a handle the session
    does not hold, a graph holding a graph command or a tape command, a launch of an unknown
    graph id, and an unknown op are refused with clear errors; the session goes on."""
    from weft.v1 import exec_pb2
    rt = wp._runtime.get_runtime()
    GC = exec_pb2.GraphCommand
    x = wp.zeros(8)
    with wp.ScopedCapture() as capture:
        wp.launch(axpy, 8, inputs=[x, x, 1.0])
    launch = type(capture.graph.commands[0])()
    launch.CopyFrom(capture.graph.commands[0])
    launch.launch.args[0].array.handle = 0x7FFF_FFFF_0000
    rt.submit(_graph_command(GC.CREATE, 0xDEAD01, device, [launch]))
    with pytest.raises(Exception, match="unknown array handle"):
        wp.synchronize()
    rt.submit(_graph_command(GC.LAUNCH, 0xDEAD01))
    with pytest.raises(Exception, match="unknown"):
        wp.synchronize()
    nested = _graph_command(GC.LAUNCH, 1)
    for inner, message in ((nested, "not a launch, copy or fill"),
                           (exec_pb2.Command(tape=exec_pb2.TapeCommand(op=exec_pb2.TapeCommand.ZERO,
                                                                        tape_id=1)),
                            "not a launch, copy or fill")):
        rt.submit(_graph_command(GC.CREATE, 0xDEAD02, device, [inner]))
        with pytest.raises(Exception, match=message):
            wp.synchronize()
    rt.submit(_graph_command(7, 0xDEAD03))
    with pytest.raises(Exception, match="unknown graph op"):
        wp.synchronize()
    x.fill_(1.0)
    assert x.numpy()[0] == 1.0


def test_a_graph_replays_after_its_arrays_are_freed_by_handle(device):
    """The daemon's graph holds the arrays it names: even a client that frees their handles
    (bypassing the Python-side retention) replays it safely, on memory still alive."""
    from weft.v1 import array_pb2
    rt = wp._runtime.get_runtime()
    x = wp.array(np.arange(16, dtype=np.float32))
    out = wp.zeros(1)
    with wp.ScopedCapture() as capture:
        wp.launch(read_at, 1, inputs=[x, 5, out])
    wp.synchronize()                       # the CREATE ran
    rt.call(rt.array_stub.Free, array_pb2.FreeArrayRequest(handle=x._ref().handle))
    wp.capture_launch(capture.graph)
    assert out.numpy()[0] == 5.0


def test_record_only_launches_are_checked_and_not_adjoint(device):
    """A raw record-only launch (what a capture sends for a tape) gets the forward checks,
    is refused with adjoint, and runs nothing."""
    rt = wp._runtime.get_runtime()
    x = wp.array(np.arange(8, dtype=np.float32))
    with wp.ScopedCapture() as capture:
        wp.launch(axpy, 8, inputs=[x, x, 1.0])
    cmd = type(capture.graph.commands[0])()
    cmd.CopyFrom(capture.graph.commands[0])
    cmd.launch.record_only = True
    rt.submit(cmd)
    wp.synchronize()
    np.testing.assert_array_equal(x.numpy(), np.arange(8))   # validated, not run
    bad = type(cmd)()
    bad.CopyFrom(cmd)
    bad.launch.adjoint = True
    rt.submit(bad)
    with pytest.raises(Exception, match="record_only"):
        wp.synchronize()
    short = type(cmd)()
    short.CopyFrom(cmd)
    del short.launch.args[-1]
    rt.submit(short)
    with pytest.raises(Exception, match="(?i)argument"):
        wp.synchronize()


def test_capture_debug_dot_print(tmp_path, device):
    x = wp.zeros(8)
    with wp.ScopedCapture() as capture:
        wp.launch(axpy, 8, inputs=[x, x, 1.0])
        x.zero_()
    path = tmp_path / "graph.dot"
    wp.capture_debug_dot_print(capture.graph, str(path))
    text = path.read_text()
    assert text.startswith("digraph") and "launch axpy" in text and "fill" in text
    assert "n0 -> n1" in text


@wp.kernel
def scaled_keys(src: wp.array(dtype=wp.int32), k: int, keys: wp.array(dtype=wp.int32)):
    i = wp.tid()
    keys[i] = src[i] * k


@wp.kernel
def plus_one(keys: wp.array(dtype=wp.int32), out: wp.array(dtype=wp.int32)):
    i = wp.tid()
    out[i] = keys[i] + 1


def test_captured_utils_are_host_steps_in_the_graph_order(rng, device, tmp_path):
    """weft's wp.utils algorithms run on the host: captured, each is a host step of the graph,
    run by every capture_launch after the graph's earlier launches and before its later ones
    (the sort sees what the launch before it wrote; the launch after it sees the sorted keys)."""
    n = 1000
    src = wp.zeros(n, dtype=wp.int32)
    keys = wp.zeros(2 * n, dtype=wp.int32)          # the second half: the sort's scratch
    values = wp.zeros(2 * n, dtype=wp.int32)
    out = wp.zeros(n, dtype=wp.int32)
    scan = wp.zeros(n, dtype=wp.int32)
    with wp.ScopedCapture() as capture:
        wp.launch(scaled_keys, n, inputs=[src, -3, keys])
        wp.utils.radix_sort_pairs(keys, values, n)
        wp.launch(plus_one, n, inputs=[keys, out])
        wp.utils.array_scan(out, scan)
        assert wp.utils.radix_sort_pairs(keys, values, 0) is None   # nothing to do: no step
    assert len(capture.graph) == 4
    for _ in range(3):                              # fresh data before each replay
        src_np = rng.integers(-100_000, 100_000, n).astype(np.int32)
        src.assign(src_np)
        values.assign(np.concatenate([np.arange(n, dtype=np.int32), np.zeros(n, np.int32)]))
        wp.capture_launch(capture.graph)
        scaled = src_np.astype(np.int64) * -3
        order = np.argsort(scaled, kind="stable")
        np.testing.assert_array_equal(out.numpy(), (scaled[order] + 1).astype(np.int32))
        np.testing.assert_array_equal(values.numpy()[:n], order.astype(np.int32))
        np.testing.assert_array_equal(scan.numpy(), np.cumsum(scaled[order] + 1).astype(np.int32))
    path = tmp_path / "graph.dot"
    wp.capture_debug_dot_print(capture.graph, str(path))
    assert "host step wp.utils.radix_sort_pairs" in path.read_text()


def test_captured_utils_check_their_arguments_when_captured(device):
    keys = wp.zeros(32, dtype=wp.int32)
    values = wp.zeros(32, dtype=wp.int32)
    four = wp.zeros(4)
    with wp.ScopedCapture() as capture:
        with pytest.raises(RuntimeError, match="2\\*count elements"):
            wp.utils.radix_sort_pairs(keys, values, 17)
        with pytest.raises(RuntimeError, match="returns a value on the host"):
            wp.utils.array_sum(four)
        with pytest.raises(RuntimeError, match="returns a value on the host"):
            wp.utils.runlength_encode(keys, keys, values)
    assert len(capture.graph) == 0


def test_a_graph_with_host_steps_launched_while_capturing(rng, device):
    n = 64
    keys = wp.zeros(2 * n, dtype=wp.int32)
    values = wp.zeros(2 * n, dtype=wp.int32)
    out = wp.zeros(n, dtype=wp.int32)
    with wp.ScopedCapture() as inner:
        wp.utils.radix_sort_pairs(keys, values, n)
    with wp.ScopedCapture() as outer:
        wp.capture_launch(inner.graph)
        wp.launch(plus_one, n, inputs=[keys, out])
    keys_np = rng.integers(-1000, 1000, n).astype(np.int32)
    keys.assign(np.concatenate([keys_np, np.zeros(n, np.int32)]))
    wp.capture_launch(outer.graph)
    np.testing.assert_array_equal(out.numpy(), np.sort(keys_np, kind="stable") + 1)


def test_arrays_made_and_dropped_while_capturing_stay_for_the_graph(rng, device):
    value = float(rng.uniform(1, 2))
    out = wp.zeros(1)
    with wp.ScopedCapture() as capture:
        tmp = wp.full(8, value)                 # its fill is recorded too
        wp.launch(read_at, 1, inputs=[tmp, 3, out])
        del tmp
        gc.collect()
    wp.capture_launch(capture.graph)
    assert out.numpy()[0] == np.float32(value)


def test_a_graph_launched_while_capturing_becomes_part_of_the_new_one(device):
    x = wp.zeros(4)
    with wp.ScopedCapture() as inner:
        wp.launch(axpy, 4, inputs=[wp.full(4, 1.0), x, 2.0])
    with wp.ScopedCapture() as outer:
        wp.capture_launch(inner.graph)
        wp.capture_launch(inner.graph)
    del inner
    gc.collect()                          # the outer graph keeps the inner one
    wp.capture_launch(outer.graph)
    np.testing.assert_array_equal(x.numpy(), 4.0)


@wp.kernel
def grouped_neighbours(grid: wp.uint64, points: wp.array(dtype=wp.vec3), groups: wp.array(dtype=int),
                       radius: float, counts: wp.array(dtype=int)):
    i = wp.tid()
    q = wp.hash_grid_query(grid, points[i], radius, groups[i])
    j = int(0)
    n = int(0)
    while wp.hash_grid_query_next(q, j):
        if wp.length(points[j] - points[i]) <= radius:
            n += 1
    counts[i] = n


def test_captured_hash_grid_builds_and_refits_run_at_every_replay(rng, device):
    """A HashGrid.build and a Mesh.refit inside a capture are commands of the graph: each replay
    rebuilds from the arrays' values then (group ids written by captured work and group ids first
    seen at replay included), in order with the captured launches; checked against brute force."""
    n = 200
    pts = rng.uniform(0, 1, size=(n, 3)).astype(np.float32)
    points = wp.array(pts, dtype=wp.vec3, device=device)
    groups = wp.zeros(n, dtype=int, device=device)
    source = wp.array(rng.integers(0, 3, size=n).astype(np.int32), dtype=int, device=device)
    counts = wp.zeros(n, dtype=int, device=device)
    grid = wp.HashGrid(8, 8, 8, device=device)
    grid.build(points, 0.15, groups=groups)
    with wp.ScopedCapture(device) as capture:
        wp.copy(groups, source)
        grid.build(points, 0.15, groups=groups)
        wp.launch(grouped_neighbours, n, inputs=[grid.id, points, groups, 0.15, counts], device=device)
    assert not counts.numpy().any()          # nothing ran while capturing

    def brute(g):
        d = np.linalg.norm(pts[:, None, :].astype(np.float64) - pts[None, :, :], axis=2)
        return ((d <= 0.15 - 1e-5) & (g[:, None] == g[None, :])).sum(1), \
            ((d <= 0.15 + 1e-5) & (g[:, None] == g[None, :])).sum(1)

    for ids in (source.numpy(), rng.integers(1000, 1003, size=n).astype(np.int32)):
        source.assign(ids)
        wp.capture_launch(capture.graph)
        got = counts.numpy()
        low, high = brute(ids)
        assert ((got >= low) & (got <= high)).all()
    # a refit captured after a launch that moves the mesh sees the moved points at each replay
    tri = np.array([[0, 1, 2]], dtype=np.int32)
    mpts = wp.array(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float32), dtype=wp.vec3, device=device)
    mesh = wp.Mesh(mpts, wp.array(tri.ravel(), dtype=int, device=device))
    lift = wp.zeros(1, dtype=float, device=device)
    hit = wp.zeros(1, dtype=int, device=device)
    with wp.ScopedCapture(device) as capture:
        wp.launch(move_mesh, 3, inputs=[mpts, lift], device=device)
        mesh.refit()
        wp.launch(ray_down, 1, inputs=[mesh.id, lift, hit], device=device)
    for z in (0.5, 2.0, 7.0):
        lift.fill_(z)
        wp.capture_launch(capture.graph)
        assert hit.numpy()[0] == 1, z     # the refit saw the lifted triangle


@wp.kernel
def move_mesh(points: wp.array(dtype=wp.vec3), lift: wp.array(dtype=float)):
    i = wp.tid()
    p = points[i]
    points[i] = wp.vec3(p[0], p[1], lift[0])


@wp.kernel
def ray_down(mesh: wp.uint64, lift: wp.array(dtype=float), hit: wp.array(dtype=int)):
    # a short ray crossing z = lift only: misses a tree whose bounds were not refitted
    q = wp.mesh_query_ray(mesh, wp.vec3(0.2, 0.2, lift[0] + 0.25), wp.vec3(0.0, 0.0, -1.0), 0.5)
    hit[0] = wp.where(q.result, 1, 0)


def test_geometry_commands_are_checked_like_any_command(device):
    """Raw geometry commands as a hostile client sends them: a create (only builds, refits,
    rebuilds and frees are commands), an unknown object id, a HashGrid build with a handle the
    session does not hold, a free of a forged id and a build after the object's free; each is
    refused with a clear error and the session goes on."""
    from weft import geometry
    from weft.v1 import exec_pb2
    rt = wp._runtime.get_runtime()
    G = geometry._pb2().GeometryRequest
    grid = wp.HashGrid(2, 2, 2, device=device)
    for request, message in ((G(op=G.CREATE_BVH), "goes to GeometryService"),
                             (G(op=G.REFIT, id=grid.id ^ (1 << 40)), "names no live object"),
                             (G(op=G.BUILD_HASH_GRID, id=grid.id, points=0x7FFF_FFFF_0000, radius=1.0),
                              "unknown array handle"),
                             (G(op=99), "unknown operation"),
                             (G(op=G.FREE, id=grid.id ^ (1 << 40)), "names no live object")):
        rt.submit(exec_pb2.Command(geometry=request))
        with pytest.raises(Exception, match=message):
            wp.synchronize()
    other = wp.HashGrid(2, 2, 2, device=device)
    rt.submit(exec_pb2.Command(geometry=G(op=G.FREE, id=other.id)))
    rt.submit(exec_pb2.Command(geometry=G(op=G.REFIT, id=other.id)))
    with pytest.raises(Exception, match="names no live object"):
        wp.synchronize()
    other.id = 0   # freed above
    x = wp.zeros(4, device=device)
    x.fill_(2.0)
    assert x.numpy()[0] == 2.0
