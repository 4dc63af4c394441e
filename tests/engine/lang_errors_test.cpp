// Parser errors, must-fail-with-this-message kind: every unsupported construct and common
// syntax error gives exactly one diagnostic with this message at this user file:line:col
// (the function starts at line 100 of the user's file), with the source line and a caret.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "engine/lang/parser.h"

namespace weft::lang {
namespace {

struct ErrorCase {
  const char* name;
  const char* body;     // lines after "def k(x: float):\n" (source line 2 = user line 101)
  const char* message;  // substring of the diagnostic's message
  uint32_t line;        // user line
  uint32_t column;
};

constexpr uint32_t kFirstLine = 100;

// Sorted by name.
const ErrorCase kCases[] = {
    {"argument_unpacking_after_kw", "    f(x=1, *a)\n", "iterable argument unpacking follows keyword argument", 101, 12},
    {"argument_unpacking_kw", "    f(**a)\n", "keyword argument unpacking (**kwargs) is not supported", 101, 7},
    {"assign_to_call", "    f(x) = 1\n", "cannot assign to function call", 101, 5},
    {"assign_to_comparison", "    a < b = 1\n", "cannot assign to comparison", 101, 5},
    {"assign_to_literal", "    1 = x\n", "cannot assign to literal", 101, 5},
    {"assign_to_none", "    None = x\n", "cannot assign to None", 101, 5},
    {"assign_to_tuple_with_call", "    a, f() = x\n", "cannot assign to function call", 101, 8},
    {"async_statement", "    async with a:\n        pass\n", "'async' is not supported", 101, 5},
    {"augassign_to_tuple", "    a, b += 1\n", "'tuple' is an illegal expression for augmented assignment", 101, 5},
    {"await", "    y = await x\n", "'await' is not supported in kernels", 101, 9},
    {"break_outside_loop", "    if x:\n        break\n", "'break' outside loop", 102, 9},
    {"bytes_literal", "    s = b'abc'\n", "bytes literals are not supported in kernels", 101, 9},
    {"class", "    class A:\n        pass\n", "class definitions are not allowed inside kernels", 101, 5},
    {"colon_missing", "    if x\n        pass\n", "expected ':' after the 'if' condition, found end of line", 101, 9},
    {"complex_literal", "    y = 2j\n", "complex (imaginary) number literals are not supported", 101, 9},
    {"continue_outside_loop", "    for i in range(3):\n        pass\n    continue\n", "'continue' outside loop", 103, 5},
    {"del", "    del x\n", "'del' is not supported in kernels", 101, 5},
    {"dict_literal", "    d = {1: 2}\n", "dict and set literals are not supported in kernels", 101, 9},
    {"dict_comprehension", "    d = {i: i for i in range(3)}\n", "dict and set literals are not supported", 101, 9},
    {"duplicate_keyword", "    f(a=1, a=2)\n", "keyword argument repeated: a", 101, 12},
    {"elif_without_if", "    elif x:\n        pass\n", "'elif' without a matching 'if'", 101, 5},
    {"ellipsis", "    y = ...\n", "'...' (Ellipsis) is not supported in kernels", 101, 9},
    {"empty_subscript", "    y = a[]\n", "expected an index inside '[]'", 101, 11},
    {"equals_in_condition", "    while x = 1:\n        pass\n", "maybe you meant '==' instead of '='", 101, 13},
    {"for_else", "    for i in range(3):\n        pass\n    else:\n        pass\n", "'else' clauses on 'for' loops are not supported", 103, 5},
    {"fstring", "    print(f'{x}')\n", "f-strings are not supported in kernels", 101, 11},
    {"generator_in_call", "    y = sum(i for i in range(3))\n", "comprehensions and generator expressions are not supported", 101, 15},
    {"global", "    global g\n", "'global' declarations are not supported in kernels", 101, 5},
    {"ifexp_without_else", "    y = a if b\n", "expected 'else' after 'if' expression", 101, 15},
    {"import", "    import math\n", "import statements are not allowed inside kernels", 101, 5},
    {"import_from", "    from math import sin\n", "import statements are not allowed inside kernels", 101, 5},
    {"indent_unexpected", "    x = 1\n        y = 2\n", "unexpected indent", 102, 9},
    {"indented_block_missing", "    for i in range(3):\n    pass\n", "expected an indented block after 'for' statement on line 101", 102, 5},
    {"lambda", "    f = lambda a: a\n", "lambda expressions are not supported in kernels", 101, 9},
    {"list_comprehension", "    y = [i * 2 for i in range(3)]\n", "comprehensions and generator expressions are not supported", 101, 16},
    {"nested_decorated_def", "    @wp.func\n    def g():\n        pass\n", "decorators are not allowed inside kernels", 101, 5},
    {"nested_def", "    def g():\n        pass\n", "nested function definitions are not supported", 101, 5},
    {"nonlocal", "    nonlocal g\n", "'nonlocal' declarations are not supported", 101, 5},
    {"positional_after_keyword", "    f(a=1, 2)\n", "positional argument follows keyword argument", 101, 12},
    {"raise", "    raise ValueError()\n", "'raise' is not supported in kernels", 101, 5},
    {"set_literal", "    s = {1, 2}\n", "dict and set literals are not supported", 101, 9},
    {"starred_assignment", "    a, *b = x\n", "starred expressions (*x) are not supported", 101, 8},
    {"starred_expression", "    return *a, b\n", "starred expressions (*x) are not supported", 101, 12},
    {"statement_trailing_tokens", "    y = x x\n", "expected end of line after the statement, found 'x'", 101, 11},
    {"string_unterminated", "    s = 'abc\n", "unterminated string literal (detected at line 101)", 101, 9},
    {"triple_string_unterminated", "    s = '''abc\n    y = 1\n", "unterminated triple-quoted string literal", 101, 9},
    {"try", "    try:\n        pass\n    except:\n        pass\n", "exception handling ('try') is not supported", 101, 5},
    {"unclosed_paren", "    y = f(x,\n    z = 2\n", "'(' was never closed", 101, 10},
    {"unindent_mismatch", "    if x:\n        y = 1\n      z = 2\n", "unindent does not match any outer indentation level", 103, 7},
    {"walrus", "    if (n := 10) > 5:\n        pass\n", "the walrus operator ':=' is not supported in kernels", 101, 11},
    {"while_else", "    while x:\n        pass\n    else:\n        pass\n", "'else' clauses on 'while' loops are not supported", 103, 5},
    {"with", "    with wp.ScopedDevice('cpu'):\n        pass\n", "'with' statements are not supported in kernels", 101, 5},
    {"yield", "    yield x\n", "'yield' is not supported in kernels", 101, 5},
    {"yield_in_assignment", "    y = yield x\n", "'yield' is not supported in kernels", 101, 9},
};

TEST(LangErrors, EveryCaseGivesOneLocatedDiagnostic) {
  for (const ErrorCase& c : kCases) {
    FunctionSource fn;
    fn.name = "k";
    fn.file = "/home/user/sim.py";
    fn.first_line = kFirstLine;
    fn.source = std::string("def k(x: float):\n") + c.body;
    std::vector<Diagnostic> diags;
    auto r = ParseFunction(fn, &diags);
    ASSERT_FALSE(r.ok()) << c.name;
    EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument) << c.name;
    ASSERT_EQ(diags.size(), 1u) << c.name;
    const Diagnostic& d = diags[0];
    EXPECT_NE(d.message.find(c.message), std::string::npos)
        << c.name << ": got \"" << d.message << "\"";
    EXPECT_EQ(d.location.file, "/home/user/sim.py") << c.name;
    EXPECT_EQ(d.location.line, c.line) << c.name << ": " << d.ToString();
    EXPECT_EQ(d.location.column, c.column) << c.name << ": " << d.ToString();
    EXPECT_EQ(d.severity, Diagnostic::Severity::kError) << c.name;
    // The status text is the formatted diagnostic: it names the user's file and line.
    EXPECT_NE(r.status().message().find("/home/user/sim.py:" + std::to_string(c.line) + ":"),
              std::string::npos)
        << c.name << ": " << r.status().message();
  }
}

TEST(LangErrors, FunctionHeaderErrors) {
  struct Case {
    const char* source;
    const char* message;
    uint32_t line, column;
  };
  const Case cases[] = {
      {"async def k():\n    pass\n", "async functions are not supported in kernels", 100, 1},
      {"class K:\n    pass\n", "expected a function definition ('def')", 100, 1},
      {"def k()\n    pass\n", "expected ':' after the function definition, found end of line", 100, 8},
      {"def k(*args):\n    pass\n", "variadic parameters (*args, **kwargs) are not supported", 100, 7},
      {"def k(**kw):\n    pass\n", "variadic parameters (*args, **kwargs) are not supported", 100, 7},
      {"def k(a, /, b):\n    pass\n", "positional-only parameter markers ('/') are not supported", 100, 10},
      {"def k(a, a):\n    pass\n", "duplicate argument 'a' in function definition", 100, 10},
      {"def k(a=1, b):\n    pass\n", "parameter without a default follows parameter with a default", 100, 12},
      {"def k():\n    pass\ndef other():\n    pass\n", "unexpected code after the end of function 'k'", 102, 1},
      {"def k():\n", "expected an indented block after function definition on line 100", 100, 9},
      {"x = 1\n", "expected 'def' at the start of the function source", 100, 1},
      {"", "expected 'def' at the start of the function source", 100, 1},
  };
  for (const Case& c : cases) {
    FunctionSource fn;
    fn.file = "m.py";
    fn.first_line = kFirstLine;
    fn.source = c.source;
    std::vector<Diagnostic> diags;
    auto r = ParseFunction(fn, &diags);
    ASSERT_FALSE(r.ok()) << c.source;
    ASSERT_EQ(diags.size(), 1u) << c.source;
    EXPECT_NE(diags[0].message.find(c.message), std::string::npos)
        << c.source << " -> " << diags[0].message;
    EXPECT_EQ(diags[0].location.line, c.line) << c.source << " -> " << diags[0].ToString();
    EXPECT_EQ(diags[0].location.column, c.column) << c.source << " -> " << diags[0].ToString();
  }
}

TEST(LangErrors, DiagnosticShowsSourceLineAndCaret) {
  FunctionSource fn;
  fn.file = "sim.py";
  fn.first_line = 20;
  fn.source = "def k(x: float):\n    y = lambda q: q\n";
  std::vector<Diagnostic> diags;
  auto r = ParseFunction(fn, &diags);
  ASSERT_FALSE(r.ok());
  ASSERT_EQ(diags.size(), 1u);
  EXPECT_EQ(diags[0].source_line, "    y = lambda q: q");
  EXPECT_EQ(diags[0].ToString(),
            "sim.py:21:9: error: lambda expressions are not supported in kernels; define a "
            "@wp.func instead\n"
            "        y = lambda q: q\n"
            "            ^");
  EXPECT_EQ(r.status().message(), diags[0].ToString());
}

TEST(LangErrors, EarliestErrorWinsOverLaterLexicalError) {
  FunctionSource fn;
  fn.file = "sim.py";
  fn.first_line = 1;
  fn.source = "def k():\n    y = lambda: 0\n    s = f'{y}'\n";
  std::vector<Diagnostic> diags;
  ASSERT_FALSE(ParseFunction(fn, &diags).ok());
  ASSERT_EQ(diags.size(), 1u);
  EXPECT_NE(diags[0].message.find("lambda"), std::string::npos) << diags[0].message;
  EXPECT_EQ(diags[0].location.line, 2u);
  fn.source = "def k():\n    s = f'{y}'\n    y = lambda: 0\n";
  diags.clear();
  ASSERT_FALSE(ParseFunction(fn, &diags).ok());
  EXPECT_NE(diags[0].message.find("f-strings"), std::string::npos) << diags[0].message;
  EXPECT_EQ(diags[0].location.line, 2u);
}

TEST(LangErrors, ErrorAtEndOfInputPointsAtLastLine) {
  FunctionSource fn;
  fn.file = "sim.py";
  fn.first_line = 10;
  fn.source = "def k():\n    if x:\n\n";
  std::vector<Diagnostic> diags;
  ASSERT_FALSE(ParseFunction(fn, &diags).ok());
  ASSERT_EQ(diags.size(), 1u);
  EXPECT_NE(diags[0].message.find("expected an indented block after 'if' statement on line 11"),
            std::string::npos)
      << diags[0].message;
  EXPECT_EQ(diags[0].location.line, 11u);
  EXPECT_EQ(diags[0].source_line, "    if x:");
  EXPECT_EQ(diags[0].location.column, 10u);
}

TEST(LangErrors, NullDiagnosticsListIsAllowed) {
  FunctionSource fn;
  fn.file = "sim.py";
  fn.source = "def k():\n    del x\n";
  auto r = ParseFunction(fn, nullptr);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("sim.py:2:5: error: 'del' is not supported"),
            std::string::npos)
      << r.status().message();
}

}  // namespace
}  // namespace weft::lang
