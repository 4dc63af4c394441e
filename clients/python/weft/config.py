"""wp.config: process-wide settings under Warp 1.19's names and defaults.

What weft does with them:
  mode                 "release" | "debug"; sent with every module as its "mode" option (part of
                       the module's cache key); any other value is refused at compile time.
  verify_fp            sent as the "verify_fp" module option; after each launch the client
                       checks the launch's float arrays and raises FloatingPointError naming the
                       kernel, the argument and the launch line when one holds a NaN or an inf.
  print_launches       each wp.launch prints "kernel: KEY dim: DIM inputs: [...] device: DEV".
  verbose              each module the daemon really compiles (not a cache hit) prints
                       "Module NAME load on device DEV took T ms (compiled)".
  enable_vector_component_overwrites, optimization_level: sent with the module's options when
                       set away from their defaults (so they are part of its cache key).
The daemon owns the module cache (weftd --cache-dir). A weftd the client starts itself gets a
disk cache: kernel_cache_dir, else $WEFT_CACHE_DIR, else ~/.cache/weft/modules, or none (memory
only) with cache_kernels = False; a daemon started otherwise keeps its own setting. CUDA, tile,
mathdx settings are accepted and change nothing; enable_mempools_at_init is the default of the GPU
pools' switch (weft/mempool.py).
"""
import sys as _sys
import types as _types
from enum import IntEnum as _IntEnum

LOG_DEBUG = 10
LOG_INFO = 20
LOG_WARNING = 30
LOG_ERROR = 40


class LaunchArrayAccessMode(_IntEnum):
    """How launches check that array arguments live on the launch device."""

    RELAXED = 0
    CHECKED = 1
    STRICT = 2


class DeterministicMode(_IntEnum):
    """Ordering guarantees for atomic operations (the CPU daemon runs them in a fixed order)."""

    NOT_GUARANTEED = 0
    RUN_TO_RUN = 1
    GPU_TO_GPU = 2


version = "1.19.0"                  # the Warp API version this client follows
launch_array_access_mode = LaunchArrayAccessMode.RELAXED
verify_fp = False
verify_cuda = False
print_launches = False
mode = "release"
optimization_level = None
verbose = False
verbose_warnings = False
quiet = False
log_level = LOG_INFO
verify_autograd_array_access = False
enable_vector_component_overwrites = False
legacy_scalar_return_types = False
cache_kernels = True
kernel_cache_dir = None
cuda_output = None
ptx_target_arch = None
cuda_arch_suffix = None
lineinfo = False
line_directives = True
compile_time_trace = False
enable_backward = True
enable_cpu_blocks = False
default_grid_stride = True
enable_mathdx_gemm = True
enable_mathdx_solver = True
enable_mathdx_fft = True
cpu_compiler_flags = None
llvm_cuda = False
enable_graph_capture_module_load_by_default = True
enable_mempools_at_init = True
track_memory = False
max_unroll = 16
enable_tiles_in_stack_memory = True
use_precompiled_headers = True
legacy_cpu_linker = False
load_module_max_workers = 0
deterministic = DeterministicMode.NOT_GUARANTEED
deterministic_max_records = 0
deterministic_debug = False


_COMPILE_SETTINGS = ("mode", "verify_fp", "enable_vector_component_overwrites",
                     "optimization_level", "max_unroll", "enable_backward", "default_grid_stride")


class _ConfigModule(_types.ModuleType):
    """wp.config's module type: checks the enum settings, and a changed compile setting makes
    the next launch rebuild its module options (compiled kernels are looked up again)."""

    def __setattr__(self, name, value):
        if name == "launch_array_access_mode" and not isinstance(value, LaunchArrayAccessMode):
            raise ValueError(f"wp.config.launch_array_access_mode must be a "
                             f"wp.config.LaunchArrayAccessMode value, got {value!r}")
        if name == "deterministic" and not isinstance(value, DeterministicMode):
            raise ValueError(f"wp.config.deterministic must be a wp.DeterministicMode value, "
                             f"got {value!r}")
        super().__setattr__(name, value)
        if name in _COMPILE_SETTINGS:
            from weft._kernel import module as _module  # noqa: PLC0415 - imports this module

            _module.bump_version()


_sys.modules[__name__].__class__ = _ConfigModule


def module_options() -> dict:
    """The settings that belong to a module's compile options (and so to its cache key):
    mode and verify_fp always, the others when set away from their defaults."""
    if mode not in ("release", "debug"):
        raise ValueError(f"wp.config.mode must be 'release' or 'debug', got {mode!r}")
    out = {"mode": mode, "verify_fp": bool(verify_fp)}
    if enable_vector_component_overwrites:
        out["enable_vector_component_overwrites"] = True
    if optimization_level is not None:
        out["optimization_level"] = int(optimization_level)
    return out
