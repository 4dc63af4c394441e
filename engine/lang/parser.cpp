// Recursive-descent parser for the kernel language (see parser.h). One function per grammar
// rule, the rule written above it; Python's precedence exactly. The first error stops the
// parse: every rule returns null after it, and ParseFunction turns it into one Diagnostic.
#include "engine/lang/parser.h"

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <set>
#include <string_view>

#include "engine/lang/ast_printer.h"
#include "engine/lang/lexer.h"

namespace weft::lang {
namespace {

// Stack the parser may use below ParseFunctionDef's frame, whatever the frame sizes of this
// build: deeper input is an error, so a thread with a small stack is still safe.
constexpr uintptr_t kStackBudgetBytes = 256 * 1024;
// Operators and trailers (`.x`, `(...)`, `[...]`) that wrap an already built operand, per
// statement. Chains like `a0 + a1 + ... + aN` are parsed by a loop, not by recursion, but the
// tree they build is N deep, and every later pass (the AST's own destructor included) walks
// it recursively: tree height <= this + the recursion depth, so it bounds them all.
constexpr int kMaxOperatorsPerStatement = 1000;
// elif branches of one if statement (each nests one level deeper in the tree).
constexpr int kMaxElifBranches = 500;

using ast::ExprPtr;
using ast::StmtPtr;

class Parser {
 public:
  Parser(const FunctionSource& fn, std::vector<Token> tokens, const ParseLimits& limits)
      : fn_(fn),
        tokens_(std::move(tokens)),
        max_block_depth_(limits.max_block_depth < kMaxBlockDepth ? limits.max_block_depth : kMaxBlockDepth),
        max_expression_depth_(limits.max_expression_depth < kMaxExpressionDepth ? limits.max_expression_depth
                                                                                 : kMaxExpressionDepth) {}

  bool failed() const { return failed_; }
  TextPosition error_pos() const { return error_pos_; }
  const std::string& error_message() const { return error_message_; }

  // function = decorator* "def" NAME "(" [params] ")" ["->" expression] ":" block EOF
  // decorator = "@" expression NEWLINE
  std::unique_ptr<ast::FunctionDef> ParseFunctionDef() {
    stack_base_ = reinterpret_cast<uintptr_t>(__builtin_frame_address(0));
    std::vector<std::string> decorators;
    while (IsOp("@")) {
      Next();
      std::string text;
      while (!IsKind(TokenKind::kNewline) && !IsKind(TokenKind::kEndOfFile)) text += Next().text;
      if (!ExpectKind(TokenKind::kNewline, "end of line after the decorator")) return nullptr;
      decorators.push_back(std::move(text));
    }
    if (IsKw("async")) return Fail(Peek(), "async functions are not supported in kernels");
    if (IsKw("class")) {
      return Fail(Peek(), "expected a function definition ('def'); classes are not kernels "
                          "(use @wp.struct for data types)");
    }
    if (!IsKw("def")) return Fail(Peek(), "expected 'def' at the start of the function source");
    auto fn = Make<ast::FunctionDef>(Next());
    fn->decorators = std::move(decorators);
    if (!IsKind(TokenKind::kName)) return Unexpected(Peek(), "a function name after 'def'");
    fn->name = Next().text;
    if (!ExpectOp("(", "'(' after the function name")) return nullptr;
    if (!ParseParams(fn.get())) return nullptr;
    if (!ExpectOp(")", "')' after the parameters")) return nullptr;
    if (AcceptOp("->")) {
      in_annotation_ = true;
      fn->returns = ParseExpression();
      in_annotation_ = false;
      if (!fn->returns) return nullptr;
    }
    if (!ExpectColon("function definition")) return nullptr;
    if (!ParseBlock(&fn->body, "function definition", fn->loc.line, &fn->docstring)) return nullptr;
    if (!IsKind(TokenKind::kEndOfFile)) {
      return Fail(Peek(), "unexpected code after the end of function '" + fn->name +
                              "' (send one function per FunctionSource)");
    }
    return fn;
  }

 private:
  bool in_annotation_ = false;   // parsing a parameter or return annotation
  // ---- token access ----------------------------------------------------------------------
  const Token& Peek(size_t ahead = 0) const {
    const size_t i = pos_ + ahead;
    return i < tokens_.size() ? tokens_[i] : tokens_.back();
  }
  const Token& Next() {
    const Token& t = Peek();
    if (pos_ + 1 < tokens_.size()) ++pos_;
    return t;
  }
  bool IsKind(TokenKind k, size_t ahead = 0) const { return Peek(ahead).kind == k; }
  bool IsOp(std::string_view op, size_t ahead = 0) const {
    return Peek(ahead).kind == TokenKind::kOperator && Peek(ahead).text == op;
  }
  bool IsKw(std::string_view kw, size_t ahead = 0) const {
    return Peek(ahead).kind == TokenKind::kKeyword && Peek(ahead).text == kw;
  }
  bool AcceptOp(std::string_view op) {
    if (!IsOp(op)) return false;
    Next();
    return true;
  }
  bool AcceptKw(std::string_view kw) {
    if (!IsKw(kw)) return false;
    Next();
    return true;
  }
  bool ExpectOp(std::string_view op, const char* what) {
    if (AcceptOp(op)) return true;
    Unexpected(Peek(), what);
    return false;
  }
  bool ExpectKind(TokenKind k, const char* what) {
    if (IsKind(k)) {
      Next();
      return true;
    }
    Unexpected(Peek(), what);
    return false;
  }
  // ":" at the end of a compound statement's header.
  bool ExpectColon(const char* construct) {
    if (AcceptOp(":")) return true;
    if (IsOp("=")) {
      Fail(Peek(), "invalid syntax: '=' in the " + std::string(construct) +
                       " (maybe you meant '==' instead of '=')");
      return false;
    }
    Unexpected(Peek(), (std::string("':' after the ") + construct).c_str());
    return false;
  }

  SourceLocation Loc(const Token& t) const {
    SourceLocation loc;
    loc.file = fn_.file;
    loc.line = fn_.first_line + t.pos.line - 1;
    loc.column = t.pos.column;
    return loc;
  }

  template <typename T>
  std::unique_ptr<T> Make(const Token& at) {
    auto n = std::make_unique<T>();
    n->loc = Loc(at);
    return n;
  }

  // ---- errors ------------------------------------------------------------------------------
  std::nullptr_t Fail(TextPosition pos, std::string message) {
    if (!failed_) {
      failed_ = true;
      error_pos_ = pos;
      error_message_ = std::move(message);
    }
    return nullptr;
  }
  std::nullptr_t Fail(const Token& t, std::string message) { return Fail(t.pos, std::move(message)); }

  static std::string Describe(const Token& t) {
    switch (t.kind) {
      case TokenKind::kNewline: return "end of line";
      case TokenKind::kEndOfFile: return "end of input";
      case TokenKind::kIndent: return "an indented line";
      case TokenKind::kDedent: return "the end of the indented block";
      case TokenKind::kString: return "string " + t.text;
      default: return "'" + t.text + "'";
    }
  }

  // A token that no rule accepts here: name the constructs we reject, else "expected X".
  std::nullptr_t Unexpected(const Token& t, const char* expected) {
    if (t.kind == TokenKind::kOperator) {
      if (t.text == ":=") return Fail(t, "the walrus operator ':=' is not supported in kernels");
    }
    if (t.kind == TokenKind::kKeyword) {
      if (t.text == "for") {
        return Fail(t, "comprehensions and generator expressions are not supported in kernels; "
                       "write a for loop");
      }
      if (t.text == "lambda") return RejectLambda(t);
      if (t.text == "yield") return RejectYield(t);
      if (t.text == "await") return Fail(t, "'await' is not supported in kernels");
    }
    if (t.kind == TokenKind::kIndent) return Fail(t, "unexpected indent");
    return Fail(t, std::string("invalid syntax: expected ") + expected + ", found " + Describe(t));
  }

  std::nullptr_t RejectLambda(const Token& t) {
    return Fail(t, "lambda expressions are not supported in kernels; define a @wp.func instead");
  }
  std::nullptr_t RejectYield(const Token& t) {
    return Fail(t, "'yield' is not supported in kernels (kernels and funcs cannot be generators)");
  }

  // Counts one operator that wraps an existing operand (see kMaxOperatorsPerStatement).
  bool CountOperator(const Token& at) {
    if (++operators_in_statement_ <= kMaxOperatorsPerStatement) return true;
    Fail(at, "expression too long: more than " + std::to_string(kMaxOperatorsPerStatement) +
                 " operators in one statement; split it into several statements");
    return false;
  }

  std::nullptr_t ExpressionTooDeep() {
    return Fail(Peek(), "expression too deeply nested (this daemon allows " + std::to_string(max_expression_depth_) +
                            " levels, its max_expression_depth)");
  }

  // Recursion guard for expressions and blocks, so hostile input cannot exhaust the stack.
  class DepthGuard {
   public:
    DepthGuard(int* depth, int limit, uintptr_t stack_base)
        : depth_(depth), over_(++*depth > limit || StackUsed(stack_base) > kStackBudgetBytes) {}
    ~DepthGuard() { --*depth_; }
    bool over() const { return over_; }

   private:
    static uintptr_t StackUsed(uintptr_t base) {
      const auto here = reinterpret_cast<uintptr_t>(__builtin_frame_address(0));
      return base > here ? base - here : here - base;
    }
    int* depth_;
    bool over_;
  };

  // ---- function header ---------------------------------------------------------------------

  // params = param ("," param)* [","]
  // param  = NAME [":" expression] ["=" expression]
  bool ParseParams(ast::FunctionDef* fn) {
    std::set<std::string> seen;
    bool saw_default = false;
    while (!IsOp(")")) {
      const Token& t = Peek();
      if (IsOp("*") || IsOp("**")) {
        Fail(t, "variadic parameters (*args, **kwargs) are not supported in kernels");
        return false;
      }
      if (IsOp("/")) {
        Fail(t, "positional-only parameter markers ('/') are not supported in kernels");
        return false;
      }
      if (!IsKind(TokenKind::kName)) {
        Unexpected(t, "a parameter name");
        return false;
      }
      ast::Param p;
      p.loc = Loc(t);
      p.name = Next().text;
      if (!seen.insert(p.name).second) {
        Fail(t, "duplicate argument '" + p.name + "' in function definition");
        return false;
      }
      if (AcceptOp(":")) {
        in_annotation_ = true;   // tuple[int, ...]: the Ellipsis is a name there
        p.annotation = ParseExpression();
        in_annotation_ = false;
        if (!p.annotation) return false;
      }
      if (AcceptOp("=")) {
        p.default_value = ParseExpression();
        if (!p.default_value) return false;
        saw_default = true;
      } else if (saw_default) {
        Fail(t, "parameter without a default follows parameter with a default");
        return false;
      }
      fn->params.push_back(std::move(p));
      if (!AcceptOp(",")) break;
    }
    return true;
  }

  // ---- statements --------------------------------------------------------------------------

  // block = NEWLINE INDENT statement+ DEDENT | simple_stmts
  // Bare string statements are dropped (the first of a function body is its docstring); a
  // block left empty by that gets a Pass.
  bool ParseBlock(ast::StmtList* out, const char* construct, uint32_t header_line,
                  std::string* docstring = nullptr) {
    DepthGuard guard(&block_depth_, max_block_depth_, stack_base_);
    if (guard.over()) {
      Fail(Peek(), "too many statically nested blocks (this daemon allows " + std::to_string(max_block_depth_) +
                       ", its max_block_depth)");
      return false;
    }
    const Token& first = Peek();
    if (IsKind(TokenKind::kNewline)) {
      Next();
      if (!IsKind(TokenKind::kIndent)) {
        Fail(Peek(), std::string("expected an indented block after ") + construct + " on line " +
                         std::to_string(header_line));
        return false;
      }
      Next();
      while (!IsKind(TokenKind::kDedent) && !IsKind(TokenKind::kEndOfFile)) {
        if (!ParseStatement(out)) return false;
      }
      if (!ExpectKind(TokenKind::kDedent, "the end of the block")) return false;
    } else {
      if (!ParseSimpleStatements(out)) return false;
    }
    bool first_stmt = true;
    for (auto it = out->begin(); it != out->end();) {
      const auto* es = ast::As<ast::ExprStmt>(it->get());
      const auto* c = es ? ast::As<ast::Constant>(es->value.get()) : nullptr;
      if (c && c->type == ast::Constant::Type::kString) {
        if (first_stmt && docstring) *docstring = c->string_value;
        it = out->erase(it);
      } else {
        ++it;
      }
      first_stmt = false;
    }
    if (out->empty()) out->push_back(Make<ast::Pass>(first));
    return true;
  }

  // statement = if_stmt | for_stmt | while_stmt | simple_stmts
  bool ParseStatement(ast::StmtList* out) {
    operators_in_statement_ = 0;
    const Token& t = Peek();
    if (t.kind == TokenKind::kIndent) {
      Fail(t, "unexpected indent");
      return false;
    }
    if (t.kind == TokenKind::kKeyword) {
      if (t.text == "if") return Push(out, ParseIf());
      if (t.text == "for") return Push(out, ParseFor());
      if (t.text == "while") return Push(out, ParseWhile());
      if (t.text == "def") {
        Fail(t, "nested function definitions are not supported in kernels; define a @wp.func at "
                "module level");
        return false;
      }
      if (t.text == "class") {
        Fail(t, "class definitions are not allowed inside kernels; use @wp.struct at module level");
        return false;
      }
      if (t.text == "with") {
        Fail(t, "'with' statements are not supported in kernels");
        return false;
      }
      if (t.text == "try" || t.text == "except" || t.text == "finally") {
        Fail(t, "exception handling ('" + t.text + "') is not supported in kernels");
        return false;
      }
      if (t.text == "async") {
        Fail(t, "'async' is not supported in kernels");
        return false;
      }
      if (t.text == "elif" || t.text == "else") {
        Fail(t, "invalid syntax: '" + t.text + "' without a matching 'if'");
        return false;
      }
    }
    if (IsOp("@")) {
      Fail(t, "decorators are not allowed inside kernels (nested functions are not supported)");
      return false;
    }
    return ParseSimpleStatements(out);
  }

  bool Push(ast::StmtList* out, StmtPtr s) {
    if (!s) return false;
    out->push_back(std::move(s));
    return true;
  }

  // simple_stmts = simple_stmt (";" simple_stmt)* [";"] NEWLINE
  bool ParseSimpleStatements(ast::StmtList* out) {
    while (true) {
      if (!Push(out, ParseSimpleStatement())) return false;
      if (AcceptOp(";")) {
        if (IsKind(TokenKind::kNewline)) break;
        continue;
      }
      break;
    }
    return ExpectKind(TokenKind::kNewline, "end of line after the statement");
  }

  // simple_stmt = "pass" | "break" | "continue" | return_stmt | assert_stmt
  //             | assignment | star_expressions
  StmtPtr ParseSimpleStatement() {
    const Token& t = Peek();
    if (t.kind == TokenKind::kKeyword) {
      if (t.text == "pass") return Next(), Make<ast::Pass>(t);
      if (t.text == "break" || t.text == "continue") {
        if (loop_depth_ == 0) return Fail(t, "'" + t.text + "' outside loop");
        Next();
        if (t.text == "break") return Make<ast::Break>(t);
        return Make<ast::Continue>(t);
      }
      if (t.text == "return") return ParseReturn();
      if (t.text == "assert") return ParseAssert();
      if (t.text == "del") return Fail(t, "'del' is not supported in kernels");
      if (t.text == "import" || t.text == "from") {
        return Fail(t, "import statements are not allowed inside kernels; import at module level");
      }
      if (t.text == "global" || t.text == "nonlocal") {
        return Fail(t, "'" + t.text + "' declarations are not supported in kernels");
      }
      if (t.text == "raise") return Fail(t, "'raise' is not supported in kernels (no exceptions)");
    }
    return ParseAssignmentOrExpression();
  }

  // return_stmt = "return" [star_expressions]
  StmtPtr ParseReturn() {
    auto r = Make<ast::Return>(Next());
    if (!IsKind(TokenKind::kNewline) && !IsOp(";")) {
      r->value = ParseStarExpressions();
      if (!r->value) return nullptr;
    }
    return r;
  }

  // assert_stmt = "assert" expression ["," expression]
  StmtPtr ParseAssert() {
    auto a = Make<ast::Assert>(Next());
    a->test = ParseExpression();
    if (!a->test) return nullptr;
    if (AcceptOp(",")) {
      a->msg = ParseExpression();
      if (!a->msg) return nullptr;
    }
    return a;
  }

  static bool IsAugAssignOp(const Token& t, ast::BinaryOperator* op) {
    if (t.kind != TokenKind::kOperator || t.text.size() < 2 || t.text.back() != '=') return false;
    const std::string_view s(t.text.data(), t.text.size() - 1);
#define WEFT_AUG_CASE(E, S, N)         \
  if (s == S) {                        \
    *op = ast::BinaryOperator::E;      \
    return true;                       \
  }
    WEFT_FOR_EACH_BINARY_OPERATOR(WEFT_AUG_CASE)
#undef WEFT_AUG_CASE
    return false;
  }

  // assignment = single_target ":" expression ["=" star_expressions]
  //            | (star_targets "=")+ star_expressions
  //            | single_target augassign star_expressions
  // expr_stmt  = star_expressions
  StmtPtr ParseAssignmentOrExpression() {
    const Token& start = Peek();
    ExprPtr first = ParseStarExpressions();
    if (!first) return nullptr;
    ast::BinaryOperator aug_op;
    if (IsOp(":")) {
      const Token& colon = Next();
      if (ast::As<ast::Tuple>(first.get())) {
        return Fail(start, "only single target (not tuple) can be annotated");
      }
      if (!IsSingleTarget(*first)) return Fail(start, "illegal target for annotation");
      auto s = Make<ast::AnnAssign>(start);
      s->target = std::move(first);
      s->annotation = ParseExpression();
      if (!s->annotation) return nullptr;
      (void)colon;
      if (AcceptOp("=")) {
        s->value = ParseStarExpressions();
        if (!s->value) return nullptr;
      }
      return s;
    }
    if (IsAugAssignOp(Peek(), &aug_op)) {
      const Token& op_tok = Next();
      if (!IsSingleTarget(*first)) {
        return Fail(start, "'" + TargetDescription(*first) +
                               "' is an illegal expression for augmented assignment");
      }
      auto s = Make<ast::AugAssign>(start);
      s->target = std::move(first);
      s->op = aug_op;
      s->op_loc = Loc(op_tok);
      s->value = ParseStarExpressions();
      if (!s->value) return nullptr;
      return s;
    }
    if (IsOp("=")) {
      auto s = Make<ast::Assign>(start);
      ExprPtr last = std::move(first);
      const Token* last_start = &start;
      while (AcceptOp("=")) {
        if (!CheckTarget(*last, *last_start)) return nullptr;
        s->targets.push_back(std::move(last));
        last_start = &Peek();
        if (IsKw("yield")) return RejectYield(Peek());
        last = ParseStarExpressions();
        if (!last) return nullptr;
      }
      s->value = std::move(last);
      return s;
    }
    auto s = Make<ast::ExprStmt>(start);
    s->value = std::move(first);
    return s;
  }

  static bool IsSingleTarget(const ast::Expr& e) {
    return e.kind == ast::ExprKind::kName || e.kind == ast::ExprKind::kAttribute ||
           e.kind == ast::ExprKind::kSubscript;
  }

  static std::string TargetDescription(const ast::Expr& e) {
    switch (e.kind) {
      case ast::ExprKind::kConstant: {
        const auto& c = static_cast<const ast::Constant&>(e);
        if (c.type == ast::Constant::Type::kBool) return c.bool_value ? "True" : "False";
        if (c.type == ast::Constant::Type::kNone) return "None";
        return "literal";
      }
      case ast::ExprKind::kCall: return "function call";
      case ast::ExprKind::kCompare: return "comparison";
      case ast::ExprKind::kIfExp: return "conditional expression";
      case ast::ExprKind::kTuple: return "tuple";
      case ast::ExprKind::kList: return "list";
      case ast::ExprKind::kName: return "name";
      case ast::ExprKind::kAttribute: return "attribute";
      case ast::ExprKind::kSubscript: return "subscript";
      default: return "expression";
    }
  }

  // target = NAME | primary "." NAME | primary "[" subscripts "]" | "(" targets ")" | "[" targets "]"
  bool CheckTarget(const ast::Expr& e, const Token& at) {
    if (IsSingleTarget(e)) return true;
    if (const auto* t = ast::As<ast::Tuple>(&e)) {
      for (const auto& elt : t->elts) {
        if (!CheckTarget(*elt, at)) return false;
      }
      return true;
    }
    if (const auto* l = ast::As<ast::List>(&e)) {
      for (const auto& elt : l->elts) {
        if (!CheckTarget(*elt, at)) return false;
      }
      return true;
    }
    TextPosition pos = at.pos;
    // Point at the offending sub-expression when it is not the whole target.
    pos.line = e.loc.line - fn_.first_line + 1;
    pos.column = e.loc.column;
    std::string msg = "cannot assign to " + TargetDescription(e);
    if (e.kind == ast::ExprKind::kCall || e.kind == ast::ExprKind::kConstant ||
        e.kind == ast::ExprKind::kBinOp || e.kind == ast::ExprKind::kCompare) {
      msg += " (maybe you meant '==' instead of '=')";
    }
    Fail(pos, std::move(msg));
    return false;
  }

  // if_stmt = "if" expression ":" block ("elif" expression ":" block)* ["else" ":" block]
  // Each elif is an If (is_elif) alone in the previous branch's orelse; the chain is parsed by
  // a loop and capped, since the tree it builds is as deep as the chain is long.
  StmtPtr ParseIf() {
    const Token& if_tok = Next();
    auto s = Make<ast::If>(if_tok);
    s->test = ParseExpression();
    if (!s->test) return nullptr;
    if (!ExpectColon("'if' condition")) return nullptr;
    if (!ParseBlock(&s->body, "'if' statement", s->loc.line)) return nullptr;
    ast::If* last = s.get();
    int elif_count = 0;
    while (IsKw("elif")) {
      const Token& elif_tok = Next();
      if (++elif_count > kMaxElifBranches) {
        return Fail(elif_tok, "too many 'elif' branches in one 'if' statement (more than " +
                                  std::to_string(kMaxElifBranches) + ")");
      }
      auto elif = Make<ast::If>(elif_tok);
      elif->is_elif = true;
      elif->test = ParseExpression();
      if (!elif->test) return nullptr;
      if (!ExpectColon("'elif' condition")) return nullptr;
      if (!ParseBlock(&elif->body, "'elif' statement", elif->loc.line)) return nullptr;
      ast::If* next = elif.get();
      last->orelse.push_back(std::move(elif));
      last = next;
    }
    if (IsKw("else")) {
      const Token& else_tok = Next();
      if (!ExpectColon("'else'")) return nullptr;
      if (!ParseBlock(&last->orelse, "'else' statement", else_tok.pos.line + fn_.first_line - 1)) {
        return nullptr;
      }
    }
    return s;
  }

  // for_stmt = "for" target_list "in" star_expressions ":" block
  // target_list = bitwise_or ("," bitwise_or)* [","]     (checked to be assignable)
  StmtPtr ParseFor() {
    const Token& for_tok = Next();
    auto s = Make<ast::For>(for_tok);
    const Token& target_tok = Peek();
    ExprPtr first = ParseBitwiseOr();
    if (!first) return nullptr;
    if (IsOp(",")) {
      auto tuple = Make<ast::Tuple>(target_tok);
      tuple->elts.push_back(std::move(first));
      while (AcceptOp(",")) {
        if (IsKw("in")) break;
        ExprPtr e = ParseBitwiseOr();
        if (!e) return nullptr;
        tuple->elts.push_back(std::move(e));
      }
      s->target = std::move(tuple);
    } else {
      s->target = std::move(first);
    }
    if (!CheckTarget(*s->target, target_tok)) return nullptr;
    if (!IsKw("in")) return Unexpected(Peek(), "'in' after the for-loop variable");
    Next();
    s->iter = ParseStarExpressions();
    if (!s->iter) return nullptr;
    if (!ExpectColon("'for' header")) return nullptr;
    ++loop_depth_;
    const bool body_ok = ParseBlock(&s->body, "'for' statement", s->loc.line);
    --loop_depth_;
    if (!body_ok) return nullptr;
    if (IsKw("else")) {
      return Fail(Peek(), "'else' clauses on 'for' loops are not supported in kernels");
    }
    return s;
  }

  // while_stmt = "while" expression ":" block
  StmtPtr ParseWhile() {
    auto s = Make<ast::While>(Next());
    s->test = ParseExpression();
    if (!s->test) return nullptr;
    if (!ExpectColon("'while' condition")) return nullptr;
    ++loop_depth_;
    const bool body_ok = ParseBlock(&s->body, "'while' statement", s->loc.line);
    --loop_depth_;
    if (!body_ok) return nullptr;
    if (IsKw("else")) {
      return Fail(Peek(), "'else' clauses on 'while' loops are not supported in kernels");
    }
    return s;
  }

  // ---- expressions -------------------------------------------------------------------------

  // Can `t` begin an expression? (Decides whether a trailing comma ends a tuple.)
  static bool StartsExpression(const Token& t) {
    switch (t.kind) {
      case TokenKind::kName:
      case TokenKind::kInt:
      case TokenKind::kFloat:
      case TokenKind::kString:
        return true;
      case TokenKind::kKeyword:
        return t.text == "True" || t.text == "False" || t.text == "None" || t.text == "not" ||
               t.text == "lambda" || t.text == "await" || t.text == "yield";
      case TokenKind::kOperator:
        return t.text == "(" || t.text == "[" || t.text == "{" || t.text == "-" ||
               t.text == "+" || t.text == "~" || t.text == "*" || t.text == "**" ||
               t.text == "...";
      default:
        return false;
    }
  }

  // star_expressions = expression ("," expression)* [","]   (a Tuple when a comma appears)
  ExprPtr ParseStarExpressions() {
    const Token& start = Peek();
    ExprPtr first = ParseExpression();
    if (!first) return nullptr;
    if (!IsOp(",")) return first;
    auto tuple = Make<ast::Tuple>(start);
    tuple->elts.push_back(std::move(first));
    while (AcceptOp(",")) {
      if (!StartsExpression(Peek())) break;
      ExprPtr e = ParseExpression();
      if (!e) return nullptr;
      tuple->elts.push_back(std::move(e));
    }
    return tuple;
  }

  // expression = disjunction ["if" disjunction "else" expression] | lambda (rejected)
  ExprPtr ParseExpression() {
    DepthGuard guard(&expr_depth_, max_expression_depth_, stack_base_);
    if (guard.over()) return ExpressionTooDeep();
    if (IsKw("lambda")) return RejectLambda(Peek());
    if (IsKw("yield")) return RejectYield(Peek());
    if (IsOp("*") || IsOp("**")) {
      return Fail(Peek(), "starred expressions (*x) are not supported in kernels");
    }
    ExprPtr body = ParseDisjunction();
    if (!body) return nullptr;
    if (!IsKw("if")) return body;
    Next();
    auto e = std::make_unique<ast::IfExp>();
    e->loc = body->loc;
    e->body = std::move(body);
    e->test = ParseDisjunction();
    if (!e->test) return nullptr;
    if (!IsKw("else")) return Fail(Peek(), "expected 'else' after 'if' expression");
    Next();
    e->orelse = ParseExpression();
    if (!e->orelse) return nullptr;
    return e;
  }

  // disjunction = conjunction ("or" conjunction)*
  // conjunction = inversion ("and" inversion)*
  ExprPtr ParseBoolOp(bool is_or) {
    ExprPtr first = is_or ? ParseBoolOp(false) : ParseInversion();
    if (!first) return nullptr;
    const char* kw = is_or ? "or" : "and";
    if (!IsKw(kw)) return first;
    auto e = std::make_unique<ast::BoolOp>();
    e->loc = first->loc;
    e->op = is_or ? ast::BoolOperator::kOr : ast::BoolOperator::kAnd;
    e->values.push_back(std::move(first));
    while (AcceptKw(kw)) {
      ExprPtr v = is_or ? ParseBoolOp(false) : ParseInversion();
      if (!v) return nullptr;
      e->values.push_back(std::move(v));
    }
    return e;
  }
  ExprPtr ParseDisjunction() { return ParseBoolOp(true); }

  // inversion = "not" inversion | comparison
  ExprPtr ParseInversion() {
    if (!IsKw("not")) return ParseComparison();
    DepthGuard guard(&expr_depth_, max_expression_depth_, stack_base_);
    if (guard.over()) return ExpressionTooDeep();
    auto e = Make<ast::UnaryOp>(Next());
    e->op = ast::UnaryOperator::kNot;
    e->operand = ParseInversion();
    if (!e->operand) return nullptr;
    return e;
  }

  // comp_op = "==" | "!=" | "<" | "<=" | ">" | ">=" | "in" | "not" "in" | "is" | "is" "not"
  bool AcceptCompareOp(ast::CompareOperator* op) {
    const Token& t = Peek();
    if (t.kind == TokenKind::kOperator) {
      if (t.text == "==") *op = ast::CompareOperator::kEq;
      else if (t.text == "!=") *op = ast::CompareOperator::kNotEq;
      else if (t.text == "<") *op = ast::CompareOperator::kLt;
      else if (t.text == "<=") *op = ast::CompareOperator::kLtE;
      else if (t.text == ">") *op = ast::CompareOperator::kGt;
      else if (t.text == ">=") *op = ast::CompareOperator::kGtE;
      else return false;
      Next();
      return true;
    }
    if (IsKw("in")) {
      Next();
      *op = ast::CompareOperator::kIn;
      return true;
    }
    if (IsKw("not") && IsKw("in", 1)) {
      Next();
      Next();
      *op = ast::CompareOperator::kNotIn;
      return true;
    }
    if (IsKw("is")) {
      Next();
      *op = AcceptKw("not") ? ast::CompareOperator::kIsNot : ast::CompareOperator::kIs;
      return true;
    }
    return false;
  }

  // comparison = bitwise_or (comp_op bitwise_or)*
  ExprPtr ParseComparison() {
    ExprPtr first = ParseBitwiseOr();
    if (!first) return nullptr;
    ast::CompareOperator op;
    if (!AcceptCompareOp(&op)) return first;
    auto e = std::make_unique<ast::Compare>();
    e->loc = first->loc;
    e->left = std::move(first);
    do {
      ExprPtr right = ParseBitwiseOr();
      if (!right) return nullptr;
      e->ops.push_back(op);
      e->comparators.push_back(std::move(right));
    } while (AcceptCompareOp(&op));
    return e;
  }

  // The binary levels between comparison and factor, all left-associative (loosest first):
  //   bitwise_or  = bitwise_xor ("|" bitwise_xor)*
  //   bitwise_xor = bitwise_and ("^" bitwise_and)*
  //   bitwise_and = shift_expr ("&" shift_expr)*
  //   shift_expr  = sum (("<<" | ">>") sum)*
  //   sum         = term (("+" | "-") term)*
  //   term        = factor (("*" | "/" | "//" | "%" | "@") factor)*
  // parsed by precedence climbing, one stack frame per operand instead of one per level.
  static int BinaryLevel(const Token& t, ast::BinaryOperator* op) {
    if (t.kind != TokenKind::kOperator) return 0;
    struct Row {
      const char* spelling;
      ast::BinaryOperator op;
      int level;
    };
    static const Row kRows[] = {
        {"|", ast::BinaryOperator::kBitOr, 1},      {"^", ast::BinaryOperator::kBitXor, 2},
        {"&", ast::BinaryOperator::kBitAnd, 3},     {"<<", ast::BinaryOperator::kLShift, 4},
        {">>", ast::BinaryOperator::kRShift, 4},    {"+", ast::BinaryOperator::kAdd, 5},
        {"-", ast::BinaryOperator::kSub, 5},        {"*", ast::BinaryOperator::kMul, 6},
        {"/", ast::BinaryOperator::kDiv, 6},        {"//", ast::BinaryOperator::kFloorDiv, 6},
        {"%", ast::BinaryOperator::kMod, 6},        {"@", ast::BinaryOperator::kMatMul, 6},
    };
    for (const Row& r : kRows) {
      if (t.text == r.spelling) {
        *op = r.op;
        return r.level;
      }
    }
    return 0;
  }

  // Operands joined by binary operators of level >= min_level.
  ExprPtr ParseBinary(int min_level) {
    ExprPtr left = ParseFactor();
    if (!left) return nullptr;
    while (true) {
      ast::BinaryOperator op;
      const int level = BinaryLevel(Peek(), &op);
      if (level == 0 || level < min_level) return left;
      if (!CountOperator(Peek())) return nullptr;
      const Token& op_tok = Next();
      auto e = std::make_unique<ast::BinOp>();
      e->loc = left->loc;
      e->op = op;
      e->op_loc = Loc(op_tok);
      e->left = std::move(left);
      e->right = ParseBinary(level + 1);  // left-associative: the right operand binds tighter
      if (!e->right) return nullptr;
      left = std::move(e);
    }
  }

  // bitwise_or (the loosest binary level; also the for-loop target's level)
  ExprPtr ParseBitwiseOr() { return ParseBinary(1); }

  // factor = ("+" | "-" | "~") factor | power
  ExprPtr ParseFactor() {
    DepthGuard guard(&expr_depth_, max_expression_depth_, stack_base_);
    if (guard.over()) return ExpressionTooDeep();
    ast::UnaryOperator op;
    if (IsOp("+")) op = ast::UnaryOperator::kPlus;
    else if (IsOp("-")) op = ast::UnaryOperator::kMinus;
    else if (IsOp("~")) op = ast::UnaryOperator::kInvert;
    else return ParsePower();
    auto e = Make<ast::UnaryOp>(Next());
    e->op = op;
    e->operand = ParseFactor();
    if (!e->operand) return nullptr;
    return e;
  }

  // power = primary ["**" factor]        (right-associative; binds tighter than a unary
  //                                       operator on its left: -x**2 == -(x**2))
  ExprPtr ParsePower() {
    if (IsKw("await")) return Fail(Peek(), "'await' is not supported in kernels");
    ExprPtr base = ParsePrimary();
    if (!base) return nullptr;
    if (!IsOp("**")) return base;
    const Token& op_tok = Next();
    auto e = std::make_unique<ast::BinOp>();
    e->loc = base->loc;
    e->op = ast::BinaryOperator::kPow;
    e->op_loc = Loc(op_tok);
    e->left = std::move(base);
    e->right = ParseFactor();
    if (!e->right) return nullptr;
    return e;
  }

  // primary = atom ("." NAME | "(" [arguments] ")" | "[" subscripts "]")*
  ExprPtr ParsePrimary() {
    ExprPtr e = ParseAtom();
    while (e) {
      if ((IsOp(".") || IsOp("(") || IsOp("[")) && !CountOperator(Peek())) return nullptr;
      if (IsOp(".")) {
        Next();
        if (!IsKind(TokenKind::kName)) return Unexpected(Peek(), "an attribute name after '.'");
        const Token& name = Next();
        auto a = std::make_unique<ast::Attribute>();
        a->loc = e->loc;
        a->value = std::move(e);
        a->attr = name.text;
        a->attr_loc = Loc(name);
        e = std::move(a);
      } else if (IsOp("(")) {
        Next();
        auto c = std::make_unique<ast::Call>();
        c->loc = e->loc;
        c->func = std::move(e);
        if (!ParseArguments(c.get())) return nullptr;
        e = std::move(c);
      } else if (IsOp("[")) {
        Next();
        auto s = std::make_unique<ast::Subscript>();
        s->loc = e->loc;
        s->value = std::move(e);
        if (!ParseSubscripts(s.get())) return nullptr;
        e = std::move(s);
      } else {
        break;
      }
    }
    return e;
  }

  // arguments = argument ("," argument)* [","]
  // argument  = NAME "=" expression | expression
  bool ParseArguments(ast::Call* call) {
    std::set<std::string> keywords;
    while (!IsOp(")")) {
      const Token& t = Peek();
      if (IsOp("**")) {
        Fail(t, "keyword argument unpacking (**kwargs) is not supported in kernels");
        return false;
      }
      if (IsOp("*")) {
        if (!call->keywords.empty()) {
          Fail(t, "iterable argument unpacking follows keyword argument");
          return false;
        }
        Next();
        auto star = Make<ast::Starred>(t);
        star->value = ParseExpression();
        if (!star->value) return false;
        call->args.push_back(std::move(star));
        if (!AcceptOp(",")) break;
        continue;
      }
      if (t.kind == TokenKind::kName && IsOp("=", 1)) {
        Next();
        Next();
        ast::Keyword kw;
        kw.loc = Loc(t);
        kw.name = t.text;
        if (!keywords.insert(kw.name).second) {
          Fail(t, "keyword argument repeated: " + kw.name);
          return false;
        }
        kw.value = ParseExpression();
        if (!kw.value) return false;
        call->keywords.push_back(std::move(kw));
      } else {
        if (!call->keywords.empty()) {
          Fail(t, "positional argument follows keyword argument");
          return false;
        }
        ExprPtr arg = ParseExpression();
        if (!arg) return false;
        if (IsKw("for")) {
          Unexpected(Peek(), "");
          return false;
        }
        call->args.push_back(std::move(arg));
      }
      if (!AcceptOp(",")) break;
    }
    return ExpectOp(")", "',' or ')' in the argument list");
  }

  // subscripts = subscript ("," subscript)* [","]
  // subscript  = expression | [expression] ":" [expression] [":" [expression]]
  bool ParseSubscripts(ast::Subscript* sub) {
    if (IsOp("]")) {
      Fail(Peek(), "expected an index inside '[]'");
      return false;
    }
    while (!IsOp("]")) {
      const Token& t = Peek();
      ExprPtr lower;
      if (!IsOp(":")) {
        lower = ParseExpression();
        if (!lower) return false;
      }
      if (IsOp(":")) {
        auto slice = Make<ast::Slice>(t);
        slice->lower = std::move(lower);
        Next();
        if (!IsOp(":") && !IsOp(",") && !IsOp("]")) {
          slice->upper = ParseExpression();
          if (!slice->upper) return false;
        }
        if (AcceptOp(":")) {
          if (!IsOp(",") && !IsOp("]")) {
            slice->step = ParseExpression();
            if (!slice->step) return false;
          }
        }
        sub->indices.push_back(std::move(slice));
      } else {
        sub->indices.push_back(std::move(lower));
      }
      if (!AcceptOp(",")) break;
    }
    return ExpectOp("]", "',' or ']' after the index");
  }

  // atom = NAME | "True" | "False" | "None" | NUMBER | STRING+
  //      | "(" [star_expressions] ")" | "[" [expression ("," expression)* [","]] "]"
  ExprPtr ParseAtom() {
    const Token& t = Peek();
    switch (t.kind) {
      case TokenKind::kName: {
        auto n = Make<ast::Name>(Next());
        n->id = t.text;
        return n;
      }
      case TokenKind::kInt: {
        auto c = Make<ast::Constant>(Next());
        c->type = ast::Constant::Type::kInt;
        c->text = t.text;
        c->int_decimal = t.int_decimal;
        c->int_value = t.int_value;
        c->int_fits_u64 = t.int_fits_u64;
        return c;
      }
      case TokenKind::kFloat: {
        auto c = Make<ast::Constant>(Next());
        c->type = ast::Constant::Type::kFloat;
        c->text = t.text;
        c->float_value = t.float_value;
        return c;
      }
      case TokenKind::kString: {
        auto c = Make<ast::Constant>(Next());
        c->type = ast::Constant::Type::kString;
        c->text = t.text;
        c->string_value = t.string_value;
        while (IsKind(TokenKind::kString)) {  // adjacent literals are joined, as in Python
          const Token& more = Next();
          c->text += " " + more.text;
          c->string_value += more.string_value;
        }
        return c;
      }
      case TokenKind::kKeyword: {
        if (t.text == "True" || t.text == "False" || t.text == "None") {
          auto c = Make<ast::Constant>(Next());
          c->text = t.text;
          c->type = t.text == "None" ? ast::Constant::Type::kNone : ast::Constant::Type::kBool;
          c->bool_value = t.text == "True";
          return c;
        }
        if (t.text == "lambda") return RejectLambda(t);
        if (t.text == "yield") return RejectYield(t);
        return Unexpected(t, "an expression");
      }
      case TokenKind::kOperator: {
        if (t.text == "(") return ParseParenthesized();
        if (t.text == "[") return ParseList();
        if (t.text == "{") return Fail(t, "dict and set literals are not supported in kernels");
        if (t.text == "..." && in_annotation_) {
          auto n = Make<ast::Name>(Next());
          n->id = "Ellipsis";
          return n;
        }
        if (t.text == "...") return Fail(t, "'...' (Ellipsis) is not supported in kernels");
        return Unexpected(t, "an expression");
      }
      default:
        return Unexpected(t, "an expression");
    }
  }

  // "(" ")" | "(" expression ")" | "(" expression "," [star_expressions] ")"
  ExprPtr ParseParenthesized() {
    const Token& open = Next();
    if (AcceptOp(")")) {
      auto t = Make<ast::Tuple>(open);
      t->parenthesized = true;
      return t;
    }
    if (IsKw("yield")) return RejectYield(Peek());
    ExprPtr first = ParseExpression();
    if (!first) return nullptr;
    if (IsOp(")")) {
      Next();
      return first;
    }
    if (IsKw("for")) return Unexpected(Peek(), "");
    if (!IsOp(",")) return Unexpected(Peek(), "',' or ')'");
    auto tuple = Make<ast::Tuple>(open);
    tuple->parenthesized = true;
    tuple->elts.push_back(std::move(first));
    while (AcceptOp(",")) {
      if (IsOp(")")) break;
      ExprPtr e = ParseExpression();
      if (!e) return nullptr;
      tuple->elts.push_back(std::move(e));
    }
    if (!ExpectOp(")", "',' or ')' in the tuple")) return nullptr;
    return tuple;
  }

  // "[" [expression ("," expression)* [","]] "]"
  ExprPtr ParseList() {
    auto list = Make<ast::List>(Next());
    while (!IsOp("]")) {
      ExprPtr e = ParseExpression();
      if (!e) return nullptr;
      if (IsKw("for")) return Unexpected(Peek(), "");
      list->elts.push_back(std::move(e));
      if (!AcceptOp(",")) break;
    }
    if (!ExpectOp("]", "',' or ']' in the list")) return nullptr;
    return list;
  }

  const FunctionSource& fn_;
  std::vector<Token> tokens_;
  size_t pos_ = 0;
  const int max_block_depth_;
  const int max_expression_depth_;
  int expr_depth_ = 0;
  int block_depth_ = 0;
  int loop_depth_ = 0;  // enclosing for/while loops, for "'break' outside loop"
  uintptr_t stack_base_ = 0;
  int operators_in_statement_ = 0;
  bool failed_ = false;
  TextPosition error_pos_;
  std::string error_message_;
};

// Text of 1-based line `line` of `source`, without its line break.
std::string SourceLine(std::string_view source, uint32_t line) {
  size_t start = 0;
  for (uint32_t l = 1; l < line; ++l) {
    const size_t nl = source.find('\n', start);
    if (nl == std::string_view::npos) return "";
    start = nl + 1;
  }
  size_t end = source.find('\n', start);
  if (end == std::string_view::npos) end = source.size();
  std::string text(source.substr(start, end - start));
  if (!text.empty() && text.back() == '\r') text.pop_back();
  return text;
}

Status Report(const FunctionSource& fn, TextPosition pos, const std::string& message,
              std::vector<Diagnostic>* diags) {
  Diagnostic d;
  d.severity = Diagnostic::Severity::kError;
  d.message = message;
  d.location.file = fn.file;
  // An error at the very end of the input points at the last line that has text.
  uint32_t line = pos.line ? pos.line : 1;
  uint32_t column = pos.column;
  std::string text = SourceLine(fn.source, line);
  if (text.empty() && line > 1) {
    uint32_t prev = line - 1;
    while (prev > 1 && SourceLine(fn.source, prev).find_first_not_of(" \t") == std::string::npos) --prev;
    text = SourceLine(fn.source, prev);
    line = prev;
    column = 1;
    for (char c : text) {
      if ((static_cast<unsigned char>(c) & 0xC0) != 0x80) ++column;
    }
  }
  d.location.line = fn.first_line + line - 1;
  d.location.column = column;
  d.source_line = std::move(text);
  std::string formatted = d.ToString();
  if (diags) diags->push_back(std::move(d));
  return InvalidArgument(std::move(formatted));
}

}  // namespace

Expected<std::unique_ptr<ast::FunctionDef>> ParseFunction(const FunctionSource& fn,
                                                          std::vector<Diagnostic>* diags,
                                                          const ParseLimits& limits) {
  TextPosition lex_error;
  std::vector<Token> partial;
  auto tokens = Tokenize(fn.source, &lex_error, &partial, fn.first_line);
  if (!tokens.ok()) {
    // Report a syntax error that comes before the lexical one first (Python's order): parse
    // the tokens scanned so far, ended by an end-of-input marker at the lexical error.
    Token end;
    end.kind = TokenKind::kEndOfFile;
    end.pos = lex_error;
    partial.push_back(end);
    Parser early(fn, std::move(partial), limits);
    (void)early.ParseFunctionDef();
    const TextPosition p = early.error_pos();
    if (early.failed() &&
        (p.line < lex_error.line || (p.line == lex_error.line && p.column < lex_error.column))) {
      return Report(fn, p, early.error_message(), diags);
    }
    return Report(fn, lex_error, tokens.status().message(), diags);
  }
  Parser parser(fn, std::move(tokens).value(), limits);
  auto def = parser.ParseFunctionDef();
  if (parser.failed() || !def) {
    return Report(fn, parser.error_pos(), parser.error_message(), diags);
  }
  if (const char* dump = std::getenv("WEFT_DUMP_AST"); dump && *dump && *dump != '0') {
    std::fprintf(stderr, "// WEFT_DUMP_AST %s:%u\n%s", fn.file.c_str(), fn.first_line,
                 PrintFunction(*def).c_str());
  }
  return std::unique_ptr<ast::FunctionDef>(std::move(def));
}

}  // namespace weft::lang
