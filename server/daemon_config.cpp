// Command line + TOML configuration of weftd.
#include "server/daemon_config.h"

#include <sys/stat.h>
#include <unistd.h>

#include <cctype>
#include <cstdlib>
#include <tuple>
#include <fstream>
#include <iostream>
#include <optional>
#include <sstream>
#include <type_traits>

#include <CLI/CLI.hpp>
#include <toml++/toml.h>

namespace weft::server {

std::string DefaultSocketPath() {
  const char* xdg = std::getenv("XDG_RUNTIME_DIR");
  if (xdg && *xdg) return std::string(xdg) + "/weft/weftd.sock";
  return "/tmp/weft-" + std::to_string(getuid()) + "/weftd.sock";
}

Expected<std::string> ReadTokenFile(const std::string& path) {
  std::ifstream f(path);
  if (!f) return InvalidArgument("cannot read token file " + path);
  std::stringstream ss;
  ss << f.rdbuf();
  std::string t = ss.str();
  size_t b = t.find_first_not_of(" \t\r\n"), e = t.find_last_not_of(" \t\r\n");
  if (b == std::string::npos) return InvalidArgument("token file " + path + " is empty");
  struct stat st {};
  if (stat(path.c_str(), &st) == 0 && (st.st_mode & 077))
    std::cerr << "weftd: warning: token file " << path << " is readable by other users\n";
  return t.substr(b, e - b + 1);
}

Expected<uint64_t> ParseByteSize(const std::string& text) {
  const std::string bad = "'" + text + "' is not a byte size (expected e.g. 4096, 512M, 16G, 1T)";
  size_t i = 0;
  uint64_t v = 0;
  if (text.empty() || !std::isdigit(static_cast<unsigned char>(text[0]))) return InvalidArgument(bad);
  while (i < text.size() && std::isdigit(static_cast<unsigned char>(text[i]))) {
    if (__builtin_mul_overflow(v, 10u, &v) || __builtin_add_overflow(v, static_cast<uint64_t>(text[i] - '0'), &v))
      return InvalidArgument(bad);
    ++i;
  }
  std::string unit = text.substr(i);
  for (char& c : unit) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  int shift = 0;
  if (unit.empty() || unit == "B") shift = 0;
  else if (unit == "K" || unit == "KB" || unit == "KIB") shift = 10;
  else if (unit == "M" || unit == "MB" || unit == "MIB") shift = 20;
  else if (unit == "G" || unit == "GB" || unit == "GIB") shift = 30;
  else if (unit == "T" || unit == "TB" || unit == "TIB") shift = 40;
  else return InvalidArgument(bad);
  if (shift && v > (~0ull >> shift)) return InvalidArgument(bad);
  return v << shift;
}

namespace {

const toml::node* Key(const toml::table& t, const std::string& dashed) {
  if (auto* n = t.get(dashed)) return n;
  std::string under = dashed;
  for (char& c : under)
    if (c == '-') c = '_';
  return t.get(under);
}

Status ApplyToml(const std::string& path, DaemonConfig* c, const CLI::App& app) {
  toml::table t;
  try {
    t = toml::parse_file(path);
  } catch (const toml::parse_error& e) {
    std::ostringstream os;
    os << "config " << path << ": " << e.description() << " at line " << e.source().begin.line;
    return InvalidArgument(os.str());
  }
  auto given = [&](const char* flag) { return app.count(flag) > 0; };
  for (auto&& [k, v] : t) {
    static const char* known[] = {"listen", "cache-dir", "log-level", "token-file", "cpu-threads", "verify-cuda",
                                  "verify-cuda-archs",
                                  "allow-unchecked", "isolate-sessions", "device-hosts", "native-dir", "max-module-bytes", "max-functions",
                                  "max-block-depth", "max-expression-depth", "attach-timeout", "launch-time-limit",
                                  "compile-time-limit",
                                  "max-launch-threads", "max-sessions-per-principal", "max-queued-commands",
                                  "cache-max-bytes", "max-memory", "max-principal-memory",
                                  "max-session-memory", "max-session-hosts"};
    std::string dashed(k.str());
    for (char& ch : dashed)
      if (ch == '_') ch = '-';
    bool ok = false;
    for (const char* n : known) ok = ok || dashed == n;
    if (!ok) return InvalidArgument("config " + path + ": unknown key '" + std::string(k.str()) + "'");
  }
  if (!given("--listen")) {
    if (auto* n = Key(t, "listen")) {
      if (auto s = n->value<std::string>()) c->listen.push_back(*s);
      else if (auto* arr = n->as_array())
        for (auto& e : *arr)
          if (auto s2 = e.value<std::string>()) c->listen.push_back(*s2);
    }
  }
  auto str = [&](const char* key, const char* flag, std::string* out) {
    if (given(flag)) return;
    if (auto* n = Key(t, key))
      if (auto s = n->value<std::string>()) *out = *s;
  };
  str("cache-dir", "--cache-dir", &c->cache_dir);
  str("log-level", "--log-level", &c->log_level);
  str("token-file", "--token-file", &c->token_file);
  str("native-dir", "--native-dir", &c->native_dir);
  if (!given("--cpu-threads"))
    if (auto* n = Key(t, "cpu-threads"))
      if (auto v = n->value<int64_t>()) c->cpu_threads = static_cast<int>(*v);
  if (!given("--verify-cuda"))
    if (auto* n = Key(t, "verify-cuda"))
      if (auto v = n->value<bool>()) c->verify_cuda = *v;
  str("verify-cuda-archs", "--verify-cuda-archs", &c->verify_cuda_archs_text);
  auto integer = [&](const char* key, const char* flag, auto* out) {
    if (given(flag)) return;
    if (auto* n = Key(t, key))
      if (auto v = n->value<int64_t>()) *out = static_cast<std::remove_pointer_t<decltype(out)>>(*v < 0 ? 0 : *v);
  };
  integer("max-module-bytes", "--max-module-bytes", &c->max_module_bytes);
  integer("max-functions", "--max-functions", &c->max_functions);
  integer("max-block-depth", "--max-block-depth", &c->max_block_depth);
  integer("max-expression-depth", "--max-expression-depth", &c->max_expression_depth);
  if (!given("--allow-unchecked"))
    if (auto* n = Key(t, "allow-unchecked"))
      if (auto v = n->value<bool>()) c->allow_unchecked = *v;
  if (!given("--isolate-sessions"))
    if (auto* n = Key(t, "isolate-sessions"))
      if (auto v = n->value<bool>()) c->isolate_sessions = *v;
  if (!given("--device-hosts"))
    if (auto* n = Key(t, "device-hosts"))
      if (auto v = n->value<bool>()) c->device_hosts = *v;
  // Byte sizes: an integer or a string with a unit ("16G").
  auto bytes = [&](const char* key, const char* flag, uint64_t* out) -> Status {
    if (given(flag)) return Status::Ok();
    const toml::node* n = Key(t, key);
    if (!n) return Status::Ok();
    if (auto v = n->value<int64_t>()) {
      if (*v < 0) return InvalidArgument("config " + path + ": " + key + " must be >= 0");
      *out = static_cast<uint64_t>(*v);
      return Status::Ok();
    }
    if (auto s = n->value<std::string>()) {
      auto parsed = ParseByteSize(*s);
      if (!parsed.ok()) return InvalidArgument("config " + path + ": " + key + ": " + parsed.status().message());
      *out = *parsed;
      return Status::Ok();
    }
    return InvalidArgument("config " + path + ": " + key + " must be a byte size");
  };
  WEFT_RETURN_IF_ERROR(bytes("max-memory", "--max-memory", &c->max_memory));
  WEFT_RETURN_IF_ERROR(bytes("max-principal-memory", "--max-principal-memory", &c->max_principal_memory));
  WEFT_RETURN_IF_ERROR(bytes("max-session-memory", "--max-session-memory", &c->max_session_memory));
  // Numbers: a wrong type or a negative value is an error, never ignored.
  auto number = [&](const char* key, auto* out) -> Status {
    if (given((std::string("--") + key).c_str())) return Status::Ok();
    const toml::node* n = Key(t, key);
    if (!n) return Status::Ok();
    std::optional<double> v;
    if (auto i = n->value<int64_t>()) v = static_cast<double>(*i);
    else if (auto d = n->value<double>()) v = *d;
    if (!v || *v < 0) return InvalidArgument("config " + path + ": " + key + " must be a number >= 0");
    *out = static_cast<std::remove_pointer_t<decltype(out)>>(*v);
    return Status::Ok();
  };
  WEFT_RETURN_IF_ERROR(number("attach-timeout", &c->attach_timeout_s));
  WEFT_RETURN_IF_ERROR(number("launch-time-limit", &c->launch_time_limit_s));
  WEFT_RETURN_IF_ERROR(number("compile-time-limit", &c->compile_time_limit_s));
  WEFT_RETURN_IF_ERROR(number("max-launch-threads", &c->max_launch_threads));
  WEFT_RETURN_IF_ERROR(number("max-sessions-per-principal", &c->max_sessions_per_principal));
  WEFT_RETURN_IF_ERROR(number("max-queued-commands", &c->max_queued_commands));
  WEFT_RETURN_IF_ERROR(number("cache-max-bytes", &c->cache_max_bytes));
  WEFT_RETURN_IF_ERROR(number("max-session-hosts", &c->max_session_hosts));
  return Status::Ok();
}

}  // namespace

Expected<DaemonConfig> ParseDaemonConfig(int argc, char** argv, int* exit_code) {
  DaemonConfig c;
  std::string config_file;
  CLI::App app{"weftd: GPU compute daemon for Warp-style kernels"};
  app.add_option("--listen", c.listen, "Address to listen on, repeatable: unix:/path or tcp:host:port "
                                       "(default unix:" + DefaultSocketPath() + ")");
  app.add_option("--cache-dir", c.cache_dir, "Directory of the compiled-module disk cache");
  app.add_option("--log-level", c.log_level, "trace, debug, info, warn, error, critical or off");
  app.add_option("--config", config_file, "TOML file with the same keys (command-line flags win)");
  app.add_option("--token-file", c.token_file, "File holding the token TCP clients must send");
  app.add_option("--cpu-threads", c.cpu_threads, "Threads of the CPU launch pool (default: all cores)");
  app.add_option("--native-dir", c.native_dir, "engine/native headers for the CPU JIT");
  app.add_flag("--verify-cuda", c.verify_cuda, "Also compile every generated module with NVRTC");
  app.add_option("--verify-cuda-archs", c.verify_cuda_archs_text,
                 "The CUDA architectures --verify-cuda compiles for, comma separated, e.g. 75,90 (default 90)");
  app.add_flag("--allow-unchecked", c.allow_unchecked, "Let sessions turn array bounds checks off");
  app.add_flag("--isolate-sessions", c.isolate_sessions,
               "Run every local session in a process of its own (a session host), checked ones too");
  app.add_flag("--device-hosts", c.device_hosts,
               "Run the checked local sessions of each device in one process per device (a device host)");
  app.add_option("--max-module-bytes", c.max_module_bytes, "Largest module source a client may compile, in bytes (default 2 MiB)");
  app.add_option("--max-functions", c.max_functions, "Most kernels and funcs in one module (default 2000)");
  app.add_option("--max-block-depth", c.max_block_depth, "Deepest nesting of blocks in kernel code, 1..100 (default 100)");
  app.add_option("--max-expression-depth", c.max_expression_depth,
                 "Deepest nesting of expressions in kernel code, 1..1000 (default 1000)");
  app.add_flag("--version", c.show_version, "Print the version and exit");
  std::string max_memory, max_principal_memory, max_session_memory;
  app.add_option("--max-memory", max_memory, "Daemon-wide limit on array memory, e.g. 16G (default: the size of /dev/shm)");
  app.add_option("--max-principal-memory", max_principal_memory,
                 "Limit on the array memory of one principal's sessions together (default: none)");
  app.add_option("--max-session-memory", max_session_memory, "Limit on the array memory of one session (default: none)");
  app.add_option("--attach-timeout", c.attach_timeout_s,
                 "Seconds a new session may go without an Attach stream before it is reaped (default 30)");
  app.add_option("--launch-time-limit", c.launch_time_limit_s,
                 "Seconds a kernel launch may run before it is stopped; 0 = no limit (default 300)");
  app.add_option("--compile-time-limit", c.compile_time_limit_s,
                 "Seconds clang (CPU) or NVRTC (CUDA) may spend on one module before the compile is stopped; "
                 "compiles then run in a child process (weft-cc); 0 = no limit, in process (default 30)");
  app.add_option("--max-launch-threads", c.max_launch_threads,
                 "Most threads in one launch, and elements in one fill or copy (default 2^32)");
  app.add_option("--max-sessions-per-principal", c.max_sessions_per_principal,
                 "Most open sessions per Unix user / per TCP token (default 256)");
  app.add_option("--max-queued-commands", c.max_queued_commands,
                 "Most commands queued and not yet run per session (default 65536)");
  app.add_option("--cache-max-bytes", c.cache_max_bytes,
                 "Size bound of the disk module cache; least recently used modules are removed (default 2 GiB)");
  app.add_option("--max-session-hosts", c.max_session_hosts,
                 "Most session hosts (unchecked sessions, or every local session with --isolate-sessions) "
                 "per principal at once (default 4)");
  app.add_option("--host-principal", c.host_principal, "Set by the daemon when it starts a session host")
      ->group("");
  app.add_option("--host-device", c.host_device, "Set by the daemon when it starts a device host")->group("");
  app.add_option("--host-ready-fd", c.host_ready_fd, "Set by the daemon when it starts a session host")->group("");
  app.add_option("--host-parent", c.host_parent, "Set by the daemon when it starts a session host")->group("");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    *exit_code = app.exit(e);
    return Status(StatusCode::kCancelled, "exit");
  }
  if (c.show_version) {
    std::cout << "weftd " << WEFT_VERSION << "\n";
    *exit_code = 0;
    return Status(StatusCode::kCancelled, "exit");
  }
  for (auto [text, out, flag] : {std::tuple{&max_memory, &c.max_memory, "--max-memory"},
                                 std::tuple{&max_principal_memory, &c.max_principal_memory, "--max-principal-memory"},
                                 std::tuple{&max_session_memory, &c.max_session_memory, "--max-session-memory"}}) {
    if (text->empty()) continue;
    auto parsed = ParseByteSize(*text);
    if (!parsed.ok()) return InvalidArgument(std::string(flag) + ": " + parsed.status().message());
    *out = *parsed;
  }
  if (!config_file.empty()) WEFT_RETURN_IF_ERROR(ApplyToml(config_file, &c, app));
  if (c.cpu_threads < 0) return InvalidArgument("--cpu-threads must be >= 0");
  for (size_t at = 0; at < c.verify_cuda_archs_text.size();) {
    size_t end = c.verify_cuda_archs_text.find(',', at);
    if (end == std::string::npos) end = c.verify_cuda_archs_text.size();
    std::string item = c.verify_cuda_archs_text.substr(at, end - at);
    if (item.rfind("sm_", 0) == 0) item = item.substr(3);
    if (item.empty() || item.size() > 3 || item.find_first_not_of("0123456789") != std::string::npos)
      return InvalidArgument("--verify-cuda-archs: '" + c.verify_cuda_archs_text +
                             "' is not a comma-separated list of architectures such as 75,90");
    c.verify_cuda_archs.push_back(std::stoi(item));
    at = end + 1;
  }
  if (c.max_module_bytes == 0 || c.max_functions == 0)
    return InvalidArgument("--max-module-bytes and --max-functions must be > 0");
  if (c.max_block_depth < 1 || c.max_block_depth > 100)
    return InvalidArgument("--max-block-depth must be between 1 and 100");
  if (c.max_expression_depth < 1 || c.max_expression_depth > 1000)
    return InvalidArgument("--max-expression-depth must be between 1 and 1000");
  if (c.attach_timeout_s <= 0) return InvalidArgument("--attach-timeout must be > 0 seconds");
  if (c.launch_time_limit_s < 0) return InvalidArgument("--launch-time-limit must be >= 0 (0 = no limit)");
  if (c.compile_time_limit_s < 0) return InvalidArgument("--compile-time-limit must be >= 0 (0 = no limit)");
  if (c.max_launch_threads == 0) return InvalidArgument("--max-launch-threads must be > 0");
  if (c.max_sessions_per_principal == 0) return InvalidArgument("--max-sessions-per-principal must be > 0");
  if (c.max_queued_commands == 0) return InvalidArgument("--max-queued-commands must be > 0");
  if (!c.host_device.empty()) {
    const std::string& d = c.host_device;
    const bool gpu = d.size() > 5 && d.size() <= 8 && d.rfind("cuda:", 0) == 0 &&
                     d.find_first_not_of("0123456789", 5) == std::string::npos;
    if (d != "cpu" && !gpu) return InvalidArgument("--host-device: expected cpu or cuda:N");
    if (!c.host_principal.empty()) return InvalidArgument("--host-device and --host-principal exclude each other");
  }
  if (c.listen.empty()) c.listen.push_back("unix:" + DefaultSocketPath());
  for (const auto& l : c.listen)
    if (l.rfind("unix:", 0) != 0 && l.rfind("tcp:", 0) != 0)
      return InvalidArgument("--listen " + l + ": expected unix:/path or tcp:host:port");
  return c;
}


std::vector<std::string> SessionHostArguments(const DaemonConfig& c) {
  std::vector<std::string> a;
  auto add = [&](const char* flag, const std::string& value) {
    a.push_back(flag);
    a.push_back(value);
  };
  if (!c.cache_dir.empty()) add("--cache-dir", c.cache_dir);
  add("--log-level", c.log_level);
  if (!c.native_dir.empty()) add("--native-dir", c.native_dir);
  if (c.cpu_threads > 0) add("--cpu-threads", std::to_string(c.cpu_threads));
  if (c.allow_unchecked) a.push_back("--allow-unchecked");
  if (c.verify_cuda) a.push_back("--verify-cuda");
  if (!c.verify_cuda_archs_text.empty()) add("--verify-cuda-archs", c.verify_cuda_archs_text);
  add("--max-module-bytes", std::to_string(c.max_module_bytes));
  add("--max-functions", std::to_string(c.max_functions));
  add("--max-block-depth", std::to_string(c.max_block_depth));
  add("--max-expression-depth", std::to_string(c.max_expression_depth));
  if (c.max_memory) add("--max-memory", std::to_string(c.max_memory));
  if (c.max_principal_memory) add("--max-principal-memory", std::to_string(c.max_principal_memory));
  if (c.max_session_memory) add("--max-session-memory", std::to_string(c.max_session_memory));
  add("--attach-timeout", std::to_string(c.attach_timeout_s));
  add("--launch-time-limit", std::to_string(c.launch_time_limit_s));
  add("--compile-time-limit", std::to_string(c.compile_time_limit_s));
  add("--max-launch-threads", std::to_string(c.max_launch_threads));
  add("--max-queued-commands", std::to_string(c.max_queued_commands));
  add("--max-sessions-per-principal", std::to_string(c.max_sessions_per_principal));
  add("--cache-max-bytes", std::to_string(c.cache_max_bytes));
  return a;
}

}  // namespace weft::server
