// Names of the AST's node kinds and operators, generated from the X-macro lists in ast.h.
#include "engine/lang/ast.h"

namespace weft::ast {

const char* ExprKindName(ExprKind k) {
  switch (k) {
#define WEFT_AST_NAME_CASE(N) \
  case ExprKind::k##N:        \
    return #N;
    WEFT_FOR_EACH_AST_EXPR(WEFT_AST_NAME_CASE)
#undef WEFT_AST_NAME_CASE
  }
  return "?";
}

const char* StmtKindName(StmtKind k) {
  switch (k) {
#define WEFT_AST_NAME_CASE(N) \
  case StmtKind::k##N:        \
    return #N;
    WEFT_FOR_EACH_AST_STMT(WEFT_AST_NAME_CASE)
#undef WEFT_AST_NAME_CASE
  }
  return "?";
}

#define WEFT_AST_SPELLING_CASE(E, S, N) \
  case Op::E:                           \
    return S;
#define WEFT_AST_ASTNAME_CASE(E, S, N) \
  case Op::E:                          \
    return N;
#define WEFT_AST_DEFINE_OP_NAMES(OpType, LIST)   \
  const char* Spelling(OpType op) {              \
    using Op = OpType;                           \
    switch (op) { LIST(WEFT_AST_SPELLING_CASE) } \
    return "?";                                  \
  }                                              \
  const char* AstName(OpType op) {               \
    using Op = OpType;                           \
    switch (op) { LIST(WEFT_AST_ASTNAME_CASE) }  \
    return "?";                                  \
  }

WEFT_AST_DEFINE_OP_NAMES(BinaryOperator, WEFT_FOR_EACH_BINARY_OPERATOR)
WEFT_AST_DEFINE_OP_NAMES(UnaryOperator, WEFT_FOR_EACH_UNARY_OPERATOR)
WEFT_AST_DEFINE_OP_NAMES(BoolOperator, WEFT_FOR_EACH_BOOL_OPERATOR)
WEFT_AST_DEFINE_OP_NAMES(CompareOperator, WEFT_FOR_EACH_COMPARE_OPERATOR)

#undef WEFT_AST_DEFINE_OP_NAMES
#undef WEFT_AST_ASTNAME_CASE
#undef WEFT_AST_SPELLING_CASE

}  // namespace weft::ast
