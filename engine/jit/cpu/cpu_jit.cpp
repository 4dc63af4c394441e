// CpuJit: in-process clang -> object code -> ORC LLJIT (placeholder until the JIT lands).
namespace weft::jit {}
