// C++ emission: sema's SSA IR -> one translation unit for the CPU (clang) or CUDA (NVRTC)
// target, plus each kernel's argument-block layout.
// Expects: a checked Module (sema/check.h). Guarantees: the source includes only weft.h and
// codegen_support.h (engine/native); user funcs are `static inline` functions taking
// `const wp::launch_context_t* __ctx` first; kernels are the entry points of
// engine/native/launch_abi.h. With options.enable_backward every function also gets a
// side-effect-free replay twin and an adjoint (adj_<name>), and kernels a backward entry
// point; without it no adjoint code is emitted at all. `// file.py:42` comments point
// every statement back at the user's source. Client text (names, file names, formats)
// enters the source only through engine/codegen/emit_text.h.
#pragma once

#include "engine/codegen/generate_module.h"
#include "engine/sema/ir.h"

namespace weft::codegen {

// A failure of the emitter itself (a bug) becomes InvalidArgument with one Diagnostic at the
// function being emitted (appended to *diags when given), never an unlocated error.
Expected<GeneratedModule> EmitCpp(const sema::Module& module, const CodegenOptions& options,
                                  std::vector<Diagnostic>* diags = nullptr);

// Layout of one kernel parameter (exposed for tests).
Expected<ParamLayout> LayoutParam(const std::string& name, const sema::Type& type, const sema::StructTable& structs);

}  // namespace weft::codegen
