// Parser tests, must-pass kind: one test per construct (parse -> print -> compare), Python's
// precedence (a table plus random operator chains checked against a shunting-yard
// reference), locations in the user's file, literal values, Warp's documentation kernels,
// and robustness (random mutations and deep nesting never crash and give at most one error).
#include <gtest/gtest.h>

#include <cstdlib>
#include <random>
#include <string>
#include <vector>

#include "engine/lang/ast_printer.h"
#include "engine/lang/parser.h"

namespace weft::lang {
namespace {

FunctionSource Source(const std::string& text, uint32_t first_line = 1) {
  FunctionSource fn;
  fn.name = "f";
  fn.source = text;
  fn.file = "kern.py";
  fn.first_line = first_line;
  return fn;
}

std::unique_ptr<ast::FunctionDef> MustParse(const std::string& text, uint32_t first_line = 1) {
  std::vector<Diagnostic> diags;
  auto r = ParseFunction(Source(text, first_line), &diags);
  EXPECT_TRUE(r.ok()) << text << "\n" << r.status().ToString();
  EXPECT_TRUE(diags.empty());
  if (!r.ok()) return nullptr;
  return std::move(r).value();
}

// The printed body of `def f():\n<body>` without the def line.
std::string Body(const std::string& body) {
  auto fn = MustParse("def f():\n" + body);
  if (!fn) return "<parse failed>";
  std::string out;
  for (const auto& s : fn->body) out += PrintStmt(*s);
  return out;
}

// The printed expression `text`.
std::string Expr(const std::string& text) {
  auto fn = MustParse("def f():\n    return " + text + "\n");
  if (!fn || fn->body.empty()) return "<parse failed>";
  const auto* r = ast::As<ast::Return>(fn->body[0].get());
  if (!r || !r->value) return "<no value>";
  return PrintExpr(*r->value);
}

// ---- statements, one test per construct ------------------------------------------------------

TEST(LangParser, AnnAssign) {
  EXPECT_EQ(Body("    x: float = 1.0\n"), "annassign x: float = 1.0\n");
  EXPECT_EQ(Body("    v: wp.vec3\n"), "annassign v: (. wp vec3)\n");
  EXPECT_EQ(Body("    a.b: int = 2\n"), "annassign (. a b): int = 2\n");
}

TEST(LangParser, Assert) {
  EXPECT_EQ(Body("    assert x > 0\n"), "assert (cmp x > 0)\n");
  EXPECT_EQ(Body("    assert x, 'bad x'\n"), "assert x, \"bad x\"\n");
}

TEST(LangParser, Assign) {
  EXPECT_EQ(Body("    x = 1\n"), "assign x = 1\n");
  EXPECT_EQ(Body("    a[i, j] = v.x\n"), "assign ([] a i j) = (. v x)\n");
  EXPECT_EQ(Body("    p.vel.y = 0.0\n"), "assign (. (. p vel) y) = 0.0\n");
}

TEST(LangParser, AssignChained) {
  EXPECT_EQ(Body("    a = b[i] = c.d = 0\n"), "assign a = ([] b i) = (. c d) = 0\n");
}

TEST(LangParser, AssignTupleUnpacking) {
  EXPECT_EQ(Body("    a, b = f(x)\n"), "assign (tuple a b) = (call f x)\n");
  EXPECT_EQ(Body("    (a, b), c = g()\n"), "assign (tuple (tuple a b) c) = (call g)\n");
  EXPECT_EQ(Body("    a, = t\n"), "assign (tuple a) = t\n");
  EXPECT_EQ(Body("    [a, b] = 1, 2\n"), "assign (list a b) = (tuple 1 2)\n");
  EXPECT_EQ(Body("    x[0], y.z = y.z, x[0]\n"),
            "assign (tuple ([] x 0) (. y z)) = (tuple (. y z) ([] x 0))\n");
}

TEST(LangParser, AugAssignEveryOperator) {
  const char* ops[] = {"+", "-", "*", "@", "/", "//", "%", "**", "<<", ">>", "|", "^", "&"};
  for (const char* op : ops) {
    EXPECT_EQ(Body(std::string("    x[i] ") + op + "= 2\n"),
              std::string("augassign ([] x i) ") + op + "= 2\n");
  }
}

TEST(LangParser, BreakContinuePass) {
  EXPECT_EQ(Body("    while True:\n        break\n        continue\n        pass\n"),
            "while True\n  break\n  continue\n  pass\n");
}

TEST(LangParser, DecoratorsAreSkippedAndRecorded) {
  auto fn = MustParse("@wp.kernel\n@wp.kernel(enable_backward=False)\ndef k():\n    pass\n");
  ASSERT_TRUE(fn);
  EXPECT_EQ(fn->name, "k");
  ASSERT_EQ(fn->decorators.size(), 2u);
  EXPECT_EQ(fn->decorators[0], "wp.kernel");
  EXPECT_EQ(fn->decorators[1], "wp.kernel(enable_backward=False)");
  EXPECT_EQ(fn->loc.line, 3u);
}

TEST(LangParser, DocstringsAndBareStringsAreDropped) {
  auto fn = MustParse("def f(x: float):\n    '''Doc\n    string.'''\n    y = x\n    \"note\"\n");
  ASSERT_TRUE(fn);
  EXPECT_EQ(fn->docstring, "Doc\n    string.");
  EXPECT_EQ(PrintFunction(*fn), "def f(x: float)\n  doc \"Doc\\n    string.\"\n  assign y = x\n");
  // A block left empty gets a pass.
  EXPECT_EQ(Body("    if a:\n        'only a note'\n"), "if a\n  pass\n");
  auto only_doc = MustParse("def g():\n    \"\"\"Just a docstring.\"\"\"\n");
  ASSERT_TRUE(only_doc);
  EXPECT_EQ(PrintFunction(*only_doc), "def g()\n  doc \"Just a docstring.\"\n  pass\n");
}

TEST(LangParser, ExprStatement) {
  EXPECT_EQ(Body("    wp.atomic_add(a, 0, 1.0)\n"), "expr (call (. wp atomic_add) a 0 1.0)\n");
  EXPECT_EQ(Body("    print(x)\n"), "expr (call print x)\n");
  EXPECT_EQ(Body("    wp.printf(\"%d %f\\n\", i, x)\n"),
            "expr (call (. wp printf) \"%d %f\\n\" i x)\n");
}

TEST(LangParser, For) {
  EXPECT_EQ(Body("    for i in range(n):\n        s += i\n"),
            "for i in (call range n)\n  augassign s += i\n");
  EXPECT_EQ(Body("    for i in range(0, 10, 2): s += i\n"),
            "for i in (call range 0 10 2)\n  augassign s += i\n");
}

TEST(LangParser, ForTupleTarget) {
  EXPECT_EQ(Body("    for i, j in pairs:\n        pass\n"), "for (tuple i j) in pairs\n  pass\n");
  EXPECT_EQ(Body("    for (i, j) in pairs:\n        pass\n"), "for (tuple i j) in pairs\n  pass\n");
}

TEST(LangParser, FunctionDef) {
  auto fn = MustParse(
      "def f(a: wp.array(dtype=wp.vec3), b: wp.array2d[float], c: float = 1.5, d=2,) -> "
      "tuple[float, int]:\n    return c, d\n");
  ASSERT_TRUE(fn);
  EXPECT_EQ(PrintFunction(*fn),
            "def f(a: (call (. wp array) dtype=(. wp vec3)), b: ([] (. wp array2d) float), "
            "c: float = 1.5, d = 2) -> ([] tuple float int)\n  return (tuple c d)\n");
  ASSERT_EQ(fn->params.size(), 4u);
  EXPECT_EQ(fn->params[3].annotation, nullptr);
  EXPECT_NE(fn->params[3].default_value, nullptr);
  EXPECT_EQ(MustParse("def g():\n    pass\n")->returns, nullptr);
}

TEST(LangParser, If) {
  EXPECT_EQ(Body("    if a:\n        x = 1\n"), "if a\n  assign x = 1\n");
  EXPECT_EQ(Body("    if a: x = 1\n"), "if a\n  assign x = 1\n");
}

TEST(LangParser, IfElifElse) {
  const std::string printed = Body(
      "    if a:\n        x = 1\n    elif b:\n        x = 2\n    elif c:\n        x = 3\n"
      "    else:\n        x = 4\n");
  EXPECT_EQ(printed,
            "if a\n  assign x = 1\nelif b\n  assign x = 2\nelif c\n  assign x = 3\nelse\n"
            "  assign x = 4\n");
  auto fn = MustParse("def f():\n    if a:\n        pass\n    elif b:\n        pass\n");
  ASSERT_TRUE(fn);
  const auto* outer = ast::As<ast::If>(fn->body[0].get());
  ASSERT_TRUE(outer);
  ASSERT_EQ(outer->orelse.size(), 1u);
  const auto* inner = ast::As<ast::If>(outer->orelse[0].get());
  ASSERT_TRUE(inner);
  EXPECT_TRUE(inner->is_elif);
  EXPECT_TRUE(inner->orelse.empty());
  // An explicit `else: if` is not an elif.
  EXPECT_EQ(Body("    if a:\n        pass\n    else:\n        if b:\n            pass\n"),
            "if a\n  pass\nelse\n  if b\n    pass\n");
}

TEST(LangParser, LongElifChainsParseUpToTheCap) {
  auto chain = [](int elifs) {
    std::string s = "def f():\n    if a == 0:\n        x = 0\n";
    for (int i = 1; i <= elifs; ++i) {
      s += "    elif a == " + std::to_string(i) + ":\n        x = " + std::to_string(i) + "\n";
    }
    return s + "    else:\n        x = -1\n";
  };
  auto fn = MustParse(chain(500));
  ASSERT_TRUE(fn);
  int depth = 0;
  const ast::If* node = ast::As<ast::If>(fn->body[0].get());
  while (node && node->orelse.size() == 1 && ast::As<ast::If>(node->orelse[0].get())) {
    node = ast::As<ast::If>(node->orelse[0].get());
    EXPECT_TRUE(node->is_elif);
    ++depth;
  }
  EXPECT_EQ(depth, 500);
  ASSERT_TRUE(node);
  ASSERT_EQ(node->orelse.size(), 1u);
  EXPECT_EQ(PrintStmt(*node->orelse[0]), "assign x = (u- 1)\n");
  std::vector<Diagnostic> diags;
  auto r = ParseFunction(Source(chain(501)), &diags);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(diags[0].message.find("too many 'elif' branches in one 'if' statement (more than 500)"),
            std::string::npos)
      << diags[0].message;
  EXPECT_EQ(diags[0].location.line, 2u + 2u * 501u);
  EXPECT_FALSE(ParseFunction(Source(chain(50000)), nullptr).ok());
}

TEST(LangParser, LineContinuations) {
  EXPECT_EQ(Body("    x = a + \\\n        b\n"), "assign x = (+ a b)\n");
  EXPECT_EQ(Body("    x = f(a,\n  b,\n\n            c)\n"), "assign x = (call f a b c)\n");
}

TEST(LangParser, Return) {
  EXPECT_EQ(Body("    return\n"), "return\n");
  EXPECT_EQ(Body("    return x\n"), "return x\n");
  EXPECT_EQ(Body("    return x, y\n"), "return (tuple x y)\n");
  EXPECT_EQ(Body("    return (x, y)\n"), "return (tuple x y)\n");
  EXPECT_EQ(Body("    return x,\n"), "return (tuple x)\n");
}

TEST(LangParser, SemicolonsSeparateStatements) {
  EXPECT_EQ(Body("    a = 1; b = 2;\n"), "assign a = 1\nassign b = 2\n");
}

TEST(LangParser, While) {
  EXPECT_EQ(Body("    while i < n:\n        i += 1\n"), "while (cmp i < n)\n  augassign i += 1\n");
}

// ---- expressions, one test per construct -----------------------------------------------------

TEST(LangParser, AttributeChains) {
  EXPECT_EQ(Expr("wp.types.vector"), "(. (. wp types) vector)");
  EXPECT_EQ(Expr("a.shape[0]"), "([] (. a shape) 0)");
  EXPECT_EQ(Expr("f(x).y"), "(. (call f x) y)");
}

TEST(LangParser, BinOp) {
  EXPECT_EQ(Expr("a + b"), "(+ a b)");
  EXPECT_EQ(Expr("a @ b"), "(@ a b)");
  EXPECT_EQ(Expr("a // b % c"), "(% (// a b) c)");
}

TEST(LangParser, BoolOpIsFlat) {
  EXPECT_EQ(Expr("a and b and c"), "(and a b c)");
  EXPECT_EQ(Expr("a or b or c"), "(or a b c)");
  EXPECT_EQ(Expr("a or b and c or d"), "(or a (and b c) d)");
}

TEST(LangParser, Call) {
  EXPECT_EQ(Expr("f()"), "(call f)");
  EXPECT_EQ(Expr("f(a, b,)"), "(call f a b)");
  EXPECT_EQ(Expr("wp.array(dtype=float, ndim=2)"), "(call (. wp array) dtype=float ndim=2)");
  EXPECT_EQ(Expr("f(a, k=b == c)"), "(call f a k=(cmp b == c))");
  EXPECT_EQ(Expr("f(g(h(x)))"), "(call f (call g (call h x)))");
  EXPECT_EQ(Expr("wp.vec3([1.0, 2.0, 3.0])"), "(call (. wp vec3) (list 1.0 2.0 3.0))");
}

TEST(LangParser, CompareChained) {
  EXPECT_EQ(Expr("a < b"), "(cmp a < b)");
  EXPECT_EQ(Expr("0 <= i < n"), "(cmp 0 <= i < n)");
  EXPECT_EQ(Expr("a == b != c > d >= e"), "(cmp a == b != c > d >= e)");
  EXPECT_EQ(Expr("a is None"), "(cmp a is None)");
  EXPECT_EQ(Expr("a is not None"), "(cmp a is not None)");
  EXPECT_EQ(Expr("a in b"), "(cmp a in b)");
  EXPECT_EQ(Expr("a not in b"), "(cmp a not in b)");
}

TEST(LangParser, Constants) {
  EXPECT_EQ(Expr("True"), "True");
  EXPECT_EQ(Expr("False"), "False");
  EXPECT_EQ(Expr("None"), "None");
  EXPECT_EQ(Expr("42"), "42");
  EXPECT_EQ(Expr("0xff"), "255");
  EXPECT_EQ(Expr("1.5"), "1.5");
  EXPECT_EQ(Expr("1."), "1.0");
  EXPECT_EQ(Expr(".25"), "0.25");
  EXPECT_EQ(Expr("1e-3"), "0.001");
  EXPECT_EQ(Expr("'ab' \"cd\""), "\"abcd\"");
  EXPECT_EQ(Expr("-1"), "(u- 1)");  // negative numbers are unary minus, as in Python's ast
}

TEST(LangParser, ConstantValuesKept) {
  auto fn = MustParse(
      "def f():\n    return 123456789012345678901234567890, 0x10, 2.5e-3, 'a' 'b', 18446744073709551615\n");
  ASSERT_TRUE(fn);
  const auto* r = ast::As<ast::Return>(fn->body[0].get());
  ASSERT_TRUE(r);
  const auto* t = ast::As<ast::Tuple>(r->value.get());
  ASSERT_TRUE(t);
  ASSERT_EQ(t->elts.size(), 5u);
  const auto* big = ast::As<ast::Constant>(t->elts[0].get());
  ASSERT_TRUE(big);
  EXPECT_EQ(big->type, ast::Constant::Type::kInt);
  EXPECT_EQ(big->int_decimal, "123456789012345678901234567890");
  EXPECT_FALSE(big->int_fits_u64);
  EXPECT_EQ(big->text, "123456789012345678901234567890");
  const auto* hex = ast::As<ast::Constant>(t->elts[1].get());
  EXPECT_EQ(hex->int_value, 16u);
  EXPECT_TRUE(hex->int_fits_u64);
  EXPECT_EQ(hex->text, "0x10");
  const auto* fl = ast::As<ast::Constant>(t->elts[2].get());
  EXPECT_EQ(fl->type, ast::Constant::Type::kFloat);
  EXPECT_EQ(fl->float_value, 2.5e-3);
  EXPECT_EQ(fl->text, "2.5e-3");
  const auto* str = ast::As<ast::Constant>(t->elts[3].get());
  EXPECT_EQ(str->type, ast::Constant::Type::kString);
  EXPECT_EQ(str->string_value, "ab");
  const auto* u64max = ast::As<ast::Constant>(t->elts[4].get());
  EXPECT_TRUE(u64max->int_fits_u64);
  EXPECT_EQ(u64max->int_value, 18446744073709551615ull);
}

TEST(LangParser, IfExp) {
  EXPECT_EQ(Expr("a if c else b"), "(? c a b)");
  EXPECT_EQ(Expr("a if c else b if d else e"), "(? c a (? d b e))");
  EXPECT_EQ(Expr("x + 1 if a or b else -x"), "(? (or a b) (+ x 1) (u- x))");
}

TEST(LangParser, ListAndTuple) {
  EXPECT_EQ(Expr("[]"), "(list)");
  EXPECT_EQ(Expr("[a, b + 1,]"), "(list a (+ b 1))");
  EXPECT_EQ(Expr("()"), "(tuple)");
  EXPECT_EQ(Expr("(a,)"), "(tuple a)");
  EXPECT_EQ(Expr("(a)"), "a");
  EXPECT_EQ(Expr("((a, b), c)"), "(tuple (tuple a b) c)");
}

TEST(LangParser, Name) { EXPECT_EQ(Expr("match"), "match"); }

TEST(LangParser, Subscript) {
  EXPECT_EQ(Expr("a[i]"), "([] a i)");
  EXPECT_EQ(Expr("a[i, j, k, l]"), "([] a i j k l)");
  EXPECT_EQ(Expr("a[(i, j)]"), "([] a (tuple i j))");
  EXPECT_EQ(Expr("m[i][j]"), "([] ([] m i) j)");
  EXPECT_EQ(Expr("a[i + 1, j * 2]"), "([] a (+ i 1) (* j 2))");
}

TEST(LangParser, SliceInSubscript) {
  EXPECT_EQ(Expr("v[1:3]"), "([] v (: 1 3 _))");
  EXPECT_EQ(Expr("v[:]"), "([] v (: _ _ _))");
  EXPECT_EQ(Expr("v[::2]"), "([] v (: _ _ 2))");
  EXPECT_EQ(Expr("v[a::]"), "([] v (: a _ _))");
  EXPECT_EQ(Expr("m[i, :]"), "([] m i (: _ _ _))");
  EXPECT_EQ(Expr("m[:n, 1:]"), "([] m (: _ n _) (: 1 _ _))");
}

TEST(LangParser, UnaryOp) {
  EXPECT_EQ(Expr("-x"), "(u- x)");
  EXPECT_EQ(Expr("+x"), "(u+ x)");
  EXPECT_EQ(Expr("~x"), "(~ x)");
  EXPECT_EQ(Expr("not x"), "(not x)");
  EXPECT_EQ(Expr("- - x"), "(u- (u- x))");
  EXPECT_EQ(Expr("not not x"), "(not (not x))");
}

// ---- precedence ------------------------------------------------------------------------------

TEST(LangParser, PrecedenceTable) {
  const std::pair<const char*, const char*> cases[] = {
      {"a + b * c", "(+ a (* b c))"},
      {"a * b + c", "(+ (* a b) c)"},
      {"a - b - c", "(- (- a b) c)"},
      {"a / b / c", "(/ (/ a b) c)"},
      {"a ** b ** c", "(** a (** b c))"},
      {"-a ** b", "(u- (** a b))"},
      {"a ** -b", "(** a (u- b))"},
      {"a ** -b ** c", "(** a (u- (** b c)))"},
      {"-a * b", "(* (u- a) b)"},
      {"~a + b", "(+ (~ a) b)"},
      {"a | b ^ c & d", "(| a (^ b (& c d)))"},
      {"a & b << c", "(& a (<< b c))"},
      {"a << b + c", "(<< a (+ b c))"},
      {"a + b < c", "(cmp (+ a b) < c)"},
      {"a | b == c", "(cmp (| a b) == c)"},
      {"not a == b", "(not (cmp a == b))"},
      {"not a and b", "(and (not a) b)"},
      {"a and not b", "(and a (not b))"},
      {"a or b and c", "(or a (and b c))"},
      {"a if b or c else d and e", "(? (or b c) a (and d e))"},
      {"a @ b * c", "(* (@ a b) c)"},
      {"(a + b) * c", "(* (+ a b) c)"},
      {"a[i] ** 2", "(** ([] a i) 2)"},
      {"-a.b[c](d)", "(u- (call ([] (. a b) c) d))"},
      {"a < b == c", "(cmp a < b == c)"},
      {"a in b and c not in d", "(and (cmp a in b) (cmp c not in d))"},
      {"2 ** -1", "(** 2 (u- 1))"},
      {"a % -b", "(% a (u- b))"},
  };
  for (const auto& [src, want] : cases) EXPECT_EQ(Expr(src), want) << src;
}

// Shunting-yard reference for chains of binary/unary operators over names, independent of the
// parser's recursive descent. Unary prefix operators bind looser than ** on their right.
std::string ReferenceTree(const std::vector<std::string>& toks) {
  auto prec = [](const std::string& op) {
    if (op == "|") return 1;
    if (op == "^") return 2;
    if (op == "&") return 3;
    if (op == "<<" || op == ">>") return 4;
    if (op == "+" || op == "-") return 5;
    if (op == "*" || op == "/" || op == "//" || op == "%" || op == "@") return 6;
    if (op == "u-" || op == "u+" || op == "~") return 7;
    return 8;  // **
  };
  std::vector<std::string> out, ops;
  auto reduce = [&]() {
    const std::string op = ops.back();
    ops.pop_back();
    if (op == "u-" || op == "u+" || op == "~") {
      out.back() = "(" + op + " " + out.back() + ")";
    } else {
      const std::string r = out.back();
      out.pop_back();
      out.back() = "(" + op + " " + out.back() + " " + r + ")";
    }
  };
  bool expect_operand = true;
  for (const std::string& t : toks) {
    if (expect_operand) {
      if (t == "-" || t == "+" || t == "~") {
        ops.push_back(t == "~" ? "~" : "u" + t);
      } else {
        out.push_back(t);
        expect_operand = false;
      }
      continue;
    }
    const int p = prec(t);
    const bool right = t == "**";
    while (!ops.empty() && (prec(ops.back()) > p || (prec(ops.back()) == p && !right))) reduce();
    ops.push_back(t);
    expect_operand = true;
  }
  while (!ops.empty()) reduce();
  return out.back();
}

TEST(LangParser, PrecedenceRandomChainsMatchShuntingYard) {
  const char* binary[] = {"|", "^", "&", "<<", ">>", "+", "-", "*", "/", "//", "%", "@", "**"};
  const char* unary[] = {"-", "+", "~"};
  std::mt19937 rng(std::random_device{}());
  for (int iter = 0; iter < 3000; ++iter) {
    std::vector<std::string> toks;
    std::string src;
    const int n = 1 + static_cast<int>(rng() % 7);
    for (int i = 0; i < n; ++i) {
      while (rng() % 4 == 0) {
        toks.push_back(unary[rng() % 3]);
        src += toks.back() + " ";
      }
      toks.push_back(std::string(1, static_cast<char>('a' + i)));
      src += toks.back();
      if (i + 1 < n) {
        toks.push_back(binary[rng() % 13]);
        src += " " + toks.back() + " ";
      }
    }
    ASSERT_EQ(Expr(src), ReferenceTree(toks)) << src;
  }
}

// ---- locations -------------------------------------------------------------------------------

TEST(LangParser, LocationsMapToTheUsersFile) {
  auto fn = MustParse(
      "@wp.kernel\n"
      "def k(a: wp.array(dtype=float),\n"
      "      n: int):\n"
      "    i = wp.tid()\n"
      "\n"
      "    # comment\n"
      "    if i < n:\n"
      "        a[i] += 2.0 * \\\n"
      "            a[i]\n"
      "    x = f(1, key=2)\n",
      100);
  ASSERT_TRUE(fn);
  EXPECT_EQ(PrintFunction(*fn, {true}),
            "@wp.kernel\n"
            "def k(a: (call (. wp array) dtype=float), n: int)  @101:1\n"
            "  assign i = (call (. wp tid))  @103:5\n"
            "  if (cmp i < n)  @106:5\n"
            "    augassign ([] a i) += (* 2.0 ([] a i))  @107:9\n"
            "  assign x = (call f 1 key=2)  @109:5\n");
  EXPECT_EQ(fn->params[1].loc.line, 102u);
  EXPECT_EQ(fn->params[1].loc.column, 7u);
  EXPECT_EQ(fn->params[1].loc.file, "kern.py");
  const auto* aug = ast::As<ast::AugAssign>(ast::As<ast::If>(fn->body[1].get())->body[0].get());
  ASSERT_TRUE(aug);
  EXPECT_EQ(aug->op_loc.line, 107u);
  EXPECT_EQ(aug->op_loc.column, 14u);
  const auto* mul = ast::As<ast::BinOp>(aug->value.get());
  ASSERT_TRUE(mul);
  EXPECT_EQ(mul->loc.line, 107u);
  EXPECT_EQ(mul->loc.column, 17u);
  EXPECT_EQ(mul->op_loc.column, 21u);
  EXPECT_EQ(mul->right->loc.line, 108u);
  EXPECT_EQ(mul->right->loc.column, 13u);
  const auto* call = ast::As<ast::Call>(ast::As<ast::Assign>(fn->body[2].get())->value.get());
  ASSERT_TRUE(call);
  EXPECT_EQ(call->keywords[0].loc.column, 14u);
  EXPECT_EQ(call->args[0]->loc.column, 11u);
  const auto* tid = ast::As<ast::Call>(ast::As<ast::Assign>(fn->body[0].get())->value.get());
  const auto* attr = ast::As<ast::Attribute>(tid->func.get());
  ASSERT_TRUE(attr);
  EXPECT_EQ(attr->loc.column, 9u);
  EXPECT_EQ(attr->attr_loc.column, 12u);
}

// ---- Warp's documentation kernels -------------------------------------------------------------

TEST(LangParser, WarpDocumentationKernels) {
  auto saxpy = MustParse(
      "@wp.kernel\n"
      "def saxpy(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):\n"
      "    i = wp.tid()\n"
      "    y[i] = a * x[i] + y[i]\n");
  ASSERT_TRUE(saxpy);
  EXPECT_EQ(PrintFunction(*saxpy),
            "@wp.kernel\n"
            "def saxpy(x: (call (. wp array) dtype=float), y: (call (. wp array) dtype=float), "
            "a: float)\n"
            "  assign i = (call (. wp tid))\n"
            "  assign ([] y i) = (+ (* a ([] x i)) ([] y i))\n");
  auto integrate = MustParse(
      "@wp.kernel\n"
      "def integrate(x: wp.array(dtype=wp.vec3),\n"
      "              v: wp.array(dtype=wp.vec3),\n"
      "              f: wp.array(dtype=wp.vec3),\n"
      "              w: wp.array(dtype=float),\n"
      "              gravity: wp.vec3,\n"
      "              dt: float):\n"
      "\n"
      "   # thread id\n"
      "   tid = wp.tid()\n"
      "\n"
      "   x0 = x[tid]\n"
      "   v0 = v[tid]\n"
      "\n"
      "   # inverse mass\n"
      "   inv_mass = w[tid]\n"
      "\n"
      "   # simple semi-implicit Euler. v1 = v0 + a dt, x1 = x0 + v1 dt\n"
      "   v1 = v0 + (f[tid] * inv_mass + gravity * wp.step(0.0 - inv_mass)) * dt\n"
      "   x1 = x0 + v1 * dt\n"
      "\n"
      "   # store results\n"
      "   x[tid] = x1\n"
      "   v[tid] = v1\n");
  ASSERT_TRUE(integrate);
  EXPECT_EQ(integrate->params.size(), 6u);
  ASSERT_EQ(integrate->body.size(), 8u);
  EXPECT_EQ(PrintStmt(*integrate->body[4]),
            "assign v1 = (+ v0 (* (+ (* ([] f tid) inv_mass) (* gravity (call (. wp step) (- 0.0 "
            "inv_mass)))) dt))\n");
}

// ---- visitors and dumping ---------------------------------------------------------------------

struct NameCounter : ast::ConstExprVisitor<NameCounter, int> {
  int Count(const ast::Expr* e) { return e ? VisitExpr(*e) : 0; }
  int VisitName(const ast::Name&) { return 1; }
  int VisitConstant(const ast::Constant&) { return 0; }
  int VisitAttribute(const ast::Attribute& a) { return Count(a.value.get()); }
  int VisitSubscript(const ast::Subscript& s) {
    int n = Count(s.value.get());
    for (const auto& i : s.indices) n += Count(i.get());
    return n;
  }
  int VisitSlice(const ast::Slice& s) {
    return Count(s.lower.get()) + Count(s.upper.get()) + Count(s.step.get());
  }
  int VisitCall(const ast::Call& c) {
    int n = Count(c.func.get());
    for (const auto& a : c.args) n += Count(a.get());
    for (const auto& k : c.keywords) n += Count(k.value.get());
    return n;
  }
  int VisitBinOp(const ast::BinOp& b) { return Count(b.left.get()) + Count(b.right.get()); }
  int VisitUnaryOp(const ast::UnaryOp& u) { return Count(u.operand.get()); }
  int VisitBoolOp(const ast::BoolOp& b) {
    int n = 0;
    for (const auto& v : b.values) n += Count(v.get());
    return n;
  }
  int VisitCompare(const ast::Compare& c) {
    int n = Count(c.left.get());
    for (const auto& v : c.comparators) n += Count(v.get());
    return n;
  }
  int VisitIfExp(const ast::IfExp& e) {
    return Count(e.test.get()) + Count(e.body.get()) + Count(e.orelse.get());
  }
  int VisitTuple(const ast::Tuple& t) {
    int n = 0;
    for (const auto& v : t.elts) n += Count(v.get());
    return n;
  }
  int VisitStarred(const ast::Starred& s) { return Count(s.value.get()); }
  int VisitList(const ast::List& l) {
    int n = 0;
    for (const auto& v : l.elts) n += Count(v.get());
    return n;
  }
};

TEST(LangParser, VisitorReachesEveryExpressionKind) {
  auto fn = MustParse(
      "def f():\n    return a.b[c, d:e:g](h, k=i) + -j if l and m < n else (o, [p]), 1\n");
  ASSERT_TRUE(fn);
  const auto* r = ast::As<ast::Return>(fn->body[0].get());
  EXPECT_EQ(NameCounter().Count(r->value.get()), 13);
  EXPECT_STREQ(ast::ExprKindName(ast::ExprKind::kIfExp), "IfExp");
  EXPECT_STREQ(ast::StmtKindName(ast::StmtKind::kAugAssign), "AugAssign");
  EXPECT_STREQ(ast::AstName(ast::CompareOperator::kNotIn), "NotIn");
  EXPECT_STREQ(ast::Spelling(ast::BinaryOperator::kFloorDiv), "//");
}

TEST(LangParser, DumpAstEnvironmentVariable) {
  setenv("WEFT_DUMP_AST", "1", 1);
  testing::internal::CaptureStderr();
  auto fn = MustParse("def dumped(x: float):\n    return x\n", 7);
  const std::string err = testing::internal::GetCapturedStderr();
  unsetenv("WEFT_DUMP_AST");
  EXPECT_NE(err.find("def dumped(x: float)\n  return x\n"), std::string::npos) << err;
  EXPECT_NE(err.find("kern.py:7"), std::string::npos) << err;
}

// ---- robustness --------------------------------------------------------------------------------

TEST(LangParser, DeepNestingIsAnErrorNotACrash) {
  std::vector<Diagnostic> diags;
  const std::string many_minus = "def f():\n    return " + std::string(20000, '-') + "x\n";
  auto r1 = ParseFunction(Source(many_minus), &diags);
  ASSERT_FALSE(r1.ok());
  EXPECT_NE(r1.status().message().find("expression too deeply nested"), std::string::npos);
  std::string many_not = "def f():\n    return ";
  for (int i = 0; i < 5000; ++i) many_not += "not ";
  auto r2 = ParseFunction(Source(many_not + "x\n"), nullptr);
  EXPECT_FALSE(r2.ok());
  std::string pow_chain = "def f():\n    return x";
  for (int i = 0; i < 5000; ++i) pow_chain += " ** x";
  auto r3 = ParseFunction(Source(pow_chain + "\n"), nullptr);
  EXPECT_FALSE(r3.ok());
  std::string ifs = "def f():\n";
  for (int i = 0; i < 150; ++i) ifs += std::string(4 * (i + 1), ' ') + "if a:\n";
  ifs += std::string(4 * 151, ' ') + "pass\n";
  auto r4 = ParseFunction(Source(ifs), nullptr);
  ASSERT_FALSE(r4.ok());
  EXPECT_NE(r4.status().message().find("too many statically nested blocks"), std::string::npos);
  // Reasonable nesting still parses (the parser's stack budget is 256 KiB, see parser.cpp).
  EXPECT_TRUE(MustParse("def f():\n    return " + std::string(50, '(') + "x" +
                        std::string(50, ')') + "\n"));
  std::string calls = "def f():\n    return ";
  for (int i = 0; i < 25; ++i) calls += "g(a[";
  calls += "x";
  for (int i = 0; i < 25; ++i) calls += "])";
  EXPECT_TRUE(MustParse(calls + "\n"));
  // Far deeper than the budget allows: an error at the point where it ran out, never a crash.
  std::string deep_calls = "def f():\n    return ";
  for (int i = 0; i < 99; ++i) deep_calls += "g(a[";
  auto r5 = ParseFunction(Source(deep_calls + "x" + std::string(99, ']') + "\n"), nullptr);
  EXPECT_FALSE(r5.ok());
}

TEST(LangParser, LongOperatorChainsAreBoundedPerStatement) {
  // Chains are parsed by loops but build trees as deep as they are long; the per-statement cap
  // keeps every recursive walk of the tree (destructor, printer, sema) shallow.
  auto chain = [](int terms, const char* op) {
    std::string s = "x = a0";
    for (int i = 1; i < terms; ++i) s += std::string(" ") + op + " a" + std::to_string(i);
    return s;
  };
  EXPECT_TRUE(MustParse("def f():\n    " + chain(1001, "+") + "\n    " + chain(1001, "*") + "\n"));
  std::vector<Diagnostic> diags;
  auto r = ParseFunction(Source("def f():\n    " + chain(1002, "+") + "\n", 5), &diags);
  ASSERT_FALSE(r.ok());
  ASSERT_EQ(diags.size(), 1u);
  EXPECT_NE(diags[0].message.find("expression too long: more than 1000 operators in one statement"),
            std::string::npos)
      << diags[0].message;
  EXPECT_EQ(diags[0].location.line, 6u);
  // Far longer chains, of operators and of trailers, fail the same way instead of crashing.
  EXPECT_FALSE(ParseFunction(Source("def f():\n    " + chain(300000, "-") + "\n"), nullptr).ok());
  std::string trailers = "def f():\n    y = x";
  for (int i = 0; i < 100000; ++i) trailers += i % 3 == 0 ? ".a" : i % 3 == 1 ? "(b)" : "[c]";
  EXPECT_FALSE(ParseFunction(Source(trailers + "\n"), nullptr).ok());
}

TEST(LangParser, RandomMutationsGiveSuccessOrExactlyOneDiagnostic) {
  const std::string base =
      "@wp.kernel\n"
      "def k(a: wp.array(dtype=float), b: wp.array2d[wp.vec3], n: int = 3):\n"
      "    \"\"\"doc\"\"\"\n"
      "    i, j = wp.tid()\n"
      "    if i < n and not j >= 2:\n"
      "        a[i] += 2.0 ** -b[i, j].x if n else 0x1F\n"
      "    elif i:\n"
      "        wp.printf('%d\\n', i)\n"
      "    for q in range(0, n, 2):\n"
      "        while q > 0:\n"
      "            q -= 1; continue\n"
      "    return\n";
  const char alphabet[] = "()[]{}:;,.=+-*/%@<>!~'\"\\#\n \tabc019_xe";
  std::mt19937 rng(std::random_device{}());
  int failures = 0;
  for (int iter = 0; iter < 3000; ++iter) {
    std::string src = base;
    const int edits = 1 + static_cast<int>(rng() % 3);
    for (int e = 0; e < edits; ++e) {
      const size_t at = rng() % src.size();
      switch (rng() % 3) {
        case 0: src.erase(at, 1 + rng() % 3); break;
        case 1: src.insert(at, 1, alphabet[rng() % (sizeof(alphabet) - 1)]); break;
        default: src[at] = alphabet[rng() % (sizeof(alphabet) - 1)]; break;
      }
    }
    std::vector<Diagnostic> diags;
    auto r = ParseFunction(Source(src, 50), &diags);
    if (r.ok()) {
      EXPECT_TRUE(diags.empty()) << src;
      EXPECT_TRUE(r.value() != nullptr);
    } else {
      ++failures;
      ASSERT_EQ(diags.size(), 1u) << src;
      EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
      EXPECT_FALSE(diags[0].message.empty()) << src;
      EXPECT_GE(diags[0].location.line, 50u) << src << diags[0].ToString();
      EXPECT_EQ(diags[0].location.file, "kern.py");
    }
  }
  EXPECT_GT(failures, 100);  // the mutations do produce errors
}

}  // namespace
}  // namespace weft::lang
