"""Interop in a remote (TCP) session, where no memory is shared: DLPack export and to_torch
give copies of the array's data, copy=False is refused with BufferError, and from_torch /
from_dlpack copy the data in; results are checked against the source values."""


def test_remote_session_copies(tcp_weftd, run_client, torch):
    run_client("""
        import numpy as np
        import torch
        import weft as wp
        import weft._runtime as rt
        wp.init()
        assert not rt.get_runtime().local
        rng = np.random.default_rng()
        values = rng.standard_normal(20).astype(np.float32)
        a = wp.array(values, device="cpu")
        assert a.ptr is None
        try:
            a.__dlpack__(copy=False)
        except BufferError as err:
            assert "remote session" in str(err)
        else:
            raise AssertionError("copy=False must be refused without shared memory")
        view = np.from_dlpack(a)
        assert np.array_equal(view, values)
        t = wp.to_torch(a)
        assert np.array_equal(t.numpy(), values)
        t.mul_(2.0)                                    # a copy: the array is unchanged
        assert np.array_equal(a.numpy(), values)
        b = wp.from_torch(torch.tensor(values * 3.0))
        assert np.array_equal(b.numpy(), values * 3.0)
        c = wp.from_dlpack(np.arange(5, dtype=np.int64))
        assert np.array_equal(c.numpy(), np.arange(5))
        print("OK")
    """, env={"WEFT_ADDRESS": tcp_weftd.address, "WEFT_TOKEN": tcp_weftd.token}, timeout=180)
