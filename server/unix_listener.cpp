// UnixListener: bind/listen, the accept loop with SO_PEERCRED, and the fd -> peer registry.
#include "server/unix_listener.h"

#include <fcntl.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>

#include <grpcpp/server_posix.h>
#include <spdlog/spdlog.h>

namespace weft::server {

Expected<std::unique_ptr<UnixListener>> UnixListener::Listen(const std::vector<std::string>& paths) {
  std::unique_ptr<UnixListener> l(new UnixListener());
  if (pipe2(l->wake_fds_, O_CLOEXEC | O_NONBLOCK) != 0)
    return Internal(std::string("pipe: ") + std::strerror(errno));
  for (const auto& path : paths) {
    int fd = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (fd < 0) return Internal(std::string("socket: ") + std::strerror(errno));
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    if (path.size() >= sizeof(addr.sun_path)) {
      close(fd);
      return InvalidArgument("socket path too long: " + path);
    }
    std::memcpy(addr.sun_path, path.c_str(), path.size() + 1);
    if (bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0 || chmod(path.c_str(), 0600) != 0 ||
        listen(fd, SOMAXCONN) != 0) {
      std::string err = std::strerror(errno);
      close(fd);
      return Unavailable("cannot listen on unix:" + path + ": " + err);
    }
    fcntl(fd, F_SETFL, fcntl(fd, F_GETFL) | O_NONBLOCK);
    l->listen_fds_.push_back(fd);
  }
  return l;
}

UnixListener::~UnixListener() {
  Stop();
  for (int fd : wake_fds_)
    if (fd >= 0) close(fd);
}

void UnixListener::Start(grpc::Server* server) {
  server_ = server;
  if (!listen_fds_.empty()) thread_ = std::thread([this] { AcceptLoop(); });
}

void UnixListener::Stop() {
  if (thread_.joinable()) {
    char b = 1;
    (void)!write(wake_fds_[1], &b, 1);
    thread_.join();
  }
  for (int fd : listen_fds_) close(fd);
  listen_fds_.clear();
}

std::optional<PeerCredentials> UnixListener::PeerOf(const std::string& grpc_peer) const {
  if (grpc_peer.rfind("fd:", 0) != 0) return std::nullopt;
  int fd = 0;
  for (size_t i = 3; i < grpc_peer.size(); ++i) {
    if (grpc_peer[i] < '0' || grpc_peer[i] > '9' || fd > (1 << 24)) return std::nullopt;
    fd = fd * 10 + (grpc_peer[i] - '0');
  }
  std::lock_guard<std::mutex> lock(mu_);
  auto it = peers_.find(fd);
  if (it == peers_.end()) return std::nullopt;
  return it->second;
}

void UnixListener::AcceptLoop() {
  std::vector<pollfd> fds;
  for (int fd : listen_fds_) fds.push_back({fd, POLLIN, 0});
  fds.push_back({wake_fds_[0], POLLIN, 0});
  while (true) {
    for (auto& p : fds) p.revents = 0;
    if (poll(fds.data(), fds.size(), -1) < 0) {
      if (errno == EINTR) continue;
      spdlog::error("unix listener: poll failed: {}", std::strerror(errno));
      return;
    }
    if (fds.back().revents) return;   // Stop()
    for (size_t i = 0; i + 1 < fds.size(); ++i) {
      if (!(fds[i].revents & POLLIN)) continue;
      while (true) {
        int c = accept4(fds[i].fd, nullptr, nullptr, SOCK_CLOEXEC | SOCK_NONBLOCK);
        if (c < 0) {
          if (errno == EMFILE || errno == ENFILE) {
            // Out of descriptors: the connection stays queued; back off instead of spinning.
            spdlog::warn("unix listener: cannot accept a connection: {}", std::strerror(errno));
            std::this_thread::sleep_for(std::chrono::milliseconds(100));
          }
          break;   // EAGAIN: nothing more to accept now
        }
        ucred cred{};
        socklen_t len = sizeof(cred);
        if (getsockopt(c, SOL_SOCKET, SO_PEERCRED, &cred, &len) != 0) {
          spdlog::warn("unix listener: SO_PEERCRED failed ({}); connection refused", std::strerror(errno));
          close(c);
          continue;
        }
        {
          std::lock_guard<std::mutex> lock(mu_);
          peers_[c] = PeerCredentials{cred.uid, cred.pid};
        }
        grpc::AddInsecureChannelFromFd(server_, c);   // gRPC owns (and closes) c from here
      }
    }
  }
}

}  // namespace weft::server
