"""Work that cannot be stopped, and the command limits (issue 7, findings 8 and 9): a kernel
that never ends stops when its client dies or its time limit passes; a launch of dim 2^40 and
a fill over a 2^40-element stride-0 view are refused with a message naming the limit; a huge
strided fill stops when its session closes; SIGTERM stops the daemon within its bound while a
kernel spins; queued commands per session are limited; an unknown tape op is refused; an
error longer than gRPC's metadata limit reaches the client as a clear, truncated message."""
import signal
import textwrap
import time

import grpc
import numpy as np
import pytest

from weft.v1 import array_pb2, exec_pb2, types_pb2

FLOAT32 = 11
INT32 = 7
# The bound docs/operations.md states for SIGTERM (cancel, 2 s grace for calls, close).
SIGTERM_BOUND_S = 5.0

# A kernel that never ends by itself (client code; the prelude of the spinning clients).
SPIN_KERNEL = """
import weft as wp
wp.init()
wp.set_device("cpu")

@wp.kernel
def spin(out: wp.array(dtype=int)):
    i = int(0)
    while True:
        i = (i + 1) % 1000003
        out[0] = i
"""

SPINNER = SPIN_KERNEL + """
out = wp.zeros(1, dtype=int)
wp.synchronize()
wp.launch(spin, dim=2, inputs=[out])
import weft._runtime as rt
rt.get_runtime().flush()   # the launch runs now, before this process blocks in synchronize
print("spinning", flush=True)
wp.synchronize()
print("returned", flush=True)
"""


def as_file(tmp_path, name: str, code: str) -> str:
    """Child code that runs `code` from a file (kernels must be defined in a file)."""
    path = tmp_path / f"{name}.py"
    path.write_text(textwrap.dedent(code))
    return f"import runpy; runpy.run_path({str(path)!r}, run_name='__main__')"


@pytest.fixture
def cpu(wp):
    with wp.ScopedDevice("cpu"):
        yield wp


def test_infinite_loop_stops_when_its_client_dies(weftd, cpu, spawn_client, tmp_path, wait_for):
    wp = cpu
    mine = wp.array(np.arange(100, dtype=np.float32))
    before = weftd.stats()
    child = spawn_client(as_file(tmp_path, "spinner", SPINNER))
    assert child.stdout.readline().strip() == "spinning", child.stderr.read()
    time.sleep(1.0)   # the kernel spins (it never ends by itself)
    child.send_signal(signal.SIGKILL)
    child.wait(timeout=10)
    killed = time.monotonic()
    # reaping closes the session, which waits for its launch: the launch must have stopped
    reaped = wait_for(lambda: weftd.stats().sessions_reaped_total > before.sessions_reaped_total, 10.0)
    assert reaped, "the dead client's session was not reaped (its kernel still runs?)"
    assert time.monotonic() - killed < 10.0
    idle_from = weftd.cpu_seconds()
    time.sleep(1.0)
    idle = weftd.cpu_seconds() - idle_from
    assert idle < 0.5, f"the daemon still burns CPU after the reap ({idle:.2f} s in 1 s)"
    assert weftd.stats().arrays <= before.arrays + 1

    @wp.kernel
    def double(a: wp.array(dtype=float)):
        i = wp.tid()
        a[i] = a[i] * 2.0

    wp.launch(double, dim=100, inputs=[mine])
    np.testing.assert_allclose(mine.numpy(), np.arange(100) * 2.0)


@pytest.mark.parametrize("device", ["cpu", "cuda:0"])
def test_launch_time_limit_stops_a_spinning_kernel(start_weftd, run_client, tmp_path, device):
    # On a GPU the loop polls a cancel word in device memory that the daemon sets with a copy
    # on another stream while the kernel runs (docs/cuda.md).
    daemon = start_weftd(["--launch-time-limit", "1"])
    prelude = SPIN_KERNEL.replace('wp.set_device("cpu")', f'wp.set_device("{device}")')
    if device != "cpu":
        prelude = prelude.replace("wp.init()\n", "wp.init()\nif not wp.is_cuda_available():\n"
                                  "    print('NO CUDA'); raise SystemExit(0)\n", 1)
    out = run_client(as_file(tmp_path, "time_limit", prelude + textwrap.dedent("""
        import time

        @wp.kernel
        def one(out: wp.array(dtype=int)):
            out[wp.tid()] = 1

        out = wp.zeros(4, dtype=int)
        wp.synchronize()
        start = time.monotonic()
        wp.launch(spin, dim=1, inputs=[out])
        try:
            wp.synchronize()
            print("NOT STOPPED")
        except Exception as e:
            print("stopped after", round(time.monotonic() - start, 2), "s:", e)
        wp.launch(one, dim=4, inputs=[out])
        print("after", out.numpy().tolist())
    """)), env={"WEFT_ADDRESS": daemon.address}, timeout=120)
    if "NO CUDA" in out.stdout:
        pytest.skip("weftd has no CUDA device")
    assert "stopped after" in out.stdout, out.stdout + out.stderr
    assert "launch time limit of 1 s" in out.stdout, out.stdout
    assert "--launch-time-limit" in out.stdout
    seconds = float(out.stdout.split("stopped after", 1)[1].split()[0])
    assert seconds < 10.0
    assert "after [1, 1, 1, 1]" in out.stdout, out.stdout   # the session still works


def test_launch_of_dim_2_to_the_40_is_refused(cpu):
    wp = cpu

    @wp.kernel
    def touch(a: wp.array(dtype=float)):
        i = wp.tid()
        if i < 4:
            a[i] = 1.0

    a = wp.zeros(4, dtype=float)
    wp.synchronize()
    for dim in (2 ** 40, (2 ** 20, 2 ** 20), (2 ** 16, 2 ** 16, 2)):
        with pytest.raises(wp.WeftError) as info:
            wp.launch(touch, dim=dim, inputs=[a])
            wp.synchronize()
        assert "--max-launch-threads" in str(info.value), str(info.value)
        assert "RESOURCE_EXHAUSTED" in str(info.value) or "limit" in str(info.value)
    wp.launch(touch, dim=4, inputs=[a])
    np.testing.assert_array_equal(a.numpy(), np.ones(4, np.float32))


def raw_array(raw, n=4):
    return raw.arrays.Create(array_pb2.CreateArrayRequest(
        dtype=types_pb2.DType(scalar=FLOAT32, type_name="float32"), shape=[n], device="cpu",
        init=array_pb2.CreateArrayRequest.ZEROS), metadata=raw.metadata, timeout=10).info


def fill(handle, shape, strides, value=1.0):
    return exec_pb2.Command(fill=exec_pb2.FillCommand(
        dst=types_pb2.ArrayRef(handle=handle, shape=shape, strides=strides),
        value=np.float32(value).tobytes()))


def test_fill_over_a_2_to_the_40_stride_0_view_is_refused(weftd):
    with weftd.raw_session("pytest stride0") as raw:
        info = raw_array(raw)
        with pytest.raises(grpc.RpcError) as error:
            raw.exec.Submit(exec_pb2.SubmitRequest(commands=[fill(info.handle, [2 ** 40], [0])],
                                                   synchronize=True),
                            metadata=raw.metadata, timeout=30)
        assert error.value.code() == grpc.StatusCode.RESOURCE_EXHAUSTED
        assert "--max-launch-threads" in error.value.details()
        ok = raw.exec.Submit(exec_pb2.SubmitRequest(commands=[fill(info.handle, [4], [4], 5.0)],
                                                    synchronize=True),
                             metadata=raw.metadata, timeout=30)
        assert not ok.sync.error


def test_a_long_strided_fill_stops_when_its_session_closes(weftd):
    """2^32 element writes through a stride-0 view (allowed by the default limit) take many
    seconds; closing the session stops them within a fraction of that."""
    with weftd.raw_session("pytest bystander") as bystander:
        mine = raw_array(bystander)
        raw = weftd.raw_session("pytest long fill")
        info = raw_array(raw)
        raw.exec.Submit(exec_pb2.SubmitRequest(commands=[fill(info.handle, [2 ** 32], [0])]),
                        metadata=raw.metadata, timeout=30)
        time.sleep(0.3)
        start = time.monotonic()
        raw.close()
        elapsed = time.monotonic() - start
        assert elapsed < 3.0, f"close took {elapsed:.1f} s: the fill was not cancelled"
        sync = bystander.exec.Submit(exec_pb2.SubmitRequest(
            commands=[fill(mine.handle, [4], [4], 2.0)], synchronize=True),
            metadata=bystander.metadata, timeout=30).sync
        assert not sync.error


def test_sigterm_stops_the_daemon_while_a_kernel_spins(start_weftd, spawn_client, tmp_path):
    daemon = start_weftd()
    child = spawn_client(as_file(tmp_path, "spinner", SPINNER), env={"WEFT_ADDRESS": daemon.address})
    assert child.stdout.readline().strip() == "spinning", child.stderr.read()
    time.sleep(0.5)
    start = time.monotonic()
    daemon.proc.send_signal(signal.SIGTERM)
    code = daemon.proc.wait(timeout=30)
    elapsed = time.monotonic() - start
    assert code == 0, daemon.log()[-3000:]
    assert elapsed < SIGTERM_BOUND_S, f"weftd took {elapsed:.1f} s to stop"
    assert not daemon.shm_files()
    assert "weftd stopped" in daemon.log()


def test_queued_commands_per_session_are_limited(start_weftd):
    daemon = start_weftd(["--max-queued-commands", "10"])
    with daemon.raw_session("pytest queue") as raw:
        info = raw_array(raw)
        batch = [fill(info.handle, [4], [4], float(i)) for i in range(11)]
        with pytest.raises(grpc.RpcError) as error:
            raw.exec.Submit(exec_pb2.SubmitRequest(commands=batch), metadata=raw.metadata,
                            timeout=10)
        assert error.value.code() == grpc.StatusCode.RESOURCE_EXHAUSTED
        assert "--max-queued-commands" in error.value.details()
        ok = raw.exec.Submit(exec_pb2.SubmitRequest(commands=batch[:10], synchronize=True),
                             metadata=raw.metadata, timeout=10)
        assert not ok.sync.error
        chunks = raw.arrays.Read(array_pb2.ReadArrayRequest(handle=info.handle),
                                 metadata=raw.metadata, timeout=10)
        data = np.frombuffer(b"".join(c.data for c in chunks), np.float32)
        np.testing.assert_array_equal(data, np.full(4, 9.0, np.float32))


def test_unknown_tape_op_is_refused(weftd):
    with weftd.raw_session("pytest tape op") as raw:
        for op in (7, 99, 2 ** 31 - 1):
            cmd = exec_pb2.Command(tape=exec_pb2.TapeCommand(op=op, tape_id=1))
            with pytest.raises(grpc.RpcError) as error:
                raw.exec.Submit(exec_pb2.SubmitRequest(commands=[cmd], synchronize=True),
                                metadata=raw.metadata, timeout=10)
            assert error.value.code() == grpc.StatusCode.INVALID_ARGUMENT
            assert f"unknown tape op {op}" in error.value.details()
        ok = raw.exec.Submit(exec_pb2.SubmitRequest(commands=[exec_pb2.Command(
            tape=exec_pb2.TapeCommand(op=exec_pb2.TapeCommand.FREE, tape_id=1))], synchronize=True),
            metadata=raw.metadata, timeout=10)
        assert not ok.sync.error


def test_an_error_too_long_for_metadata_arrives_truncated(cpu):
    """A compile error quoting a 60 KB source line: far over gRPC's 8 KiB metadata limit."""
    wp = cpu
    long_sum = " + ".join(["x"] * 15000)
    source = (f"def long_error(a: wp.array(dtype=float)):\n"
              f"    x = float(1.0)\n"
              f"    a[0] = {long_sum} + not_defined_anywhere\n")
    from weft.v1 import module_pb2
    import weft._runtime as runtime
    rt = runtime.get_runtime()
    module = module_pb2.ModuleSource(name="long_error", functions=[module_pb2.FunctionSource(
        name="long_error", source=source, file="long_error.py", first_line=1, is_kernel=True,
        param_types=["array(float32,1)"], param_names=["a"], key="long_error.long_error")],
        symbols=[module_pb2.Symbol(name="wp", builtin_module="warp")])
    with pytest.raises(grpc.RpcError) as error:
        rt.module_stub.Compile(module_pb2.CompileRequest(module=module, device="cpu"),
                               metadata=rt.metadata, timeout=60)
    assert error.value.code() == grpc.StatusCode.INVALID_ARGUMENT, \
        f"{error.value.code()}: {error.value.details()[:300]}"
    details = error.value.details()
    assert "not_defined_anywhere" in details or "truncated" in details
    assert "message truncated" in details
    assert len(details) < 8192
