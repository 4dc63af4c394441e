// FastLane: listening, the hello (peer uid + one-time secret), serving Submit (plain or quiet:
// answered only when it fails), Synchronize, ArrayService Create/Free/Describe/ImportCuda and
// GeometryService.Call frames through the gRPC methods' handler functions, replies in chunks.
#include "server/fast_lane.h"

#include <fcntl.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <string_view>
#include <thread>
#include <vector>

#include <google/protobuf/arena.h>
#include <spdlog/spdlog.h>

#include "engine/core/frame_trace.h"
#include "engine/runtime/ipc_token.h"
#include "server/lane_ring.h"
#include "server/spin_window.h"
#include "server/services.h"
#include "weft/v1/array.pb.h"
#include "weft/v1/exec.pb.h"
#include "weft/v1/session.pb.h"

namespace weft::server {

namespace {

void PutU32(std::string* out, uint32_t v) {
  for (int i = 0; i < 4; ++i) out->push_back(static_cast<char>((v >> (8 * i)) & 0xff));
}
uint32_t GetU32(const char* p) {
  uint32_t v = 0;
  for (int i = 0; i < 4; ++i) v |= static_cast<uint32_t>(static_cast<unsigned char>(p[i])) << (8 * i);
  return v;
}

// Where a connection's frames go: the socket, or once the client opened one, the ring
// (LaneRing), with the socket left for wake frames.
struct LaneIo {
  int fd = -1;
  LaneRing* ring = nullptr;
};

// Sends a wake frame to a client asleep on its ring's socket: a reply header with
// FastLane::kWakeReplyFlag and nothing else. A full socket buffer already holds wake frames.
void SendWake(int fd) {
  std::string frame;
  PutU32(&frame, 0);
  PutU32(&frame, FastLane::kWakeReplyFlag);
  (void)!send(fd, frame.data(), frame.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
}

// Puts one reply frame into the ring, waiting while the client has not read enough to make
// room (polling the socket for its hang-up: a client that never reads holds only this lane's
// thread). False when the peer is gone or its tail broke the ring.
bool PutRingFrame(const LaneIo& io, const std::string& frame) {
  int wait_ms = 0;
  for (;;) {
    bool asleep = false, corrupt = false;
    std::string why;
    if (io.ring->TryPutReply(frame.data(), frame.size(), &asleep, &corrupt, &why)) {
      if (asleep) SendWake(io.fd);
      return true;
    }
    if (corrupt) {
      spdlog::warn("fast lane: {}; the connection ends", why);
      return false;
    }
    if (wait_ms == 0) {
      std::this_thread::yield();
    } else {
      pollfd p{io.fd, 0, 0};
      if (poll(&p, 1, wait_ms) > 0 && (p.revents & (POLLHUP | POLLERR | POLLNVAL))) return false;
    }
    wait_ms = std::min(wait_ms * 2 + 1, 100);
  }
}

// Sends `payload` as one reply (several frames when it is larger than a chunk). False when
// the peer is gone. `extra_flags`: FastLane::kQuietReplyFlag on the error of a quiet Submit.
bool SendReply(const LaneIo& io, StatusCode code, const std::string& payload, bool closing = false,
               uint32_t extra_flags = 0) {
  size_t off = 0;
  do {
    const size_t n = std::min(FastLane::kReplyChunkBytes, payload.size() - off);
    const bool more = off + n < payload.size();
    std::string frame;
    frame.reserve(8 + n);
    PutU32(&frame, static_cast<uint32_t>(code));
    PutU32(&frame, (more ? 1u : 0u) | (closing ? 2u : 0u) | extra_flags);
    frame.append(payload, off, n);
    if (io.ring) {
      if (!PutRingFrame(io, frame)) return false;
    } else {
      ssize_t w;
      do {
        w = send(io.fd, frame.data(), frame.size(), MSG_NOSIGNAL);
      } while (w < 0 && errno == EINTR);
      if (w != static_cast<ssize_t>(frame.size())) return false;
    }
    off += n;
  } while (off < payload.size());
  return true;
}
// An error reply; `closing`: the daemon ends the connection after it (a frame it cannot go on
// from), else (the request's own error, as gRPC would return it) the lane stays usable.
bool SendError(const LaneIo& io, const Status& st, bool closing = true) {
  return SendReply(io, st.code(), st.message(), closing);
}

enum class FrameResult { kContinue, kEnd, kUnknownMethod };
// When a served frame gets a reply: always (the plain methods), only on failure, flagged
// kQuietReplyFlag (quiet Submit), or never (unanswered Free; a failure is logged).
enum class Answer { kAlways, kOnFailure, kNever };

// A client sends its next frame soon after a synchronizing reply (a launch + synchronize
// loop), after the reply to a GPU-only batch (it goes on queueing launches), and, once its
// session works on a GPU, after an array frame (a training step makes arrays, imports
// framework tensors and frees them between its launches): polling for it a while avoids a
// thread wake-up per frame (and the client's wake frame), which cost more than the daemon's
// work on such a frame. Not after other frames of a session that never touched a GPU (the CPU
// device's kernels need the cores); on machines of 4 cores or more, at most a quarter of the
// cores' worth of lanes at once. How long: from 60 up to 400 us, following the client's gaps
// between frames (server/spin_window.h: a client whose Python takes 150 us between frames is
// polled for about 300 us; one that paused gets 60 us); after that without a frame the lane
// thread blocks as before. WEFT_LANE_POLLERS=N overrides the number of lanes that may
// poll at once.
std::atomic<int> spinning_lanes{0};

int MaxSpinningLanes() {
  static const int max_spinning = [] {
    // WEFT_LANE_POLLERS overrides how many lanes may poll at once (0: none).
    if (const char* env = std::getenv("WEFT_LANE_POLLERS")) return std::clamp(std::atoi(env), 0, 1024);
    return static_cast<int>(std::thread::hardware_concurrency() / 4);
  }();
  return max_spinning;
}

// Whether lanes follow their clients' gaps and poll after the array frames of GPU sessions
// (WEFT_LANE_ADAPTIVE_SPIN=0: a fixed 60 us after synchronizing and GPU-only frames only,
// the behaviour before, kept for measuring one against the other).
bool AdaptiveSpin() {
  static const bool adaptive = [] {
    const char* env = std::getenv("WEFT_LANE_ADAPTIVE_SPIN");
    return !(env && std::string_view(env) == "0");
  }();
  return adaptive;
}

// Calls `poll` until it returns true or `window` passed; false at once when as many lanes as
// may poll already do.
template <typename Poll>
bool SpinFor(std::chrono::steady_clock::duration window, Poll&& poll) {
  if (spinning_lanes.fetch_add(1) >= MaxSpinningLanes()) {
    spinning_lanes.fetch_sub(1);
    return false;
  }
  const auto until = std::chrono::steady_clock::now() + window;
  bool got = false;
  do {
    got = poll();
  } while (!got && std::chrono::steady_clock::now() < until);
  spinning_lanes.fetch_sub(1);
  return got;
}

ssize_t SpinReceive(int fd, msghdr* msg, std::chrono::steady_clock::duration window) {
  ssize_t n = -1;
  SpinFor(window, [&] {
    n = recvmsg(fd, msg, MSG_DONTWAIT);
    if (n >= 0 || (errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR)) return true;
    n = -1;
    return false;
  });
  return n;
}

// Whether this daemon offers rings (LaneRing): WEFT_LANE_RING=0 never, =1 wherever the kernel
// has the barrier, otherwise where lanes may poll (on fewer than 4 cores a lane never polls,
// and a ring would then cost a wake frame and a barrier per frame).
bool RingsOffered() {
  static const bool offered = [] {
    const char* env = std::getenv("WEFT_LANE_RING");
    if (env && std::string(env) == "0") return false;
    if (!LaneRing::Supported()) return false;
    return (env && std::string(env) == "1") || MaxSpinningLanes() > 0;
  }();
  return offered;
}

// Sends the reply to a ring's opening: OK, the region's size (u64), and the memfd attached.
bool SendRingReply(int fd, const LaneRing& ring) {
  std::string frame;
  PutU32(&frame, 0);
  PutU32(&frame, 0);
  const uint64_t size = ring.size();
  for (int i = 0; i < 8; ++i) frame.push_back(static_cast<char>((size >> (8 * i)) & 0xff));
  iovec iov{frame.data(), frame.size()};
  alignas(cmsghdr) char control[CMSG_SPACE(sizeof(int))] = {};
  msghdr msg{};
  msg.msg_iov = &iov;
  msg.msg_iovlen = 1;
  msg.msg_control = control;
  msg.msg_controllen = sizeof(control);
  cmsghdr* c = CMSG_FIRSTHDR(&msg);
  c->cmsg_level = SOL_SOCKET;
  c->cmsg_type = SCM_RIGHTS;
  c->cmsg_len = CMSG_LEN(sizeof(int));
  const int ring_fd = ring.fd();
  std::memcpy(CMSG_DATA(c), &ring_fd, sizeof(int));
  ssize_t w;
  do {
    w = sendmsg(fd, &msg, MSG_NOSIGNAL);
  } while (w < 0 && errno == EINTR);
  return w == static_cast<ssize_t>(frame.size());
}

// Whether a batch only queues work on GPU streams: kernel launches on "cuda..." devices and
// stream orderings (events, stream memory operations). Copies, fills, tapes and graphs may do
// host work (a CPU copy, a list replay, a backward pass on the CPU).
bool OnlyQueuesGpuWork(const v1::SubmitRequest& req) {
  for (const v1::Command& c : req.commands()) {
    if (c.has_cuda_value() || c.has_cuda_event()) continue;
    if (c.has_launch() && c.launch().device().rfind("cuda", 0) == 0) continue;
    return false;
  }
  return true;
}

// WEFT_LANE_TRACE: when each phase of a frame ended (frame_trace::NowNs).
struct FrameTimes {
  int64_t received = 0, parsed = 0, served = 0, replied = 0;
};

// WEFT_LANE_TRACE: the phases of one connection's frames, by kind, summarized when it ends.
class LaneTrace {
 public:
  // At most kMaxSamples frames of a kind are kept (the latest ones, in a ring).
  static constexpr size_t kMaxSamples = 1u << 18;
  void Add(const char* kind, int64_t idle_ns, const FrameTimes& t, const frame_trace::Phases& p) {
    Samples& s = by_kind_[kind];
    const int64_t values[kPhases] = {idle_ns,           t.parsed - t.received, t.served - t.parsed,
                                     p.device_sync_ns,  p.stream_wait_ns,      p.stream_polls,
                                     t.replied - t.served, p.gpu_launch_ns, p.driver_launch_ns};
    for (int i = 0; i < kPhases; ++i) {
      if (s.phase[i].size() < kMaxSamples) s.phase[i].push_back(values[i]);
      else s.phase[i][s.frames % kMaxSamples] = values[i];
    }
    if (p.stream_blocks > 0) ++s.blocked;
    ++s.frames;
  }
  // One line per kind: medians (us) of each phase. Appended to the file WEFT_LANE_TRACE names.
  void Write(const std::string& session) {
    std::string out;
    for (auto& [kind, s] : by_kind_) {
      char line[512];
      std::snprintf(line, sizeof(line),
                    "lane-trace session=%s kind=%s frames=%zu median_us: before=%.1f parse=%.1f serve=%.1f "
                    "(device_sync=%.1f stream_wait=%.1f polls=%.0f gpu_launch=%.1f driver_launch=%.1f) "
                    "reply=%.1f blocked_frames=%zu\n",
                    session.c_str(), kind.c_str(), s.frames, Median(s.phase[0]) / 1e3, Median(s.phase[1]) / 1e3,
                    Median(s.phase[2]) / 1e3, Median(s.phase[3]) / 1e3, Median(s.phase[4]) / 1e3,
                    Median(s.phase[5]), Median(s.phase[7]) / 1e3, Median(s.phase[8]) / 1e3,
                    Median(s.phase[6]) / 1e3, s.blocked);
      out += line;
    }
    if (out.empty()) return;
    const char* path = std::getenv("WEFT_LANE_TRACE");
    int f = open(path, O_WRONLY | O_APPEND | O_CREAT | O_CLOEXEC, 0600);
    if (f < 0) {
      spdlog::info("{}", out);
      return;
    }
    (void)!write(f, out.data(), out.size());
    close(f);
  }

 private:
  // before (client time), parse, serve, device sync, stream wait, stream polls, reply, GPU
  // launch, driver launch call
  static constexpr int kPhases = 9;
  struct Samples {
    size_t frames = 0;
    size_t blocked = 0;   // frames whose stream wait blocked on the stream's host function
    std::vector<int64_t> phase[kPhases];
  };
  static double Median(std::vector<int64_t>& v) {
    if (v.empty()) return 0;
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return static_cast<double>(v[v.size() / 2]);
  }
  std::map<std::string, Samples> by_kind_;
};

// One request frame of a bound connection: parses the body as Req, serves it with
// `serve(session, request, &response)` (the gRPC method's handler function), and replies as
// `answer` says. A
// body that does not parse ends the connection; the handler's error is the reply and the lane
// stays open. The session reference is released before the reply is sent, so a slow peer
// never holds a closed session alive. `times` (WEFT_LANE_TRACE) gets the phases' end times.
template <typename Req, typename Resp, typename Fn>
FrameResult ServeFrame(const LaneIo& io, const char* name, const char* body, int body_len, std::shared_ptr<Session>& s,
                       Fn&& serve, FrameTimes* times = nullptr, Answer answer = Answer::kAlways) {
  // The request and response live on an arena: a Submit of many launches parses into a few
  // blocks (the first on this stack) instead of one heap allocation per message and string.
  alignas(16) char first_block[16384];
  google::protobuf::ArenaOptions options;
  options.initial_block = first_block;
  options.initial_block_size = sizeof(first_block);
  google::protobuf::Arena arena(options);
  Req& req = *google::protobuf::Arena::CreateMessage<Req>(&arena);
  if (!req.ParseFromArray(body, body_len)) {
    SendError(io, InvalidArgument(std::string("fast lane: a ") + name + " frame that does not parse"));
    return FrameResult::kEnd;
  }
  Resp& resp = *google::protobuf::Arena::CreateMessage<Resp>(&arena);
  if (times) times->parsed = frame_trace::NowNs();
  Status st = serve(*s, req, &resp);
  s.reset();
  if (times) times->served = frame_trace::NowNs();
  FrameResult r;
  if (answer == Answer::kNever) {
    if (!st.ok()) spdlog::debug("fast lane: unanswered {} failed: {}", name, st.ToString());
    r = FrameResult::kContinue;
  } else if (!st.ok()) {
    const uint32_t flags = answer == Answer::kOnFailure ? FastLane::kQuietReplyFlag : 0;
    r = SendReply(io, st.code(), st.message(), /*closing=*/false, flags) ? FrameResult::kContinue
                                                                          : FrameResult::kEnd;
  } else if (answer == Answer::kOnFailure) {
    r = FrameResult::kContinue;   // answered only when it fails
  } else {
    std::string out;
    resp.SerializeToString(&out);
    r = SendReply(io, StatusCode::kOk, out) ? FrameResult::kContinue : FrameResult::kEnd;
  }
  if (times) times->replied = frame_trace::NowNs();
  return r;
}

}  // namespace

Expected<std::unique_ptr<FastLane>> FastLane::Listen(Engine& engine, const std::string& path) {
  sockaddr_un addr{};
  if (path.size() >= sizeof(addr.sun_path)) return InvalidArgument("fast-lane socket path too long: " + path);
  int fd = socket(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0);
  if (fd < 0) return Unavailable(std::string("fast lane: socket: ") + std::strerror(errno));
  addr.sun_family = AF_UNIX;
  std::strncpy(addr.sun_path, path.c_str(), sizeof(addr.sun_path) - 1);
  if (bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0 || listen(fd, 128) != 0) {
    std::string err = std::strerror(errno);
    close(fd);
    return Unavailable("fast lane: cannot listen on " + path + ": " + err);
  }
  auto lane = std::unique_ptr<FastLane>(new FastLane(engine, path, fd));
  if (pipe2(lane->wake_fds_, O_CLOEXEC) != 0) return Unavailable("fast lane: pipe failed");
  return lane;
}

FastLane::~FastLane() {
  Stop();
  Join();
  if (listen_fd_ >= 0) close(listen_fd_);
  for (int f : wake_fds_)
    if (f >= 0) close(f);
}

std::string FastLane::NewSecret(const std::string& id, const std::string& principal) {
  std::string secret = NewIpcSecret() + NewIpcSecret();   // 256 random bits, hex
  std::lock_guard<std::mutex> lock(mu_);
  // Secrets of sessions that closed without connecting go; the map stays as large as the
  // number of open sessions.
  for (auto it = secrets_.begin(); it != secrets_.end();)
    it = engine_.FindSession(it->first) ? std::next(it) : secrets_.erase(it);
  secrets_[id] = Pending{secret, principal};
  return secret;
}

void FastLane::Start() { accept_thread_ = std::thread([this] { AcceptLoop(); }); }

void FastLane::Stop() {
  std::lock_guard<std::mutex> lock(mu_);
  if (stopped_) return;
  stopped_ = true;
  if (wake_fds_[1] >= 0) {
    char b = 1;
    (void)!write(wake_fds_[1], &b, 1);
  }
  for (auto& c : conns_)
    if (c.fd >= 0) shutdown(c.fd, SHUT_RDWR);
}

void FastLane::Join() {
  if (accept_thread_.joinable()) accept_thread_.join();
  std::list<Conn> conns;
  {
    std::lock_guard<std::mutex> lock(mu_);
    conns.splice(conns.end(), conns_);
  }
  for (auto& c : conns) {
    if (c.thread.joinable()) c.thread.join();
    if (c.fd >= 0) close(c.fd);
  }
}

void FastLane::ReapFinished() {
  for (auto it = conns_.begin(); it != conns_.end();) {
    if (it->done.load()) {
      it->thread.join();
      it = conns_.erase(it);
    } else {
      ++it;
    }
  }
}

void FastLane::AcceptLoop() {
  for (;;) {
    pollfd fds[2] = {{listen_fd_, POLLIN, 0}, {wake_fds_[0], POLLIN, 0}};
    int r = poll(fds, 2, -1);
    if (r < 0 && errno == EINTR) continue;
    if (r < 0 || (fds[1].revents & POLLIN)) return;
    if (!(fds[0].revents & POLLIN)) continue;
    int fd = accept4(listen_fd_, nullptr, nullptr, SOCK_CLOEXEC);
    if (fd < 0) continue;
    std::lock_guard<std::mutex> lock(mu_);
    ReapFinished();
    if (stopped_ || conns_.size() >= kMaxConnections) {
      if (!stopped_) spdlog::warn("fast lane: {} connections open, one refused", conns_.size());
      close(fd);
      continue;
    }
    conns_.emplace_back();
    Conn* c = &conns_.back();
    c->fd = fd;
    c->thread = std::thread([this, c] {
      Serve(c);
      std::lock_guard<std::mutex> lock(mu_);   // the fd goes as soon as its peer does
      close(c->fd);
      c->fd = -1;
      c->done.store(true);
    });
  }
}

void FastLane::Serve(Conn* c) {
  const int fd = c->fd;
  LaneIo io{fd, nullptr};
  std::unique_ptr<LaneRing> ring;   // once the client opened one
  ucred cred{};
  socklen_t len = sizeof(cred);
  if (getsockopt(fd, SOL_SOCKET, SO_PEERCRED, &cred, &len) != 0) return;
  const std::string principal = "unix-uid:" + std::to_string(cred.uid);
  timeval hello_timeout{kHelloTimeoutS, 0};
  setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &hello_timeout, sizeof(hello_timeout));

  // Small until the hello is accepted: connections that never bind cost little memory.
  std::vector<char> buf(kMaxHelloBytes + 1);
  std::string session_id;
  bool spin_next = false;   // the client is expected to send again soon (SpinWindow)
  // the session queued GPU work or made GPU arrays through this lane (WEFT_LANE_ADAPTIVE_SPIN=0:
  // never set, so array frames are not followed by polling)
  bool works_on_gpu = false;
  const bool adaptive_spin = AdaptiveSpin();
  SpinWindow spin_window(adaptive_spin);
  const bool trace = frame_trace::Enabled();
  std::unique_ptr<LaneTrace> lane_trace = trace ? std::make_unique<LaneTrace>() : nullptr;
  struct WriteTrace {
    std::unique_ptr<LaneTrace>& t;
    std::string& id;
    ~WriteTrace() {
      if (t && !id.empty()) t->Write(id.substr(0, 8));
    }
  } write_trace{lane_trace, session_id};
  int64_t last_replied = 0;
  FrameTimes times;
  const char* kind = nullptr;
  // The next request frame into `buf`: its length, or -1 when the connection ends (peer gone,
  // shut down, no hello in time, or a frame the lane cannot go on from, answered).
  int idle_wake_pause_ms = 0;   // ring: the pause after a wake that found no record
  bool slept = false;           // the last frame came after the lane thread blocked for it
  auto receive = [&]() -> ssize_t {
    slept = false;
    if (ring) {
      for (;;) {
        size_t len = 0;
        std::string why;
        const LaneRing::Take take = ring->TakeRequest(buf.data(), buf.size(), &len, &why);
        if (take == LaneRing::Take::kFrame) {
          spin_next = false;
          idle_wake_pause_ms = 0;
          return static_cast<ssize_t>(len);
        }
        if (take == LaneRing::Take::kCorrupt) {
          SendError(io, InvalidArgument(why));
          return -1;
        }
        if (spin_next && SpinFor(spin_window.window(), [&] { return ring->RequestPublished(); })) continue;
        spin_next = false;
        // Wake frames left from before (the client saw the flag just as weftd found its
        // record) go first: only a wake sent after the flag below was set may end the sleep.
        char wake[16];
        ssize_t n;
        while ((n = recv(fd, wake, sizeof(wake), MSG_DONTWAIT)) > 0) {
          if (n != 4 || GetU32(wake) != kRingWake) {
            SendError(io, InvalidArgument("fast lane: only wake frames may come on the socket of a ring"));
            return -1;
          }
        }
        if (n == 0) return -1;
        if (!ring->SleepUnlessPublished()) continue;
        slept = true;
        do {
          n = recv(fd, wake, sizeof(wake), 0);
        } while (n < 0 && errno == EINTR);
        ring->Wake();
        if (n <= 0) return -1;
        if (n != 4 || GetU32(wake) != kRingWake) {
          SendError(io, InvalidArgument("fast lane: only wake frames may come on the socket of a ring"));
          return -1;
        }
        // A wake with no record behind it: a client follows a record with a wake, so this one
        // wakes weftd for nothing. Each sleep costs a barrier on every CPU running a ring's
        // client, so such wakes are answered with growing pauses (1 ms doubling to 128 ms,
        // back to none with the next record): a client cannot make weftd disturb the others.
        if (!ring->RequestPublished()) {
          idle_wake_pause_ms = std::min(idle_wake_pause_ms == 0 ? 1 : 2 * idle_wake_pause_ms, 128);
          pollfd p{fd, 0, 0};
          if (poll(&p, 1, idle_wake_pause_ms) > 0 && (p.revents & (POLLHUP | POLLERR | POLLNVAL))) return -1;
        }
      }
    }
    iovec iov{buf.data(), buf.size()};
    msghdr msg{};
    msg.msg_iov = &iov;
    msg.msg_iovlen = 1;
    ssize_t n = spin_next ? SpinReceive(fd, &msg, spin_window.window()) : -1;
    spin_next = false;
    if (n < 0) {
      slept = true;
      do {
        n = recvmsg(fd, &msg, 0);
      } while (n < 0 && errno == EINTR);
    }
    if (n <= 0) return -1;   // peer gone, shut down, or no hello in time
    const size_t limit = session_id.empty() ? kMaxHelloBytes : kMaxRequestBytes;
    if ((msg.msg_flags & MSG_TRUNC) || static_cast<size_t>(n) > limit) {
      SendError(io, InvalidArgument("fast lane: frame larger than " + std::to_string(limit) + " bytes"));
      return -1;
    }
    return n;
  };
  const std::string capabilities = std::string(kHelloCapabilities) + (RingsOffered() ? " ring" : "");
  for (;;) {
    const ssize_t n = receive();
    if (n < 0) return;
    spin_window.FrameArrived(std::chrono::steady_clock::now(), slept);
    if (trace) {
      times = FrameTimes{};
      times.received = frame_trace::NowNs();
      frame_trace::Reset();
      kind = nullptr;
    }
    if (n < 4) {
      SendError(io, InvalidArgument("fast lane: frame shorter than its header"));
      return;
    }
    const uint32_t method = GetU32(buf.data());
    const char* body = buf.data() + 4;
    const int body_len = static_cast<int>(n - 4);

    if (session_id.empty()) {   // the hello
      v1::FastLaneHello hello;
      if (method != kHello || !hello.ParseFromArray(body, body_len)) {
        SendError(io, InvalidArgument("fast lane: the first frame must be a hello"));
        return;
      }
      Status st = Status::Ok();
      {
        std::lock_guard<std::mutex> lock(mu_);
        auto it = secrets_.find(hello.session_id());
        if (it == secrets_.end() || it->second.principal != principal || !SecretsEqual(hello.secret(), it->second.secret)) {
          st = PermissionDenied("fast lane: unknown session, wrong secret, or a secret already used");
        } else {
          secrets_.erase(it);   // one connection per secret
        }
      }
      if (st.ok() && !engine_.FindSession(hello.session_id()))
        st = FailedPrecondition("fast lane: the session is closed");
      if (!st.ok()) {
        spdlog::warn("fast lane: hello refused from {}: {}", principal, st.message());
        SendError(io, st);
        return;
      }
      session_id = hello.session_id();
      buf.resize(kMaxRequestBytes + 1);
      timeval none{0, 0};
      setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &none, sizeof(none));
      if (!SendReply(io, StatusCode::kOk, capabilities)) return;
      continue;
    }

    if (method == kRingOpen) {
      if (ring) {
        SendError(io, InvalidArgument("fast lane: the ring is open already"));
        return;
      }
      if (!RingsOffered()) {
        if (!SendReply(io, StatusCode::kFailedPrecondition, "fast lane: this daemon offers no ring")) return;
        continue;
      }
      auto created = LaneRing::Create(kMaxRequestBytes);
      if (!created.ok()) {
        spdlog::warn("fast lane: {}", created.status().message());
        if (!SendReply(io, created.status().code(), created.status().message())) return;
        continue;
      }
      if (!SendRingReply(fd, **created)) return;
      ring = std::move(*created);
      ring->CloseFd();
      io.ring = ring.get();
      continue;
    }
    std::shared_ptr<Session> s = engine_.FindSession(session_id);
    if (!s || s->options().principal != principal) {
      SendError(io, FailedPrecondition("no session: the fast lane's session is closed"));
      return;
    }
    Engine& engine = engine_;
    FrameResult r = FrameResult::kUnknownMethod;
    switch (method) {
      case kSubmit:
      case kSubmitQuiet:
        r = ServeFrame<v1::SubmitRequest, v1::SubmitResponse>(io, "Submit", body, body_len, s,
            [&](Session& ss, const auto& req, auto* resp) {
              if (method == kSubmitQuiet && (req.synchronize() || req.run()))
                return InvalidArgument("fast lane: a quiet Submit cannot synchronize or run (nothing would answer it)");
              // A GPU-only batch is queued on streams in microseconds: it runs here when the
              // session's executor is idle, and the client's next frame (it queues on while
              // this one is answered) is polled for. Any other batch (CPU kernels need the
              // cores) goes to the executor thread, and the lane then waits in recvmsg.
              const bool gpu_only = OnlyQueuesGpuWork(req);
              spin_next = req.synchronize() || req.run() || gpu_only;
              works_on_gpu = works_on_gpu || (adaptive_spin && gpu_only);
              if (trace)
                kind = req.synchronize() ? (gpu_only ? "submit-gpu+sync" : "submit+sync")
                                         : (gpu_only ? "submit-gpu" : "submit");
              return ExecSubmit(engine, ss, req, resp, gpu_only);
            }, trace ? &times : nullptr, method == kSubmitQuiet ? Answer::kOnFailure : Answer::kAlways);
        break;
      case kSynchronize:
        spin_next = true;
        kind = "synchronize";
        r = ServeFrame<v1::SynchronizeRequest, v1::SynchronizeResponse>(io, "Synchronize", body, body_len, s,
            [&](Session& ss, const auto&, auto* resp) { ExecSynchronize(engine, ss, resp); return Status::Ok(); },
            trace ? &times : nullptr);
        break;
      case kArrayCreate:
        r = ServeFrame<v1::CreateArrayRequest, v1::CreateArrayResponse>(io, "ArrayService.Create", body, body_len, s,
            [&](Session& ss, const auto& req, auto* resp) {
              works_on_gpu = works_on_gpu || (adaptive_spin && req.device().starts_with("cuda"));
              return ArrayCreate(engine, ss, req, resp);
            });
        spin_next = works_on_gpu;
        break;
      case kArrayFree:
        r = ServeFrame<v1::FreeArrayRequest, v1::FreeArrayResponse>(io, "ArrayService.Free", body, body_len, s,
            [&](Session& ss, const auto& req, auto*) { return ArrayFree(engine, ss, req); });
        spin_next = works_on_gpu;
        break;
      case kArrayFreeUnanswered:
        r = ServeFrame<v1::FreeArrayRequest, v1::FreeArrayResponse>(io, "ArrayService.Free", body, body_len, s,
            [&](Session& ss, const auto& req, auto*) { return ArrayFree(engine, ss, req); }, nullptr,
            Answer::kNever);
        spin_next = works_on_gpu;
        break;
      case kArrayDescribe:
        r = ServeFrame<v1::DescribeArrayRequest, v1::DescribeArrayResponse>(io, "ArrayService.Describe", body, body_len, s,
            [&](Session& ss, const auto& req, auto* resp) { return ArrayDescribe(engine, ss, req, resp); });
        spin_next = works_on_gpu;
        break;
      case kArrayImportCuda:
        r = ServeFrame<v1::ImportCudaRequest, v1::ImportCudaResponse>(io, "ArrayService.ImportCuda", body, body_len, s,
            [&](Session& ss, const auto& req, auto* resp) { return ArrayImportCuda(engine, ss, req, resp); });
        works_on_gpu = works_on_gpu || adaptive_spin;
        spin_next = works_on_gpu;
        break;
      case kGeometryCall:
        r = ServeFrame<v1::GeometryRequest, v1::GeometryResponse>(io, "GeometryService.Call", body, body_len, s,
            [&](Session& ss, const auto& req, auto* resp) { return GeometryCall(engine, ss, req, resp); });
        break;
      default:
        break;
    }
    if (r == FrameResult::kUnknownMethod) {
      SendError(io, InvalidArgument("fast lane: unknown method " + std::to_string(method)));
      return;
    }
    if (r == FrameResult::kEnd) return;
    spin_window.FrameDone(std::chrono::steady_clock::now());
    if (trace && kind && times.replied) {
      lane_trace->Add(kind, last_replied ? times.received - last_replied : 0, times, frame_trace::Current());
      last_replied = times.replied;
    } else if (trace) {
      last_replied = frame_trace::NowNs();
    }
  }
}

}  // namespace weft::server
