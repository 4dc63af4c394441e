// Where the client connects: explicit address, $WEFT_ADDRESS, or the default Unix socket.
#include "address.h"

#include <sys/stat.h>
#include <unistd.h>

#include <cstdlib>

namespace weft::inline client_v1::detail {

namespace {

bool IsSocket(const std::string& path) {
  struct stat st{};
  return ::stat(path.c_str(), &st) == 0 && S_ISSOCK(st.st_mode);
}

std::string Env(const char* name) {
  const char* v = std::getenv(name);
  return v ? std::string(v) : std::string();
}

}  // namespace

ResolvedAddress ParseAddress(const std::string& address) {
  if (address.rfind("unix:", 0) == 0) {
    std::string path = address.substr(5);
    // gRPC also accepts "unix:///abs/path"; normalize to one slash.
    while (path.size() > 1 && path[0] == '/' && path[1] == '/') path.erase(0, 1);
    return {"unix:" + path, true};
  }
  if (!address.empty() && address[0] == '/') return {"unix:" + address, true};
  if (address.rfind("tcp:", 0) == 0) return {address.substr(4), false};
  return {address, false};
}

std::string DefaultSocketPath() {
  const std::string xdg = Env("XDG_RUNTIME_DIR");
  const std::string xdg_path = xdg.empty() ? std::string() : xdg + "/weft/weftd.sock";
  const std::string tmp_path = "/tmp/weft-" + std::to_string(::getuid()) + "/weftd.sock";
  if (!xdg_path.empty() && IsSocket(xdg_path)) return xdg_path;
  if (IsSocket(tmp_path)) return tmp_path;
  return xdg_path.empty() ? tmp_path : xdg_path;
}

ResolvedAddress Resolve(const ConnectOptions& options) {
  std::string address = options.address;
  if (address.empty()) address = Env("WEFT_ADDRESS");
  if (address.empty()) address = "unix:" + DefaultSocketPath();
  return ParseAddress(address);
}

}  // namespace weft::client_v1::detail

namespace weft::inline client_v1 {

std::string ResolveAddress(const ConnectOptions& options) { return detail::Resolve(options).target; }

}  // namespace weft::client_v1
