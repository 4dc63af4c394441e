// Native library: wp.expect_eq / expect_neq / expect_near. A failed expectation records a
// LAUNCH_EXPECT_FAILED error (first error of the launch wins, launch_abi.h) whose message shows
// both values, e.g. "expect_eq(1 2 3, 1 2 4)"; the kernel goes on (as in Warp). On a GPU the
// values travel as a print record in the error's message, formatted by the daemon at the
// synchronize (a record too long for it is printed to the kernel's output instead).
// expect_*(ctx, a, b) has no location; the code generator emits expect_*_at(ctx, function_id,
// line, a, b) so the error names the user's line.
#pragma once

#include "print.h"

namespace wp {

template <typename A, typename B>
WP_FUNC void expect_report(const launch_context_t* ctx, int32 function_id, int32 line, const char* what, const A& a, const B& b) {
  print_line l;
  l.add("%s", what);   // a string goes alone in its piece (GPU print records)
  l.add("(");
  print_value(l, a);
  l.add(", ");
  print_value(l, b);
  l.add(")");
#if WP_DEVICE_CODE
  if (!report_error(ctx, LAUNCH_EXPECT_FAILED, function_id, line, -1, 0, nullptr, nullptr, nullptr)) return;
  char* m = ctx->error->message;
  const int n = l.rec.size();
  if (!l.rec.full && n < (int)sizeof(ctx->error->message)) {
    const char* rec = l.rec.bytes();
    m[0] = EXPECT_RECORD;
    for (int i = 0; i < n; ++i) m[1 + i] = rec[i];
  } else {
    m[0] = EXPECT_IN_OUTPUT;
    l.add(" failed at line %d\n", line);
    l.flush(ctx);
  }
#else
  report_error(ctx, LAUNCH_EXPECT_FAILED, function_id, line, -1, 0, nullptr, nullptr, l.text());
#endif
}

// Component-wise |a - b| <= tol (NaN never passes).
template <typename T> WP_FUNC bool near_ok(T a, T b, T tol) { return abs(T(a - b)) <= tol; }
template <unsigned N, typename T> WP_FUNC bool near_ok(const vec_t<N, T>& a, const vec_t<N, T>& b, T tol) {
  for (unsigned i = 0; i < N; ++i)
    if (!near_ok(a.c[i], b.c[i], tol)) return false;
  return true;
}
template <unsigned R, unsigned C, typename T> WP_FUNC bool near_ok(const mat_t<R, C, T>& a, const mat_t<R, C, T>& b, T tol) {
  for (unsigned i = 0; i < R; ++i)
    for (unsigned j = 0; j < C; ++j)
      if (!near_ok(a.data[i][j], b.data[i][j], tol)) return false;
  return true;
}
template <typename T> WP_FUNC bool near_ok(const quat_t<T>& a, const quat_t<T>& b, T tol) {
  for (int i = 0; i < 4; ++i)
    if (!near_ok(a[i], b[i], tol)) return false;
  return true;
}

template <typename A, typename B>
WP_FUNC void expect_eq_at(const launch_context_t* ctx, int32 function_id, int32 line, const A& a, const B& b) {
  if (!(a == b)) expect_report(ctx, function_id, line, "expect_eq", a, b);
}
template <typename A, typename B>
WP_FUNC void expect_neq_at(const launch_context_t* ctx, int32 function_id, int32 line, const A& a, const B& b) {
  if (a == b) expect_report(ctx, function_id, line, "expect_neq", a, b);
}
template <typename A, typename T>
WP_FUNC void expect_near_at(const launch_context_t* ctx, int32 function_id, int32 line, const A& a, const A& b, T tol) {
  if (!near_ok(a, b, tol)) expect_report(ctx, function_id, line, "expect_near", a, b);
}
// expect_near(a, b) without a tolerance: Warp's default, 1e-6 (in the scalar type of a).
template <typename T> WP_FUNC T near_default_tol(const T&) { return T(1.0e-6f); }
template <unsigned N, typename T> WP_FUNC T near_default_tol(const vec_t<N, T>&) { return T(1.0e-6f); }
template <unsigned R, unsigned C, typename T> WP_FUNC T near_default_tol(const mat_t<R, C, T>&) { return T(1.0e-6f); }
template <typename T> WP_FUNC T near_default_tol(const quat_t<T>&) { return T(1.0e-6f); }
template <typename A>
WP_FUNC void expect_near_at(const launch_context_t* ctx, int32 function_id, int32 line, const A& a, const A& b) {
  expect_near_at(ctx, function_id, line, a, b, near_default_tol(a));
}
template <typename A> WP_FUNC void expect_near(const launch_context_t* ctx, const A& a, const A& b) {
  expect_near_at(ctx, -1, 0, a, b, near_default_tol(a));
}
template <typename A, typename B>
WP_FUNC void expect_eq(const launch_context_t* ctx, const A& a, const B& b) { expect_eq_at(ctx, -1, 0, a, b); }
template <typename A, typename B>
WP_FUNC void expect_neq(const launch_context_t* ctx, const A& a, const B& b) { expect_neq_at(ctx, -1, 0, a, b); }
template <typename A, typename T>
WP_FUNC void expect_near(const launch_context_t* ctx, const A& a, const A& b, T tol) { expect_near_at(ctx, -1, 0, a, b, tol); }

// Not differentiable: adjoints are no-ops.
template <typename... A> WP_FUNC void adj_expect_eq(A&&...) {}
template <typename... A> WP_FUNC void adj_expect_neq(A&&...) {}
template <typename... A> WP_FUNC void adj_expect_near(A&&...) {}

}  // namespace wp
