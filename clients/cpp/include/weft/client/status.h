// Errors as values for the C++ client: Status (ok, or a code + message) and Expected<T> (a value
// or the Status explaining why there is none). The client's twin of engine/core/status.h, so
// that libweft-client never links the engine: same codes (gRPC's numbering), same API.
// Everything lives in the inline namespace weft::client_v1, so the two twins never collide at
// link time; a translation unit that includes both must spell weft::client_v1::Status.
#pragma once

#include <string>
#include <utility>
#include <variant>

namespace weft {
inline namespace client_v1 {

// gRPC status codes, by value.
enum class StatusCode {
  kOk = 0,
  kCancelled = 1,
  kUnknown = 2,
  kInvalidArgument = 3,
  kDeadlineExceeded = 4,
  kNotFound = 5,
  kAlreadyExists = 6,
  kPermissionDenied = 7,
  kResourceExhausted = 8,
  kFailedPrecondition = 9,
  kAborted = 10,
  kOutOfRange = 11,
  kUnimplemented = 12,
  kInternal = 13,
  kUnavailable = 14,
  kDataLoss = 15,
  kUnauthenticated = 16,
};

// "INVALID_ARGUMENT" for kInvalidArgument, and so on.
const char* StatusCodeName(StatusCode code);

class [[nodiscard]] Status {
 public:
  Status() = default;
  Status(StatusCode code, std::string message) : code_(code), message_(std::move(message)) {}
  static Status Ok() { return {}; }

  bool ok() const { return code_ == StatusCode::kOk; }
  StatusCode code() const { return code_; }
  const std::string& message() const { return message_; }
  // "OK" or "CODE: message".
  std::string ToString() const;

 private:
  StatusCode code_ = StatusCode::kOk;
  std::string message_;
};

inline Status InvalidArgument(std::string m) { return {StatusCode::kInvalidArgument, std::move(m)}; }
inline Status NotFound(std::string m) { return {StatusCode::kNotFound, std::move(m)}; }
inline Status OutOfRange(std::string m) { return {StatusCode::kOutOfRange, std::move(m)}; }
inline Status FailedPrecondition(std::string m) { return {StatusCode::kFailedPrecondition, std::move(m)}; }
inline Status Internal(std::string m) { return {StatusCode::kInternal, std::move(m)}; }
inline Status Unavailable(std::string m) { return {StatusCode::kUnavailable, std::move(m)}; }
inline Status DataLoss(std::string m) { return {StatusCode::kDataLoss, std::move(m)}; }

// A value of T, or the Status explaining why there is none.
template <typename T>
class [[nodiscard]] Expected {
 public:
  Expected(T value) : v_(std::move(value)) {}          // NOLINT: implicit by design
  Expected(Status status) : v_(std::move(status)) {}   // NOLINT: must not be ok()

  bool ok() const { return v_.index() == 0; }
  explicit operator bool() const { return ok(); }
  const Status& status() const {
    static const Status kOk;
    return ok() ? kOk : std::get<1>(v_);
  }
  T& value() & { return std::get<0>(v_); }
  const T& value() const& { return std::get<0>(v_); }
  T&& value() && { return std::get<0>(std::move(v_)); }
  T* operator->() { return &std::get<0>(v_); }
  const T* operator->() const { return &std::get<0>(v_); }
  T& operator*() & { return std::get<0>(v_); }
  const T& operator*() const& { return std::get<0>(v_); }

 private:
  std::variant<T, Status> v_;
};

}  // namespace client_v1
}  // namespace weft

#define WEFT_CLIENT_CONCAT_INNER(a, b) a##b
#define WEFT_CLIENT_CONCAT(a, b) WEFT_CLIENT_CONCAT_INNER(a, b)

// Return the Status from the enclosing function if `expr` failed.
#define WEFT_CLIENT_RETURN_IF_ERROR(expr)       \
  do {                                          \
    ::weft::client_v1::Status _weft_cs = (expr); \
    if (!_weft_cs.ok()) return _weft_cs;        \
  } while (0)

// `WEFT_CLIENT_ASSIGN_OR_RETURN(auto x, f());` binds the value or returns the error.
#define WEFT_CLIENT_ASSIGN_OR_RETURN(decl, expr)                           \
  auto WEFT_CLIENT_CONCAT(_weft_ce, __LINE__) = (expr);                    \
  if (!WEFT_CLIENT_CONCAT(_weft_ce, __LINE__).ok())                        \
    return WEFT_CLIENT_CONCAT(_weft_ce, __LINE__).status();                \
  decl = std::move(WEFT_CLIENT_CONCAT(_weft_ce, __LINE__)).value()
