// Unparser tests: minimal parentheses on a table of precedence cases, and on random fully
// parenthesized expressions the round trip parse -> unparse -> parse gives the same tree.
#include <gtest/gtest.h>

#include <random>
#include <string>

#include "engine/lang/ast_printer.h"
#include "engine/lang/parser.h"
#include "engine/lang/unparse.h"

namespace weft::lang {
namespace {

std::unique_ptr<ast::FunctionDef> ParseReturn(const std::string& expr) {
  FunctionSource fn;
  fn.file = "u.py";
  fn.source = "def f():\n    return " + expr + "\n";
  auto r = ParseFunction(fn, nullptr);
  EXPECT_TRUE(r.ok()) << expr << "\n" << r.status().ToString();
  if (!r.ok()) return nullptr;
  return std::move(r).value();
}

const ast::Expr* ReturnValue(const ast::FunctionDef& fn) {
  return static_cast<const ast::Return&>(*fn.body[0]).value.get();
}

std::string RoundTrip(const std::string& expr) {
  auto fn = ParseReturn(expr);
  return fn ? UnparseExpr(*ReturnValue(*fn)) : "<parse failed>";
}

TEST(LangUnparse, KeepsOnlyNeededParentheses) {
  const std::pair<const char*, const char*> cases[] = {
      {"a + b * c", "a + b * c"},
      {"(a + b) * c", "(a + b) * c"},
      {"a - (b - c)", "a - (b - c)"},
      {"(a - b) - c", "a - b - c"},
      {"a ** b ** c", "a ** b ** c"},
      {"(a ** b) ** c", "(a ** b) ** c"},
      {"-a ** 2", "-a ** 2"},
      {"(-a) ** 2", "(-a) ** 2"},
      {"a ** -b", "a ** -b"},
      {"-(a * b)", "-(a * b)"},
      {"- -a", "--a"},
      {"not a == b", "not a == b"},
      {"(not a) == b", "(not a) == b"},
      {"(a < b) < c", "(a < b) < c"},
      {"a < b < c", "a < b < c"},
      {"a and (b or c)", "a and (b or c)"},
      {"(a and b) and c", "(a and b) and c"},
      {"a and b and c", "a and b and c"},
      {"(a if b else c) if d else e", "(a if b else c) if d else e"},
      {"a if b else c if d else e", "a if b else c if d else e"},
      {"(a + b).x", "(a + b).x"},
      {"(1).real", "(1).real"},
      {"f(a, k=b if c else d)[i, j:k, ::2]", "f(a, k=b if c else d)[i, j:k, ::2]"},
      {"a[(i, j)]", "a[(i, j)]"},
      {"(a,)", "(a,)"},
      {"()", "()"},
      {"a, b", "(a, b)"},
      {"[1, 2.5e-3, 'x' \"y\", 0xFF, None, True]", "[1, 2.5e-3, 'x' \"y\", 0xFF, None, True]"},
      {"a | b ^ c & d << e + f * g", "a | b ^ c & d << e + f * g"},
      {"((a | b) ^ c) & d", "((a | b) ^ c) & d"},
      {"wp.vec3(1.0, 2.0, 3.0) @ m", "wp.vec3(1.0, 2.0, 3.0) @ m"},
      {"a is not None", "a is not None"},
      {"a not in b", "a not in b"},
  };
  for (const auto& [in, want] : cases) EXPECT_EQ(RoundTrip(in), want) << in;
}

TEST(LangUnparse, SynthesizedConstantsWithoutSourceText) {
  ast::Constant c;
  c.type = ast::Constant::Type::kString;
  c.string_value = "it's\n";
  EXPECT_EQ(UnparseExpr(c), "'it\\'s\\n'");
  ast::Constant f;
  f.type = ast::Constant::Type::kFloat;
  f.float_value = 2.0;
  EXPECT_EQ(UnparseExpr(f), "2.0");
  ast::Constant i;
  i.type = ast::Constant::Type::kInt;
  i.int_decimal = "123456789012345678901234567890";
  EXPECT_EQ(UnparseExpr(i), "123456789012345678901234567890");
}

// Random expressions written with a parenthesis around every operation.
class RandomExpr {
 public:
  explicit RandomExpr(uint32_t seed) : rng_(seed) {}

  std::string Gen(int depth) {
    if (depth <= 0) return Leaf();
    switch (rng_() % 12) {
      case 0: return Leaf();
      case 1: return "(" + Pick({"-", "+", "~", "not "}) + Gen(depth - 1) + ")";
      case 2: return "(" + Gen(depth - 1) + " " + Pick({"and", "or"}) + " " + Gen(depth - 1) + ")";
      case 3: {
        std::string s = "(" + Gen(depth - 1);
        const int n = 1 + static_cast<int>(rng_() % 2);
        for (int i = 0; i < n; ++i) {
          s += " " + Pick({"<", "<=", "==", "!=", ">", ">=", "is", "is not", "in", "not in"}) + " " +
               Gen(depth - 1);
        }
        return s + ")";
      }
      case 4: return "(" + Gen(depth - 1) + " if " + Gen(depth - 1) + " else " + Gen(depth - 1) + ")";
      case 5: return "(" + Gen(depth - 1) + ")." + Pick({"x", "shape", "real"});  // `1.x` is not Python
      case 6: return Primary(depth) + "(" + Gen(depth - 1) + ", k=" + Gen(depth - 1) + ")";
      case 7: {
        std::string idx = rng_() % 3 == 0 ? Gen(depth - 1) + ":" + (rng_() % 2 ? Gen(depth - 1) : "")
                                           : Gen(depth - 1);
        if (rng_() % 2) idx += ", " + Gen(depth - 1);
        return Primary(depth) + "[" + idx + "]";
      }
      case 8: return "(" + Gen(depth - 1) + ", " + Gen(depth - 1) + ")";
      case 9: return "[" + Gen(depth - 1) + "]";
      default:
        return "(" + Gen(depth - 1) + " " +
               Pick({"+", "-", "*", "/", "//", "%", "**", "@", "<<", ">>", "&", "|", "^"}) + " " +
               Gen(depth - 1) + ")";
    }
  }

 private:
  std::string Primary(int depth) { return rng_() % 2 ? Leaf() : "(" + Gen(depth - 1) + ")"; }
  std::string Leaf() {
    return Pick({"a", "b", "wp", "1", "2.5", "1e-3", "0x1F", "'s'", "True", "None", "1.", "f()"});
  }
  std::string Pick(std::initializer_list<const char*> options) {
    return *(options.begin() + rng_() % options.size());
  }
  std::mt19937 rng_;
};

TEST(LangUnparse, RandomRoundTripsGiveTheSameTree) {
  RandomExpr gen(std::random_device{}());
  for (int i = 0; i < 2000; ++i) {
    const std::string src = gen.Gen(4);
    auto first = ParseReturn(src);
    ASSERT_TRUE(first) << src;
    const std::string text = UnparseExpr(*ReturnValue(*first));
    auto second = ParseReturn(text);
    ASSERT_TRUE(second) << src << "\n -> " << text;
    EXPECT_EQ(PrintExpr(*ReturnValue(*second)), PrintExpr(*ReturnValue(*first)))
        << src << "\n -> " << text;
    EXPECT_EQ(UnparseExpr(*ReturnValue(*second)), text) << src;  // a fixed point
  }
}

}  // namespace
}  // namespace weft::lang
