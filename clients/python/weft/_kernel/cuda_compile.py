"""Compiling for a CUDA architecture without a GPU: wp.compile(..., arch=N) and
wp.compile_aot_module. The daemon compiles the module with NVRTC for sm_N (CompileRequest
cuda_arch) and reads each entry point's resources from the CUBIN; nothing is loaded on a
device, so this works on a machine without a GPU or a CUDA driver."""

from __future__ import annotations

import dataclasses
import os
import pathlib

from .errors import WeftCompileError


@dataclasses.dataclass(frozen=True)
class CudaKernelReport:
    """One entry point (a kernel's forward or adjoint) as the CUBIN describes it."""
    kernel: str
    adjoint: bool
    symbol: str
    registers: int        # per thread
    code_bytes: int       # machine code
    shared_bytes: int     # static shared memory
    local_bytes: int      # stack frame per thread
    const_bytes: int      # constant bank 0 (parameters and the driver's area)


@dataclasses.dataclass
class CudaCompileReport:
    """The result of compiling a kernel or a module for one CUDA architecture."""
    arch: int
    binary_size: int              # CUBIN bytes (all builds of the module together)
    nvrtc_version: str
    kernels: list                 # CudaKernelReport, forward then adjoint per kernel
    compile_ms: float = 0.0
    cache_hit: bool = False
    binaries: list = dataclasses.field(default_factory=list, repr=False)   # (digest, CUBIN)

    def kernel(self, name: str, adjoint: bool = False) -> CudaKernelReport:
        for k in self.kernels:
            if k.kernel == name and k.adjoint == adjoint:
                return k
        raise KeyError(f"no {'adjoint of ' if adjoint else ''}kernel {name!r} in the sm_{self.arch} "
                       f"report (has {sorted({k.kernel for k in self.kernels})})")

    def __str__(self) -> str:
        rows = [f"sm_{self.arch}: {self.binary_size} bytes of CUBIN (NVRTC {self.nvrtc_version})",
                f"{'kernel':<32} {'pass':<8} {'regs':>5} {'code':>8} {'shared':>7} {'local':>6} {'const':>6}"]
        for k in self.kernels:
            rows.append(f"{k.kernel:<32} {'adjoint' if k.adjoint else 'forward':<8} {k.registers:>5} "
                        f"{k.code_bytes:>8} {k.shared_bytes:>7} {k.local_bytes:>6} {k.const_bytes:>6}")
        return "\n".join(rows)


def parse_arch(arch) -> int:
    """An architecture as the client may write it: 90, "90", "sm_90" (checked by the daemon)."""
    value = arch
    if isinstance(value, str):
        text = value.strip().lower()
        text = text[3:] if text.startswith("sm_") else text
        if not text.isdigit():
            raise ValueError(f"unknown CUDA architecture {arch!r} (expected e.g. 75, 80, 90 or 'sm_90')")
        value = int(text)
    if isinstance(value, bool) or not isinstance(value, int) or not 0 < value < 1000:
        raise ValueError(f"unknown CUDA architecture {arch!r} (expected e.g. 75, 80, 90 or 'sm_90')")
    return value


def check_device(device) -> str:
    """The device string of a CUDA compile: None, "cuda" or "cuda:N" (a Device is named)."""
    if device is None:
        return "cuda"
    name = device if isinstance(device, str) else getattr(device, "alias", None) or str(device)
    if name == "cuda" or (name.startswith("cuda:") and name[5:].isdigit()):
        return name
    raise ValueError(f"arch= compiles for a CUDA device; device must be None, 'cuda' or 'cuda:N', not {device!r}")


def _sources_of(kernels) -> list:
    """The distinct ModuleSource messages (with their digests) that build these kernels, with
    the module's enable_backward setting (the daemon then adds the adjoint entry points)."""
    from . import module as module_mod  # noqa: PLC0415

    seen = {}
    for k in kernels:
        instances = list(k._specializations.values()) if k.is_generic else [k]
        for instance in instances:
            source, _ = module_mod.build_module_source(instance)
            if not module_mod.build_options(instance).get("enable_backward", True):
                source.options["enable_backward"] = "false"
            digest = module_mod.content_hash(source)
            seen.setdefault(digest, source)
    return list(seen.items())


def compile_for_arch(kernels, arch, device=None, return_binary: bool = False) -> CudaCompileReport:
    """Compiles the builds of `kernels` for sm_<arch> and merges their reports."""
    from weft import _runtime  # noqa: PLC0415
    from weft.v1 import module_pb2  # noqa: PLC0415

    from .module import format_diagnostics  # noqa: PLC0415

    sm = parse_arch(arch)
    dev = check_device(device)
    sources = _sources_of(kernels)
    if not sources:
        raise WeftCompileError("nothing to compile: no kernels (a generic kernel needs wp.overload first)")
    rt = _runtime.get_runtime()
    report = CudaCompileReport(arch=sm, binary_size=0, nvrtc_version="", kernels=[], cache_hit=True)
    for digest, source in sources:
        request = module_pb2.CompileRequest(module=source, device=dev, cuda_arch=sm,
                                            return_binary=return_binary)
        try:
            response = rt.call(rt.module_stub.Compile, request)
        except Exception as err:  # noqa: BLE001 - a WeftError from the runtime: add context
            diags = list(getattr(err, "diagnostics", []) or [])
            text = format_diagnostics(diags) if diags else str(err)
            raise WeftCompileError(f"module {source.name} failed to compile for sm_{sm}:\n{text}", diags) from None
        errors = [d for d in response.diagnostics if d.severity == 0]
        if errors or not response.HasField("cuda"):
            text = format_diagnostics(response.diagnostics) or "no diagnostics"
            raise WeftCompileError(f"module {source.name} failed to compile for sm_{sm}:\n{text}",
                                   list(response.diagnostics))
        cuda = response.cuda
        report.binary_size += cuda.binary_size
        report.nvrtc_version = cuda.nvrtc_version
        report.compile_ms += response.compile_ms
        report.cache_hit = report.cache_hit and response.cache_hit
        known = {(k.kernel, k.adjoint) for k in report.kernels}
        for k in cuda.kernels:
            if (k.kernel, k.adjoint) in known:
                continue
            report.kernels.append(CudaKernelReport(
                kernel=k.kernel, adjoint=k.adjoint, symbol=k.symbol, registers=k.registers,
                code_bytes=k.code_bytes, shared_bytes=k.shared_bytes, local_bytes=k.local_bytes,
                const_bytes=k.const_bytes))
        if return_binary:
            report.binaries.append((digest, bytes(cuda.binary)))
    return report


def _archs_of_devices(device) -> list:
    from ..device import get_device  # noqa: PLC0415

    devices = device if isinstance(device, (list, tuple)) else [device]
    archs = []
    for d in devices:
        dev = get_device(d)
        if not getattr(dev, "is_cuda", False):
            raise NotImplementedError(f"compile_aot_module for {dev}: weft keeps CPU modules in the daemon's "
                                      f"cache (they are compiled on first launch); AOT artifacts are CUDA only")
        archs.append(dev.arch)
    return archs


def compile_aot_module(module, device=None, arch=None, module_dir=None, use_ptx=None, strip_hash=None) -> list:
    """Warp's wp.compile_aot_module: compiles `module` ahead of time for the CUDA architectures
    in `arch` (and those of the CUDA devices in `device`) and writes one CUBIN per build and
    architecture to module_dir (default: ~/.cache/weft/aot). Returns the paths, in target
    order. PTX (use_ptx=True) and CPU devices are not supported."""
    import types  # noqa: PLC0415

    from . import module as module_mod  # noqa: PLC0415

    if use_ptx:
        raise NotImplementedError("compile_aot_module(use_ptx=True): weft compiles CUDA modules to CUBIN only")
    del strip_hash   # symbol names are weft's own (weft_<kernel>_cuda_forward): nothing to strip
    if isinstance(module, types.ModuleType):
        name = module.__name__
    elif isinstance(module, str):
        name = module
    elif isinstance(module, module_mod.Module):
        name = module.name
    else:
        raise TypeError(f"compile_aot_module expects a module, a module name or a weft Module, got {module!r}")
    targets = []
    if device is not None:
        targets += _archs_of_devices(device)
    if arch is not None:
        targets += [parse_arch(a) for a in (arch if isinstance(arch, (list, tuple, set)) else [arch])]
    if not targets:
        from ..device import get_device  # noqa: PLC0415
        targets = _archs_of_devices(get_device())
    kernels = module_mod.kernels_of(name)
    if not kernels:
        raise RuntimeError(f"Cannot compile module {name}: it has no kernels")
    out_dir = pathlib.Path(module_dir) if module_dir is not None else \
        pathlib.Path(os.path.expanduser("~/.cache/weft/aot"))
    paths = []
    for sm in targets:
        report = compile_for_arch(kernels, sm, return_binary=True)
        for digest, binary in report.binaries:
            base = f"{name.replace('.', '_')}_{digest[:7]}"
            path = out_dir / base / f"{base}.sm{sm}.cubin"
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_suffix(".tmp")
            tmp.write_bytes(binary)
            tmp.replace(path)
            paths.append(path)
    return paths
