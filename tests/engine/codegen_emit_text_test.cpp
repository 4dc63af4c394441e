// The escaping and mangling functions through which client text enters generated C++
// (engine/codegen/emit_text.h): whatever the input — newlines, `*/`, backslashes, `??/`,
// NULs, non-ASCII, very long text — the output stays inside its context; and a module whose
// every client-chosen name is hostile generates code with no line of the client's making
// (the engine's API boundary refuses such names; this checks the layer behind it).
#include <gtest/gtest.h>

#include <set>
#include <string>

#include "engine/codegen/emit_text.h"
#include "engine/codegen/generate_module.h"

namespace weft::codegen {
namespace {

const std::string kNul("a\0b", 3);
const std::string kHostile[] = {
    "plain",
    "new\nline",
    "x\n#include \"/etc/passwd\"\n",
    "end */ of comment /* again",
    "back\\slash\\",
    "trigraph ?\?/\nnext",
    "cr\rlf\r\n",
    kNul,
    "caf\xc3\xa9 \xe2\x80\xae \xff\xfe",
    "\"quoted\" 'single' %d %s %n",
    std::string(100000, 'A') + "\n}",
};

bool AllPrintableAscii(const std::string& s) {
  for (char c : s)
    if (static_cast<unsigned char>(c) < 0x20 || static_cast<unsigned char>(c) >= 0x7f) return false;
  return true;
}

TEST(EmitText, IdentifierIsOnlyIdentifierCharacters) {
  for (const auto& in : kHostile) {
    std::string out = MangleIdentifier(in);
    for (char c : out) EXPECT_TRUE(std::isalnum(static_cast<unsigned char>(c)) || c == '_') << out.substr(0, 80);
  }
  EXPECT_EQ(MangleIdentifier("saxpy"), "saxpy");
  EXPECT_EQ(MangleIdentifier("my_kernel2"), "my_kernel2");
  EXPECT_EQ(MangleIdentifier("mymod.Particle"), "mymodZ2EParticle");
  EXPECT_EQ(MangleIdentifier("Zeta"), "ZZeta");
  EXPECT_EQ(MangleIdentifier("caf\xc3\xa9"), "cafZC3ZA9");
  EXPECT_EQ(MangleIdentifier(kNul), "aZ00b");
}

TEST(EmitText, IdentifierManglingIsInjective) {
  // Names that a lossy mangling ('.' and '_' to '_') would merge.
  const std::string names[] = {"a.b", "a_b", "aZ2Eb", "a.Z", "a_Z", "aZ", "aZZ", "a__b", "a._b", "a\xc3\xa9", "aZC3ZA9"};
  std::set<std::string> seen;
  for (const auto& n : names) EXPECT_TRUE(seen.insert(MangleIdentifier(n)).second) << n;
}

TEST(EmitText, StringLiteralKeepsEveryByteAndStaysOneToken) {
  for (const auto& in : kHostile) {
    std::string out = CppStringLiteral(in);
    ASSERT_GE(out.size(), 2u);
    EXPECT_EQ(out.front(), '"');
    EXPECT_EQ(out.back(), '"');
    EXPECT_TRUE(AllPrintableAscii(out)) << out.substr(0, 80);
    // Inside the quotes every '"' and '?' is escaped, and every backslash starts an escape.
    for (size_t i = 1; i + 1 < out.size(); ++i) {
      if (out[i] == '\\') {
        ++i;
        continue;
      }
      EXPECT_NE(out[i], '"') << out.substr(0, 80);
      EXPECT_NE(out[i], '?') << out.substr(0, 80);
    }
  }
  EXPECT_EQ(CppStringLiteral("a\"b\\c\n"), "\"a\\\"b\\\\c\\n\"");
  EXPECT_EQ(CppStringLiteral("?\?/"), "\"\\?\\?/\"");
  EXPECT_EQ(CppStringLiteral(kNul), "\"a\\000b\"");
  EXPECT_EQ(CppStringLiteral("\x01" "7"), "\"\\0017\"");  // three octal digits, then the '7'
  EXPECT_EQ(CppStringLiteral("\xc3\xa9"), "\"\\303\\251\"");
}

TEST(EmitText, CommentTextCannotEndTheComment) {
  for (const auto& in : kHostile) {
    std::string out = CommentText(in);
    EXPECT_TRUE(AllPrintableAscii(out)) << out.substr(0, 80);
    EXPECT_EQ(out.find('\\'), std::string::npos) << out;
    EXPECT_EQ(out.find("*/"), std::string::npos) << out;
    EXPECT_EQ(out.find("?\?"), std::string::npos) << out;
    EXPECT_LE(out.size(), 200u * 3 + 3);
  }
  EXPECT_EQ(CommentText("kernels.py"), "kernels.py");
  EXPECT_EQ(CommentText("a\nb"), "a%0Ab");
  EXPECT_EQ(CommentText("end\\"), "end%5C");
  EXPECT_EQ(CommentText("*/"), "*%2F");
  EXPECT_EQ(CommentText("50%"), "50%25");
  EXPECT_EQ(CommentText(std::string(300, 'x')), std::string(200, 'x') + "...");
}

TEST(EmitText, LineDirectiveFileNameIsOneQuotedToken) {
  for (const auto& in : kHostile) {
    std::string out = LineDirective(42, in);
    EXPECT_EQ(out.rfind("#line 42 \"", 0), 0u);
    EXPECT_EQ(out.back(), '"');
    std::string inner = out.substr(10, out.size() - 11);
    EXPECT_TRUE(AllPrintableAscii(inner));
    EXPECT_EQ(inner.find_first_of("\"\\?"), std::string::npos) << inner;
  }
  EXPECT_EQ(LineDirective(7, "dir/kernels.py"), "#line 7 \"dir/kernels.py\"");
}

// A module whose struct, field, function, kernel, parameter and file names all carry a
// payload: the generated translation unit has exactly the two #include lines codegen writes
// and otherwise only #line directives exactly as LineDirective writes them for the kernel's
// file, the payload never starts a line, and clang accepts it.
TEST(EmitText, HostileNamesNeverBecomeCode) {
  const std::string payload = "x\n#include \"/etc/passwd\"\nint injected = system(\"touch /tmp/pwned\");\n//";
  ModuleSource m;
  m.name = "mod\n#error injected";
  Symbol wp;
  wp.name = "wp";
  wp.kind = Symbol::Kind::kBuiltinModule;
  wp.target = "warp";
  Symbol st;
  st.name = "S";
  st.kind = Symbol::Kind::kType;
  st.target = "struct(m.S)";
  m.symbols = {wp, st};
  m.structs.push_back({"m.S",
                       {{"pos", "vec(3,float32)"}, {"evil" + payload, "float32"}, {"mass", "float32"}, {"more*/" + payload, "int32"}}});
  m.structs.push_back({"other" + payload, {{"f" + payload, "int32"}}});
  FunctionSource k;
  k.name = "k" + payload;
  k.key = k.name;
  k.file = "file" + payload + "\\";
  k.first_line = 3;
  k.is_kernel = true;
  k.source = "def k(a: wp.array(dtype=float), s: S):\n    i = wp.tid()\n    a[i] = s.mass + wp.length(s.pos)\n";
  k.param_types = {"array(float32,1)", "struct(m.S)"};
  k.param_names = {"a" + payload, "s\\"};
  m.functions.push_back(k);
  for (bool backward : {false, true}) {
    CodegenOptions o;
    o.enable_backward = backward;
    std::vector<Diagnostic> diags;
    auto gm = GenerateModule(m, o, &diags);
    ASSERT_TRUE(gm.ok()) << gm.status().message() << (diags.empty() ? "" : diags[0].ToString());
    size_t start = 0;
    int includes = 0;
    const std::string& src = gm->source;
    while (start < src.size()) {
      size_t end = src.find('\n', start);
      if (end == std::string::npos) end = src.size();
      std::string line = src.substr(start, end - start);
      start = end + 1;
      size_t first = line.find_first_not_of(' ');
      // #line directives map generated code to the user's lines: each must be exactly
      // LineDirective's output for the kernel's file (the file name one quoted, %-encoded token).
      if (line.rfind("#line ", 0) == 0) {
        size_t sp = line.find(' ', 6);
        ASSERT_NE(sp, std::string::npos) << line;
        uint32_t n = static_cast<uint32_t>(std::stoul(line.substr(6, sp - 6)));
        EXPECT_EQ(line, codegen::LineDirective(n, k.file));
        continue;
      }
      if (first != std::string::npos && line[first] == '#') {
        EXPECT_TRUE(line == "#include \"weft.h\"" || line == "#include \"codegen_support.h\"") << line;
        ++includes;
      }
      // Outside comments the payload survives only inside mangled identifiers.
      std::string code = line.substr(0, line.find("//"));
      for (const char* raw : {"injected =", "system(", "passwd\"", "#include \"/"})
        EXPECT_EQ(code.find(raw), std::string::npos) << "payload outside a comment: " << line;
      EXPECT_TRUE(line.empty() || line.back() != '\\') << line;
    }
    EXPECT_EQ(includes, 2);
    for (const auto& kl : gm->kernels) {
      for (char c : kl.forward_symbol) EXPECT_TRUE(std::isalnum(static_cast<unsigned char>(c)) || c == '_');
    }
    std::string file = ::testing::TempDir() + "/weft_emit_text_" + std::to_string(::getpid()) + ".cpp";
    FILE* f = std::fopen(file.c_str(), "w");
    ASSERT_NE(f, nullptr);
    std::fwrite(src.data(), 1, src.size(), f);
    std::fclose(f);
    std::string cmd = "clang++-19 -std=c++17 -fsyntax-only -Wno-unused-variable -I" WEFT_NATIVE_DIR " " + file +
                      " > /dev/null 2>&1";
    EXPECT_EQ(std::system(cmd.c_str()), 0) << "generated code does not compile: " << file;
  }
}

}  // namespace
}  // namespace weft::codegen
