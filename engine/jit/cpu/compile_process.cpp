// CompileProcess: spawning, feeding, timing out and reaping the child compiler (parent side),
// and the child compiler's main.
#include "engine/jit/cpu/compile_process.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <iterator>
#include <mutex>
#include <set>

#include <spdlog/spdlog.h>

extern char** environ;

namespace weft::jit {
namespace {

// A socket pair rather than a pipe for the child's stdin: send(MSG_NOSIGNAL) never raises
// SIGPIPE in the parent when the child dies early.
struct Fds {
  int parent = -1;
  int child = -1;
  ~Fds() {
    if (parent >= 0) ::close(parent);
    if (child >= 0) ::close(child);
  }
};

bool MakePair(Fds* fds) {
  int sv[2];
  if (::socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, sv) != 0) return false;
  fds->parent = sv[0];
  fds->child = sv[1];
  return true;
}

// The compiler processes running now (spawned, not yet reaped), for StopCompilerChildren.
std::mutex g_children_mu;
std::set<pid_t> g_children;
bool g_stopping = false;

std::string FormatSeconds(double s) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%g", s);
  return buf;
}

}  // namespace

std::vector<std::string> CompilerChildArgs(const CpuJitOptions& options, const std::string& pch_path,
                                           std::string_view name, double time_limit_s) {
  std::vector<std::string> args = {"--name", std::string(name), "--opt", std::to_string(options.opt_level),
                                   "--native", options.native_cpu ? "1" : "0",
                                   "--limit", FormatSeconds(time_limit_s)};
  if (!pch_path.empty()) args.insert(args.end(), {"--pch", pch_path});
  for (const auto& dir : options.include_dirs) args.insert(args.end(), {"--include", dir});
  for (const auto& flag : options.extra_flags) args.insert(args.end(), {"--flag", flag});
  return args;
}

void StopCompilerChildren() {
  std::lock_guard<std::mutex> lock(g_children_mu);
  g_stopping = true;
  for (pid_t pid : g_children) ::kill(pid, SIGKILL);   // not reaped yet: the pid is still ours
}

Expected<std::string> CompileInChild(const std::string& executable, const std::vector<std::string>& args,
                                     std::string_view source, std::string_view name, double time_limit_s,
                                     std::string_view target) {
  auto stopping = [&] {
    return Unavailable("weftd is stopping: the compile of " + std::string(name) + " was stopped");
  };
  {
    std::lock_guard<std::mutex> lock(g_children_mu);
    if (g_stopping) return stopping();
  }
  Fds in, out, err;
  if (!MakePair(&in) || !MakePair(&out) || !MakePair(&err))
    return Internal(std::string("compiler child: socketpair failed: ") + std::strerror(errno));

  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_adddup2(&actions, in.child, 0);
  posix_spawn_file_actions_adddup2(&actions, out.child, 1);
  posix_spawn_file_actions_adddup2(&actions, err.child, 2);
  posix_spawn_file_actions_addclosefrom_np(&actions, 3);   // none of the daemon's sockets or slabs
  posix_spawnattr_t attr;
  posix_spawnattr_init(&attr);
  sigset_t none, defaults;
  sigemptyset(&none);
  sigemptyset(&defaults);
  sigaddset(&defaults, SIGPIPE);
  sigaddset(&defaults, SIGALRM);
  sigaddset(&defaults, SIGTERM);
  posix_spawnattr_setsigmask(&attr, &none);         // the daemon blocks SIGTERM in its threads
  posix_spawnattr_setsigdefault(&attr, &defaults);  // and ignores SIGPIPE
  posix_spawnattr_setflags(&attr, POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF);
  std::vector<char*> argv;
  argv.push_back(const_cast<char*>(executable.c_str()));
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  pid_t pid = -1;
  const auto start = std::chrono::steady_clock::now();
  int rc = posix_spawn(&pid, executable.c_str(), &actions, &attr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  posix_spawnattr_destroy(&attr);
  if (rc != 0) return Internal("cannot start the compiler process " + executable + ": " + std::strerror(rc));
  {
    std::lock_guard<std::mutex> lock(g_children_mu);
    g_children.insert(pid);
    if (g_stopping) ::kill(pid, SIGKILL);
  }
  ::close(in.child);
  ::close(out.child);
  ::close(err.child);
  in.child = out.child = err.child = -1;
  for (int fd : {in.parent, out.parent, err.parent}) ::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) | O_NONBLOCK);

  const auto deadline = start + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                                    std::chrono::duration<double>(time_limit_s));
  std::string object, diagnostics;
  size_t written = 0;
  bool timed_out = false;
  char buf[65536];
  while (out.parent >= 0 || err.parent >= 0) {
    pollfd fds[3];
    nfds_t n = 0;
    if (in.parent >= 0) fds[n++] = {in.parent, POLLOUT, 0};
    if (out.parent >= 0) fds[n++] = {out.parent, POLLIN, 0};
    if (err.parent >= 0) fds[n++] = {err.parent, POLLIN, 0};
    auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) {
      timed_out = true;
      break;
    }
    int ready = ::poll(fds, n, static_cast<int>(std::min<long long>(left.count() + 1, 1000)));
    if (ready < 0 && errno != EINTR) break;
    for (nfds_t i = 0; i < n && ready > 0; ++i) {
      if (!fds[i].revents) continue;
      int fd = fds[i].fd;
      if (fd == in.parent) {
        ssize_t w = ::send(fd, source.data() + written, source.size() - written, MSG_NOSIGNAL);
        if (w > 0) written += static_cast<size_t>(w);
        if ((w < 0 && errno != EAGAIN && errno != EINTR) || written == source.size()) {
          ::close(in.parent);   // EOF: the child starts compiling
          in.parent = -1;
        }
        continue;
      }
      ssize_t r = ::read(fd, buf, sizeof(buf));
      if (r > 0) {
        std::string& to = fd == out.parent ? object : diagnostics;
        if (fd == err.parent && diagnostics.size() > (4u << 20)) continue;   // enough of a log
        to.append(buf, static_cast<size_t>(r));
      } else if (r == 0 || (errno != EAGAIN && errno != EINTR)) {
        ::close(fd);
        (fd == out.parent ? out.parent : err.parent) = -1;
      }
    }
  }
  bool stopped = false;
  {
    std::lock_guard<std::mutex> lock(g_children_mu);
    if (timed_out) ::kill(pid, SIGKILL);
    g_children.erase(pid);   // from here nobody else signals it; it stays ours until reaped
    stopped = g_stopping;
  }
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  if (stopped && !(WIFEXITED(status) && WEXITSTATUS(status) == 0)) return stopping();
  if (timed_out)
    return ResourceExhausted("compiling " + std::string(name) + " for " + std::string(target) +
                             " took longer than the compile time limit (" +
                             FormatSeconds(time_limit_s) +
                             " s, --compile-time-limit) and was stopped; make the module smaller (fewer or "
                             "shorter kernels, less unrolling) or ask the operator to raise the limit");
  if (WIFEXITED(status) && WEXITSTATUS(status) == 0) {
    if (object.empty()) return Internal("the compiler process produced no object code for " + std::string(name));
    return object;
  }
  if (WIFEXITED(status) && WEXITSTATUS(status) == 1)   // clang rejected the source
    return Internal(diagnostics);
  std::string how = WIFSIGNALED(status) ? "was killed by signal " + std::to_string(WTERMSIG(status))
                                        : "exited with " + std::to_string(WEXITSTATUS(status));
  return Internal("the compiler process for " + std::string(name) + " " + how + ":\n" + diagnostics);
}

int CompilerChildMain(int argc, char** argv) {
  spdlog::set_level(spdlog::level::off);   // stdout carries the object file; errors are Status values
  CpuJitOptions options;
  options.pch_header.clear();
  options.compile_only = true;
  std::string name;
  double limit_s = 0;
  for (int i = 1; i + 1 < argc; i += 2) {
    std::string key = argv[i], value = argv[i + 1];
    if (key == "--name") name = value;
    else if (key == "--opt") options.opt_level = std::atoi(value.c_str());
    else if (key == "--native") options.native_cpu = value == "1";
    else if (key == "--limit") limit_s = std::atof(value.c_str());
    else if (key == "--pch") options.existing_pch = value;
    else if (key == "--include") options.include_dirs.push_back(value);
    else if (key == "--flag") options.extra_flags.push_back(value);
    else {
      std::cerr << "weft-cc: unknown argument " << key << "\n";
      return 3;
    }
  }
  if (argc % 2 != 1 || name.empty()) {
    std::cerr << "weft-cc: the compiler process of weftd (--name FILE [--opt N] [--native 0|1] [--limit S] "
                 "[--pch FILE] [--include DIR]... [--flag F]...; C++ source on stdin, object on stdout)\n";
    return 3;
  }
  // Never outlive the parent's limit, even when the parent is gone (nobody would kill us).
  if (limit_s > 0) ::alarm(static_cast<unsigned>(std::ceil(limit_s)) + 2);
  std::string source{std::istreambuf_iterator<char>(std::cin), std::istreambuf_iterator<char>()};
  auto jit = CpuJit::Create(options);
  if (!jit.ok()) {
    std::cerr << jit.status().message();
    return 2;
  }
  auto object = (*jit)->Compile(source, name);
  if (!object.ok()) {
    std::cerr << object.status().message();
    return object.status().code() == StatusCode::kInternal ? 1 : 2;
  }
  std::fwrite(object->data(), 1, object->size(), stdout);
  return std::fflush(stdout) == 0 ? 0 : 2;
}

}  // namespace weft::jit
