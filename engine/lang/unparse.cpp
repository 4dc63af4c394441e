// Expression unparser (see unparse.h): precedence-driven, one visitor over the X-macro list.
#include "engine/lang/unparse.h"

#include <charconv>
#include <cmath>
#include <cstdio>

namespace weft::lang {
namespace {

// Python's precedence levels, loosest first (CPython's ast._Precedence).
enum Prec : int {
  kTuple = 0,
  kTest,    // a if c else b
  kOr,
  kAnd,
  kNot,
  kCmp,
  kBitOr,
  kBitXor,
  kBitAnd,
  kShift,
  kArith,
  kTerm,
  kFactor,  // unary + - ~
  kPower,
  kAtom,    // names, literals, calls, attributes, subscripts, displays
};

int BinaryPrec(ast::BinaryOperator op) {
  switch (op) {
    case ast::BinaryOperator::kBitOr: return kBitOr;
    case ast::BinaryOperator::kBitXor: return kBitXor;
    case ast::BinaryOperator::kBitAnd: return kBitAnd;
    case ast::BinaryOperator::kLShift:
    case ast::BinaryOperator::kRShift: return kShift;
    case ast::BinaryOperator::kAdd:
    case ast::BinaryOperator::kSub: return kArith;
    case ast::BinaryOperator::kMul:
    case ast::BinaryOperator::kMatMul:
    case ast::BinaryOperator::kDiv:
    case ast::BinaryOperator::kFloorDiv:
    case ast::BinaryOperator::kMod: return kTerm;
    case ast::BinaryOperator::kPow: return kPower;
  }
  return kAtom;
}

class Unparser : public ast::ConstExprVisitor<Unparser, std::string> {
 public:
  // `e` printed so that it parses back as one operand at precedence `need`.
  std::string At(const ast::Expr* e, int need) {
    if (!e) return "";
    const int saved = need_;
    need_ = need;
    std::string s = VisitExpr(*e);
    need_ = saved;
    return s;
  }

  std::string VisitName(const ast::Name& n) { return n.id; }

  std::string VisitConstant(const ast::Constant& c) {
    if (!c.text.empty()) return c.text;
    switch (c.type) {
      case ast::Constant::Type::kInt: return c.int_decimal.empty() ? std::to_string(c.int_value) : c.int_decimal;
      case ast::Constant::Type::kFloat: {
        if (std::isinf(c.float_value)) return c.float_value > 0 ? "1e309" : "-1e309";
        if (std::isnan(c.float_value)) return "float('nan')";
        char buf[64];
        auto [ptr, ec] = std::to_chars(buf, buf + sizeof(buf), c.float_value);
        std::string s(buf, ec == std::errc() ? ptr : buf);
        if (s.find_first_of(".e") == std::string::npos) s += ".0";
        return s;
      }
      case ast::Constant::Type::kBool: return c.bool_value ? "True" : "False";
      case ast::Constant::Type::kNone: return "None";
      case ast::Constant::Type::kString: return QuotePythonString(c.string_value, '\'');
    }
    return "";
  }

  std::string VisitAttribute(const ast::Attribute& a) {
    std::string base = At(a.value.get(), kAtom);
    // `1 .x` would lex as the float `1.` followed by `x`.
    if (const auto* c = ast::As<ast::Constant>(a.value.get());
        c && c->type == ast::Constant::Type::kInt) {
      base = "(" + base + ")";
    }
    return base + "." + a.attr;
  }

  std::string VisitSubscript(const ast::Subscript& s) {
    std::string out = At(s.value.get(), kAtom) + "[";
    for (size_t i = 0; i < s.indices.size(); ++i) {
      if (i) out += ", ";
      out += At(s.indices[i].get(), kTest);
    }
    return out + "]";
  }

  std::string VisitSlice(const ast::Slice& s) {
    std::string out = At(s.lower.get(), kTest) + ":" + At(s.upper.get(), kTest);
    if (s.step) out += ":" + At(s.step.get(), kTest);
    return out;
  }

  std::string VisitCall(const ast::Call& c) {
    std::string out = At(c.func.get(), kAtom) + "(";
    bool first = true;
    for (const auto& a : c.args) {
      if (!first) out += ", ";
      first = false;
      out += At(a.get(), kTest);
    }
    for (const auto& k : c.keywords) {
      if (!first) out += ", ";
      first = false;
      out += k.name + "=" + At(k.value.get(), kTest);
    }
    return out + ")";
  }

  std::string VisitBinOp(const ast::BinOp& b) {
    const int p = BinaryPrec(b.op);
    const bool right_assoc = b.op == ast::BinaryOperator::kPow;
    // `a ** -b` needs no parentheses: the right operand of ** is a unary-level factor.
    const std::string left = At(b.left.get(), right_assoc ? p + 1 : p);
    const std::string right = At(b.right.get(), right_assoc ? kFactor : p + 1);
    return Wrap(p, left + " " + ast::Spelling(b.op) + " " + right);
  }

  std::string VisitUnaryOp(const ast::UnaryOp& u) {
    if (u.op == ast::UnaryOperator::kNot) return Wrap(kNot, "not " + At(u.operand.get(), kNot));
    return Wrap(kFactor, std::string(ast::Spelling(u.op)) + At(u.operand.get(), kFactor));
  }

  std::string VisitBoolOp(const ast::BoolOp& b) {
    const int p = b.op == ast::BoolOperator::kAnd ? kAnd : kOr;
    std::string out;
    for (size_t i = 0; i < b.values.size(); ++i) {
      if (i) out += std::string(" ") + ast::Spelling(b.op) + " ";
      out += At(b.values[i].get(), p + 1);
    }
    return Wrap(p, out);
  }

  std::string VisitCompare(const ast::Compare& c) {
    std::string out = At(c.left.get(), kCmp + 1);
    for (size_t i = 0; i < c.ops.size() && i < c.comparators.size(); ++i) {
      out += std::string(" ") + ast::Spelling(c.ops[i]) + " " + At(c.comparators[i].get(), kCmp + 1);
    }
    return Wrap(kCmp, out);
  }

  std::string VisitIfExp(const ast::IfExp& e) {
    return Wrap(kTest, At(e.body.get(), kTest + 1) + " if " + At(e.test.get(), kTest + 1) +
                           " else " + At(e.orelse.get(), kTest));
  }

  std::string VisitTuple(const ast::Tuple& t) {
    std::string out = "(";
    for (size_t i = 0; i < t.elts.size(); ++i) {
      if (i) out += ", ";
      out += At(t.elts[i].get(), kTest);
    }
    if (t.elts.size() == 1) out += ",";
    return out + ")";
  }

  std::string VisitStarred(const ast::Starred& s) { return "*" + At(s.value.get(), kBitOr); }

  std::string VisitList(const ast::List& l) {
    std::string out = "[";
    for (size_t i = 0; i < l.elts.size(); ++i) {
      if (i) out += ", ";
      out += At(l.elts[i].get(), kTest);
    }
    return out + "]";
  }

 private:
  std::string Wrap(int prec, std::string text) const {
    return prec < need_ ? "(" + text + ")" : text;
  }

  int need_ = kTuple;
};

}  // namespace

std::string UnparseExpr(const ast::Expr& expr) { return Unparser().At(&expr, kTuple); }

std::string QuotePythonString(const std::string& s, char quote) {
  std::string out(1, quote);
  for (unsigned char c : s) {
    switch (c) {
      case '\\': out += "\\\\"; break;
      case '\n': out += "\\n"; break;
      case '\t': out += "\\t"; break;
      case '\r': out += "\\r"; break;
      default:
        if (c == static_cast<unsigned char>(quote)) {
          out += '\\';
          out.push_back(quote);
        } else if (c < 0x20 || c == 0x7F) {
          char buf[8];
          std::snprintf(buf, sizeof(buf), "\\x%02x", c);
          out += buf;
        } else {
          out.push_back(static_cast<char>(c));
        }
    }
  }
  return out + quote;
}

}  // namespace weft::lang
