"""wp.compile(..., arch=N) and wp.compile_aot_module on a machine without a GPU: the daemon
compiles with NVRTC for sm_N and reports, per kernel, forward and adjoint, registers per
thread and code/shared/local/constant bytes read from the CUBIN. Attacks: architectures
outside the list, a CPU device with an architecture, huge values through raw gRPC."""
from __future__ import annotations

import grpc
import numpy as np
import pytest

pytestmark = pytest.mark.usefixtures("needs_nvrtc")


@pytest.fixture(scope="module")
def kernels(wp):
    @wp.kernel
    def arch_saxpy(a: float, x: wp.array(dtype=float), y: wp.array(dtype=float)):
        i = wp.tid()
        y[i] = a * wp.sin(x[i]) + y[i]

    @wp.kernel
    def arch_heavy(x: wp.array(dtype=wp.vec3), out: wp.array(dtype=float)):
        i = wp.tid()
        v = x[i]
        m = wp.outer(v, v) + wp.identity(3, dtype=float)
        out[i] = wp.determinant(m) + wp.length(wp.inverse(m) @ v)

    return arch_saxpy, arch_heavy


@pytest.mark.parametrize("arch", [75, 90])
def test_a_kernel_compiles_for_an_architecture_without_a_gpu(wp, kernels, arch):
    saxpy, _ = kernels
    report = wp.compile(saxpy, device="cuda", arch=arch)
    assert report.arch == arch
    assert report.binary_size > 1000
    forward = report.kernel("arch_saxpy")
    adjoint = report.kernel("arch_saxpy", adjoint=True)
    for k in (forward, adjoint):
        assert 0 < k.registers <= 255, k
        assert k.code_bytes > 0 and k.const_bytes > 0, k
    assert forward.symbol != adjoint.symbol
    print(report)


def test_a_module_reports_every_kernel_and_archs_differ(wp, kernels):
    import sys

    module = sys.modules[__name__]
    reports = wp.compile(module, arch=["sm_75", "90"])
    assert [r.arch for r in reports] == [75, 90]
    for report in reports:
        names = {(k.kernel, k.adjoint) for k in report.kernels}
        assert {("arch_saxpy", False), ("arch_saxpy", True), ("arch_heavy", False),
                ("arch_heavy", True)} <= names, names
        # more work, more machine code (registers are allocated in steps: they may tie)
        assert report.kernel("arch_heavy").code_bytes > report.kernel("arch_saxpy").code_bytes
    # The CUBIN differs per architecture (different machine code).
    assert reports[0].binary_size != reports[1].binary_size or \
        reports[0].kernel("arch_heavy").code_bytes != reports[1].kernel("arch_heavy").code_bytes
    again = wp.compile(module, arch=90)
    assert again.cache_hit
    assert again.kernels == reports[1].kernels


def test_compile_for_an_architecture_changes_nothing_else(wp, kernels):
    """The arch-only build is never loaded: the kernel still runs on the CPU afterwards."""
    saxpy, _ = kernels
    wp.compile(saxpy, arch=90)
    x = wp.array(np.random.rand(64).astype(np.float32) + 0.5, dtype=float, device="cpu")
    y = wp.array(np.random.rand(64).astype(np.float32) + 0.5, dtype=float, device="cpu")
    expect = 2.0 * np.sin(x.numpy().astype(np.float64)) + y.numpy()
    wp.launch(saxpy, dim=64, inputs=[2.0, x, y], device="cpu")
    np.testing.assert_allclose(y.numpy(), expect, rtol=1e-6)


def test_compile_aot_module_writes_cubins(wp, kernels, tmp_path):
    import sys

    paths = wp.compile_aot_module(sys.modules[__name__], arch=[75, 90], module_dir=tmp_path)
    assert len(paths) >= 2
    assert any(str(p).endswith(".sm75.cubin") for p in paths)
    assert any(str(p).endswith(".sm90.cubin") for p in paths)
    for p in paths:
        data = p.read_bytes()
        assert data[:4] == b"\x7fELF" and tmp_path in p.parents
    with pytest.raises(NotImplementedError):
        wp.compile_aot_module(sys.modules[__name__], arch=90, module_dir=tmp_path, use_ptx=True)


@pytest.mark.parametrize("arch", [0, 52, 61, 70, 91, 999])
def test_unknown_architectures_are_refused_with_the_list(wp, kernels, arch):
    saxpy, _ = kernels
    with pytest.raises((wp.WeftCompileError, ValueError)) as error:
        wp.compile(saxpy, arch=arch)
    text = str(error.value)
    assert f"unknown CUDA architecture {arch}" in text
    if isinstance(error.value, wp.WeftCompileError):
        assert "75" in text and "90" in text   # the supported list


@pytest.mark.parametrize("arch", ["sm_", "90a", -90, True, 2.5, 10**6])
def test_malformed_architectures_are_refused_by_the_client(wp, kernels, arch):
    saxpy, _ = kernels
    with pytest.raises(ValueError, match="unknown CUDA architecture"):
        wp.compile(saxpy, arch=arch)


def test_a_cpu_device_with_an_architecture_is_refused(wp, kernels):
    saxpy, _ = kernels
    with pytest.raises(ValueError, match="CUDA device"):
        wp.compile(saxpy, device="cpu", arch=90)


def _raw_module():
    from weft.v1 import module_pb2

    return module_pb2.ModuleSource(name="raw_arch", functions=[module_pb2.FunctionSource(
        name="k", source="def k(a: wp.array(dtype=float)):\n    a[wp.tid()] = 1.0\n",
        file="raw_arch.py", first_line=1, is_kernel=True, param_types=["array(float32,1)"],
        param_names=["a"], key="raw_arch.k")], symbols=[module_pb2.Symbol(name="wp", builtin_module="warp")])


@pytest.mark.parametrize("arch,device", [(2**32 - 1, "cuda"), (61, ""), (90, "cpu"), (90, "tpu:0"),
                                         (90, "cuda:0\n#include </etc/passwd>")])
def test_raw_grpc_bad_arch_or_device_is_invalid_argument(weftd, arch, device):
    from weft.v1 import module_pb2

    with weftd.raw_session() as raw:
        with pytest.raises(grpc.RpcError) as error:
            raw.modules.Compile(module_pb2.CompileRequest(module=_raw_module(), device=device, cuda_arch=arch),
                                metadata=raw.metadata, timeout=60)
        assert error.value.code() == grpc.StatusCode.INVALID_ARGUMENT, error.value.details()
        assert "\n#include" not in error.value.details()   # client text is escaped, never raw
        # The daemon keeps serving the session.
        ok = raw.modules.Compile(module_pb2.CompileRequest(module=_raw_module(), device="cuda", cuda_arch=90,
                                                           return_binary=True),
                                 metadata=raw.metadata, timeout=120)
        assert ok.cuda.arch == 90 and not ok.module_id
        assert ok.cuda.binary[:4] == b"\x7fELF" and len(ok.cuda.binary) == ok.cuda.binary_size
        assert [(k.kernel, k.adjoint) for k in ok.cuda.kernels] == [("k", False), ("k", True)]


@pytest.mark.parametrize("arch", [75, 90])
def test_geometry_queries_compile_for_the_gpu(wp, arch):
    """The BVH walk and the mesh closest-point search (engine/native/bvh.h, mesh.h) take their
    GPU-only paths (read-only-cache node loads) under NVRTC: compiled here for sm_75 and sm_90,
    without a GPU; docs/cuda.md."""
    @wp.kernel
    def arch_geometry(mesh: wp.uint64, bvh: wp.uint64, p: wp.array(dtype=wp.vec3), out: wp.array(dtype=float)):
        i = wp.tid()
        q = wp.mesh_query_point_no_sign(mesh, p[i], 10.0)
        box = wp.bvh_query_aabb(bvh, p[i], p[i] + wp.vec3(1.0))
        item = int(0)
        n = int(0)
        while wp.bvh_query_next(box, item):
            n += 1
        out[i] = q.u + float(n)

    report = wp.compile(arch_geometry, device="cuda", arch=arch)
    forward = report.kernel("arch_geometry")
    assert report.arch == arch and 0 < forward.registers <= 255 and forward.code_bytes > 0, report


@pytest.mark.parametrize("arch", [75, 90])
def test_cuda_entries_are_lean_whatever_grid_stride_says(wp, arch):
    """A kernel's CUDA entries run one index per thread (no loop: the loop's prologue would carry
    the hoisted invariants of the bounds checks' error paths); a launch that needs the loop
    (max_blocks) gets the module's grid-stride variant, built on first use, unless the kernel,
    the module option default_grid_stride or wp.config.default_grid_stride said False (then
    max_blocks is refused, as Warp 1.19 does). So the default, grid_stride=False and
    grid_stride=True compile to the same entry."""
    def body(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):
        i = wp.tid()
        y[i] = a * x[i] + y[i]

    default = wp.compile(wp.Kernel(func=body, key="stride_default", module="unique"),
                         device="cuda", arch=arch).kernel("body")
    lean = wp.compile(wp.Kernel(func=body, key="stride_lean", module="unique",
                                options={"grid_stride": False}), device="cuda", arch=arch).kernel("body")
    explicit = wp.compile(wp.Kernel(func=body, key="stride_explicit", module="unique",
                                    options={"grid_stride": True}), device="cuda", arch=arch).kernel("body")
    assert default.code_bytes == lean.code_bytes == explicit.code_bytes > 0, (default, lean, explicit)
    assert default.registers == lean.registers == explicit.registers, (default, lean, explicit)
    old = wp.config.default_grid_stride
    try:
        wp.config.default_grid_stride = False
        by_config = wp.Kernel(func=body, key="stride_config", module="unique")
        assert wp.compile(by_config, device="cuda", arch=arch).kernel("body").code_bytes == lean.code_bytes
    finally:
        wp.config.default_grid_stride = old
