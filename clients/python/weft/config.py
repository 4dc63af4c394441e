"""wp.config: process-wide settings, as Warp names them. The kernel API reads these when it
builds modules (mode, verify_fp, enable_backward...); the rest are accepted for compatibility."""

version = "0.1.0"
mode = "release"            # "release" | "debug": compile options sent with each module
verify_fp = False           # check kernels' floating-point results for NaN/inf
verify_cuda = False
print_launches = False
verbose = False
verbose_warnings = False
quiet = False               # weft prints no banner either way
enable_backward = True      # generate adjoint code when a backward pass needs it
max_unroll = 16
cache_kernels = True
kernel_cache_dir = None     # the daemon owns the cache; kept for compatibility
enable_vector_component_overwrites = False
