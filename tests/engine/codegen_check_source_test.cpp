// Compile-request checks (engine/codegen/check_source.h): names must be Python identifiers
// (dotted where the protocol says so) and are refused with the field and the name, never
// repaired; modules over the compile limits are refused naming the limit.
#include <gtest/gtest.h>

#include <string>

#include "engine/codegen/check_source.h"

namespace weft::codegen {
namespace {

ModuleSource Good() {
  ModuleSource m;
  m.name = "tests.mod";
  FunctionSource f;
  f.name = "saxpy";
  f.key = "tests.mod.saxpy";
  f.file = "/home/user/my project/kernels \xc3\xa9.py";  // file names are not identifiers
  f.source = "def saxpy(a: float):\n    pass\n";
  f.is_kernel = true;
  f.param_names = {"a"};
  f.param_types = {"float32"};
  m.functions.push_back(f);
  Symbol s;
  s.name = "wp";
  s.kind = Symbol::Kind::kBuiltinModule;
  s.target = "warp";
  m.symbols.push_back(s);
  m.structs.push_back({"tests.mod.Particle", {{"pos", "vec(3,float32)"}, {"_mass2", "float32"}}});
  m.options["mode"] = "release";
  return m;
}

std::string Refusal(const ModuleSource& m, const CompileLimits& limits = {}) {
  Status s = CheckModuleSource(m, limits);
  return s.ok() ? "" : s.message();
}

TEST(CheckSource, IdentifierGrammar) {
  for (const char* ok : {"a", "_", "_x1", "Particle", "caf\xc3\xa9", "\xce\xb1\xce\xb2", "\xe5\xa4\x89\xe6\x95\xb0", "match", "type"})
    EXPECT_TRUE(IsPythonIdentifier(ok)) << ok;
  for (const char* bad : {"", "1a", "a b", "a-b", "a.b", "a\nb", "class", "None", "lambda", "a;", "a*/", "a\\",
                          "a\xe2\x80\xae", "a\xe2\x80\x8b", "a\xef\xbb\xbf", "a\xc2\xa0", "a\xc3", "a\xc0\xae", "a\xed\xa0\x80",
                          "a\xf0\x9f\x98\x80"})
    EXPECT_FALSE(IsPythonIdentifier(bad)) << bad;
  EXPECT_FALSE(IsPythonIdentifier(std::string("a\0b", 3)));
  EXPECT_TRUE(IsDottedName("mymod.sub.Particle"));
  for (const char* bad : {"", ".a", "a.", "a..b", "a.1b", "a.b c"}) EXPECT_FALSE(IsDottedName(bad)) << bad;
}

TEST(CheckSource, AGoodModulePasses) { EXPECT_EQ(Refusal(Good()), ""); }

TEST(CheckSource, EveryNameFieldIsCheckedAndNamed) {
  const std::string payload = "x\n#include \"/etc/passwd\"";
  struct Case {
    const char* field;
    void (*spoil)(ModuleSource*, const std::string&);
  };
  const Case cases[] = {
      {"name", [](ModuleSource* m, const std::string& p) { m->name = p; }},
      {"functions[0].name", [](ModuleSource* m, const std::string& p) { m->functions[0].name = p; }},
      {"functions[0].key", [](ModuleSource* m, const std::string& p) { m->functions[0].key = p; }},
      {"functions[0].param_names[0]", [](ModuleSource* m, const std::string& p) { m->functions[0].param_names[0] = p; }},
      {"symbols[0].name", [](ModuleSource* m, const std::string& p) { m->symbols[0].name = p; }},
      {"structs[0].name", [](ModuleSource* m, const std::string& p) { m->structs[0].name = p; }},
      {"structs[0].fields[1].name", [](ModuleSource* m, const std::string& p) { m->structs[0].fields[1].name = p; }},
      {"options key", [](ModuleSource* m, const std::string& p) { m->options[p] = "1"; }},
  };
  for (const auto& c : cases) {
    ModuleSource m = Good();
    c.spoil(&m, payload);
    Status s = CheckModuleSource(m, {});
    ASSERT_FALSE(s.ok()) << c.field;
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
    EXPECT_NE(s.message().find(c.field), std::string::npos) << s.message();
    // The name is quoted with its newline escaped: the message stays one line.
    EXPECT_NE(s.message().find("'x\\n#include"), std::string::npos) << s.message();
    EXPECT_EQ(s.message().find('\n'), std::string::npos) << s.message();
  }
  ModuleSource m = Good();
  m.symbols[0].kind = Symbol::Kind::kFunction;
  m.symbols[0].target = "f()";
  EXPECT_NE(Refusal(m).find("symbols[0].function"), std::string::npos);
  m = Good();
  m.options["mode"] = "a\nb";
  EXPECT_NE(Refusal(m).find("options['mode']"), std::string::npos);
  m = Good();
  m.functions[0].name = std::string(2000, 'a');
  EXPECT_NE(Refusal(m).find("at most 1024 bytes"), std::string::npos);
  m = Good();
  m.functions[0].file = std::string(5000, 'f');
  EXPECT_NE(Refusal(m).find("functions[0].file"), std::string::npos);
}

TEST(CheckSource, LimitsAreEnforcedAndNamed) {
  CompileLimits limits;
  limits.max_module_bytes = 4096;
  limits.max_functions = 3;
  ModuleSource m = Good();
  EXPECT_EQ(Refusal(m, limits), "");
  m.functions[0].source += std::string(5000, '#');
  Status s = CheckModuleSource(m, limits);
  EXPECT_EQ(s.code(), StatusCode::kResourceExhausted);
  EXPECT_NE(s.message().find("max_module_bytes"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("4096"), std::string::npos) << s.message();

  m = Good();
  for (int i = 0; i < 3; ++i) m.functions.push_back(m.functions[0]);
  s = CheckModuleSource(m, limits);
  EXPECT_EQ(s.code(), StatusCode::kResourceExhausted);
  EXPECT_NE(s.message().find("max_functions"), std::string::npos) << s.message();

  // Entries count even when their strings are empty.
  m = Good();
  m.symbols.resize(1000);
  s = CheckModuleSource(m, limits);
  EXPECT_EQ(s.code(), StatusCode::kResourceExhausted) << s.message();
}

}  // namespace
}  // namespace weft::codegen
