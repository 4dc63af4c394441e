// SessionHosts: the processes the daemon runs sessions in. A session whose kernels may turn bounds
// checks off (OpenSessionRequest.unchecked, on a daemon started with --allow-unchecked), and
// every local session under --isolate-sessions, runs in a weftd of its own, a session host: this
// binary started with --host-principal, serving that one session on a Unix socket beside the
// daemon's. Under --device-hosts, the checked local sessions of each device run in one weftd per
// device, a device host (--host-device), shared by every principal on that device. A wild write,
// or a GPU fault that the CUDA driver keeps for the life of the process, then ends that host and
// never the daemon that serves everyone else. This class starts hosts (session hosts bounded per
// principal, one device host per device), waits until they listen, reaps them when they exit
// (removing their sockets) and stops the rest at shutdown.
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
  // The socket of the device host of `device` ("cpu" or "cuda:N", checked by the caller): the
  // running one, else one started now (Unavailable when it did not come up). A device host
  // serves the checked sessions of every local principal on that device; it is not counted
  // against max_per_principal (at most one per device).
  Expected<std::string> StartForDevice(const std::string& device);
  // At shutdown: refuses new hosts, sends SIGTERM to every host, then SIGKILL to those alive
  // after 3 s, and reaps them.
  void StopAll();

  // The sockets of the device hosts alive now (the daemon's Stats add theirs).
  std::vector<std::string> DeviceHostSockets() const;
  uint32_t alive() const;
  uint64_t started_total() const;

 private:
  struct Host {
    std::string principal;   // a session host's principal; empty for a device host
    std::string device;      // a device host's device; empty for a session host
    std::string socket;
  };
  // Takes a start slot (a negative key until the pid is known) and names the host's socket.
  pid_t Reserve(Host host, std::string* socket);   // caller holds mu_
  // Starts this binary as the reserved host with its role flags; its socket once it listens.
  Expected<std::string> Spawn(pid_t reserved, const std::string& socket, const std::vector<std::string>& role,
                              const std::string& what);
  void ReapLoop();
  void Forget(pid_t pid, int status);   // caller holds mu_

  const std::string binary_;
  const std::vector<std::string> arguments_;
  const std::string daemon_socket_;
  const std::string socket_dir_;
  const uint32_t max_per_principal_;
  const double start_timeout_s_;
  mutable std::mutex mu_;
  std::mutex device_start_mu_;   // held through a device host's start (one start at a time)
  std::condition_variable stop_cv_;
  bool stopping_ = false;
  std::map<pid_t, Host> hosts_;
  uint64_t started_ = 0;
  std::thread reaper_;
};

}  // namespace weft::server
