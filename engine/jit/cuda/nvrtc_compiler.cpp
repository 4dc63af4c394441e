// NVRTC wrapper: CUDA C++ source -> PTX/CUBIN (placeholder until the wrapper lands).
namespace weft::jit {}
