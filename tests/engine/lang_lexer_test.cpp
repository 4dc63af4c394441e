// Lexer tests: token streams for each lexical construct, exact literal values (against
// strtod and hand-computed big integers, plus random round trips), positions, and errors.
#include <gtest/gtest.h>

#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <string>

#include "engine/lang/lexer.h"

namespace weft::lang {
namespace {

// "NAME:x OP:= INT:1 NEWLINE EOF" (INDENT/DEDENT/NEWLINE/EOF without text).
std::string Kinds(std::string_view src) {
  TextPosition err;
  auto toks = Tokenize(src, &err);
  if (!toks.ok()) return "error " + std::to_string(err.line) + ":" + std::to_string(err.column) +
                        ": " + toks.status().message();
  std::string out;
  for (const Token& t : *toks) {
    if (!out.empty()) out += " ";
    out += TokenKindName(t.kind);
    if (t.kind != TokenKind::kNewline && t.kind != TokenKind::kIndent &&
        t.kind != TokenKind::kDedent && t.kind != TokenKind::kEndOfFile) {
      out += ":" + t.text;
    }
  }
  return out;
}

Token Single(std::string_view src) {
  TextPosition err;
  auto toks = Tokenize(src, &err);
  EXPECT_TRUE(toks.ok()) << src << ": " << toks.status().ToString();
  if (!toks.ok() || toks->empty()) return {};
  return (*toks)[0];
}

std::string LexError(std::string_view src, TextPosition* at) {
  auto toks = Tokenize(src, at);
  EXPECT_FALSE(toks.ok()) << "expected a lexical error in: " << src;
  return toks.ok() ? "" : toks.status().message();
}

TEST(LangLexer, BackslashContinuationJoinsLines) {
  EXPECT_EQ(Kinds("x = 1 + \\\n    2\n"), "NAME:x OP:= INT:1 OP:+ INT:2 NEWLINE EOF");
  EXPECT_EQ(Kinds("x = 1 + \\\r\n2\r\n"), "NAME:x OP:= INT:1 OP:+ INT:2 NEWLINE EOF");
}

TEST(LangLexer, BaseIndentationOfUndentedSourceIsAccepted) {
  EXPECT_EQ(Kinds("    def f():\n        pass\n"),
            "KEYWORD:def NAME:f OP:( OP:) OP:: NEWLINE INDENT KEYWORD:pass NEWLINE DEDENT EOF");
}

TEST(LangLexer, BlankAndCommentLinesMakeNoTokens) {
  EXPECT_EQ(Kinds("a\n\n   \n  # c\n# c\nb # c\n"), "NAME:a NEWLINE NAME:b NEWLINE EOF");
}

TEST(LangLexer, BracketsJoinLinesAndIgnoreIndentation) {
  EXPECT_EQ(Kinds("f(a,\n        b,\n  c)\n"),
            "NAME:f OP:( NAME:a OP:, NAME:b OP:, NAME:c OP:) NEWLINE EOF");
  EXPECT_EQ(Kinds("x = [1,\n# comment\n\n 2]\n"), "NAME:x OP:= OP:[ INT:1 OP:, INT:2 OP:] NEWLINE EOF");
  // A closing bracket at the start of a line does not start a new logical line.
  EXPECT_EQ(Kinds("if a:\n    f(1,\n)\n    b\n"),
            "KEYWORD:if NAME:a OP:: NEWLINE INDENT NAME:f OP:( INT:1 OP:, OP:) NEWLINE NAME:b "
            "NEWLINE DEDENT EOF");
}

TEST(LangLexer, CrlfLineEndings) {
  EXPECT_EQ(Kinds("if a:\r\n    b\r\n"), "KEYWORD:if NAME:a OP:: NEWLINE INDENT NAME:b NEWLINE DEDENT EOF");
}

TEST(LangLexer, EndOfInputWithoutNewlineClosesLineAndBlocks) {
  EXPECT_EQ(Kinds("if a:\n  if b:\n    c"),
            "KEYWORD:if NAME:a OP:: NEWLINE INDENT KEYWORD:if NAME:b OP:: NEWLINE INDENT NAME:c "
            "NEWLINE DEDENT DEDENT EOF");
}

TEST(LangLexer, ErrorMessagesAndPositions) {
  struct Case {
    const char* src;
    const char* message;
    uint32_t line, column;
  };
  const Case cases[] = {
      {"x = 'abc\n", "unterminated string literal (detected at line 1)", 1, 5},
      {"x = '''abc\n\n", "unterminated triple-quoted string literal", 1, 5},
      {"x = f'{a}'\n", "f-strings are not supported in kernels", 1, 5},
      {"x = rb'a'\n", "bytes literals are not supported in kernels", 1, 5},
      {"x = 1j\n", "complex (imaginary) number literals are not supported", 1, 5},
      {"x = 007\n", "leading zeros in decimal integer literals are not permitted", 1, 5},
      {"x = 0b102\n", "invalid digit '2' in binary literal", 1, 9},
      {"x = 0o8\n", "invalid digit '8' in octal literal", 1, 7},
      {"x = 0x\n", "invalid hexadecimal literal", 1, 7},
      {"x = 0xfg\n", "invalid hexadecimal literal", 1, 8},
      {"x = 1_\n", "invalid decimal literal", 1, 6},
      {"x = 1__0\n", "invalid decimal literal", 1, 6},
      {"x = 1e\n", "invalid decimal literal", 1, 6},
      {"x = 1abc\n", "invalid decimal literal", 1, 6},
      {"x = 1._5\n", "invalid decimal literal", 1, 7},
      {"x = (1]\n", "closing parenthesis ']' does not match opening parenthesis '('", 1, 7},
      {"x = (1,\n 2]\n", "closing parenthesis ']' does not match opening parenthesis '(' on line 1", 2, 3},
      {"x = 1)\n", "unmatched ')'", 1, 6},
      {"x = f(1,\n", "'(' was never closed", 1, 6},
      {"x = 1 \\ 2\n", "unexpected character after line continuation character", 1, 7},
      {"x = a ? b\n", "invalid character '?'", 1, 7},
      {"x = a $ b\n", "invalid character '$'", 1, 7},
      {"x = a ! b\n", "invalid character '!'", 1, 7},
      {"x = '\\x4'\n", "truncated \\x escape", 1, 6},
      {"x = '\\N{DASH}'\n", "\\N{...} escapes are not supported", 1, 6},
      {"x = caf\xC3\xA9\n", "non-ASCII character outside a string or comment", 1, 8},
      {"if a:\n    b\n  c\n", "unindent does not match any outer indentation level", 3, 3},
      {"x = \"\\U00110000\"\n", "illegal Unicode character", 1, 6},
  };
  for (const Case& c : cases) {
    TextPosition at;
    const std::string msg = LexError(c.src, &at);
    EXPECT_NE(msg.find(c.message), std::string::npos) << c.src << " -> " << msg;
    EXPECT_EQ(at.line, c.line) << c.src << " -> " << msg;
    EXPECT_EQ(at.column, c.column) << c.src << " -> " << msg;
  }
}

TEST(LangLexer, ErrorsQuoteUserLineNumbers) {
  TextPosition at;
  std::vector<Token> before;
  auto toks = Tokenize("x = (1,\n 2]\n", &at, &before, 40);
  ASSERT_FALSE(toks.ok());
  EXPECT_NE(toks.status().message().find("on line 40"), std::string::npos) << toks.status().message();
  EXPECT_EQ(at.line, 2u);  // positions stay source-relative; the parser maps them
  ASSERT_GE(before.size(), 4u);
  EXPECT_EQ(before[0].text, "x");
}

TEST(LangLexer, FloatLiteralsMatchStrtod) {
  const char* cases[] = {"1.",   ".5",   "1.5",   "1e3",         "1E+3",   "2.5e-3", "1_0.0_1",
                         "0.0",  "00.5", "007e1", "1e400",       "1e-400", "4.9e-324",
                         "1.7976931348623157e308", "0.1",  "123456789012345678901234567890.0"};
  for (const char* c : cases) {
    const Token t = Single(c);
    ASSERT_EQ(t.kind, TokenKind::kFloat) << c;
    std::string plain;
    for (const char* p = c; *p; ++p) {
      if (*p != '_') plain.push_back(*p);
    }
    const double expect = std::strtod(plain.c_str(), nullptr);
    EXPECT_EQ(t.float_value, expect) << c;
    EXPECT_EQ(t.text, c);
  }
  EXPECT_TRUE(std::isinf(Single("1e400").float_value));
  EXPECT_EQ(Single("1e-400").float_value, 0.0);
}

TEST(LangLexer, IndentAndDedent) {
  EXPECT_EQ(Kinds("if a:\n    b\n    if c:\n        d\ne\n"),
            "KEYWORD:if NAME:a OP:: NEWLINE INDENT NAME:b NEWLINE KEYWORD:if NAME:c OP:: NEWLINE "
            "INDENT NAME:d NEWLINE DEDENT DEDENT NAME:e NEWLINE EOF");
}

TEST(LangLexer, IntLiteralsExactInEveryBase) {
  struct Case {
    const char* text;
    const char* decimal;
    bool fits;
  };
  const Case cases[] = {
      {"0", "0", true},
      {"000", "0", true},
      {"0_0", "0", true},
      {"42", "42", true},
      {"1_000_000", "1000000", true},
      {"0x2A", "42", true},
      {"0X_ff", "255", true},
      {"0o52", "42", true},
      {"0O_7_7", "63", true},
      {"0b101010", "42", true},
      {"0B_1_0", "2", true},
      {"2147483647", "2147483647", true},
      {"18446744073709551615", "18446744073709551615", true},
      {"0xFFFFFFFFFFFFFFFF", "18446744073709551615", true},
      {"18446744073709551616", "18446744073709551616", false},
      {"0x10000000000000000", "18446744073709551616", false},
      {"0x10000000000000000000000000", "1267650600228229401496703205376", false},  // 2**100
      {"0o7777777777777777777777777", "37778931862957161709567", false},        // 8**25-1
  };
  for (const Case& c : cases) {
    const Token t = Single(c.text);
    ASSERT_EQ(t.kind, TokenKind::kInt) << c.text;
    EXPECT_EQ(t.int_decimal, c.decimal) << c.text;
    EXPECT_EQ(t.int_fits_u64, c.fits) << c.text;
    if (c.fits) {
      EXPECT_EQ(std::to_string(t.int_value), c.decimal) << c.text;
    }
  }
}

TEST(LangLexer, KeywordsAndSoftKeywords) {
  EXPECT_EQ(Kinds("not x and True is None\n"),
            "KEYWORD:not NAME:x KEYWORD:and KEYWORD:True KEYWORD:is KEYWORD:None NEWLINE EOF");
  EXPECT_EQ(Kinds("match = type + case + _\n"),
            "NAME:match OP:= NAME:type OP:+ NAME:case OP:+ NAME:_ NEWLINE EOF");
}

TEST(LangLexer, OperatorsLongestMatch) {
  EXPECT_EQ(Kinds("a **= b //= c >>= d <<= e -> f := g ... h\n"),
            "NAME:a OP:**= NAME:b OP://= NAME:c OP:>>= NAME:d OP:<<= NAME:e OP:-> NAME:f OP::= "
            "NAME:g OP:... NAME:h NEWLINE EOF");
  EXPECT_EQ(Kinds("a**b//c<<d>>e<=f>=g==h!=i@j\n"),
            "NAME:a OP:** NAME:b OP:// NAME:c OP:<< NAME:d OP:>> NAME:e OP:<= NAME:f OP:>= NAME:g "
            "OP:== NAME:h OP:!= NAME:i OP:@ NAME:j NEWLINE EOF");
  EXPECT_EQ(Kinds("a+=1;b-=2;c*=3;d/=4;e%=5;f&=6;g|=7;h^=8;i@=9\n"),
            "NAME:a OP:+= INT:1 OP:; NAME:b OP:-= INT:2 OP:; NAME:c OP:*= INT:3 OP:; NAME:d OP:/= "
            "INT:4 OP:; NAME:e OP:%= INT:5 OP:; NAME:f OP:&= INT:6 OP:; NAME:g OP:|= INT:7 OP:; "
            "NAME:h OP:^= INT:8 OP:; NAME:i OP:@= INT:9 NEWLINE EOF");
  EXPECT_EQ(Kinds("v.x + 1 .real\n"), "NAME:v OP:. NAME:x OP:+ INT:1 OP:. NAME:real NEWLINE EOF");
}

TEST(LangLexer, PositionsCountCharactersNotBytes) {
  TextPosition err;
  auto toks = Tokenize("s = \"\xC3\xA9\xC3\xA9\" + x\n", &err);
  ASSERT_TRUE(toks.ok());
  ASSERT_GE(toks->size(), 5u);
  EXPECT_EQ((*toks)[4].text, "x");
  EXPECT_EQ((*toks)[4].pos.column, 12u);  // s,space,=,space,",é,é,",space,+,space -> 12
}

TEST(LangLexer, PositionsAfterTripleQuotedString) {
  TextPosition err;
  auto toks = Tokenize("a = '''x\ny\nz''' + b\nc\n", &err);
  ASSERT_TRUE(toks.ok());
  ASSERT_GE(toks->size(), 8u);
  EXPECT_EQ((*toks)[2].string_value, "x\ny\nz");
  EXPECT_EQ((*toks)[2].pos.line, 1u);
  EXPECT_EQ((*toks)[4].text, "b");
  EXPECT_EQ((*toks)[4].pos.line, 3u);
  EXPECT_EQ((*toks)[4].pos.column, 8u);
  EXPECT_EQ((*toks)[6].text, "c");
  EXPECT_EQ((*toks)[6].pos.line, 4u);
}

TEST(LangLexer, RandomFloatRoundTrips) {
  std::mt19937_64 rng(std::random_device{}());
  std::uniform_real_distribution<double> mant(-1.0, 1.0);
  std::uniform_int_distribution<int> exp(-300, 300);
  for (int i = 0; i < 2000; ++i) {
    const double v = std::fabs(std::ldexp(mant(rng), exp(rng)));
    char buf[64];
    std::snprintf(buf, sizeof(buf), "%.17g", v);
    std::string text = buf;
    if (text.find_first_of(".e") == std::string::npos) text += ".";
    const Token t = Single(text);
    ASSERT_EQ(t.kind, TokenKind::kFloat) << text;
    EXPECT_EQ(t.float_value, v) << text;
  }
}

TEST(LangLexer, RandomIntRoundTripsInEveryBase) {
  std::mt19937_64 rng(std::random_device{}());
  for (int i = 0; i < 2000; ++i) {
    const uint64_t v = rng() >> (rng() % 64);
    char buf[96];
    const int base = static_cast<int>(rng() % 4);
    if (base == 0) {
      std::snprintf(buf, sizeof(buf), "%" PRIu64, v);
    } else if (base == 1) {
      std::snprintf(buf, sizeof(buf), "0x%" PRIx64, v);
    } else if (base == 2) {
      std::snprintf(buf, sizeof(buf), "0o%" PRIo64, v);
    } else {
      std::string bits;
      for (uint64_t x = v; x; x >>= 1) bits.insert(bits.begin(), static_cast<char>('0' + (x & 1)));
      std::snprintf(buf, sizeof(buf), "0b%s", bits.empty() ? "0" : bits.c_str());
    }
    const Token t = Single(buf);
    ASSERT_EQ(t.kind, TokenKind::kInt) << buf;
    EXPECT_TRUE(t.int_fits_u64) << buf;
    EXPECT_EQ(t.int_value, v) << buf;
    EXPECT_EQ(t.int_decimal, std::to_string(v)) << buf;
  }
}

TEST(LangLexer, StringEscapesAndPrefixes) {
  EXPECT_EQ(Single(R"('a\tb\n\\\'\"')").string_value, "a\tb\n\\'\"");
  EXPECT_EQ(Single(R"("\x41\101\u00e9\U0001F600")").string_value, "AA\xC3\xA9\xF0\x9F\x98\x80");
  EXPECT_EQ(Single(R"('\a\b\f\v\r\0')").string_value, std::string("\a\b\f\v\r\0", 6));
  EXPECT_EQ(Single(R"('\q')").string_value, "\\q");  // unknown escapes kept, as in Python
  EXPECT_EQ(Single(R"(r'\n\'')").string_value, "\\n\\'");
  EXPECT_EQ(Single(R"(R"\d")").string_value, "\\d");
  EXPECT_EQ(Single(R"(u'x')").string_value, "x");
  EXPECT_EQ(Single("'a\\\nb'").string_value, "ab");
  EXPECT_EQ(Single("\"\"\"a\"b\"\"c\"\"\"").string_value, "a\"b\"\"c");
  EXPECT_EQ(Single("'%d %f\\n'").text, "'%d %f\\n'");
}

TEST(LangLexer, TabsIndentToMultiplesOfEight) {
  EXPECT_EQ(Kinds("if a:\n\tb\n        c\n"),
            "KEYWORD:if NAME:a OP:: NEWLINE INDENT NAME:b NEWLINE NAME:c NEWLINE DEDENT EOF");
}

TEST(LangLexer, TooManyNestedBrackets) {
  TextPosition at;
  const std::string msg = LexError("x = " + std::string(300, '(') + "1" + std::string(300, ')'), &at);
  EXPECT_NE(msg.find("too many nested parentheses"), std::string::npos) << msg;
}

}  // namespace
}  // namespace weft::lang
