// Text dump of the SSA IR (WEFT_DUMP_IR=1 prints it between pipeline stages).
#include "engine/sema/ir.h"

namespace weft::sema {
namespace {

void DumpStmts(const Function& f, const std::vector<Stmt>& stmts, int indent, std::string* out) {
  auto pad = [&]() { out->append(static_cast<size_t>(indent) * 2, ' '); };
  auto var = [&](int v) { return "%" + std::to_string(v); };
  for (const auto& s : stmts) {
    pad();
    switch (s.kind) {
      case Stmt::Kind::kOp: {
        const Op& op = s.op;
        for (size_t i = 0; i < op.dst.size(); ++i)
          *out += (i ? ", " : "") + var(op.dst[i]) + ":" + TypeString(f.vars[op.dst[i]].type);
        if (!op.dst.empty()) *out += " = ";
        *out += OpKindName(op.kind);
        if (op.builtin) *out += " " + op.builtin->native;
        if (op.callee >= 0) *out += " func#" + std::to_string(op.callee);
        if (!op.text.empty()) *out += " '" + op.text + "'";
        for (int a : op.args) *out += " " + var(a);
        *out += "  ; line " + std::to_string(s.line) + "\n";
        break;
      }
      case Stmt::Kind::kIf:
        *out += "if " + var(s.cond) + ":\n";
        DumpStmts(f, s.then_body, indent + 1, out);
        if (!s.else_body.empty()) {
          pad();
          *out += "else:\n";
          DumpStmts(f, s.else_body, indent + 1, out);
        }
        break;
      case Stmt::Kind::kLoop:
        if (s.is_while) {
          *out += "while:\n";
          DumpStmts(f, s.cond_body, indent + 2, out);
          pad();
          *out += "  test " + var(s.cond) + "\n";
        } else {
          *out += "for " + var(s.iter) + " in range(" + var(s.start) + ", " + var(s.end) + ", " + var(s.step) + "):\n";
        }
        for (const auto& c : s.carried) {
          pad();
          *out += "  carried " + var(c.slot) + " init " + var(c.init) + " next " + var(c.next) + "\n";
        }
        DumpStmts(f, s.body, indent + 1, out);
        break;
    }
  }
}

}  // namespace

const char* OpKindName(OpKind k) {
  switch (k) {
#define WEFT_IR_NAME(N) \
  case OpKind::k##N:    \
    return #N;
    WEFT_FOR_EACH_IR_OP(WEFT_IR_NAME)
#undef WEFT_IR_NAME
  }
  return "?";
}

std::string DumpModule(const Module& m) {
  std::string out;
  for (const auto& f : m.functions) {
    out += (f.is_kernel ? "kernel " : "func ") + f.cpp_name + "(";
    for (size_t i = 0; i < f.params.size(); ++i)
      out += (i ? ", " : "") + f.param_names[i] + " %" + std::to_string(f.params[i]) + ":" +
             TypeString(f.vars[f.params[i]].type);
    out += ")";
    for (const auto& r : f.returns) out += " -> " + TypeString(r);
    out += "\n";
    DumpStmts(f, f.body, 1, &out);
  }
  return out;
}

}  // namespace weft::sema
