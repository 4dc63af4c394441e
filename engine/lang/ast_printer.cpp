// AST printer (see ast_printer.h): two visitors over the X-macro node lists, so a new node
// kind does not compile until it has a printed form.
#include "engine/lang/ast_printer.h"
#include "engine/lang/unparse.h"

#include <charconv>
#include <cmath>
#include <cstdio>

namespace weft::lang {
namespace {

// Python-like repr of a double: shortest round-trip digits, ".0" on integral values.
std::string FloatRepr(double v) {
  if (std::isnan(v)) return "nan";
  if (std::isinf(v)) return v < 0 ? "-inf" : "inf";
  char buf[64];
  auto [ptr, ec] = std::to_chars(buf, buf + sizeof(buf), v);
  std::string s(buf, ec == std::errc() ? ptr : buf);
  if (s.find_first_of(".en") == std::string::npos) s += ".0";
  return s;
}

class ExprPrinter : public ast::ConstExprVisitor<ExprPrinter, std::string> {
 public:
  std::string Print(const ast::Expr* e) { return e ? VisitExpr(*e) : "_"; }

  std::string VisitName(const ast::Name& n) { return n.id; }

  std::string VisitConstant(const ast::Constant& c) {
    switch (c.type) {
      case ast::Constant::Type::kInt: return c.int_decimal;
      case ast::Constant::Type::kFloat: return FloatRepr(c.float_value);
      case ast::Constant::Type::kBool: return c.bool_value ? "True" : "False";
      case ast::Constant::Type::kNone: return "None";
      case ast::Constant::Type::kString: return QuotePythonString(c.string_value, '"');
    }
    return "?";
  }

  std::string VisitAttribute(const ast::Attribute& a) {
    return "(. " + Print(a.value.get()) + " " + a.attr + ")";
  }

  std::string VisitSubscript(const ast::Subscript& s) {
    std::string out = "([] " + Print(s.value.get());
    for (const auto& i : s.indices) out += " " + Print(i.get());
    return out + ")";
  }

  std::string VisitSlice(const ast::Slice& s) {
    return "(: " + Print(s.lower.get()) + " " + Print(s.upper.get()) + " " + Print(s.step.get()) +
           ")";
  }

  std::string VisitCall(const ast::Call& c) {
    std::string out = "(call " + Print(c.func.get());
    for (const auto& a : c.args) out += " " + Print(a.get());
    for (const auto& k : c.keywords) out += " " + k.name + "=" + Print(k.value.get());
    return out + ")";
  }

  std::string VisitBinOp(const ast::BinOp& b) {
    return std::string("(") + ast::Spelling(b.op) + " " + Print(b.left.get()) + " " +
           Print(b.right.get()) + ")";
  }

  std::string VisitUnaryOp(const ast::UnaryOp& u) {
    const char* op = u.op == ast::UnaryOperator::kPlus    ? "u+"
                     : u.op == ast::UnaryOperator::kMinus ? "u-"
                                                          : ast::Spelling(u.op);
    return std::string("(") + op + " " + Print(u.operand.get()) + ")";
  }

  std::string VisitBoolOp(const ast::BoolOp& b) {
    std::string out = std::string("(") + ast::Spelling(b.op);
    for (const auto& v : b.values) out += " " + Print(v.get());
    return out + ")";
  }

  std::string VisitCompare(const ast::Compare& c) {
    std::string out = "(cmp " + Print(c.left.get());
    for (size_t i = 0; i < c.ops.size() && i < c.comparators.size(); ++i) {
      out += std::string(" ") + ast::Spelling(c.ops[i]) + " " + Print(c.comparators[i].get());
    }
    return out + ")";
  }

  std::string VisitIfExp(const ast::IfExp& e) {
    return "(? " + Print(e.test.get()) + " " + Print(e.body.get()) + " " + Print(e.orelse.get()) +
           ")";
  }

  std::string VisitTuple(const ast::Tuple& t) {
    std::string out = "(tuple";
    for (const auto& e : t.elts) out += " " + Print(e.get());
    return out + ")";
  }

  std::string VisitList(const ast::List& l) {
    std::string out = "(list";
    for (const auto& e : l.elts) out += " " + Print(e.get());
    return out + ")";
  }

  std::string VisitStarred(const ast::Starred& s) { return "(* " + Print(s.value.get()) + ")"; }
};

std::string P(const ast::Expr* e) { return ExprPrinter().Print(e); }

class StmtPrinter : public ast::ConstStmtVisitor<StmtPrinter> {
 public:
  StmtPrinter(int indent, const PrintOptions& options) : indent_(indent), options_(options) {}
  std::string out;

  void VisitFunctionDef(const ast::FunctionDef& f) {
    for (const auto& d : f.decorators) Line("@" + d, nullptr);
    std::string head = "def " + f.name + "(";
    for (size_t i = 0; i < f.params.size(); ++i) {
      const ast::Param& p = f.params[i];
      if (i) head += ", ";
      head += p.name;
      if (p.annotation) head += ": " + P(p.annotation.get());
      if (p.default_value) head += " = " + P(p.default_value.get());
    }
    head += ")";
    if (f.returns) head += " -> " + P(f.returns.get());
    Line(head, &f);
    ++indent_;
    if (!f.docstring.empty()) Line("doc " + QuotePythonString(f.docstring, '"'), nullptr);
    Body(f.body);
    --indent_;
  }

  void VisitAssign(const ast::Assign& a) {
    std::string s = "assign";
    for (const auto& t : a.targets) s += " " + P(t.get()) + " =";
    Line(s + " " + P(a.value.get()), &a);
  }

  void VisitAnnAssign(const ast::AnnAssign& a) {
    std::string s = "annassign " + P(a.target.get()) + ": " + P(a.annotation.get());
    if (a.value) s += " = " + P(a.value.get());
    Line(s, &a);
  }

  void VisitAugAssign(const ast::AugAssign& a) {
    Line("augassign " + P(a.target.get()) + " " + ast::Spelling(a.op) + "= " + P(a.value.get()),
         &a);
  }

  void VisitIf(const ast::If& s) {
    Line(std::string(s.is_elif ? "elif " : "if ") + P(s.test.get()), &s);
    Indented(s.body);
    if (s.orelse.size() == 1) {
      if (const auto* elif = ast::As<ast::If>(s.orelse[0].get()); elif && elif->is_elif) {
        VisitIf(*elif);
        return;
      }
    }
    if (!s.orelse.empty()) {
      Line("else", nullptr);
      Indented(s.orelse);
    }
  }

  void VisitFor(const ast::For& f) {
    Line("for " + P(f.target.get()) + " in " + P(f.iter.get()), &f);
    Indented(f.body);
  }

  void VisitWhile(const ast::While& w) {
    Line("while " + P(w.test.get()), &w);
    Indented(w.body);
  }

  void VisitBreak(const ast::Break& b) { Line("break", &b); }
  void VisitContinue(const ast::Continue& c) { Line("continue", &c); }
  void VisitPass(const ast::Pass& p) { Line("pass", &p); }

  void VisitReturn(const ast::Return& r) {
    Line(r.value ? "return " + P(r.value.get()) : std::string("return"), &r);
  }

  void VisitExprStmt(const ast::ExprStmt& e) { Line("expr " + P(e.value.get()), &e); }

  void VisitAssert(const ast::Assert& a) {
    std::string s = "assert " + P(a.test.get());
    if (a.msg) s += ", " + P(a.msg.get());
    Line(s, &a);
  }

 private:
  void Line(const std::string& text, const ast::Stmt* at) {
    out += std::string(static_cast<size_t>(indent_) * 2, ' ') + text;
    if (at && options_.with_locations) {
      out += "  @" + std::to_string(at->loc.line) + ":" + std::to_string(at->loc.column);
    }
    out += "\n";
  }
  void Body(const ast::StmtList& body) {
    for (const auto& s : body) VisitStmt(*s);
  }
  void Indented(const ast::StmtList& body) {
    ++indent_;
    Body(body);
    --indent_;
  }

  int indent_;
  const PrintOptions& options_;
};

}  // namespace

std::string PrintExpr(const ast::Expr& expr) { return ExprPrinter().Print(&expr); }

std::string PrintStmt(const ast::Stmt& stmt, int indent, const PrintOptions& options) {
  StmtPrinter p(indent, options);
  p.VisitStmt(stmt);
  return std::move(p.out);
}

std::string PrintFunction(const ast::FunctionDef& fn, const PrintOptions& options) {
  return PrintStmt(fn, 0, options);
}

}  // namespace weft::lang
