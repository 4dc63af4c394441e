// wp.printf formats (engine/sema/printf_format.h): the conversions Warp allows for the
// argument types, nothing else; length modifiers replaced by the ones the arguments need.
#include <gtest/gtest.h>

#include <string>

#include "engine/sema/printf_format.h"

namespace weft::sema {
namespace {

Type I32() { return Type::Int32(); }
Type I64() { return Type::Scalar(ScalarKind::kInt64); }
Type U8() { return Type::Scalar(ScalarKind::kUInt8); }
Type F32() { return Type::Float32(); }
Type F16() { return Type::Scalar(ScalarKind::kFloat16); }

std::string Normalized(const std::string& f, std::vector<Type> args) {
  auto r = CheckPrintfFormat(f, args);
  return r.ok() ? *r : "ERROR: " + r.status().message();
}

TEST(PrintfFormat, AllowedConversionsAreNormalized) {
  EXPECT_EQ(Normalized("x=%d y=%f\n", {I32(), F32()}), "x=%d y=%f\n");
  EXPECT_EQ(Normalized("%+05i %-3u %#x %X %o", {I32(), I32(), I32(), U8(), I32()}), "%+05i %-3u %#x %X %o");
  EXPECT_EQ(Normalized("%.3e %E %g %G %a %A %F", {F32(), F32(), F32(), F16(), F32(), F32(), F32()}),
            "%.3e %E %g %G %a %A %F");
  EXPECT_EQ(Normalized("%d", {I64()}), "%lld");        // the daemon picks the length
  EXPECT_EQ(Normalized("%ld %hhx", {I64(), I32()}), "%lld %x");
  EXPECT_EQ(Normalized("%d", {Type::Bool()}), "%d");
  EXPECT_EQ(Normalized("100%% done", {}), "100%% done");
  EXPECT_EQ(Normalized("no conversions", {}), "no conversions");
}

TEST(PrintfFormat, EverythingElseIsRefusedWithAReason) {
  struct Case {
    std::string format;
    std::vector<Type> args;
    const char* reason;
  };
  const Case cases[] = {
      {"%p", {I64()}, "conversion %p is not supported"},
      {"%s", {I64()}, "conversion %s is not supported"},
      {"%n", {I32()}, "conversion %n is not supported"},
      {"%c", {I32()}, "conversion %c is not supported"},
      {"%Lf", {F32()}, "conversion %L is not supported"},
      {"%*d", {I32(), I32()}, "'*'"},
      {"%.*f", {I32(), F32()}, "'*'"},
      {"%d", {F32()}, "expects an integer but argument 1 is float32"},
      {"%f", {I32()}, "expects a float but argument 1 is int32"},
      {"%d %d", {I32()}, "more conversions than arguments"},
      {"%d", {I32(), I32()}, "1 conversion(s) but 2 argument(s)"},
      {"50%", {}, "ends inside a conversion"},
      {"%1234d", {I32()}, "more than 3 digits"},
      {std::string("%d\0%s", 5), {I32()}, "NUL"},
  };
  for (const auto& c : cases) {
    std::string r = Normalized(c.format, c.args);
    EXPECT_NE(r.find(c.reason), std::string::npos) << c.format << " -> " << r;
    EXPECT_EQ(r.rfind("ERROR: ", 0), 0u) << c.format;
  }
}

TEST(PrintfFormat, LiteralTextPrintsItsPercentSigns) {
  EXPECT_EQ(LiteralFormat("100% %s %n"), "100%% %%s %%n");
  auto r = CheckPrintfFormat(LiteralFormat("100% %s %n"), {});
  ASSERT_TRUE(r.ok());
}

}  // namespace
}  // namespace weft::sema
