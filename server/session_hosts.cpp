// SessionHosts: starting, reaping and stopping the processes of unchecked and isolated sessions
// (session hosts) and of the sessions of one device (device hosts).
#include "server/session_hosts.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>

#include <spdlog/spdlog.h>

#include "engine/runtime/shm_slab_pool.h"

extern char** environ;

namespace weft::server {

namespace {

constexpr int kReadyFd = 3;   // the host writes one byte here once it listens

std::string ExitText(int status) {
  if (WIFEXITED(status)) return "exit status " + std::to_string(WEXITSTATUS(status));
  if (WIFSIGNALED(status)) return std::string("signal ") + strsignal(WTERMSIG(status));
  return "status " + std::to_string(status);
}

// Waits up to `timeout_s` for one byte on `fd`: true when it came, false on EOF or timeout.
bool WaitReady(int fd, double timeout_s) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  for (;;) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) return false;
    pollfd p{fd, POLLIN, 0};
    const int r = poll(&p, 1, static_cast<int>(left.count()));
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) return false;
    char byte = 0;
    const ssize_t n = read(fd, &byte, 1);
    if (n < 0 && errno == EINTR) continue;
    return n == 1;
  }
}

}  // namespace

SessionHosts::SessionHosts(std::string binary, std::vector<std::string> arguments, std::string daemon_socket,
                           uint32_t max_per_principal, double start_timeout_s)
    : binary_(std::move(binary)),
      arguments_(std::move(arguments)),
      daemon_socket_(std::move(daemon_socket)),
      socket_dir_(daemon_socket_.substr(0, daemon_socket_.rfind('/'))),
      max_per_principal_(max_per_principal),
      start_timeout_s_(start_timeout_s),
      reaper_([this] { ReapLoop(); }) {}

SessionHosts::~SessionHosts() {
  StopAll();
  reaper_.join();
}

Expected<std::string> SessionHosts::Start(const std::string& principal) {
  std::string socket;
  pid_t reserved = 0;   // the slot held until the pid is known (a negative key; pids are positive)
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (stopping_) return Unavailable("the daemon is shutting down");
    uint32_t mine = 0;
    for (const auto& [pid, host] : hosts_) mine += host.device.empty() && host.principal == principal ? 1 : 0;
    if (mine >= max_per_principal_)
      return ResourceExhausted("principal " + principal + " already has " + std::to_string(mine) +
                               " sessions in processes of their own (session hosts: unchecked sessions, or every "
                               "local session under --isolate-sessions; --max-session-hosts " +
                               std::to_string(max_per_principal_) + ")");
    reserved = Reserve(Host{principal, "", ""}, &socket);
  }
  return Spawn(reserved, socket, {"--host-principal", principal}, "for " + principal);
}

Expected<std::string> SessionHosts::StartForDevice(const std::string& device) {
  // One start per device at a time: an Open that comes while the device's host starts waits for
  // it and gets the same host.
  std::lock_guard<std::mutex> starting(device_start_mu_);
  std::string socket;
  pid_t reserved = 0;
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (stopping_) return Unavailable("the daemon is shutting down");
    // A device host that lost its GPU removes its socket and ends: a new one is started then.
    struct stat st {};
    for (const auto& [pid, host] : hosts_)
      if (pid > 0 && host.device == device && stat(host.socket.c_str(), &st) == 0) return host.socket;
    reserved = Reserve(Host{"", device, ""}, &socket);
  }
  return Spawn(reserved, socket, {"--host-device", device}, "of device " + device);
}

pid_t SessionHosts::Reserve(Host host, std::string* socket) {
  ++started_;
  *socket = socket_dir_ + "/host-" + std::to_string(getpid()) + "-" + std::to_string(started_) + ".sock";
  host.socket = *socket;
  const pid_t reserved = -static_cast<pid_t>(started_);
  hosts_[reserved] = std::move(host);
  return reserved;
}

Expected<std::string> SessionHosts::Spawn(pid_t reserved, const std::string& socket,
                                          const std::vector<std::string>& role, const std::string& what) {
  auto release_placeholder = [&] {
    std::lock_guard<std::mutex> lock(mu_);
    hosts_.erase(reserved);
  };

  int ready[2];
  if (pipe2(ready, O_CLOEXEC) != 0) {
    release_placeholder();
    return Internal(std::string("pipe: ") + std::strerror(errno));
  }
  // The write end goes to the host as fd 3 (dup2 clears close-on-exec on the copy; a write end
  // that already is fd 3 is moved first, since dup2 onto itself would keep the flag).
  int write_end = ready[1];
  if (write_end == kReadyFd) {
    write_end = fcntl(ready[1], F_DUPFD_CLOEXEC, 10);
    close(ready[1]);
  }
  std::vector<std::string> args = {binary_};
  args.insert(args.end(), arguments_.begin(), arguments_.end());
  args.insert(args.end(), {"--listen", "unix:" + socket});
  args.insert(args.end(), role.begin(), role.end());
  args.insert(args.end(), {"--host-ready-fd", std::to_string(kReadyFd), "--host-parent", std::to_string(getpid())});
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_adddup2(&actions, write_end, kReadyFd);
  pid_t pid = 0;
  const int spawned = posix_spawn(&pid, binary_.c_str(), &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  close(write_end);
  if (spawned != 0) {
    close(ready[0]);
    release_placeholder();
    return Unavailable("could not start the process " + what + " (" + binary_ + "): " + std::strerror(spawned));
  }
  const auto t0 = std::chrono::steady_clock::now();
  const bool up = WaitReady(ready[0], start_timeout_s_);
  close(ready[0]);
  std::lock_guard<std::mutex> lock(mu_);
  Host host = std::move(hosts_[reserved]);
  hosts_.erase(reserved);
  if (!up) {
    int status = 0;
    std::string why;
    if (waitpid(pid, &status, WNOHANG) == pid) {
      why = "it ended with " + ExitText(status);
    } else {
      kill(pid, SIGKILL);
      waitpid(pid, &status, 0);
      why = "it did not listen within " + std::to_string(static_cast<int>(start_timeout_s_)) + " s";
    }
    unlink(socket.c_str());
    return Unavailable("the process " + what + " did not start: " + why + " (the daemon's log has its output)");
  }
  const char* kind = host.device.empty() ? "session" : "device";
  hosts_[pid] = std::move(host);
  // The daemon's socket may have been opened to a group (docs/operations.md): the host's too.
  struct stat daemon_st {};
  if (stat(daemon_socket_.c_str(), &daemon_st) == 0) {
    for (const std::string& path : {socket, socket + ".fast"}) {
      if (chown(path.c_str(), static_cast<uid_t>(-1), daemon_st.st_gid) != 0 && errno != ENOENT)
        spdlog::warn("session host socket {}: chown: {}", path, std::strerror(errno));
      if (chmod(path.c_str(), daemon_st.st_mode & 0777) != 0 && errno != ENOENT)
        spdlog::warn("session host socket {}: chmod: {}", path, std::strerror(errno));
    }
  }
  spdlog::info("{} host pid {} {} listens on {} ({:.0f} ms to start)", kind,
               pid, what, socket,
               std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  return socket;
}

void SessionHosts::Forget(pid_t pid, int status) {
  auto it = hosts_.find(pid);
  if (it == hosts_.end()) return;
  unlink(it->second.socket.c_str());
  unlink((it->second.socket + ".fast").c_str());
  const Host& host = it->second;
  if (WIFEXITED(status) && WEXITSTATUS(status) == 0)
    spdlog::info("{} host pid {} ended", host.device.empty() ? "session" : "device", pid);
  else if (host.device.empty())
    spdlog::warn("session host pid {} of {} ended with {}: its session and arrays are gone, every other "
                 "session is untouched", pid, host.principal, ExitText(status));
  else
    spdlog::warn("device host pid {} of {} ended with {}: the sessions of that device and their arrays are gone "
                 "(the next Open for it starts a new process), every other session is untouched",
                 pid, host.device, ExitText(status));
  hosts_.erase(it);
  // A host that crashed left its shared-memory slabs behind: they go now, not at the next start.
  ShmSlabPool::RemoveStaleSlabs();
}

void SessionHosts::ReapLoop() {
  std::unique_lock<std::mutex> lock(mu_);
  while (!stopping_) {
    stop_cv_.wait_for(lock, std::chrono::milliseconds(100));
    if (stopping_) break;   // StopAll reaps from here on
    std::vector<pid_t> ended;
    std::vector<int> statuses;
    for (const auto& [pid, host] : hosts_) {
      int status = 0;
      if (pid > 0 && waitpid(pid, &status, WNOHANG) == pid) {
        ended.push_back(pid);
        statuses.push_back(status);
      }
    }
    for (size_t i = 0; i < ended.size(); ++i) Forget(ended[i], statuses[i]);
  }
}

void SessionHosts::StopAll() {
  std::vector<pid_t> pids;
  {
    std::lock_guard<std::mutex> lock(mu_);
    stopping_ = true;   // no new hosts; the reaper stops, so only this loop waits for the pids
    for (const auto& [pid, host] : hosts_)
      if (pid > 0) pids.push_back(pid);
  }
  stop_cv_.notify_all();
  for (pid_t pid : pids) kill(pid, SIGTERM);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(3);
  for (pid_t pid : pids) {
    int status = 0;
    while (waitpid(pid, &status, WNOHANG) == 0) {
      if (std::chrono::steady_clock::now() > deadline) {
        kill(pid, SIGKILL);
        waitpid(pid, &status, 0);
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    std::lock_guard<std::mutex> lock(mu_);
    Forget(pid, status);
  }
}

std::vector<std::string> SessionHosts::DeviceHostSockets() const {
  std::lock_guard<std::mutex> lock(mu_);
  std::vector<std::string> out;
  for (const auto& [pid, host] : hosts_)
    if (pid > 0 && !host.device.empty()) out.push_back(host.socket);
  return out;
}

uint32_t SessionHosts::alive() const {
  std::lock_guard<std::mutex> lock(mu_);
  uint32_t n = 0;
  for (const auto& [pid, host] : hosts_) n += pid > 0 ? 1 : 0;
  return n;
}

uint64_t SessionHosts::started_total() const {
  std::lock_guard<std::mutex> lock(mu_);
  return started_;
}

}  // namespace weft::server
