// weftd entry point: configuration, logging, the engine, the gRPC server (Unix sockets accepted
// by UnixListener, TCP with a token), keepalive, health service, the reaper of unattached
// sessions, and shutdown on SIGTERM/SIGINT within a bound: every session's work is cancelled
// and every compiler process killed first, then calls get 2 s to finish, then sessions are
// closed.
#include <dirent.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdlib>
#include <chrono>
#include <cstring>
#include <iostream>
#include <memory>
#include <thread>

#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/grpcpp.h>
#include <grpcpp/health_check_service_interface.h>
#include <spdlog/spdlog.h>

#include "engine/runtime/engine.h"
#if WEFT_WITH_CPU_JIT
#include "engine/jit/cpu/compile_process.h"
#endif
#include "server/call_auth.h"
#include "server/daemon_config.h"
#include "server/fast_lane.h"
#include "server/services.h"
#include "server/session_hosts.h"
#include "server/session_reaper.h"
#include "server/unix_listener.h"

using namespace weft;
using namespace weft::server;

namespace {

constexpr int kMaxMessageBytes = 64 << 20;

// Makes the socket's directory (0700 when we create it) and removes a stale socket file.
// Refuses when another daemon answers on it.
Status PrepareUnixSocket(const std::string& path) {
  if (path.size() >= sizeof(sockaddr_un::sun_path)) return InvalidArgument("socket path too long: " + path);
  std::string dir = path.substr(0, path.rfind('/'));
  if (!dir.empty()) {
    // mkdir -p with mode 0700 for every directory we create.
    for (size_t p = 1; p <= dir.size(); ++p) {
      if (p == dir.size() || dir[p] == '/') {
        std::string part = dir.substr(0, p);
        if (mkdir(part.c_str(), 0700) != 0 && errno != EEXIST)
          return Internal("cannot create " + part + ": " + std::strerror(errno));
      }
    }
  }
  struct stat st {};
  if (lstat(path.c_str(), &st) == 0) {
    if (!S_ISSOCK(st.st_mode)) return FailedPrecondition(path + " exists and is not a socket");
    int fd = socket(AF_UNIX, SOCK_STREAM, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::strncpy(addr.sun_path, path.c_str(), sizeof(addr.sun_path) - 1);
    bool alive = connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) == 0;
    close(fd);
    if (alive) return FailedPrecondition("another daemon is listening on " + path);
    unlink(path.c_str());
    spdlog::info("removed stale socket {}", path);
  }
  return Status::Ok();
}

// A session host keeps stdin/stdout/stderr and its readiness descriptor, nothing else the daemon
// that started it had open (slab memory files among them).
void CloseInheritedFds(int keep) {
  std::vector<int> fds;
  if (DIR* d = opendir("/proc/self/fd")) {
    while (dirent* e = readdir(d)) {
      const int fd = std::atoi(e->d_name);
      if (fd > 2 && fd != keep && fd != dirfd(d)) fds.push_back(fd);
    }
    closedir(d);
  }
  for (int fd : fds) close(fd);
}

std::string ThisExecutable() {
  char path[4096];
  const ssize_t n = readlink("/proc/self/exe", path, sizeof(path) - 1);
  return n > 0 ? std::string(path, static_cast<size_t>(n)) : std::string();
}

// A session host ends when its session has ended, when no session came within the attach
// timeout, or when the daemon that started it is gone.
void WatchSessionHost(Engine& engine, pid_t parent, double attach_timeout_s, const std::atomic<bool>& stopping) {
  const auto started = std::chrono::steady_clock::now();
  while (!stopping.load()) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    const EngineStats st = engine.Stats();
    const bool ended = st.sessions_opened_total > 0 && st.sessions == 0;
    const bool unused = st.sessions_opened_total == 0 &&
                        std::chrono::steady_clock::now() - started > std::chrono::duration<double>(attach_timeout_s);
    if (ended || unused || getppid() != parent) {
      spdlog::info("session host: {}; stopping", ended    ? "its session ended"
                                                  : unused ? "no session came"
                                                           : "the daemon that started it is gone");
      kill(getpid(), SIGTERM);
      return;
    }
  }
}

// A device host ends when the daemon that started it is gone, and when one of its GPUs was lost
// to a fault (the driver keeps that error for the life of the process): it removes its socket
// at once, so that the daemon sends new sessions of that device to a fresh process, gives the
// replies that report the fault a moment to go out, and stops. Its sessions' next calls find
// the process gone and their clients open new sessions.
void WatchDeviceHost(Engine& engine, pid_t parent, const std::string& socket, const std::atomic<bool>& stopping) {
  while (!stopping.load()) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    if (getppid() != parent) {
      spdlog::info("device host: the daemon that started it is gone; stopping");
      kill(getpid(), SIGTERM);
      return;
    }
    if (engine.AnyGpuLost()) {
      unlink(socket.c_str());
      unlink((socket + ".fast").c_str());
      spdlog::warn("device host: a GPU was lost to a kernel fault; this process ends, the daemon starts a new one "
                   "for the next session of this device");
      std::this_thread::sleep_for(std::chrono::milliseconds(250));
      kill(getpid(), SIGTERM);
      return;
    }
  }
}

}  // namespace

int main(int argc, char** argv) {
  int exit_code = 0;
  auto cfg = ParseDaemonConfig(argc, argv, &exit_code);
  if (!cfg.ok()) {
    if (cfg.status().code() == StatusCode::kCancelled) return exit_code;
    std::cerr << "weftd: " << cfg.status().message() << "\n";
    return 2;
  }
  spdlog::set_level(spdlog::level::from_str(cfg->log_level));
  spdlog::set_pattern(cfg->device_host()    ? "[%Y-%m-%d %H:%M:%S.%e] [weftd " + cfg->host_device + " %P] [%l] %v"
                      : cfg->session_host() ? "[%Y-%m-%d %H:%M:%S.%e] [weftd host %P] [%l] %v"
                                            : "[%Y-%m-%d %H:%M:%S.%e] [weftd] [%l] %v");
  if (cfg->session_host()) {
    CloseInheritedFds(cfg->host_ready_fd);
    // No PR_SET_PDEATHSIG: it fires when the *thread* that started the host ends (a gRPC
    // handler thread), not the daemon. WatchSessionHost compares getppid() on a timer instead.
    if (getppid() != static_cast<pid_t>(cfg->host_parent)) return 1;   // the daemon is already gone
    if (cfg->listen.size() != 1 || cfg->listen.front().rfind("unix:", 0) != 0) {
      std::cerr << "weftd: a session host listens on exactly one unix: address\n";
      return 2;
    }
  }

  // Every thread created from here on inherits the blocked set; one thread waits for them.
  sigset_t stop_signals;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGTERM);
  sigaddset(&stop_signals, SIGINT);
  pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);
  signal(SIGPIPE, SIG_IGN);
  umask(077);   // sockets 0600, slabs 0600, cache files private

  std::string token;
  if (!cfg->token_file.empty()) {
    auto t = ReadTokenFile(cfg->token_file);
    if (!t.ok()) {
      std::cerr << "weftd: " << t.status().message() << "\n";
      return 2;
    }
    token = *t;
  }
  std::vector<std::string> unix_paths;
  for (const auto& l : cfg->listen) {
    if (l.rfind("tcp:", 0) == 0 && token.empty()) {
      std::cerr << "weftd: --listen " << l << " needs --token-file (TCP clients must send a token)\n";
      return 2;
    }
    if (l.rfind("unix:", 0) == 0) {
      std::string path = l.substr(5);
      Status st = PrepareUnixSocket(path);
      if (!st.ok()) {
        std::cerr << "weftd: " << st.message() << "\n";
        return 2;
      }
      unix_paths.push_back(path);
    }
  }

  EngineOptions eo;
  eo.cpu_threads = cfg->cpu_threads;
  eo.limits.max_launch_threads = cfg->max_launch_threads;
  eo.limits.max_queued_commands = cfg->max_queued_commands;
  eo.launch_time_limit_s = cfg->launch_time_limit_s;
  eo.modules.compile_time_limit_s = cfg->compile_time_limit_s;
  eo.max_sessions_per_principal = cfg->max_sessions_per_principal;
  eo.modules.disk_capacity_bytes = cfg->cache_max_bytes;
  // Unchecked kernels run only in session hosts; the daemon sends unchecked sessions there.
  // A device host serves checked sessions only (an unchecked one there could fault a GPU that
  // other principals' sessions use).
  eo.allow_unchecked = cfg->allow_unchecked && cfg->session_host() && !cfg->device_host();
  eo.session_host = cfg->session_host();
  eo.device_host = cfg->device_host();
  if (cfg->host_device == "cpu") eo.use_gpus = false;
  if (cfg->device_host() && cfg->host_device != "cpu") eo.only_gpu = std::stoi(cfg->host_device.substr(5));
  eo.memory.daemon = cfg->max_memory;
  eo.memory.per_principal = cfg->max_principal_memory;
  eo.memory.per_session = cfg->max_session_memory;
  eo.modules.cache_dir = cfg->cache_dir;
  eo.modules.native_dir = cfg->native_dir.empty() ? WEFT_NATIVE_DIR : cfg->native_dir;
  eo.modules.verify_cuda = cfg->verify_cuda;
  eo.modules.verify_cuda_archs = cfg->verify_cuda_archs;
  eo.modules.limits.max_module_bytes = cfg->max_module_bytes;
  eo.modules.limits.max_functions = cfg->max_functions;
  eo.modules.limits.max_block_depth = cfg->max_block_depth;
  eo.modules.limits.max_expression_depth = cfg->max_expression_depth;
  auto engine = Engine::Create(eo);
  if (!engine.ok()) {
    std::cerr << "weftd: " << engine.status().message() << "\n";
    return 1;
  }

  auto unix_listener = UnixListener::Listen(unix_paths);
  if (!unix_listener.ok()) {
    std::cerr << "weftd: " << unix_listener.status().message() << "\n";
    return 1;
  }
  CallAuth auth(**engine, token, unix_listener->get());
  if (cfg->session_host() && !cfg->device_host()) auth.RestrictTo(cfg->host_principal);
  std::unique_ptr<SessionHosts> hosts;
  if ((cfg->allow_unchecked || cfg->isolate_sessions || cfg->device_hosts) && !cfg->session_host() &&
      !unix_paths.empty()) {
    hosts = std::make_unique<SessionHosts>(ThisExecutable(), SessionHostArguments(*cfg), unix_paths.front(),
                                           cfg->max_session_hosts, /*start_timeout_s=*/60);
  }
  // The fast lane (server/fast_lane.h) beside the first Unix socket: <path>.fast. Its stale
  // file goes (the daemon that owned it is gone: the gRPC socket beside it was stale too).
  std::unique_ptr<FastLane> fast_lane;
  if (!unix_paths.empty()) {
    const std::string fast_path = unix_paths.front() + ".fast";
    unlink(fast_path.c_str());
    auto lane = FastLane::Listen(**engine, fast_path);
    if (lane.ok()) {
      fast_lane = std::move(lane).value();
    } else {
      spdlog::warn("{}; local clients use gRPC only", lane.status().message());
    }
  }
  SessionReaper reaper(**engine, cfg->attach_timeout_s);   // before the services: Attach queues reaps to it
  SessionServiceImpl::Routing routing;
  routing.single_session = cfg->session_host() && !cfg->device_host();
  routing.unchecked_hosts = cfg->allow_unchecked && !cfg->session_host();
  routing.isolate = cfg->isolate_sessions && !cfg->session_host();
  routing.device_hosts = cfg->device_hosts && !cfg->session_host();
  SessionServiceImpl session_service(auth, reaper, fast_lane.get(), hosts.get(), routing);
  ArrayServiceImpl array_service(auth);
  ExecServiceImpl exec_service(auth);
  ModuleServiceImpl module_service(auth);
  DeviceServiceImpl device_service(auth);
  GeometryServiceImpl geometry_service(auth);

  grpc::EnableDefaultHealthCheckService(true);
  grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  grpc::ServerBuilder builder;
  for (const auto& l : cfg->listen)   // unix: paths are accepted by the UnixListener
    if (l.rfind("tcp:", 0) == 0) builder.AddListeningPort(l.substr(4), grpc::InsecureServerCredentials());
  builder.SetMaxReceiveMessageSize(kMaxMessageBytes);
  builder.SetMaxSendMessageSize(kMaxMessageBytes);
  builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_TIME_MS, 2000);
  builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_TIMEOUT_MS, 3000);
  builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS, 1);
  builder.AddChannelArgument(GRPC_ARG_HTTP2_MAX_PINGS_WITHOUT_DATA, 0);
  builder.AddChannelArgument(GRPC_ARG_HTTP2_MIN_RECV_PING_INTERVAL_WITHOUT_DATA_MS, 1000);
  builder.RegisterService(&session_service);
  builder.RegisterService(&array_service);
  builder.RegisterService(&exec_service);
  builder.RegisterService(&module_service);
  builder.RegisterService(&device_service);
  builder.RegisterService(&geometry_service);
  std::unique_ptr<grpc::Server> server = builder.BuildAndStart();
  if (!server) {
    std::cerr << "weftd: could not listen on every address (in use, or a bad address)\n";
    return 1;
  }
  (*unix_listener)->Start(server.get());
  if (fast_lane) fast_lane->Start();
  for (const auto& l : cfg->listen) spdlog::info("listening on {}", l);
  if (fast_lane) spdlog::info("fast lane on {}", fast_lane->path());
  spdlog::info("weftd {} ready (pid {}, {} CPU threads{})", WEFT_VERSION, getpid(), (*engine)->pool().size(),
               cfg->device_host()     ? ", device host of " + cfg->host_device
               : cfg->session_host()  ? ", session host of " + cfg->host_principal
               : cfg->allow_unchecked ? ", unchecked sessions allowed (each in a process of its own)"
                                      : "");
  std::atomic<bool> stopping{false};
  std::thread host_watch;
  if (cfg->session_host()) {
    if (cfg->host_ready_fd >= 0) {
      const char ready = 'r';
      (void)!write(cfg->host_ready_fd, &ready, 1);
      close(cfg->host_ready_fd);
    }
    if (cfg->device_host())
      host_watch = std::thread(WatchDeviceHost, std::ref(**engine), static_cast<pid_t>(cfg->host_parent),
                               unix_paths.front(), std::cref(stopping));
    else
      host_watch = std::thread(WatchSessionHost, std::ref(**engine), static_cast<pid_t>(cfg->host_parent),
                               cfg->attach_timeout_s, std::cref(stopping));
  }

  std::thread waiter([&] {
    int sig = 0;
    sigwait(&stop_signals, &sig);
    spdlog::info("signal {} received: shutting down", sig);
    stopping = true;
    (*unix_listener)->Stop();
    if (fast_lane) fast_lane->Stop();
    if (hosts) hosts->StopAll();
    (*engine)->CancelAllSessions();   // running kernels stop at their next poll
#if WEFT_WITH_CPU_JIT
    jit::StopCompilerChildren();      // running compiles end now (Unavailable)
#endif
    server->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(2));
  });
  server->Wait();
  waiter.join();
  if (host_watch.joinable()) host_watch.join();
  hosts.reset();
  reaper.Stop();
  if (fast_lane) {
    fast_lane->Join();
    unlink(fast_lane->path().c_str());
    fast_lane.reset();
  }
  server.reset();
  (*engine).reset();   // closes sessions, unlinks every slab
  for (const auto& p : unix_paths) unlink(p.c_str());
  spdlog::info("weftd stopped");
  return 0;
}
