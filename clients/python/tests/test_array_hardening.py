"""Issue 7, findings 3-6 and the memory part of 9, attacked through the public API: adjoint
launches with arrays of the wrong shape, type or stride; a struct array whose client-claimed
struct_size is smaller than the kernel's struct; shapes whose element count wraps 64 bits;
sessions that try to see each other's memory (shared slabs, reused blocks, exports); memory
quotas. Each attack gets a clear error, leaves another session's canary array unchanged, and
the daemon keeps serving (a normal launch and read still work afterwards)."""
import mmap
import os

import grpc
import numpy as np
import pytest

import weft as wp
from weft._kernel import module as module_mod
from weft.v1 import array_pb2, exec_pb2, types_pb2

FLOAT32 = 11


@wp.kernel
def hard_scale(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = 2.0 * x[i]


@wp.struct
class HardBig:
    a: wp.mat44
    b: wp.mat44
    c: wp.mat44
    tag: float


@wp.kernel
def hard_struct_write(s: wp.array(dtype=HardBig)):
    i = wp.tid()
    v = HardBig()
    v.tag = float(i) + 1.0
    s[i] = v


# ------------------------------------------------------------------------------------------
# helpers


def f32(values):
    return types_pb2.DType(scalar=FLOAT32, type_name="float32"), values.astype(np.float32)


def create(raw, values=None, shape=None, init=None, dtype=None):
    if values is not None:
        dtype, data = f32(np.asarray(values))
        request = array_pb2.CreateArrayRequest(dtype=dtype, shape=list(data.shape), device="cpu",
                                               init=array_pb2.CreateArrayRequest.DATA,
                                               value=data.tobytes())
    else:
        request = array_pb2.CreateArrayRequest(
            dtype=dtype or types_pb2.DType(scalar=FLOAT32, type_name="float32"), shape=list(shape),
            device="cpu", init=array_pb2.CreateArrayRequest.EMPTY if init is None else init)
    return raw.arrays.Create(request, metadata=raw.metadata, timeout=10).info


def read(raw, handle):
    chunks = raw.arrays.Read(array_pb2.ReadArrayRequest(handle=handle), metadata=raw.metadata,
                             timeout=10)
    return b"".join(c.data for c in chunks)


def submit_and_sync(raw, *commands):
    response = raw.exec.Submit(exec_pb2.SubmitRequest(commands=list(commands), synchronize=True),
                               metadata=raw.metadata, timeout=60)
    return response.sync


@pytest.fixture
def victim(weftd):
    """Another session with a canary array of known values; `.unchanged()` checks its bytes."""
    with weftd.raw_session("pytest victim") as raw:
        values = np.random.default_rng(7).standard_normal(256).astype(np.float32)
        info = create(raw, values)

        class Victim:
            session = raw
            handle = info.handle

            @staticmethod
            def unchanged():
                np.testing.assert_array_equal(np.frombuffer(read(raw, info.handle), np.float32), values)

        yield Victim


@pytest.fixture
def attacker(weftd):
    with weftd.raw_session("pytest attacker") as raw:
        yield raw


def still_serving(wp_module):
    x = wp_module.array(np.arange(64, dtype=np.float32), device="cpu")
    y = wp_module.zeros(64, dtype=float, device="cpu")
    wp_module.launch(hard_scale, dim=64, inputs=[x], outputs=[y], device="cpu")
    np.testing.assert_array_equal(y.numpy(), np.arange(64, dtype=np.float32) * 2.0)


def compiled_scale(wp_module):
    compiled, info = module_mod.compile_kernel(hard_scale, "cpu", backward=True)
    return compiled.module_id, info.name or "hard_scale"


def adjoint_launch(module_id, kernel, x, y, adj_x, adj_y):
    arg = lambda ref: exec_pb2.ArgValue(array=ref)   # noqa: E731
    return exec_pb2.Command(launch=exec_pb2.LaunchCommand(
        module_id=module_id, kernel=kernel, dim=[64], device="cpu",
        args=[arg(x), arg(y)], adjoint=True, adj_args=[arg(adj_x), arg(adj_y)]))


# ------------------------------------------------------------------------------------------
# finding 3: adjoint launches


def test_adjoint_arrays_of_wrong_shape_or_type_are_refused_python_client(wp, victim):
    x = wp.array(np.ones(64, np.float32), device="cpu")
    y = wp.zeros(64, dtype=float, device="cpu")
    adj_y = wp.array(np.ones(64, np.float32), device="cpu")
    small = wp.zeros(4, dtype=float, device="cpu")          # the primal x has 64 elements
    with pytest.raises(Exception) as info:
        wp.launch(hard_scale, dim=64, inputs=[x], outputs=[y], adj_inputs=[small],
                  adj_outputs=[adj_y], adjoint=True, device="cpu")
        wp.synchronize()
    assert "primal" in str(info.value) and "(4,)" in str(info.value), str(info.value)
    ints = wp.zeros(64, dtype=wp.int32, device="cpu")
    with pytest.raises(Exception) as info:
        wp.launch(hard_scale, dim=64, inputs=[x], outputs=[y], adj_inputs=[ints],
                  adj_outputs=[adj_y], adjoint=True, device="cpu")
        wp.synchronize()
    assert "int32" in str(info.value) and "float32" in str(info.value), str(info.value)
    np.testing.assert_array_equal(small.numpy(), np.zeros(4, np.float32))
    # the right shape and type work
    adj_x = wp.zeros(64, dtype=float, device="cpu")
    wp.launch(hard_scale, dim=64, inputs=[x], outputs=[y], adj_inputs=[adj_x],
              adj_outputs=[adj_y], adjoint=True, device="cpu")
    np.testing.assert_array_equal(adj_x.numpy(), np.full(64, 2.0, np.float32))
    victim.unchanged()
    still_serving(wp)


def test_adjoint_far_stride_and_foreign_handle_are_refused_raw(wp, weftd, victim, attacker):
    module_id, kernel = compiled_scale(wp)
    x = create(attacker, np.ones(64))
    y = create(attacker, np.zeros(64))
    adj = create(attacker, np.zeros(64))
    ref = lambda info, **kw: types_pb2.ArrayRef(handle=info.handle, **kw)   # noqa: E731
    cases = {
        # a stride that walks 1 TiB past the allocation
        "far stride": ref(adj, shape=[64], strides=[1 << 40]),
        # a negative stride reaching before the allocation
        "negative stride": ref(adj, byte_offset=0, shape=[64], strides=[-4]),
        # another session's array
        "foreign handle": types_pb2.ArrayRef(handle=victim.handle),
        # fewer elements than the primal
        "short view": ref(adj, shape=[8], strides=[4]),
    }
    for name, bad in cases.items():
        sync = submit_and_sync(attacker, adjoint_launch(module_id, kernel, ref(x), ref(y), bad, ref(adj)))
        assert sync.error, f"{name}: an invalid adjoint array must fail"
        assert sync.error_code in (grpc.StatusCode.INVALID_ARGUMENT.value[0],
                                   grpc.StatusCode.OUT_OF_RANGE.value[0],
                                   grpc.StatusCode.NOT_FOUND.value[0]), (name, sync.error)
    victim.unchanged()
    np.testing.assert_array_equal(np.frombuffer(read(attacker, adj.handle), np.float32), np.zeros(64))
    # a well-formed adjoint launch of the same module still runs
    adj_y = create(attacker, np.ones(64))
    sync = submit_and_sync(attacker, adjoint_launch(module_id, kernel, ref(x), ref(y), ref(adj), ref(adj_y)))
    assert not sync.error, sync.error
    np.testing.assert_array_equal(np.frombuffer(read(attacker, adj.handle), np.float32), np.full(64, 2.0))
    still_serving(wp)


# ------------------------------------------------------------------------------------------
# finding 4: struct_size


@wp.kernel
def hard_bits(a: wp.array(dtype=wp.uint32), out: wp.array(dtype=wp.uint32)):
    i = wp.tid()
    out[i] = a[i] >> wp.uint32(23)


@wp.kernel
def hard_vec_lengths(a: wp.array(dtype=wp.vec3), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = wp.length(a[i])


def test_views_as_another_dtype_in_kernels_and_their_attacks(wp, victim, attacker):
    """array.view(dtype) in a kernel reads the same bytes as the new type (Warp's semantics; the
    view has no gradient); a raw ArrayRef whose view dtype would reach past the allocation, is
    misaligned, a struct, or bool over floats is refused by the one validation, before any
    byte is read."""
    rng = np.random.default_rng()
    f = rng.standard_normal(64).astype(np.float32) * np.float32(1e30) ** rng.uniform(-1, 1, 64).astype(np.float32)
    a = wp.array(f, device="cpu", requires_grad=True)
    out = wp.zeros(64, dtype=wp.uint32, device="cpu")
    bits = a.view(wp.uint32)
    assert bits.grad is None and not bits.requires_grad
    wp.launch(hard_bits, dim=64, inputs=[bits, out], device="cpu")
    np.testing.assert_array_equal(out.numpy(), f.view(np.uint32) >> 23)
    g = (rng.standard_normal(63) * 10.0 ** rng.uniform(-6, 6, 63)).astype(np.float32)   # no float32 overflow
    flat = wp.array(g.reshape(21, 3), device="cpu")
    lengths = wp.zeros(21, dtype=float, device="cpu")
    wp.launch(hard_vec_lengths, dim=21, inputs=[flat.view(wp.vec3), lengths], device="cpu")
    np.testing.assert_allclose(lengths.numpy(), np.linalg.norm(g.reshape(21, 3).astype(np.float64), axis=1),
                               rtol=1e-6)

    compiled, info = module_mod.compile_kernel(hard_bits, "cpu")
    src = create(attacker, np.ones(16))                       # 64 bytes
    dst = create(attacker, shape=[64], dtype=types_pb2.DType(scalar=8, type_name="uint32"))
    as_type = lambda name, scalar, elem=(): types_pb2.DType(scalar=scalar, elem_shape=list(elem), type_name=name)  # noqa: E731
    cases = {
        "past the end": types_pb2.ArrayRef(handle=src.handle, shape=[32], view_dtype=as_type("uint32", 8)),
        "vec3 past the end": types_pb2.ArrayRef(handle=src.handle, shape=[6],
                                                view_dtype=as_type("vec(3,float32)", 11, [3])),
        "misaligned": types_pb2.ArrayRef(handle=src.handle, byte_offset=2, shape=[4],
                                         view_dtype=as_type("uint32", 8)),
        "struct": types_pb2.ArrayRef(handle=src.handle, shape=[1],
                                     view_dtype=types_pb2.DType(type_name="struct(x.S)", struct_size=64)),
        "bool over floats": types_pb2.ArrayRef(handle=src.handle, shape=[16], view_dtype=as_type("bool", 1)),
        "foreign handle": types_pb2.ArrayRef(handle=victim.handle, shape=[16], view_dtype=as_type("uint32", 8)),
    }
    for name, bad in cases.items():
        launch = exec_pb2.Command(launch=exec_pb2.LaunchCommand(
            module_id=compiled.module_id, kernel=info.name or "hard_bits", dim=[16], device="cpu",
            args=[exec_pb2.ArgValue(array=bad),
                  exec_pb2.ArgValue(array=types_pb2.ArrayRef(handle=dst.handle))]))
        sync = submit_and_sync(attacker, launch)
        assert sync.error, f"{name}: must fail"
        assert sync.error_code in (grpc.StatusCode.INVALID_ARGUMENT.value[0],
                                   grpc.StatusCode.OUT_OF_RANGE.value[0],
                                   grpc.StatusCode.NOT_FOUND.value[0]), (name, sync.error)
    # copies and fills go through the same check
    for bad in (cases["past the end"], cases["misaligned"], cases["foreign handle"]):
        fill = exec_pb2.Command(fill=exec_pb2.FillCommand(dst=bad, value=b"\xff" * 4))
        copy = exec_pb2.Command(copy=exec_pb2.CopyCommand(dst=bad, src=types_pb2.ArrayRef(handle=dst.handle)))
        for cmd in (fill, copy):
            assert submit_and_sync(attacker, cmd).error
    np.testing.assert_array_equal(np.frombuffer(read(attacker, dst.handle), np.uint32), np.zeros(64, np.uint32))
    np.testing.assert_array_equal(np.frombuffer(read(attacker, src.handle), np.float32), np.ones(16, np.float32))
    victim.unchanged()
    still_serving(wp)


def test_struct_array_smaller_than_the_kernel_struct_is_refused_raw(wp, victim, attacker):
    good = wp.zeros(4, dtype=HardBig, device="cpu")
    compiled, info = module_mod.compile_kernel(hard_struct_write, "cpu")
    claimed = types_pb2.DType()
    claimed.CopyFrom(good._info.dtype)
    real_size = claimed.struct_size
    assert real_size >= 196
    claimed.struct_size = 1                      # "1-byte structs"
    tiny = create(attacker, shape=[4], dtype=claimed, init=array_pb2.CreateArrayRequest.ZEROS)
    launch = exec_pb2.Command(launch=exec_pb2.LaunchCommand(
        module_id=compiled.module_id, kernel=info.name or "hard_struct_write", dim=[4], device="cpu",
        args=[exec_pb2.ArgValue(array=types_pb2.ArrayRef(handle=tiny.handle))]))
    sync = submit_and_sync(attacker, launch)
    assert sync.error_code == grpc.StatusCode.INVALID_ARGUMENT.value[0], sync.error
    assert f"{real_size} bytes per element" in sync.error and "1 bytes" in sync.error, sync.error
    assert read(attacker, tiny.handle) == bytes(4)
    victim.unchanged()
    # the same kernel on a real struct array works
    wp.launch(hard_struct_write, dim=4, inputs=[good], device="cpu")
    assert list(good.numpy()["tag"]) == [1.0, 2.0, 3.0, 4.0]
    still_serving(wp)


# ------------------------------------------------------------------------------------------
# finding 5: element counts that wrap 64 bits


def test_wrapping_element_counts_are_refused_raw(wp, victim, attacker):
    a = create(attacker, np.arange(16))
    wrap = types_pb2.ArrayRef(handle=a.handle, shape=[1 << 32, 1 << 32], strides=[0, 0])
    ok = types_pb2.ArrayRef(handle=a.handle, shape=[16], strides=[4])
    for command in (
        exec_pb2.Command(copy=exec_pb2.CopyCommand(dst=ok, src=wrap)),
        exec_pb2.Command(copy=exec_pb2.CopyCommand(dst=wrap, src=wrap)),
        exec_pb2.Command(fill=exec_pb2.FillCommand(dst=wrap, value=b"\0\0\x80\x3f")),
        exec_pb2.Command(copy=exec_pb2.CopyCommand(
            dst=types_pb2.ArrayRef(handle=a.handle, shape=[1 << 40, 1 << 40]), src=ok)),
    ):
        # Refused before anything runs: by the per-command element limit at submit
        # (RESOURCE_EXHAUSTED naming --max-launch-threads) or by the array validation at sync.
        try:
            sync = submit_and_sync(attacker, command)
        except grpc.RpcError as refused:
            assert refused.code() == grpc.StatusCode.RESOURCE_EXHAUSTED, refused.details()
            assert "--max-launch-threads" in refused.details(), refused.details()
            continue
        assert sync.error_code == grpc.StatusCode.INVALID_ARGUMENT.value[0], sync.error
        assert "too many elements" in sync.error, sync.error
    # a kernel argument with such a view
    module_id, kernel = compiled_scale(wp)
    launch = exec_pb2.Command(launch=exec_pb2.LaunchCommand(
        module_id=module_id, kernel=kernel, dim=[16], device="cpu",
        args=[exec_pb2.ArgValue(array=wrap), exec_pb2.ArgValue(array=ok)]))
    sync = submit_and_sync(attacker, launch)
    assert sync.error_code == grpc.StatusCode.INVALID_ARGUMENT.value[0], sync.error
    # creation with a wrapping shape and DATA of the wrapped size
    with pytest.raises(grpc.RpcError) as err:
        attacker.arrays.Create(array_pb2.CreateArrayRequest(
            dtype=types_pb2.DType(scalar=FLOAT32), shape=[1 << 31, 1 << 31, 1 << 31, 1 << 31],
            device="cpu", init=array_pb2.CreateArrayRequest.DATA, value=b""),
            metadata=attacker.metadata, timeout=10)
    assert err.value.code() == grpc.StatusCode.RESOURCE_EXHAUSTED, err.value.details()
    np.testing.assert_array_equal(np.frombuffer(read(attacker, a.handle), np.float32), np.arange(16))
    victim.unchanged()
    still_serving(wp)


# ------------------------------------------------------------------------------------------
# finding 6: sessions see each other's memory only through exports


def test_sessions_never_share_a_slab_and_reused_memory_is_clean(weftd, victim, attacker):
    mine = create(attacker, np.arange(64))
    assert mine.shm_name and victim.session.arrays.Describe(
        array_pb2.DescribeArrayRequest(handle=victim.handle), metadata=victim.session.metadata,
        timeout=10).info.shm_name != mine.shm_name
    # A secret written and freed by one session is not what another session's new array holds.
    secret = np.full(4096, 1234.5, np.float32)
    with weftd.raw_session("pytest secret owner") as owner:
        for _ in range(4):
            handle = create(owner, secret).handle
            owner.arrays.Free(array_pb2.FreeArrayRequest(handle=handle), metadata=owner.metadata,
                              timeout=10)
        keep = create(owner, secret)       # the owner's slab stays alive
        for _ in range(4):
            fresh = create(attacker, shape=[4096])     # EMPTY
            data = np.frombuffer(read(attacker, fresh.handle), np.float32)
            assert not np.any(data == 1234.5), "a new array holds another session's old data"
        owner_slab = owner.arrays.Describe(array_pb2.DescribeArrayRequest(handle=keep.handle),
                                           metadata=owner.metadata, timeout=10).info.shm_name
        assert owner_slab != fresh.shm_name
    victim.unchanged()


def test_an_import_maps_the_exported_bytes_and_nothing_else(weftd, victim, attacker):
    exported_values = np.arange(64, dtype=np.float32)
    exported = create(attacker, exported_values)
    neighbour = create(attacker, np.full(1024, 777.0, np.float32))   # same slab as `exported`
    assert exported.shm_name == neighbour.shm_name
    token = attacker.arrays.Export(array_pb2.ExportArrayRequest(handle=exported.handle),
                                   metadata=attacker.metadata, timeout=10).token
    # the export moved the array into a slab of its own; the exporter sees the new place
    moved = attacker.arrays.Describe(array_pb2.DescribeArrayRequest(handle=exported.handle),
                                     metadata=attacker.metadata, timeout=10).info
    assert moved.shm_name != neighbour.shm_name
    with weftd.raw_session("pytest importer") as importer:
        info = importer.arrays.Import(array_pb2.ImportArrayRequest(token=token),
                                      metadata=importer.metadata, timeout=10).info
        assert info.shm_name == moved.shm_name and info.shm_name != neighbour.shm_name
        path = "/dev/shm/" + info.shm_name.lstrip("/")
        fd = os.open(path, os.O_RDONLY)
        try:
            size = os.fstat(fd).st_size
            with mmap.mmap(fd, size, mmap.MAP_SHARED, mmap.PROT_READ) as mm:
                whole = bytes(mm)
        finally:
            os.close(fd)
        # The whole file: the exported bytes, then zeros; nothing of the neighbour.
        assert size < 64 * 4 + 8192
        start = info.shm_offset
        np.testing.assert_array_equal(np.frombuffer(whole[start:start + 256], np.float32), exported_values)
        assert whole[:start] == bytes(start) and whole[start + 256:] == bytes(size - start - 256)
        assert np.float32(777.0).tobytes() not in whole
        # writes through the import are seen by the exporter (the same bytes)
        importer.arrays.Write(iter([array_pb2.WriteArrayRequest(
            handle=info.handle, chunk=array_pb2.ArrayChunk(byte_offset=0, data=np.float32(-1).tobytes()))]),
            metadata=importer.metadata, timeout=10)
    data = np.frombuffer(read(attacker, exported.handle), np.float32)
    assert data[0] == -1 and np.array_equal(data[1:], exported_values[1:])
    np.testing.assert_array_equal(np.frombuffer(read(attacker, neighbour.handle), np.float32),
                                  np.full(1024, 777.0, np.float32))
    victim.unchanged()


def test_python_exporter_views_follow_the_export(wp):
    a = wp.array(np.arange(32, dtype=np.float32), device="cpu")
    b = wp.zeros(32, dtype=float, device="cpu")          # shares a's slab
    before = a._info.shm_name
    token = a.ipc_handle()
    assert a._info.shm_name != before and b._info.shm_name == before
    view = a.numpy()
    view[0] = 42.0
    imported = wp.from_ipc_handle(token, dtype=wp.float32, shape=(32,))
    assert imported.numpy()[0] == 42.0
    np.testing.assert_array_equal(imported.numpy()[1:], np.arange(1, 32, dtype=np.float32))


# ------------------------------------------------------------------------------------------
# quotas (finding 9, memory)


@pytest.fixture
def limited_weftd(start_weftd, tmp_path):
    config = tmp_path / "weftd.toml"
    config.write_text('max-principal-memory = "3M"\n')
    return start_weftd(["--max-session-memory", "2M", "--config", str(config)])


def expect_exhausted(call, limit_name):
    with pytest.raises(grpc.RpcError) as err:
        call()
    assert err.value.code() == grpc.StatusCode.RESOURCE_EXHAUSTED, err.value.details()
    assert limit_name in err.value.details(), err.value.details()
    return err.value.details()


def test_session_and_principal_memory_limits(limited_weftd):
    with limited_weftd.raw_session("quota a") as a, limited_weftd.raw_session("quota b") as b:
        first = create(a, shape=[256 * 1024])             # 1 MiB
        create(a, shape=[200 * 1024])                     # 0.8 MiB: 1.8 MiB in session a
        details = expect_exhausted(lambda: create(a, shape=[128 * 1024]), "per-session")
        assert "max-session-memory" in details and "2097152" in details, details
        create(b, shape=[256 * 1024])                     # b: 1 MiB; the principal: 2.8 MiB
        expect_exhausted(lambda: create(b, shape=[128 * 1024]), "per-principal")
        # freeing returns the bytes
        a.arrays.Free(array_pb2.FreeArrayRequest(handle=first.handle), metadata=a.metadata, timeout=10)
        create(b, shape=[128 * 1024])
        # requires_grad counts the gradient too
        expect_exhausted(lambda: a.arrays.Create(array_pb2.CreateArrayRequest(
            dtype=types_pb2.DType(scalar=FLOAT32), shape=[200 * 1024], device="cpu",
            requires_grad=True), metadata=a.metadata, timeout=10), "memory limit")
        assert create(a, np.arange(8)).handle   # still serving


def _swap_bytes():
    with open("/proc/meminfo") as meminfo:
        for line in meminfo:
            if line.startswith("SwapTotal:"):
                return int(line.split()[1]) * 1024
    return 0


def test_daemon_wide_limit_defaults_to_dev_shm(weftd, attacker, victim):
    """The finding: 120 GiB of arrays accepted on a 23 GiB machine. By default the daemon-wide
    limit is the size of /dev/shm (at most memory + swap), counted in reserved bytes: untouched
    arrays worth twice that are refused once the limit is reached."""
    st = os.statvfs("/dev/shm")
    shm = st.f_blocks * st.f_frsize
    phys = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") + _swap_bytes()
    limit = min(shm, phys)
    quarter = limit // 4 // 4                            # float32 elements in a quarter
    held = []
    with pytest.raises(grpc.RpcError) as err:
        for _ in range(8):                               # 2x the limit in reservations
            held.append(create(attacker, shape=[quarter]))
    assert err.value.code() == grpc.StatusCode.RESOURCE_EXHAUSTED, err.value.details()
    assert "daemon-wide memory limit" in err.value.details(), err.value.details()
    assert 3 <= len(held) <= 4
    for info in held:
        attacker.arrays.Free(array_pb2.FreeArrayRequest(handle=info.handle), metadata=attacker.metadata,
                             timeout=10)
    assert create(attacker, shape=[quarter]).handle      # freed bytes are available again
    victim.unchanged()


def test_python_client_sees_a_clear_quota_error(limited_weftd, run_client):
    proc = run_client(f"""
        import os
        os.environ["WEFT_ADDRESS"] = {limited_weftd.address!r}
        import weft as wp
        wp.set_device("cpu")
        try:
            wp.zeros(1 << 20, dtype=wp.float32)    # 4 MiB > 2 MiB per session
        except Exception as e:
            print("ERR", e)
        a = wp.zeros(16, dtype=wp.float32)
        print("OK", a.numpy().sum())
        """, env={"WEFT_ADDRESS": limited_weftd.address})
    out = proc.stdout
    assert "ERR" in out and "per-session memory limit" in out, out
    assert "OK 0.0" in out, out
