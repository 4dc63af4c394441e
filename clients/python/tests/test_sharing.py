"""Sharing arrays between client processes through one daemon (issue 2, must show): one
process writes through its NumPy view, another reads the values; no copy (the view's data
pointer stays the same across numpy() calls); ipc_handle/from_ipc_handle with Warp's extra
arguments; the memory stays alive while any session holds it."""
import json

import numpy as np
import pytest

@pytest.fixture(autouse=True)
def _cpu_by_default(wp):
    """These tests are about CPU arrays (zero-copy views): make cpu the default device even
    where the daemon has a GPU (Warp's default is then cuda:0)."""
    with wp.ScopedDevice("cpu"):
        yield


WRITER = """
import json, sys
import numpy as np
import weft as wp
wp.init()
wp.set_device("cpu")
a = wp.zeros(4096, dtype=wp.float32)
token = a.ipc_handle()
view = a.numpy()
print(json.dumps({"token": token.decode(), "ptr": view.__array_interface__["data"][0]}),
      flush=True)
sys.stdin.readline()                     # reader has opened it
view[:] = np.arange(4096, dtype=np.float32) * 0.5
view2 = a.numpy()
print(json.dumps({"written": True, "ptr2": view2.__array_interface__["data"][0],
                  "ptr3": a.numpy().__array_interface__["data"][0]}), flush=True)
sys.stdin.readline()                     # reader has written back
print(json.dumps({"sum": float(a.numpy().sum()), "first": float(a.numpy()[0])}), flush=True)
sys.stdin.readline()
"""


def test_two_processes_share_one_array(spawn_client, wp):
    writer = spawn_client(WRITER)
    first = json.loads(writer.stdout.readline())
    b = wp.from_ipc_handle(first["token"].encode(), dtype=wp.float32, shape=(4096,))
    reader_view = b.numpy()
    reader_ptr = reader_view.__array_interface__["data"][0]
    np.testing.assert_array_equal(reader_view, np.zeros(4096, np.float32))

    writer.stdin.write("go\n")
    writer.stdin.flush()
    second = json.loads(writer.stdout.readline())
    assert second["written"]
    # the writer's view did not move between numpy() calls: no copy
    assert second["ptr2"] == first["ptr"] == second["ptr3"]
    # the reader sees the writer's values through its existing view, without a new read
    expected = np.arange(4096, dtype=np.float32) * 0.5
    np.testing.assert_array_equal(reader_view, expected)
    assert b.numpy().__array_interface__["data"][0] == reader_ptr

    # and the other way round: the reader writes through a daemon command
    b[:1].fill_(-7.0)
    wp.synchronize()
    writer.stdin.write("go\n")
    writer.stdin.flush()
    third = json.loads(writer.stdout.readline())
    assert third["first"] == -7.0
    assert third["sum"] == pytest.approx(float(expected[1:].sum()) - 7.0, rel=1e-6)
    writer.stdin.write("done\n")
    writer.stdin.flush()
    assert writer.wait(timeout=30) == 0, writer.stderr.read()


def test_token_dies_with_the_last_holder(run_client, wp):
    proc = run_client("""
        import numpy as np
        import weft as wp
        wp.set_device("cpu")
        a = wp.array(np.arange(64, dtype=np.int64) * 3)
        print(a.ipc_handle().decode())
        wp.synchronize()
        """)
    # the creator has exited and nobody else held the array: it is gone
    token = proc.stdout.strip().encode()
    with pytest.raises(wp.WeftError):
        wp.from_ipc_handle(token, dtype=wp.int64, shape=(64,))


def test_import_keeps_memory_alive_after_exporter_exits(spawn_client, wp):
    child = spawn_client("""
        import sys
        import numpy as np
        import weft as wp
        wp.set_device("cpu")
        a = wp.array(np.arange(64, dtype=np.int64) * 3)
        print(a.ipc_handle().decode(), flush=True)
        sys.stdin.readline()
        """)
    token = child.stdout.readline().strip().encode()
    b = wp.from_ipc_handle(token, dtype=wp.int64, shape=(64,))
    child.stdin.write("exit\n")
    child.stdin.flush()
    assert child.wait(timeout=30) == 0
    np.testing.assert_array_equal(b.numpy(), np.arange(64, dtype=np.int64) * 3)
    b.fill_(5)
    np.testing.assert_array_equal(b.numpy(), np.full(64, 5, np.int64))


def test_from_ipc_handle_with_warp_arguments(wp):
    a = wp.array(np.arange(12, dtype=np.float32))
    token = a.ipc_handle()
    assert isinstance(token, bytes) and token
    same = wp.from_ipc_handle(token)
    assert same.dtype is wp.float32 and same.shape == (12,)
    grid = wp.from_ipc_handle(token, dtype=wp.float32, shape=(3, 4), device="cpu")
    np.testing.assert_array_equal(grid.numpy(), np.arange(12, dtype=np.float32).reshape(3, 4))
    columns = wp.from_ipc_handle(token, dtype=wp.float32, shape=(4, 3), strides=(4, 16))
    np.testing.assert_array_equal(columns.numpy(),
                                  np.arange(12, dtype=np.float32).reshape(3, 4).T)
    vec = wp.from_ipc_handle(token, dtype=wp.vec3, shape=(4,))
    np.testing.assert_array_equal(vec.numpy(), np.arange(12, dtype=np.float32).reshape(4, 3))
    with pytest.raises(RuntimeError, match="exceeds"):
        wp.from_ipc_handle(token, dtype=wp.float32, shape=(13,))
    with pytest.raises(wp.WeftError):
        wp.from_ipc_handle(b"not-a-token", dtype=wp.float32, shape=(1,))


def test_devices_report_ipc_support(wp):
    """Warp programs check device.is_ipc_supported before ipc_handle(): every device weft
    computes on shares arrays between processes (the tests above, and test_cuda_sharing.py)."""
    for d in wp.get_devices():
        if d.is_compute_supported:
            assert d.is_ipc_supported is True, d
