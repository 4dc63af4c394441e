"""`warp._src.codegen`: Warp's code generator's internals, which weft does not have.

weft compiles kernels in the daemon from the kernel's Python source; there is no Warp `Adjoint`
and no Warp-generated C++ to return. Calling `codegen_func_forward` says so.
"""
from __future__ import annotations


def codegen_func_forward(adj, func_type="kernel", device="cpu"):
    raise NotImplementedError(
        "codegen_func_forward returns the C++ that Warp's code generator writes; weft generates "
        "its code in the daemon (set WEFT_DUMP_IR=1 to see it in the daemon's log)")
