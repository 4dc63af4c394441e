// The fast lane: a second transport for local clients, carrying the hot calls of one session
// (ExecService.Submit and Synchronize; ArrayService.Create, Free, Describe and ImportCuda;
// GeometryService.Call) over a Unix
// SOCK_SEQPACKET socket without gRPC.
// Owns: the listening socket (<first unix path>.fast, mode 0600), the one-time secrets that
// bind a connection to a session (handed out by SessionService.Open to local peers), the
// per-connection threads and the frame format. Every frame is parsed and served by the same
// handler functions as the gRPC methods (ExecSubmit, ExecSynchronize, ArrayCreate, ArrayFree,
// ArrayDescribe, ArrayImportCuda, GeometryCall in services.h). A quiet Submit is answered only
// when it fails, an unanswered Free never.
//
// Frames (one datagram each; docs/protocol.md "Fast lane"):
//   request: u32 method (little endian; 1 hello, 2 Submit, 3 Synchronize, 4 ArrayService.Create,
//            5 Free, 6 Describe, 7 ImportCuda, 8 GeometryService.Call, 9 quiet Submit,
//            10 unanswered Free, 11 ring open, 12 ring wake), then the request message serialized (FastLaneHello,
//            SubmitRequest, SynchronizeRequest, CreateArrayRequest, FreeArrayRequest,
//            DescribeArrayRequest, ImportCudaRequest, GeometryRequest); at most
//            kMaxRequestBytes in all.
//   reply:   u32 status code (gRPC numbering), u32 flags (bit 0: more frames of this reply
//            follow; bit 1: the daemon ends the connection after this reply; bit 2: the
//            failure of a quiet Submit; bit 3: a wake frame of a ring, nothing else), then a
//            piece of the payload: the response message
//            serialized on OK, the error message (UTF-8) otherwise. Pieces are at most
//            kReplyChunkBytes.
// The first frame must be a hello naming the session and its secret, from a peer whose uid
// (SO_PEERCRED) is the session's principal; anything else ends the connection after an error
// reply. A secret binds one connection; a wrong frame later (unknown method, garbage,
// oversized) gets an error reply and ends that connection; the daemon keeps serving.
// A client may move the connection onto a shared-memory ring (server/lane_ring.h) after the
// hello; the socket then only wakes a reader that sleeps and tells either side the other is gone.
// WEFT_LANE_TRACE=<file>: each connection times its frames' phases and appends their medians
// per kind of frame to the file when it ends (docs/protocol.md "Fast lane").
#pragma once

#include <sys/types.h>

#include <atomic>
#include <cstdint>
#include <list>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "engine/core/status.h"
#include "engine/runtime/engine.h"

namespace weft::server {

class FastLane {
 public:
  static constexpr uint32_t kHello = 1;
  static constexpr uint32_t kSubmit = 2;
  static constexpr uint32_t kSynchronize = 3;
  static constexpr uint32_t kArrayCreate = 4;
  static constexpr uint32_t kArrayFree = 5;
  static constexpr uint32_t kArrayDescribe = 6;
  static constexpr uint32_t kArrayImportCuda = 7;
  static constexpr uint32_t kGeometryCall = 8;
  // A Submit answered only when it fails (an asynchronous batch: the client does not wait for
  // "queued"); its error reply carries kQuietReplyFlag. It may neither synchronize nor run.
  static constexpr uint32_t kSubmitQuiet = 9;
  static constexpr uint32_t kQuietReplyFlag = 4;
  // A Free (FreeArrayRequest: `handle` and `handles`) never answered, not even when it fails: a
  // client's released arrays, sent without waiting (a failure means the handle is gone already,
  // which is what the client asked for; it is logged).
  static constexpr uint32_t kArrayFreeUnanswered = 10;
  // Opens the connection's ring (LaneRing; empty body), once, when the hello offered "ring":
  // the reply is OK, the region's size (u64) and its memfd (SCM_RIGHTS). From then on requests
  // come as ring records and replies go as ring records; the socket carries only wake frames:
  // kRingWake (u32, nothing else) from the client, a reply header with kWakeReplyFlag from weftd.
  static constexpr uint32_t kRingOpen = 11;
  static constexpr uint32_t kRingWake = 12;
  static constexpr uint32_t kWakeReplyFlag = 8;
  // The hello's reply payload: what this daemon's lane serves beyond the methods above (and
  // " ring" where rings are offered).
  static constexpr const char* kHelloCapabilities = "quiet-submit unanswered-free";
  static constexpr size_t kMaxRequestBytes = 160u << 10;   // fits a default socket send buffer
  static constexpr size_t kMaxHelloBytes = 1024;           // before the hello is accepted
  static constexpr size_t kReplyChunkBytes = 64u << 10;
  static constexpr size_t kMaxConnections = 4096;
  static constexpr int kHelloTimeoutS = 5;

  // Binds and listens on `path` (already prepared: no stale file).
  static Expected<std::unique_ptr<FastLane>> Listen(Engine& engine, const std::string& path);
  ~FastLane();   // Stop() + Join()

  const std::string& path() const { return path_; }
  // A new secret for session `id` of `principal` ("unix-uid:<uid>"); replaces an unused one.
  std::string NewSecret(const std::string& id, const std::string& principal);

  void Start();
  // Stops accepting and ends every connection's reads (their threads finish their frame).
  void Stop();
  // Waits for the connection threads (after Stop).
  void Join();

 private:
  struct Conn {
    int fd = -1;   // closed (-1) by its thread when it ends, under mu_
    std::thread thread;
    std::atomic<bool> done{false};
  };
  struct Pending {
    std::string secret;
    std::string principal;
  };

  FastLane(Engine& engine, std::string path, int fd) : engine_(engine), path_(std::move(path)), listen_fd_(fd) {}
  void AcceptLoop();
  void Serve(Conn* c);
  void ReapFinished();   // joins ended threads; caller holds mu_

  Engine& engine_;
  std::string path_;
  int listen_fd_ = -1;
  int wake_fds_[2] = {-1, -1};
  std::thread accept_thread_;
  std::mutex mu_;
  std::list<Conn> conns_;
  std::map<std::string, Pending> secrets_;   // session id -> its unused secret
  bool stopped_ = false;
};

}  // namespace weft::server
