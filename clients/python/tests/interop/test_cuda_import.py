"""Framework GPU memory imported into weftd by CUDA IPC (ArrayService.ImportCuda; skipped with
the reason without a GPU the daemon computes on, without Torch/CuPy on CUDA, or where the client
cannot use CUDA IPC): wp.from_torch, tensors passed to wp.launch, from_dlpack of CuPy arrays
are the framework's memory (same device pointer, no copy, the tensor not re-pointed), writes
seen both ways with Torch's stream work ordered before the launch, the gradient the same memory
on both sides, a tensor converted again costs no new import, a block handed out again reuses
the dead import's parked handle without a round trip, a training loop's new gradient in a
freed block finds the import remembered on its tensor (which does not hold the gradient's
memory; each array does), blocks the caching allocator frees and hands out again (also after
empty_cache) are never read through an old mapping, an import refused for a stale mapping frees
the imports that hold no memory and is asked again; hostile
requests (a forged handle, a range past the allocation, a handle another session imported,
weft's own memory) get clear errors, as does a tensor of another GPU than the launch's; an
imported array cannot be exported."""
import numpy as np
import pytest

import weft as wp


@wp.kernel
def scale_sum(x: wp.array(dtype=float), s: float, total: wp.array(dtype=float)):
    i = wp.tid()
    x[i] = x[i] * s
    wp.atomic_add(total, 0, x[i])


@wp.kernel
def square_sum(x: wp.array(dtype=float), loss: wp.array(dtype=float)):
    i = wp.tid()
    wp.atomic_add(loss, 0, x[i] * x[i])


def _imported(a) -> bool:
    return a._alloc.keep is not None


def test_from_torch_imports_in_place_and_writes_are_seen_both_ways(wp, tcuda, torch, rng):
    values = rng.standard_normal(5000).astype(np.float32)
    t = torch.tensor(values, device="cuda")
    before = t.data_ptr()
    a = wp.from_torch(t)
    assert _imported(a), "not imported (copied or moved)"
    assert a.ptr == t.data_ptr() == before          # the tensor is not re-pointed
    total = wp.zeros(1, dtype=float, device=tcuda)
    wp.launch(scale_sum, dim=a.size, inputs=[a, 2.0, total], device=tcuda)
    np.testing.assert_allclose(t.cpu().numpy(), values.astype(np.float64) * 2.0, rtol=1e-6)
    t.add_(1.0)        # Torch's stream work before the launch is visible to it
    total.zero_()
    wp.launch(scale_sum, dim=a.size, inputs=[a, 3.0, total], device=tcuda)
    ref = (values.astype(np.float64) * 2.0 + 1.0) * 3.0
    np.testing.assert_allclose(t.cpu().numpy(), ref, rtol=1e-5)
    np.testing.assert_allclose(total.numpy()[0], ref.sum(), rtol=1e-4, atol=1e-2)


def test_tensor_passed_to_launch_is_imported_and_remembered(wp, tcuda, torch, rng):
    values = rng.standard_normal(3000).astype(np.float32)
    t = torch.tensor(values, device="cuda")
    before = t.data_ptr()
    total = wp.zeros(1, dtype=float, device=tcuda)
    for k in range(3):
        wp.launch(scale_sum, dim=t.shape[0], inputs=[t, 1.5, total], device=tcuda)
    assert t.data_ptr() == before
    np.testing.assert_allclose(t.cpu().numpy(), values.astype(np.float64) * 1.5 ** 3, rtol=1e-5)
    imports = t.__dict__["_weft_imports"]
    # one import for three launches (remembered under its full key and a cheap first key)
    assert len({id(v) for v in imports.values()}) == 1
    a, b = wp.from_torch(t), wp.from_torch(t)
    assert a is not b and a._handle == b._handle == next(iter(imports.values()))._handle


def test_converting_again_follows_what_the_tensor_is_now(wp, tcuda, torch, rng):
    """A tensor converted again takes the first look-up (interop/torch.py _last_import): the
    same import, a new array object; once the tensor is resized, re-pointed, asks for another
    dtype or requires grad, the conversion sees that (new shape, new memory, the gradient)."""
    values = rng.standard_normal(4096).astype(np.float32)
    t = torch.tensor(values, device="cuda")
    a = wp.from_torch(t)
    b = wp.from_torch(t)
    assert a is not b and a._handle == b._handle and b.ptr == t.data_ptr() and _imported(b)
    total = wp.zeros(1, dtype=float, device=tcuda)
    wp.launch(scale_sum, dim=4096, inputs=[b, 2.0, total], device=tcuda)
    wp.synchronize()
    np.testing.assert_allclose(t.cpu().numpy(), values.astype(np.float64) * 2.0, rtol=1e-6)
    u = torch.tensor(values.reshape(2048, 2), device="cuda")
    assert wp.from_torch(u).shape == (2048, 2) and wp.from_torch(u).shape == (2048, 2)
    c = wp.from_torch(u, dtype=wp.vec2)                 # another dtype asked for
    assert c.shape == (2048,) and c.dtype == wp.vec2 and c.ptr == u.data_ptr()
    t.resize_(1000)                                      # same memory, another shape
    d = wp.from_torch(t)
    assert d.shape == (1000,) and d.ptr == t.data_ptr()
    t.set_(torch.tensor(values[:7], device="cuda"))      # re-pointed at other memory
    e = wp.from_torch(t)
    assert e.shape == (7,) and e.ptr == t.data_ptr() and e.ptr != a.ptr
    np.testing.assert_array_equal(e.numpy(), values[:7])
    t.requires_grad_(True)                               # the gradient path, not the look-up
    f = wp.from_torch(t)
    assert f.requires_grad and f.grad is not None and t.grad is not None
    assert f.grad.ptr == t.grad.data_ptr()


def test_descriptors_converted_again_follow_the_tensor(wp, tcuda, torch, rng,
                                                      descriptors_follow_the_tensor):
    """from_torch(return_ctype=True) of a tensor converted before copies the remembered
    descriptor (interop/torch.py _last_descriptor): a new object with the same bytes, taken by
    launches like its array; once the tensor changes (re-pointed, resized, another dtype asked
    for, gradients), the descriptor says so."""
    values = rng.standard_normal(4096).astype(np.float32)
    t = torch.tensor(values, device="cuda")
    descs = [wp.from_torch(t, return_ctype=True) for _ in range(4)]
    assert len({id(d) for d in descs}) == 4
    assert {bytes(d) for d in descs} == {bytes(descs[0])}
    assert descs[-1].data == t.data_ptr() and descs[-1].shape[0] == 4096
    total = wp.zeros(1, dtype=float, device=tcuda)
    for d in descs[1:]:
        wp.launch(scale_sum, dim=4096, inputs=[d, 2.0, total], device=tcuda)
    wp.synchronize()
    np.testing.assert_allclose(t.cpu().numpy(), values.astype(np.float64) * 8.0, rtol=1e-6)
    descriptors_follow_the_tensor(t, values, "cuda")


def test_strided_tensor_view_is_imported(wp, tcuda, torch, rng):
    base = torch.tensor(rng.standard_normal((64, 6)).astype(np.float32), device="cuda")
    view = base[:, ::2]
    a = wp.from_torch(view)
    assert _imported(a) and a.ptr == view.data_ptr() and a.shape == (64, 3)
    np.testing.assert_array_equal(a.numpy(), view.cpu().numpy())


def test_gradients_are_the_same_memory(wp, tcuda, torch, rng):
    values = rng.standard_normal(1024).astype(np.float32)
    t = torch.tensor(values, device="cuda", requires_grad=True)
    a = wp.from_torch(t)
    assert a.requires_grad and t.grad is not None
    assert a.grad.ptr == t.grad.data_ptr()
    loss = wp.zeros(1, dtype=float, device=tcuda, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(square_sum, dim=a.size, inputs=[a, loss], device=tcuda)
    tape.backward(loss=loss)
    wp.synchronize()
    np.testing.assert_allclose(t.grad.cpu().numpy(), 2.0 * values.astype(np.float64), rtol=1e-6)
    with torch.no_grad():
        t.grad.mul_(0.5)                             # Torch writes the weft gradient
    np.testing.assert_allclose(a.grad.numpy(), values.astype(np.float64), rtol=1e-6)


def test_reused_blocks_are_never_read_through_an_old_mapping(wp, tcuda, torch):
    """Blocks handed out again by Torch's caching allocator (same segment), and segments freed
    with empty_cache() and allocated again (same address, maybe the same handle bytes, a new
    buffer id): every launch reads the values the tensor holds then."""
    total = wp.zeros(1, dtype=float, device=tcuda)
    for k in range(1, 9):
        block = torch.full((1 << 16,), float(k), device="cuda")
        total.zero_()
        wp.launch(scale_sum, dim=block.shape[0], inputs=[wp.from_torch(block), 1.0, total],
                  device=tcuda)
        assert total.numpy()[0] == pytest.approx(float(k) * (1 << 16))
        del block
        wp.synchronize()
        import gc

        gc.collect()                 # the weft array (and its hold on the tensor) goes
        if k % 2 == 0:
            torch.cuda.empty_cache()  # the segment goes back to the driver


def test_a_block_handed_out_again_reuses_the_parked_import(wp, tcuda, torch, monkeypatch):
    """A tensor whose import died parks its daemon handle (cuda_import.PARKED_IMPORTS); a new
    tensor Torch places in the same block of the same allocation (a training loop's new
    gradient) gets it back without a round trip and is that tensor's memory; at most
    PARKED_IMPORTS handles stay parked."""
    import gc

    from weft import _runtime
    from weft.interop import cuda_import

    rt = _runtime.get_runtime()
    n = 1 << 15
    t = torch.full((n,), 1.0, device="cuda")
    ptr = t.data_ptr()
    a = wp.from_torch(t)
    handle = a._handle
    total = wp.zeros(1, dtype=float, device=tcuda)
    wp.launch(scale_sum, dim=n, inputs=[a, 1.0, total], device=tcuda)
    wp.synchronize()
    del a, t
    gc.collect()
    t2 = torch.full((n,), 2.0, device="cuda")
    if t2.data_ptr() != ptr:
        pytest.skip("Torch placed the new tensor in another block")
    calls = []
    real = rt.array_call
    monkeypatch.setattr(rt, "array_call", lambda method, req: calls.append(method) or real(method, req))
    b = wp.from_torch(t2)
    assert "ImportCuda" not in calls, "the parked import was not reused"
    assert b._handle == handle and b.ptr == t2.data_ptr()
    total.zero_()
    wp.launch(scale_sum, dim=n, inputs=[b, 3.0, total], device=tcuda)
    assert total.numpy()[0] == pytest.approx(6.0 * n)        # t2's values, not t's
    np.testing.assert_array_equal(t2.cpu().numpy(), np.full(n, 6.0, dtype=np.float32))
    # another shape at the same address is another import
    del b
    gc.collect()
    t3 = t2.view(2, n // 2)
    c = wp.from_torch(t3)
    assert "ImportCuda" in calls and c.shape == (2, n // 2)
    del c, t3, t2
    # bounded: many distinct blocks imported and dropped
    keep = [torch.zeros(256 + 64 * k, device="cuda") for k in range(3 * cuda_import.PARKED_IMPORTS)]
    for t in keep:
        wp.from_torch(t)
    del keep, t
    gc.collect()
    assert 0 < len(cuda_import._parked(rt)) <= cuda_import.PARKED_IMPORTS


def _adjoint_step(wp, tcuda, x):
    """One step of the zero_grad() pattern on tensor `x`: its gradient dropped, `x` converted
    with a new zero gradient, the adjoint of square_sum (incoming gradient 1) written into it.
    Returns the array (it holds the gradient's memory)."""
    x.grad = None
    a = wp.from_torch(x, requires_grad=True)
    loss = wp.zeros(1, dtype=float, device=tcuda, requires_grad=True)
    loss.grad.fill_(1.0)
    wp.launch(square_sum, dim=a.size, inputs=[a, loss], adj_inputs=[a.grad, loss.grad],
              adjoint=True, device=tcuda)
    wp.synchronize()
    return a


def test_a_new_gradient_in_a_freed_block_finds_the_remembered_import(wp, tcuda, torch, rng,
                                                                      monkeypatch):
    """The training loop's pattern (zero_grad() drops the gradient, from_torch(x,
    requires_grad=True) puts new zeros there): the import remembered on the tensor does not hold
    the gradient's memory, so Torch hands a freed block out again and the conversion finds the
    import without a new one; every step's gradient is the tensor's (2x, float64 reference)."""
    from weft.interop import cuda_import

    values = rng.uniform(-3.0, 3.0, 1 << 14).astype(np.float32)
    x = torch.tensor(values, device="cuda", requires_grad=True)
    imports = []
    real = cuda_import.import_memory
    monkeypatch.setattr(cuda_import, "import_memory",
                        lambda *a, **k: imports.append(a[0].ptr) or real(*a, **k))
    seen, found_again, prev = set(), 0, None
    for _ in range(8):
        before = len(imports)
        a = _adjoint_step(wp, tcuda, x)          # the previous array lives until here
        gptr = x.grad.data_ptr()
        assert a.grad.ptr == gptr
        np.testing.assert_allclose(x.grad.cpu().numpy(), 2.0 * values.astype(np.float64),
                                   rtol=1e-6)
        if gptr in seen:
            assert len(imports) == before, "a gradient block seen before was imported again"
            found_again += 1
        seen.add(gptr)
        prev = a
    del prev
    if found_again == 0:
        pytest.skip("Torch placed every gradient in a new block")
    assert found_again >= 4


def test_an_array_holds_its_gradient_memory_the_remembered_import_does_not(wp, tcuda, torch, rng):
    """While an array from from_torch(x, requires_grad=True), or a tensor exported from its
    gradient, lives, Torch cannot hand the gradient's block to another tensor (the array's
    gradient holds it, not the import remembered on `x`)."""
    import gc

    n = 1 << 14
    x = torch.tensor(rng.standard_normal(n).astype(np.float32), device="cuda",
                     requires_grad=True)
    a = wp.from_torch(x, requires_grad=True)
    gptr = a.grad.ptr
    exported = wp.to_torch(a.grad)
    x.grad = None
    del a
    gc.collect()
    others = [torch.empty(n, device="cuda") for _ in range(6)]
    assert gptr not in [o.data_ptr() for o in others], "a block an exported gradient holds was handed out"
    del others
    a = wp.from_torch(x, requires_grad=True)     # another gradient block (the old one is held)
    assert a.grad.ptr != gptr
    del exported
    gc.collect()
    others = [torch.empty(n, device="cuda") for _ in range(6)]
    assert a.grad.ptr not in [o.data_ptr() for o in others]   # the new array holds its own


def test_a_gradient_in_a_reallocated_segment_is_imported_afresh(wp, tcuda, torch, rng,
                                                                 monkeypatch):
    """A gradient segment freed with empty_cache() and allocated again (same address, a new
    buffer id): the remembered import is not used (it maps the old segment); the adjoint
    lands in the new gradient. 16 MB tensors: Torch gives each a segment of its own (smaller
    ones share 20 MB segments, which x would keep alive)."""
    import gc

    from weft import _cuda_ipc
    from weft.interop import cuda_import

    values = rng.uniform(-2.0, 2.0, 1 << 22).astype(np.float32)
    x = torch.tensor(values, device="cuda", requires_grad=True)
    a = _adjoint_step(wp, tcuda, x)
    old, old_id = a.grad.ptr, _cuda_ipc.buffer_id(a.grad.ptr)
    x.grad = None
    del a
    gc.collect()
    torch.cuda.empty_cache()
    imports = []
    real = cuda_import.import_memory
    monkeypatch.setattr(cuda_import, "import_memory",
                        lambda *a, **k: imports.append(1) or real(*a, **k))
    a = _adjoint_step(wp, tcuda, x)
    np.testing.assert_allclose(x.grad.cpu().numpy(), 2.0 * values.astype(np.float64), rtol=1e-6)
    if x.grad.data_ptr() != old:
        pytest.skip("the new gradient segment came at another address")
    if _cuda_ipc.buffer_id(old) == old_id:
        pytest.skip("Torch kept the gradient's segment (empty_cache did not free it)")
    assert imports, "the remembered import of the freed segment was used"


def test_an_import_refused_for_a_stale_mapping_frees_unheld_imports(wp, tcuda, torch, rng,
                                                                    monkeypatch):
    """weftd refuses an import whose handle bytes it still maps for a freed segment (parked,
    or remembered on a tensor without its memory): the client frees those imports and asks
    again, and the conversion works."""
    import gc

    from weft import _runtime
    from weft.errors import WeftError
    from weft.interop import cuda_import

    rt = _runtime.get_runtime()
    x = torch.tensor(rng.standard_normal(4096).astype(np.float32), device="cuda",
                     requires_grad=True)
    _adjoint_step(wp, tcuda, x)                  # remembered on x without its gradient
    dropped = torch.ones(5000, device="cuda")
    wp.from_torch(dropped)
    del dropped
    gc.collect()                                 # parked
    assert cuda_import._parked(rt) and any(a._alloc.runtime is rt for a in cuda_import._UNHELD)
    calls = []
    real = rt.array_call

    def refuse_once(method, request):
        calls.append(method)
        if method == "ImportCuda" and calls.count("ImportCuda") == 1:
            raise WeftError("CUDA import: the allocation behind this IPC handle changed "
                            "(allocation id 1 -> 2) while arrays of this session still use "
                            "the old one; free those arrays first", "FAILED_PRECONDITION")
        return real(method, request)

    monkeypatch.setattr(rt, "array_call", refuse_once)
    t = torch.full((3000,), 2.0, device="cuda")
    b = wp.from_torch(t)
    assert calls.count("ImportCuda") == 2 and b.ptr == t.data_ptr()
    assert not cuda_import._parked(rt)
    assert not any(a._alloc.runtime is rt for a in cuda_import._UNHELD)
    assert "_weft_imports" not in x.__dict__ or not x.__dict__["_weft_imports"]
    np.testing.assert_array_equal(b.numpy(), np.full(3000, 2.0, dtype=np.float32))


def _raw_import(wp, handle: bytes, allocation_id: int, offset: int, n: int, device="cuda:0"):
    from weft import _runtime
    from weft.array import _dtype_proto

    rt = _runtime.get_runtime()
    ap = _runtime.array_pb2
    request = ap.ImportCudaRequest(device=device, dtype=_dtype_proto(wp.float32), shape=[n],
                                   data=ap.CudaMemoryRef(ipc_handle=handle,
                                                         allocation_id=allocation_id,
                                                         byte_offset=offset))
    return rt.call(rt.array_stub.ImportCuda, request).info


def test_hostile_imports_get_clear_errors(wp, tcuda, torch, rng):
    from weft import _cuda_ipc

    t = torch.zeros(1000, device="cuda")
    base, size, buffer_id, handle = _cuda_ipc.export_allocation(0, t.data_ptr())
    offset = t.data_ptr() - base
    info = _raw_import(wp, handle, buffer_id, offset, 1000)     # the honest request works
    assert info.byte_size == 4000
    wp.array._from_info(info)        # owned: freed when collected (t outlives it)
    with pytest.raises(Exception, match="runs past the end of the imported allocation"):
        _raw_import(wp, handle, buffer_id, size - 8, 4)
    with pytest.raises(Exception, match="could not be opened on cuda:0"):
        _raw_import(wp, bytes(rng.integers(0, 256, 64, dtype=np.uint8)), 5, 0, 4)
    with pytest.raises(Exception, match="IPC handle has 64 bytes"):
        _raw_import(wp, handle[:63], buffer_id, 0, 4)
    with pytest.raises(Exception, match="not a GPU"):
        _raw_import(wp, handle, buffer_id, 0, 4, device="cpu")
    own = wp.zeros(16, dtype=float, device=tcuda)
    with pytest.raises(Exception, match="weft's own memory"):
        _raw_import(wp, own._info.cuda_ipc_handle, 9, 0, 4)
    a = wp.from_torch(t)
    with pytest.raises(Exception, match="cannot be shared with other sessions"):
        a.ipc_handle()


CHILD = """
import sys, torch, weft as wp
from weft import _cuda_ipc
t = torch.ones(256, device="cuda")
a = wp.from_torch(t)
base, size, buffer_id, handle = _cuda_ipc.export_allocation(0, t.data_ptr())
print(handle.hex(), buffer_id, t.data_ptr() - base, flush=True)
sys.stdin.readline()
"""


class _Interface:
    """An object exposing a given (hand-made) __cuda_array_interface__."""

    def __init__(self, interface):
        self.__cuda_array_interface__ = interface


def test_forged_cuda_array_interfaces_in_wp_array_get_clear_errors(wp, tcuda, torch):
    """wp.array of objects whose __cuda_array_interface__ lies: a view far past its
    allocation is neither imported nor read (the copy it falls back to is refused by the
    daemon's limits), a masked array and a type weft has no scalar for are clear errors; the
    honest interface of the same memory works."""
    t = torch.arange(16, dtype=torch.float32, device="cuda")
    honest = _Interface({"shape": (16,), "typestr": "<f4", "data": (t.data_ptr(), False),
                         "version": 3, "strides": None})
    a = wp.array(honest, device=tcuda)
    assert a.ptr == t.data_ptr()
    np.testing.assert_array_equal(a.numpy(), np.arange(16, dtype=np.float32))
    past = _Interface({"shape": (1 << 40,), "typestr": "<f4", "data": (t.data_ptr(), False),
                       "version": 3, "strides": None})
    with pytest.raises(Exception, match="limit|memory|too large|exceeds"):
        wp.array(past, device=tcuda)
    masked = _Interface({"shape": (16,), "typestr": "<f4", "data": (t.data_ptr(), False),
                         "version": 3, "strides": None, "mask": honest})
    with pytest.raises(Exception, match="masked"):
        wp.array(masked, device=tcuda)
    complex_ = _Interface({"shape": (8,), "typestr": "<c8", "data": (t.data_ptr(), False),
                           "version": 3, "strides": None})
    with pytest.raises(Exception, match="unsupported dtype complex64"):
        wp.array(complex_, device=tcuda)
    np.testing.assert_array_equal(t.cpu().numpy(), np.arange(16, dtype=np.float32))


def test_a_handle_another_session_imported_is_refused(wp, tcuda, torch, spawn_client):
    child = spawn_client(CHILD)
    line = child.stdout.readline().split()
    assert line, child.stderr.read()
    handle, buffer_id, offset = bytes.fromhex(line[0]), int(line[1]), int(line[2])
    try:
        with pytest.raises(Exception, match="imported by another session"):
            _raw_import(wp, handle, buffer_id, offset, 256)
    finally:
        child.stdin.write("\n")
        child.stdin.flush()
        child.wait(timeout=60)


def test_memory_of_another_gpu_is_a_clear_error(wp, tcuda, torch):
    if torch.cuda.device_count() < 2 or len(wp.get_cuda_devices()) < 2:
        pytest.skip("needs two GPUs")
    t = torch.zeros(64, device="cuda:1")
    with pytest.raises(Exception, match="lives on cuda:1"):
        wp.launch(scale_sum, dim=64, inputs=[t, 1.0, wp.zeros(1, device="cuda:0")],
                  device="cuda:0")
    a = wp.from_torch(t)                # imported on its own GPU
    assert str(a.device) == "cuda:1" and a.ptr == t.data_ptr()


def test_wp_array_of_a_cuda_tensor_or_cupy_array_is_imported(wp, tcuda, torch, rng):
    """wp.array(t) of a CUDA tensor (or a CuPy array) is that memory, imported by CUDA IPC
    (Warp wraps __cuda_array_interface__ objects); the tensor is not re-pointed."""
    values = rng.standard_normal(2048).astype(np.float32)
    t = torch.tensor(values, device="cuda")
    before = t.data_ptr()
    a = wp.array(t, device=tcuda)
    assert _imported(a) and a.ptr == t.data_ptr() == before
    total = wp.zeros(1, dtype=float, device=tcuda)
    wp.launch(scale_sum, dim=2048, inputs=[a, 3.0, total], device=tcuda)
    wp.synchronize()
    np.testing.assert_allclose(t.cpu().numpy(), values.astype(np.float64) * 3.0, rtol=1e-6)
    leaf = torch.tensor(values, device="cuda", requires_grad=True)   # Torch's interface refuses it
    assert wp.array(leaf, device=tcuda).ptr == leaf.data_ptr()
    cp = pytest.importorskip("cupy", reason="CuPy is not installed")
    c = cp.asarray(values)
    b = wp.array(c, device=tcuda)
    assert _imported(b) and b.ptr == c.data.ptr
    np.testing.assert_array_equal(b.numpy(), values)


def test_cupy_arrays_are_imported(wp, tcuda, rng):
    cp = pytest.importorskip("cupy", reason="CuPy is not installed")
    values = rng.standard_normal(777).astype(np.float32)
    c = cp.asarray(values)
    a = wp.from_dlpack(c)
    assert _imported(a) and a.ptr == c.data.ptr
    total = wp.zeros(1, dtype=float, device=tcuda)
    wp.launch(scale_sum, dim=c.size, inputs=[c, 0.5, total], device=tcuda)
    np.testing.assert_allclose(cp.asnumpy(c), values.astype(np.float64) * 0.5, rtol=1e-6)
