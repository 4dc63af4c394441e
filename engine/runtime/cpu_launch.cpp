// CPU launch execution and launch-error formatting.
#include "engine/runtime/cpu_launch.h"

#include <algorithm>
#include <atomic>
#include <cstring>
#include <memory>

#include "engine/runtime/allocation.h"
#include "engine/runtime/cpu_lanes.h"

namespace weft {

Status CheckLaunchDim(const std::vector<int64_t>& dim) {
  if (dim.empty() || dim.size() > static_cast<size_t>(wp::ARRAY_MAX_DIMS))
    return InvalidArgument("launch dim must have 1 to 4 dimensions, got " + std::to_string(dim.size()));
  __int128 n = 1;
  for (int64_t d : dim) {
    if (d < 0) return InvalidArgument("launch dim " + ShapeString(dim) + " has a negative extent");
    n *= d;
    if (n > (static_cast<__int128>(1) << 62))
      return InvalidArgument("launch dim " + ShapeString(dim) + " is too large");
  }
  return Status::Ok();
}

Expected<wp::launch_bounds_t> LaunchBoundsOf(const std::vector<int64_t>& dim) {
  WEFT_RETURN_IF_ERROR(CheckLaunchDim(dim));
  wp::launch_bounds_t b{};
  b.ndim = static_cast<wp::int32>(dim.size());
  b.size = 1;
  for (size_t i = 0; i < wp::ARRAY_MAX_DIMS; ++i) b.shape[i] = i < dim.size() ? dim[i] : 1;
  for (int64_t d : dim) b.size *= d;
  return b;
}

namespace {

std::string IndexString(const wp::int64* v, int n) {
  std::string s = "[";
  for (int i = 0; i < n && i < wp::ARRAY_MAX_DIMS; ++i) {
    if (i) s += ", ";
    s += std::to_string(v[i]);
  }
  return s + "]";
}

}  // namespace

Status FormatLaunchError(const LoadedModule& module, const LoadedKernel& kernel, bool adjoint,
                         const wp::launch_error_t& e) {
  const KernelLayout& k = kernel.layout;
  // function_names[id] = "file.py:function"
  std::string file, func = k.name;
  if (e.function_id >= 0 && static_cast<size_t>(e.function_id) < module.function_names.size()) {
    const std::string& fn = module.function_names[e.function_id];
    size_t colon = fn.rfind(':');
    if (colon == std::string::npos) {
      func = fn;
    } else {
      file = fn.substr(0, colon);
      func = fn.substr(colon + 1);
    }
  }
  std::string where = file.empty() ? std::string("line ") + std::to_string(e.line)
                                   : file + ":" + std::to_string(e.line);
  std::string in = "kernel '" + k.name + "'" + (adjoint ? " (adjoint)" : "");
  if (func != k.name) in += ", in function '" + func + "'";
  std::string array = "array";
  if (e.array_param >= 0 && static_cast<size_t>(e.array_param) < k.params.size())
    array = "array '" + k.params[e.array_param].name + "'";
  std::string text(e.message, strnlen(e.message, sizeof(e.message)));
  int nd = e.ndim < 0 ? 0 : (e.ndim > wp::ARRAY_MAX_DIMS ? wp::ARRAY_MAX_DIMS : e.ndim);
  std::vector<int64_t> shape(e.shape, e.shape + nd);
  switch (e.kind) {
    case wp::LAUNCH_OUT_OF_BOUNDS:
      return OutOfRange(where + ": " + in + ": index " + IndexString(e.index, nd) +
                        " is out of bounds for " + array + " of shape " + ShapeString(shape));
    case wp::LAUNCH_NULL_ARRAY:
      return FailedPrecondition(where + ": " + in + ": access to " + array + " which is None (empty)");
    case wp::LAUNCH_EXPECT_FAILED:
      return Status(StatusCode::kAborted, where + ": " + in + ": expect failed" +
                                              (text.empty() ? std::string() : ": " + text));
    case wp::LAUNCH_BAD_GEOMETRY:
    case wp::LAUNCH_BAD_VALUE:
      return InvalidArgument(where + ": " + in + ": " + text);
    default:
      return Internal(where + ": " + in + ": runtime error kind " + std::to_string(e.kind) +
                      (text.empty() ? std::string() : ": " + text));
  }
}

namespace {
Status LaunchError(const CpuLaunch& l, const wp::launch_error_t& e) {
  return FormatLaunchError(*l.module, *l.kernel, l.adj_args != nullptr, e);
}
}  // namespace

Status RunCpuLaunch(ThreadPool& pool, const CpuLaunch& l, std::string* output) {
  const bool backward = l.adj_args != nullptr;
  if (!backward && !l.kernel->cpu_forward)
    return Internal("kernel '" + l.kernel->layout.name + "' has no CPU forward entry point");
  if (backward && !l.kernel->cpu_backward)
    return Internal("kernel '" + l.kernel->layout.name + "' has no CPU backward entry point");

  wp::launch_context_t ctx{};
  WEFT_ASSIGN_OR_RETURN(ctx.bounds, LaunchBoundsOf(l.dim));
  if (ctx.bounds.size == 0) return Status::Ok();
  wp::launch_error_t err{};
  err.array_param = -1;
  ctx.error = &err;
  std::unique_ptr<char[]> print_data(new char[l.print_capacity]);
  wp::print_buffer_t print{print_data.get(), l.print_capacity, 0};
  ctx.print = &print;
  ctx.flags = l.bounds_checks ? 0u : wp::LAUNCH_FLAG_NO_BOUNDS_CHECK;
  ctx.block_dim = l.block_dim;   // wp.block_dim() of a kernel without lanes (native/array.h)
  ctx.cancel = reinterpret_cast<const wp::int32*>(l.cancel);
  ctx.geometry = l.geometry;

  // Runs [b, e) in pieces of kCancelChunk threads; stops early after an error or a cancel.
  auto stopped = [&] {
    return __atomic_load_n(&err.kind, __ATOMIC_RELAXED) != 0 ||
           (l.cancel && __atomic_load_n(l.cancel, __ATOMIC_RELAXED) != 0);
  };
  const void* args = l.args->block.data();
  const uint32_t lanes = l.kernel->layout.lanes;
  if (lanes > 1) {
    // Cooperative blocks: `lanes` consecutive threads per block, the last block possibly short.
    if (l.block_dim != lanes)
      return InvalidArgument("kernel '" + l.kernel->layout.name + "' was compiled for CPU blocks of " +
                             std::to_string(lanes) + " threads (wp.config.enable_cpu_blocks) but launched with block_dim " +
                             std::to_string(l.block_dim));
    const int64_t blocks = (ctx.bounds.size + lanes - 1) / lanes;
    std::atomic<bool> no_stacks{false};
    pool.ParallelFor(blocks, [&](int64_t b, int64_t e) {
      LaneBlockRunner& runner = LaneBlockRunner::ForThisThread(static_cast<int>(lanes));
      wp::launch_context_t lane_ctx = ctx;   // this worker's block
      lane_ctx.lanes = runner.block();
      const void* adj = backward ? l.adj_args->block.data() : nullptr;
      int64_t first = 0;   // the block's first thread
      const std::function<void(int)> lane_body = [&](int lane) {
        if (backward) l.kernel->cpu_backward(&lane_ctx, args, adj, first + lane, first + lane + 1);
        else l.kernel->cpu_forward(&lane_ctx, args, first + lane, first + lane + 1);
      };
      for (int64_t blk = b; blk < e && !stopped(); ++blk) {
        first = blk * lanes;
        const int count = static_cast<int>(std::min<int64_t>(lanes, ctx.bounds.size - first));
        Status st = runner.Run(count, lane_body);
        if (!st.ok()) {
          no_stacks = true;
          return;
        }
      }
      runner.Trim();
    }, /*min_chunk=*/std::max<int64_t>(1, blocks / (4 * pool.size())), /*inline_below=*/1);
    if (no_stacks) return ResourceExhausted("kernel '" + l.kernel->layout.name + "': cannot reserve fiber stacks for its CPU blocks");
  } else if (!backward) {
    CpuForwardFn fn = l.kernel->cpu_forward;
    pool.ParallelFor(ctx.bounds.size, [&](int64_t b, int64_t e) {
      for (int64_t s = b; s < e && !stopped(); s += kCancelChunk) fn(&ctx, args, s, std::min(e, s + kCancelChunk));
    });
  } else {
    CpuBackwardFn fn = l.kernel->cpu_backward;
    const void* adj = l.adj_args->block.data();
    pool.ParallelFor(ctx.bounds.size, [&](int64_t b, int64_t e) {
      for (int64_t s = b; s < e && !stopped(); s += kCancelChunk)
        fn(&ctx, args, adj, s, std::min(e, s + kCancelChunk));
    });
  }
  uint64_t used = print.used < print.capacity ? print.used : print.capacity;
  if (used > 0 && output) {
    output->append(print.data, used);
    if (print.used > print.capacity) output->append("\n[weft: kernel print output truncated]\n");
  }
  if (err.kind != 0) return LaunchError(l, err);
  if (l.cancel && __atomic_load_n(l.cancel, __ATOMIC_RELAXED) != 0)
    return Status(StatusCode::kCancelled, "launch cancelled");
  return Status::Ok();
}

}  // namespace weft
