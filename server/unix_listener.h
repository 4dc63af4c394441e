// Unix-socket listening for weftd, done by the daemon itself so it knows who connects: binds
// and listens on each unix: path (mode 0600), accepts connections, reads the peer's uid and
// pid (SO_PEERCRED) and hands the connection to the gRPC server (AddInsecureChannelFromFd).
// gRPC names such a connection's peer "fd:<n>"; PeerOf maps that name back to the credentials
// read when fd <n> was accepted. Sound because a call holds its connection's transport, which
// holds the fd open: while a handler runs, "fd:<n>" cannot have been reused by another
// connection.
#pragma once

#include <sys/types.h>

#include <atomic>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <grpcpp/server.h>

#include "engine/core/status.h"

namespace weft::server {

struct PeerCredentials {
  uid_t uid = 0;
  pid_t pid = 0;
};

class UnixListener {
 public:
  // Binds and listens on every path (each already prepared: directory made, stale file gone).
  static Expected<std::unique_ptr<UnixListener>> Listen(const std::vector<std::string>& paths);
  ~UnixListener();   // Stop()

  // Starts the accept thread; connections go to `server` (built and started).
  void Start(grpc::Server* server);
  // Stops accepting and closes the listening sockets (connections already handed over stay).
  void Stop();

  // Credentials of the connection gRPC calls `grpc_peer` ("fd:<n>"); nullopt for any other peer.
  std::optional<PeerCredentials> PeerOf(const std::string& grpc_peer) const;

 private:
  UnixListener() = default;
  void AcceptLoop();

  std::vector<int> listen_fds_;
  int wake_fds_[2] = {-1, -1};   // a pipe: Stop() writes to wake the accept thread
  grpc::Server* server_ = nullptr;
  std::thread thread_;
  mutable std::mutex mu_;
  std::map<int, PeerCredentials> peers_;   // accepted fd -> credentials
};

}  // namespace weft::server
