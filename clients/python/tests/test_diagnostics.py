"""The CUDA toolchain queries and wp.print_diagnostics against a real weftd: the driver and
toolkit versions are Warp's (major, minor) tuples (None where absent), the supported
architectures are what the daemon's NVRTC compiles for (the same NVRTC `wp.compile(arch=...)`
uses), and print_diagnostics prints and returns the daemon's devices and toolchain."""
from __future__ import annotations


def test_toolchain_queries_are_warps_types(wp):
    driver = wp.get_cuda_driver_version()
    toolkit = wp.get_cuda_toolkit_version()
    archs = wp.get_cuda_supported_archs()
    for version in (driver, toolkit):
        assert version is None or (isinstance(version, tuple) and len(version) == 2 and
                                   all(isinstance(v, int) for v in version) and version[0] >= 11)
    assert archs == sorted(archs) and all(isinstance(a, int) for a in archs)
    assert set(archs) <= {75, 80, 86, 87, 89, 90, 100, 103, 110, 120, 121}
    assert bool(archs) == (toolkit is not None)      # both come from the daemon's NVRTC
    if wp.is_cuda_available():
        assert driver is not None
        for d in wp.get_cuda_devices():
            assert any(a <= d.arch for a in archs), (d.arch, archs)


def test_supported_archs_compile(wp, needs_nvrtc, tmp_path):
    """The lowest and highest architecture listed compile (wp.compile needs no GPU)."""
    import importlib.util
    import textwrap

    path = tmp_path / "diag_kernels.py"
    path.write_text("import weft as wp\n" + textwrap.dedent("""
        @wp.kernel
        def diag_scale(a: wp.array(dtype=float), s: float):
            i = wp.tid()
            a[i] = a[i] * s
    """))
    spec = importlib.util.spec_from_file_location("diag_kernels", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    archs = wp.get_cuda_supported_archs()
    for arch in {archs[0], archs[-1]}:
        report = wp.compile(module.diag_scale, device="cuda", arch=arch)
        assert report, arch


def test_print_diagnostics_prints_and_returns(wp, capsys):
    info = wp.print_diagnostics()
    out = capsys.readouterr().out
    assert {"warp_python", "weft", "numpy", "python", "platform", "daemon", "cuda_enabled",
            "cuda_toolkit", "cuda_driver", "nvrtc", "cuda_archs", "devices"} <= set(info)
    assert [d["alias"] for d in info["devices"]] == [d.alias for d in wp.get_devices()]
    for d in wp.get_devices():
        assert d.alias in out
    assert info["cuda_archs"] == wp.get_cuda_supported_archs()
    assert "weftd" in out and "Devices" in out
