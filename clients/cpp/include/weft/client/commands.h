// Ordered device commands (copy, fill, kernel launch, tape) and the array views they name. The client
// queues commands and sends them in one ExecService.Submit per batch; they run in order on the
// session's stream, and a failing command is reported by the next Client::Synchronize.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <variant>
#include <vector>

namespace weft {
inline namespace client_v1 {

// A (possibly strided) view of an allocation: the wire's ArrayRef. Built by Array::view() and
// Array::Slice(); the daemon checks the view lies inside the allocation.
struct ArrayView {
  std::uint64_t handle = 0;             // 0: None (an absent array argument)
  std::uint64_t byte_offset = 0;
  std::vector<std::int64_t> shape;
  std::vector<std::int64_t> strides;    // bytes; empty = contiguous
};

struct StructArg;
// One kernel argument: raw little-endian bytes (scalars, vectors, matrices, quats, transforms),
// an array view, or a struct (its fields in declaration order).
using KernelArg = std::variant<std::vector<std::byte>, ArrayView, std::shared_ptr<StructArg>>;
struct StructArg { std::vector<KernelArg> fields; };

// Raw bytes of one trivially copyable value, as a kernel argument: ArgBytes(1.5f), ArgBytes(7).
template <typename T>
KernelArg ArgBytes(const T& value) {
  const auto* p = reinterpret_cast<const std::byte*>(&value);
  return std::vector<std::byte>(p, p + sizeof(T));
}

struct LaunchSpec {
  std::string module_id;                // from ModuleService.Compile
  std::string kernel;                   // kernel name within the module
  std::vector<std::int64_t> dim;        // 1..4 dimensions
  std::vector<KernelArg> args;          // in parameter order
  bool adjoint = false;                 // run the kernel's adjoint
  std::vector<KernelArg> adj_args;
  std::string device;                   // "" = the arrays' device
};

// Where the client issued a command, reported with its error.
struct CommandOrigin {
  std::string file;
  std::uint32_t line = 0;
};

struct CopyOp { ArrayView dst; ArrayView src; };
struct FillOp { ArrayView dst; std::vector<std::byte> value; };   // one element's bytes

// Autodiff tape operations (weft.v1.TapeCommand); weft::Tape issues them for you.
struct TapeOp {
  enum class Kind { kBegin = 0, kEnd = 1, kBackward = 2, kZero = 3, kReset = 4, kFree = 5 };
  Kind kind = Kind::kBegin;
  std::uint64_t tape_id = 0;
  ArrayView loss;                            // kBackward: every element of loss's gradient = 1
  struct Seed { ArrayView array; ArrayView grad; };
  std::vector<Seed> seeds;                   // kBackward: grad copied into array's gradient
};

struct Command {
  std::variant<CopyOp, FillOp, LaunchSpec, TapeOp> op;
  CommandOrigin origin;
};

// An ordered list of commands, submitted with Client::Submit.
class CommandBatch {
 public:
  CommandBatch& Copy(ArrayView dst, ArrayView src, CommandOrigin origin = {});
  CommandBatch& Fill(ArrayView dst, std::vector<std::byte> value, CommandOrigin origin = {});
  CommandBatch& Launch(LaunchSpec launch, CommandOrigin origin = {});
  CommandBatch& Tape(TapeOp op, CommandOrigin origin = {});

  const std::vector<Command>& commands() const { return commands_; }
  std::vector<Command>& commands() { return commands_; }
  std::size_t size() const { return commands_.size(); }
  bool empty() const { return commands_.empty(); }

 private:
  std::vector<Command> commands_;
};

}  // namespace client_v1
}  // namespace weft
