// weftd settings: command line (CLI11) over an optional TOML file (--config, same keys with
// dashes or underscores), plus the default listen address.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "engine/core/status.h"

namespace weft::server {

struct DaemonConfig {
  std::vector<std::string> listen;   // "unix:/path", "tcp:host:port"
  std::string cache_dir;
  std::string log_level = "info";
  std::string token_file;
  std::string native_dir;
  int cpu_threads = 0;
  bool verify_cuda = false;
  // The architectures --verify-cuda compiles every module for: the text ("75,90") and the
  // parsed list (empty = sm_90).
  std::string verify_cuda_archs_text;
  std::vector<int> verify_cuda_archs;
  bool allow_unchecked = false;
  // Every session of a local client runs in a session host (a process of its own), checked
  // ones too: a fault or crash of any session, whatever its cause, ends only its process.
  bool isolate_sessions = false;
  // Every checked session of a local client runs in the process of its device (a device host:
  // one per device, shared by the sessions of every principal on it): a fault or crash ends
  // that process and costs only the sessions of that device (server/session_hosts.h).
  bool device_hosts = false;
  bool show_version = false;
  // Compile limits (engine/codegen/check_source.h CompileLimits; the defaults are its defaults).
  uint64_t max_module_bytes = 2u << 20;
  uint32_t max_functions = 2000;
  int max_block_depth = 100;
  int max_expression_depth = 1000;
  // Array memory limits in bytes (reserved, not touched); 0 = the default (see docs/operations.md).
  uint64_t max_memory = 0;             // daemon-wide (default: the size of /dev/shm)
  uint64_t max_principal_memory = 0;   // per principal (default: none beyond max_memory)
  uint64_t max_session_memory = 0;     // per session (default: none beyond the other two)
  // Limits (docs/operations.md lists them with their defaults).
  double attach_timeout_s = 30;              // a session with no Attach stream by then is reaped
  double launch_time_limit_s = 300;          // a launch running longer is stopped; 0 = none
  double compile_time_limit_s = 30;          // a CPU compile running longer is stopped; 0 = none
  uint64_t max_launch_threads = uint64_t{1} << 32;   // per launch (and elements per fill/copy)
  uint32_t max_sessions_per_principal = 256;
  uint64_t max_queued_commands = 65536;      // per session
  uint64_t cache_max_bytes = uint64_t{2} << 30;      // disk module cache; LRU files removed beyond it
  // Unchecked sessions run in session hosts (server/session_hosts.h); at most this many per
  // principal at once.
  uint32_t max_session_hosts = 4;
  // Set only on a session host's command line (by SessionHosts::Start, never by hand): the one
  // principal it serves, the descriptor it reports readiness on, and the daemon that started it.
  std::string host_principal;
  // Set only on a device host's command line (instead of host_principal): the device whose
  // sessions it serves ("cpu" or "cuda:N").
  std::string host_device;
  int host_ready_fd = -1;
  int64_t host_parent = 0;
  // A process the daemon started: a session host (one session of one principal) or a device
  // host (every checked local session of one device).
  bool session_host() const { return !host_principal.empty() || !host_device.empty(); }
  bool device_host() const { return !host_device.empty(); }
};

// The flags a session or device host inherits from this daemon's settings (limits, cache,
// logging, --allow-unchecked, --verify-cuda); SessionHosts adds --listen and the --host-* flags.
std::vector<std::string> SessionHostArguments(const DaemonConfig& c);

// "4096", "512M", "16G", "1T" (binary units, optional "iB"/"B") -> bytes.
Expected<uint64_t> ParseByteSize(const std::string& text);

// Parses argv (and the TOML file it names). Returns the exit code in *exit_code when the
// process should stop now (--help, --version, bad flags).
Expected<DaemonConfig> ParseDaemonConfig(int argc, char** argv, int* exit_code);

// $XDG_RUNTIME_DIR/weft/weftd.sock, else /tmp/weft-$UID/weftd.sock.
std::string DefaultSocketPath();

// Reads the TCP token (surrounding whitespace trimmed); empty files are an error.
Expected<std::string> ReadTokenFile(const std::string& path);

}  // namespace weft::server
