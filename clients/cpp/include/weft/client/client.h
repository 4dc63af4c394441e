// weft::Client: one session with a weftd daemon. Connects over a Unix socket or TCP (token),
// opens a session and holds its Attach stream on a background thread (so the daemon frees
// everything if this process dies), and offers the array operations of the Python client:
// devices, create/describe/free arrays, read/write, queued copy/fill/launch commands,
// synchronize, IPC export/import, daemon statistics; and kernel module compiles. Errors are values (Status / Expected).
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "weft/client/array.h"
#include "weft/client/commands.h"
#include "weft/client/dtype.h"
#include "weft/client/module.h"
#include "weft/client/status.h"
#include "weft/client/types.h"

namespace weft {
inline namespace client_v1 {

struct ConnectOptions {
  // "unix:/path", "/path" (a Unix socket), "host:port" or "tcp:host:port".
  // Empty: $WEFT_ADDRESS, else the default socket ($XDG_RUNTIME_DIR/weft/weftd.sock, falling
  // back to /tmp/weft-$UID/weftd.sock).
  std::string address;
  // Sent as "authorization: Bearer <token>" on every call. Empty: $WEFT_TOKEN.
  std::string token;
  // Shown in the daemon's log. Empty: "weft-cpp pid <pid>".
  std::string client_name;
  // How long to wait for the daemon to answer before Connect fails with UNAVAILABLE.
  std::chrono::milliseconds connect_timeout{5000};
  // Bytes per message of chunked Read/Write streams (at most 16 MiB).
  std::size_t chunk_size = 1u << 20;
  // False: never map shared memory (behave as a remote client, bytes through streams).
  bool map_shared_memory = true;
  // Queued commands are sent when this many are pending (and at every sync point).
  std::size_t max_pending_commands = 1024;
  // Open an unchecked session: its modules may turn bounds checks off (option
  // "bounds_checks": "false"). A weftd started with --allow-unchecked runs it in a process of
  // its own (a session host, whose socket Connect then uses); elsewhere the session is checked.
  bool unchecked = false;
  // The device the session works on ("cpu", "cuda", "cuda:N"; empty: the daemon's first GPU,
  // else the CPU). A weftd started with --device-hosts opens the session in that device's
  // process (a device host, whose socket Connect then uses); other daemons ignore it.
  std::string device;
};

struct ArrayOptions {
  std::string device = "cpu";   // "cpu", "cuda:0", "cuda" (the daemon picks)
  bool requires_grad = false;
};

// The address Connect would use for `options` (after the environment and defaults), in gRPC
// target form ("unix:/run/user/1000/weft/weftd.sock", "127.0.0.1:7000").
std::string ResolveAddress(const ConnectOptions& options);

class Client {
 public:
  // Connects and opens a session. UNAVAILABLE when no daemon answers.
  static Expected<Client> Connect(ConnectOptions options = {});

  Client() = default;                    // not connected
  Client(Client&&) noexcept = default;
  Client& operator=(Client&&) noexcept;
  Client(const Client&) = delete;
  Client& operator=(const Client&) = delete;
  ~Client();                             // Close()

  bool connected() const;
  const SessionInfo& session() const;
  // True when arrays can be mapped (Unix socket, daemon said local, mapping not disabled).
  bool local() const;

  // Closes the session: the daemon frees its arrays; Arrays still alive become inert.
  Status Close();

  Expected<std::vector<DeviceInfo>> ListDevices();
  Expected<DaemonStats> Stats();

  // Array creation. `shape` has 0..4 dimensions of non-negative extents.
  Expected<Array> Empty(const DType& dtype, std::vector<std::int64_t> shape,
                        const ArrayOptions& options = {});
  Expected<Array> Zeros(const DType& dtype, std::vector<std::int64_t> shape,
                        const ArrayOptions& options = {});
  // Every scalar component becomes `value` converted to the dtype's scalar type.
  Expected<Array> Full(const DType& dtype, std::vector<std::int64_t> shape, double value,
                       const ArrayOptions& options = {});
  // Every element becomes these bytes (n == dtype.element_size()).
  Expected<Array> FullBytes(const DType& dtype, std::vector<std::int64_t> shape,
                            const void* element, std::size_t n, const ArrayOptions& options = {});
  // From C-order bytes (n == element count * element size).
  Expected<Array> FromBytes(const DType& dtype, std::vector<std::int64_t> shape, const void* data,
                            std::size_t n, const ArrayOptions& options = {});
  // From C++ scalars: FromData<float>(values, {rows, cols}). Empty shape: 1-D of values.size().
  template <typename T>
  Expected<Array> FromData(std::span<const T> values, std::vector<std::int64_t> shape = {},
                           const ArrayOptions& options = {});
  template <typename T>
  Expected<Array> FromData(const std::vector<T>& values, std::vector<std::int64_t> shape = {},
                           const ArrayOptions& options = {}) {
    return FromData(std::span<const T>(values), std::move(shape), options);
  }

  // What the daemon knows of any handle this session can see.
  Expected<ArrayInfo> Describe(std::uint64_t handle);
  // Frees a handle by number (for handles obtained from Release()).
  Status Free(std::uint64_t handle);
  // Opens an array another session exported; the returned Array owns this session's reference.
  Expected<Array> Import(const std::string& token);

  // Queues a copy / fill (run in order with everything queued; errors at Synchronize).
  Status Copy(const ArrayView& dst, const ArrayView& src, CommandOrigin origin = {});
  Status Fill(const ArrayView& dst, std::vector<std::byte> element, CommandOrigin origin = {});
  // Compiles a module for `device` ("cpu", "cuda:0"); compile errors come back as
  // INVALID_ARGUMENT whose message lists the diagnostics (file:line: message).
  Expected<CompiledModule> Compile(const ModuleDef& module, const std::string& device = "cpu");
  // Queues a launch of a compiled kernel.
  Status Launch(LaunchSpec launch, CommandOrigin origin = {});
  // Queues a whole batch, then sends everything pending.
  Status Submit(CommandBatch batch);
  // Sends the queued commands to the daemon (does not wait for them).
  Status Flush();
  // Sends the queued commands and waits for them; returns the first error any command since
  // the last Synchronize hit (with its origin), e.g. INVALID_ARGUMENT "...at demo.cpp:12".
  Status Synchronize();
  // Kernel print() output collected by Synchronize calls since the last TakeOutput.
  std::string TakeOutput();

  // Internal: the shared connection state, for Arrays and the raw access of weft/client/raw.h.
  const std::shared_ptr<detail::ClientCore>& core() const { return core_; }

 private:
  explicit Client(std::shared_ptr<detail::ClientCore> core) : core_(std::move(core)) {}
  Expected<Array> Create(const DType& dtype, std::vector<std::int64_t> shape,
                         const ArrayOptions& options, int init, const void* value,
                         std::size_t value_size);

  std::shared_ptr<detail::ClientCore> core_;
};

template <typename T>
Expected<Array> Client::FromData(std::span<const T> values, std::vector<std::int64_t> shape,
                                 const ArrayOptions& options) {
  if (shape.empty()) shape.push_back(static_cast<std::int64_t>(values.size()));
  return FromBytes(DTypeOf<T>(), std::move(shape), values.data(), values.size_bytes(), options);
}

}  // namespace client_v1
}  // namespace weft
