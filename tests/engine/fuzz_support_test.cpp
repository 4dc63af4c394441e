// The compile fuzzer's support code (tests/fuzz): the module text format parses what the seed
// tools write, and the generated-code checks accept real modules and reject each kind of
// ill-formed output they exist to catch (comment escapes, line splices, stray directives).
#include <gtest/gtest.h>

#include "engine/codegen/generate_module.h"
#include "tests/fuzz/generated_cpp_check.h"
#include "tests/fuzz/module_text.h"

namespace weft::fuzz {
namespace {

const char* kSaxpy =
    "# a comment line\n"
    "module m\n"
    "codegen cpu backward\n"
    "builtin wp warp\n"
    "const N int32 4\n"
    "struct m.S\n"
    "field pos vec(3,float32)\n"
    "field mass float32\n"
    "kernel saxpy m.saxpy k.py 10\n"
    "param a float32\n"
    "param x array(float32,1)\n"
    "param y array(float32,1)\n"
    "source\n"
    "def saxpy(a: float, x: wp.array(dtype=float), y: wp.array(dtype=float)):\n"
    "    i = wp.tid()\n"
    "    y[i] = a * x[i] + y[i]\n"
    ".end\n";

TEST(FuzzModuleText, ParsesEveryRecord) {
  FuzzModule fm = ParseModuleText(kSaxpy);
  EXPECT_EQ(fm.module.name, "m");
  EXPECT_TRUE(fm.options.enable_backward);
  EXPECT_EQ(fm.options.target, Target::kCpu);
  ASSERT_EQ(fm.module.symbols.size(), 2u);
  EXPECT_EQ(fm.module.symbols[0].kind, Symbol::Kind::kBuiltinModule);
  EXPECT_EQ(fm.module.symbols[1].constant.value, "4");
  ASSERT_EQ(fm.module.structs.size(), 1u);
  EXPECT_EQ(fm.module.structs[0].fields[1].name, "mass");
  ASSERT_EQ(fm.module.functions.size(), 1u);
  const FunctionSource& f = fm.module.functions[0];
  EXPECT_TRUE(f.is_kernel);
  EXPECT_EQ(f.key, "m.saxpy");
  EXPECT_EQ(f.first_line, 10u);
  EXPECT_EQ(f.param_types, (std::vector<std::string>{"float32", "array(float32,1)", "array(float32,1)"}));
  EXPECT_EQ(f.source.substr(0, 10), "def saxpy(");
  EXPECT_EQ(f.source.back(), '\n');
}

TEST(FuzzModuleText, FieldEscapesRoundTrip) {
  for (std::string s : {std::string("a b"), std::string("x\ny\r\t\\"), std::string("\0z", 2), std::string("-"),
                        std::string("")}) {
    FuzzModule fm = ParseModuleText("module " + EscapeField(s) + "\n");
    EXPECT_EQ(fm.module.name, s);
  }
}

TEST(FuzzModuleText, AnyBytesParse) {
  const char kBytes[] = "param\nsource\nfield\n\xff\x00 kernel";
  FuzzModule fm = ParseModuleText(std::string(kBytes, sizeof(kBytes) - 1));
  EXPECT_TRUE(fm.module.functions.empty());
}

TEST(FuzzGeneratedCheck, AcceptsARealModule) {
  FuzzModule fm = ParseModuleText(kSaxpy);
  std::vector<Diagnostic> diags;
  auto out = GenerateModule(fm.module, fm.options, &diags);
  ASSERT_TRUE(out.ok()) << out.status().ToString();
  EXPECT_EQ(CheckGeneratedModule(*out), "");
}

GeneratedModule WithSource(const std::string& src) {
  GeneratedModule m;
  m.source = src;
  return m;
}

TEST(FuzzGeneratedCheck, RejectsIllFormedText) {
  EXPECT_EQ(CheckGeneratedModule(WithSource("#include \"weft.h\"\n// ok\nint f() { return 1; }\n")), "");
  EXPECT_EQ(CheckGeneratedModule(WithSource("#line 7 \"a\\\"b.py\"\nint x;\n")), "");
  // A client name that ended a comment: the rest of its line became code.
  EXPECT_NE(CheckGeneratedModule(WithSource("// k.py\nsystem(\"id\"); {\nint x;\n")), "");
  // A name ending in a backslash splices the next line into the comment.
  EXPECT_NE(CheckGeneratedModule(WithSource("// file k.py\\\nint x;\n")), "");
  EXPECT_NE(CheckGeneratedModule(WithSource("// a\rint x;\n")), "");
  EXPECT_NE(CheckGeneratedModule(WithSource("#include \"/etc/passwd\"\n")), "");
  EXPECT_NE(CheckGeneratedModule(WithSource("const char* s = \"abc\nint x;\n")), "");
  EXPECT_NE(CheckGeneratedModule(WithSource("int \xc3\xa9 = 1;\n")), "");
  EXPECT_EQ(CheckGeneratedModule(WithSource("// \xc3\xa9\nconst char* s = \"\xc3\xa9\";\n")), "");
  EXPECT_NE(CheckGeneratedModule(WithSource("/* open\nint x;\n")), "");
}

TEST(FuzzGeneratedCheck, RejectsInconsistentLayouts) {
  GeneratedModule m = WithSource("extern \"C\" void f() {}\n");
  KernelLayout k;
  k.name = "k";
  k.forward_symbol = "f";
  k.args_size = 8;
  ParamLayout p;
  p.name = "a";
  p.offset = 4;
  p.size = 8;
  p.align = 4;
  k.params.push_back(p);
  m.kernels.push_back(k);
  EXPECT_NE(CheckGeneratedModule(m), "");
  m.kernels[0].params[0].offset = 0;
  EXPECT_EQ(CheckGeneratedModule(m), "");
  m.kernels[0].params[0].align = 3;
  EXPECT_NE(CheckGeneratedModule(m), "");
  m.kernels[0].params[0].align = 4;
  m.kernels[0].forward_symbol = "f;g";
  EXPECT_NE(CheckGeneratedModule(m), "");
}

}  // namespace
}  // namespace weft::fuzz
