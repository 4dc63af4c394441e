// Recursive-descent parser for the kernel language (placeholder until the full parser lands).
#include "engine/lang/parser.h"

namespace weft::lang {

Expected<std::unique_ptr<ast::FunctionDef>> ParseFunction(const FunctionSource& fn,
                                                          std::vector<Diagnostic>* diags) {
  (void)diags;
  return Unimplemented("parser not implemented yet for " + fn.name);
}

}  // namespace weft::lang
