"""What a GPU -> host download of 40 MB costs, and what it could cost: weft's `array.numpy()`
(through the client's CUDA IPC mapping), warp-lang's `array.numpy()` in the same process, and
the same bytes copied by cuMemcpyDtoH from that mapping into (a) a new NumPy array, (b) a NumPy
array already touched once (no page faults), (c) a pinned buffer, then into a new NumPy array,
and (d) Torch's `.cpu()` when present; best of 5 each. Usage (GPU machine):
python3 bench/prof_download.py [--mb 40]   (WEFT_DAEMON; warp-lang on PYTHONPATH)."""
from __future__ import annotations

import argparse
import ctypes
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "clients" / "python"))

import bench_common as bc  # noqa: E402


def best(fn, k=5):
    t_best = None
    for _ in range(k):
        t = time.perf_counter()
        fn()
        dt = time.perf_counter() - t
        t_best = dt if t_best is None else min(t_best, dt)
    return t_best


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--mb", type=float, default=40)
    args = ap.parse_args()
    n = int(args.mb * 1e6 / 4)
    nbytes = 4 * n
    host = np.random.default_rng(5).random(n, dtype=np.float32)
    rows = []
    with bc.WeftSession() as (weft, _rt):
        from weft import _cuda_ipc

        a = weft.array(host, dtype=float, device="cuda:0")
        weft.synchronize()
        assert np.array_equal(a.numpy(), host)
        rows.append(("weft array.numpy()", best(a.numpy)))
        src = a.ptr
        if src is not None:
            lib = _cuda_ipc._lib

            def to_new():
                out = np.empty(nbytes, dtype=np.uint8)
                _cuda_ipc.copy_to_host(0, out.ctypes.data, src, nbytes)
                return out
            rows.append(("cuMemcpyDtoH into a new NumPy array", best(to_new)))
            import mmap  # noqa: PLC0415

            def to_huge():
                m = mmap.mmap(-1, nbytes, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS)
                m.madvise(mmap.MADV_HUGEPAGE)
                out = np.frombuffer(m, dtype=np.uint8)
                _cuda_ipc.copy_to_host(0, out.ctypes.data, src, nbytes)
                return out
            rows.append(("cuMemcpyDtoH into mmap + MADV_HUGEPAGE", best(to_huge)))

            def to_populated():
                m = mmap.mmap(-1, nbytes, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS | mmap.MAP_POPULATE)
                out = np.frombuffer(m, dtype=np.uint8)
                _cuda_ipc.copy_to_host(0, out.ctypes.data, src, nbytes)
                return out
            rows.append(("cuMemcpyDtoH into mmap + MAP_POPULATE", best(to_populated)))
            touched = np.ones(nbytes, dtype=np.uint8)
            rows.append(("cuMemcpyDtoH into a touched NumPy array",
                         best(lambda: _cuda_ipc.copy_to_host(0, touched.ctypes.data, src, nbytes))))
            pinned = ctypes.c_void_p()
            fn = lib.cuMemHostAlloc
            fn.argtypes = [ctypes.POINTER(ctypes.c_void_p), ctypes.c_size_t, ctypes.c_uint]
            fn.restype = ctypes.c_int
            with _cuda_ipc._Scope(0):
                rc = fn(ctypes.byref(pinned), nbytes, 0)
            if rc == 0:
                view = np.ctypeslib.as_array((ctypes.c_uint8 * nbytes).from_address(pinned.value))

                def via_pinned():
                    _cuda_ipc.copy_to_host(0, pinned.value, src, nbytes)
                    return view.copy()
                assert np.array_equal(via_pinned().view(np.float32), host)
                rows.append(("cuMemcpyDtoH into pinned memory only",
                             best(lambda: _cuda_ipc.copy_to_host(0, pinned.value, src, nbytes))))
                rows.append(("cuMemcpyDtoH into pinned, then a NumPy copy", best(via_pinned)))
        del a
    warp = bc.import_warp()
    if warp is not None:
        w = warp.array(host, dtype=float, device="cuda:0")
        warp.synchronize()
        rows.append(("warp-lang array.numpy()", best(w.numpy)))
    try:
        import torch  # noqa: PLC0415

        t = torch.from_numpy(host).cuda()
        torch.cuda.synchronize()
        rows.append(("torch tensor.cpu()", best(t.cpu)))
    except ImportError:
        pass
    try:
        thp = Path("/sys/kernel/mm/transparent_hugepage/enabled").read_text().strip()
    except OSError:
        thp = "unknown"
    print(f"\nGPU -> host, {nbytes / 1e6:.0f} MB (best of 5; transparent huge pages: {thp})")
    for name, t in rows:
        print(f"  {name:45s} {t * 1e3:8.2f} ms  {nbytes / t / 1e9:6.1f} GB/s")


if __name__ == "__main__":
    main()
