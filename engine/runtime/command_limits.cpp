// CheckCommandBatch: launch size, view element counts, queue depth, tape ops.
#include "engine/runtime/command_limits.h"

#include <string>

namespace weft {

namespace {

// Product of extents, saturated at 2^63 (extents are checked elsewhere to be >= 0).
uint64_t Product(const std::vector<int64_t>& extents) {
  unsigned __int128 n = 1;
  for (int64_t d : extents) {
    n *= static_cast<uint64_t>(d < 0 ? 0 : d);
    if (n > (static_cast<unsigned __int128>(1) << 63)) return uint64_t{1} << 63;
  }
  return static_cast<uint64_t>(n);
}

Status CheckView(const ArrayRef& ref, const CommandLimits& limits, size_t index, const char* what) {
  if (ref.shape.empty()) return Status::Ok();   // the whole allocation: bounded by its bytes
  uint64_t n = Product(ref.shape);
  if (n <= limits.max_launch_threads) return Status::Ok();
  return ResourceExhausted("command " + std::to_string(index) + ": " + what + " view of shape " +
                           ShapeString(ref.shape) + " has " + std::to_string(n) + " elements, more than the limit of " +
                           std::to_string(limits.max_launch_threads) + " per command (weftd --max-launch-threads)");
}

}  // namespace

Status CheckCommandBatch(const std::vector<Command>& commands, const CommandLimits& limits,
                         uint64_t already_queued) {
  if (commands.size() > limits.max_queued_commands ||
      already_queued > limits.max_queued_commands - commands.size())
    return ResourceExhausted("the session has " + std::to_string(already_queued) +
                             " command(s) queued and this batch adds " + std::to_string(commands.size()) +
                             ": more than the limit of " + std::to_string(limits.max_queued_commands) +
                             " queued commands per session (weftd --max-queued-commands); synchronize first");
  for (size_t i = 0; i < commands.size(); ++i) {
    const Command& c = commands[i];
    if (auto* l = std::get_if<LaunchCommand>(&c.kind)) {
      uint64_t n = Product(l->dim);
      if (n > limits.max_launch_threads)
        return ResourceExhausted("command " + std::to_string(i) + ": launch of kernel '" + l->kernel + "' with dim " +
                                 ShapeString(l->dim) + " has " + std::to_string(n) +
                                 " threads, more than the limit of " + std::to_string(limits.max_launch_threads) +
                                 " per launch (weftd --max-launch-threads)");
    } else if (auto* f = std::get_if<FillCommand>(&c.kind)) {
      WEFT_RETURN_IF_ERROR(CheckView(f->dst, limits, i, "fill dst"));
    } else if (auto* cp = std::get_if<CopyCommand>(&c.kind)) {
      WEFT_RETURN_IF_ERROR(CheckView(cp->dst, limits, i, "copy dst"));
      WEFT_RETURN_IF_ERROR(CheckView(cp->src, limits, i, "copy src"));
    } else if (auto* t = std::get_if<TapeCommand>(&c.kind)) {
      Status st = CheckTapeOp(t->op);
      if (!st.ok()) return Status(st.code(), "command " + std::to_string(i) + ": " + st.message());
    } else if (auto* tc = std::get_if<TimingCommand>(&c.kind)) {
      if (tc->op != TimingCommand::Op::kBegin && tc->op != TimingCommand::Op::kEnd)
        return InvalidArgument("command " + std::to_string(i) + ": unknown timing op " +
                               std::to_string(static_cast<int>(tc->op)));
    } else if (auto* te = std::get_if<TimedEventCommand>(&c.kind)) {
      if (te->op != TimedEventCommand::Op::kRecord && te->op != TimedEventCommand::Op::kDestroy)
        return InvalidArgument("command " + std::to_string(i) + ": unknown timed_event op " +
                               std::to_string(static_cast<int>(te->op)));
    } else if (auto* g = std::get_if<GraphCommand>(&c.kind)) {
      if (g->commands.size() > limits.max_graph_commands)
        return ResourceExhausted("command " + std::to_string(i) + ": a graph of " + std::to_string(g->commands.size()) +
                                 " commands, more than the limit of " + std::to_string(limits.max_graph_commands));
      for (const Command& inner : g->commands) {
        if (std::holds_alternative<GraphCommand>(inner.kind))
          return InvalidArgument("command " + std::to_string(i) + ": a graph cannot hold graph commands");
        if (std::holds_alternative<TimingCommand>(inner.kind) || std::holds_alternative<TimedEventCommand>(inner.kind))
          return InvalidArgument("command " + std::to_string(i) +
                                 ": a graph cannot hold timing commands or timing events (wp.timing_begin / timing_end "
                                 "and wp.record_event outside the capture time its launches)");
      }
      // The graph's own commands obey the per-command limits; they count once, as one command.
      Status st = CheckCommandBatch(g->commands, limits, 0);
      if (!st.ok()) return Status(st.code(), "command " + std::to_string(i) + " (graph): " + st.message());
    }
  }
  return Status::Ok();
}

}  // namespace weft
