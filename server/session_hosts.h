// SessionHosts: the processes of unchecked sessions. A session whose kernels may turn bounds
// checks off (OpenSessionRequest.unchecked, on a daemon started with --allow-unchecked) runs in
// a weftd of its own, a session host: this binary started with --host-principal, serving that
// one session on a Unix socket beside the daemon's. A wild write of an unchecked kernel, or a
// GPU fault that the CUDA driver keeps for the life of the process, then ends the host and
// never the daemon that serves everyone else. This class starts a host per unchecked Open
// (bounded per principal), waits until it listens, reaps it when it exits (removing its
// sockets) and stops the rest at shutdown.
#pragma once

#include <sys/types.h>

#include <condition_variable>
#include <cstdint>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "engine/core/status.h"

namespace weft::server {

class SessionHosts {
 public:
  // `binary`: this executable; `arguments`: the settings a host inherits (SessionHostArguments);
  // `daemon_socket`: the daemon's own Unix socket. Hosts listen beside it, and their sockets get
  // its mode and group (an operator who opened the daemon's socket to a group opened the hosts').
  SessionHosts(std::string binary, std::vector<std::string> arguments, std::string daemon_socket,
               uint32_t max_per_principal, double start_timeout_s);
  ~SessionHosts();   // StopAll
  SessionHosts(const SessionHosts&) = delete;
  SessionHosts& operator=(const SessionHosts&) = delete;

  // Starts a host for one session of `principal` and returns its socket path once it listens.
  // ResourceExhausted when the principal already has max_per_principal hosts alive;
  // Unavailable when the host did not come up (its exit status in the message).
  Expected<std::string> Start(const std::string& principal);
  // At shutdown: refuses new hosts, sends SIGTERM to every host, then SIGKILL to those alive
  // after 3 s, and reaps them.
  void StopAll();

  uint32_t alive() const;
  uint64_t started_total() const;

 private:
  struct Host {
    std::string principal;
    std::string socket;
  };
  void ReapLoop();
  void Forget(pid_t pid, int status);   // caller holds mu_

  const std::string binary_;
  const std::vector<std::string> arguments_;
  const std::string daemon_socket_;
  const std::string socket_dir_;
  const uint32_t max_per_principal_;
  const double start_timeout_s_;
  mutable std::mutex mu_;
  std::condition_variable stop_cv_;
  bool stopping_ = false;
  std::map<pid_t, Host> hosts_;
  uint64_t started_ = 0;
  std::thread reaper_;
};

}  // namespace weft::server
