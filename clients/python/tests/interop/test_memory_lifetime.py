"""Lifetime of shared memory across frameworks: a consumer (NumPy via DLPack, a Torch tensor
from to_torch or DLPack) keeps the weft allocation and its mapping alive after the weft array
object is gone, and reads the right bytes while new arrays are allocated; once every holder is
gone the allocation is freed and its address no longer resolves to weft memory (no stale
look-ups)."""
import gc

import numpy as np

import weft as wp
from weft.interop import memory


def _churn(wp, rng, count=20):
    """Allocate (and write) more arrays, so a freed block would be reused and overwritten."""
    keep = []
    for _ in range(count):
        keep.append(wp.array(rng.standard_normal(256).astype(np.float32), device="cpu"))
    wp.synchronize()
    return keep


def test_numpy_dlpack_consumer_keeps_memory_alive(wp, rng):
    values = rng.standard_normal(256).astype(np.float32)
    a = wp.array(values, device="cpu")
    view = np.from_dlpack(a)
    ptr = a.ptr
    del a
    gc.collect()
    others = _churn(wp, rng)
    assert view.ctypes.data == ptr
    np.testing.assert_array_equal(view, values)
    assert memory.find(ptr, values.nbytes) is not None     # still weft memory, still alive
    del others


def test_torch_consumer_keeps_memory_alive(wp, torch, rng):
    values = rng.standard_normal(256).astype(np.float32)
    a = wp.array(values, device="cpu")
    t1 = wp.to_torch(a)
    t2 = torch.utils.dlpack.from_dlpack(a)
    del a
    gc.collect()
    others = _churn(wp, rng)
    np.testing.assert_array_equal(t1.numpy(), values)
    np.testing.assert_array_equal(t2.numpy(), values)
    back = wp.from_torch(t1)                                # resolves to the same allocation
    assert back.ptr == t1.data_ptr()
    np.testing.assert_array_equal(back.numpy(), values)
    del others


def test_freed_allocation_no_longer_resolves(wp, rng):
    a = wp.array(rng.standard_normal(64).astype(np.float32), device="cpu")
    ptr, nbytes, handle = a.ptr, 64 * 4, a._handle
    hit = memory.find(ptr, nbytes)
    assert hit is not None and hit[1] == 0
    assert memory.find(ptr, nbytes + 4) is None             # past the allocation's end
    del a, hit
    gc.collect()
    found = memory.find(ptr, nbytes)
    # nothing else was allocated since, so nothing resolves; and it never resolves to the
    # freed allocation (its entry went away with it)
    assert found is None or found[0].info.handle != handle
    assert found is None



def test_forgetting_an_allocation_needs_no_module_globals(run_client):
    """The finalizer that drops a dead allocation's address range may run at interpreter exit,
    after the module's globals were cleared (it once failed there: "Exception ignored in ...
    forget"): it keeps what it needs. The child clears them and then lets an array die."""
    proc = run_client("""
        import gc
        import sys

        import numpy as np
        import weft as wp
        from weft.interop import memory

        a = wp.array(np.arange(1000, dtype=np.float32), device="cpu")
        view = np.asarray(a)                  # zero-copy: the slab's range is tracked
        assert float(view[999]) == 999.0
        errors = []
        sys.unraisablehook = lambda u: errors.append(repr(u.exc_value))
        memory._lock = None                   # as at interpreter exit
        memory.bisect = None
        del view, a
        gc.collect()
        print("finalizer errors:", errors)
    """)
    assert "finalizer errors: []" in proc.stdout, proc.stdout + proc.stderr
