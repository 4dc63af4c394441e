// Native library: the lanes of a cooperative CPU block (wp.config.enable_cpu_blocks). Owns the
// helpers tile ops use to meet the other lanes of their block: the lane index, the barrier,
// the one lane that performs a block's memory writes, and the exchange of one value per lane.
//
// A kernel compiled with lanes (block_dim B > 1 on the CPU) runs each block's B threads as
// fibers on one worker thread (engine/runtime/cpu_lanes.cpp). Every lane holds the whole of
// each tile, as a one-thread block does; the ops through which a lane's own value enters a
// tile (wp.tile(x), t[i] = v, t[i] += v, tile stacks) exchange the lanes' values so that every
// lane's tile stays the same, and the ops that write memory (tile_store, tile_atomic_add) are
// performed once, by the leader. Without lanes (GPUs, one thread per block) ctx->lanes is null
// and every helper is a no-op.
#pragma once

#include "codegen_support.h"

namespace wp {

WP_FUNC lane_block_t* lanes_of(const launch_context_t* ctx) {
#if WP_DEVICE_CODE
  (void)ctx;
  return nullptr;
#else
  return ctx ? ctx->lanes : nullptr;
#endif
}

// This thread's lane in its block (0 without lanes).
WP_FUNC int32 lane_index(const launch_context_t* ctx) {
  lane_block_t* b = lanes_of(ctx);
  return b ? b->lane : 0;
}

// Waits for every running lane of the block (a no-op without lanes).
WP_FUNC void lane_sync(const launch_context_t* ctx) {
  lane_block_t* b = lanes_of(ctx);
  if (b) b->sync(b);
}

// Whether this lane performs the block's memory writes: the leader, or every thread without lanes.
WP_FUNC bool lane_leads(const launch_context_t* ctx) {
  lane_block_t* b = lanes_of(ctx);
  return !b || b->lane == b->leader;
}

// Whether lane l of the block takes part (it exists and has not returned).
WP_FUNC bool lane_running(const lane_block_t* b, int32 l) { return l >= 0 && l < b->count && b->running[l] != 0; }

// The number of running lanes before lane l.
WP_FUNC int32 lane_rank(const lane_block_t* b, int32 l) {
  int32 r = 0;
  for (int32 k = 0; k < l && k < b->count; ++k) r += b->running[k] != 0;
  return r;
}

// Every lane's v: writes this lane's, waits for the others, and returns the block's array of
// them (slot l = lane l's; read only the slots of running lanes). The caller reads it, then
// calls lane_sync before the next exchange. Null when the runtime gives no memory (the lanes
// are then still in step: the wait happens).
template <typename T> WP_FUNC const T* lane_share(lane_block_t* b, const T& v) {
  char* s = b->scratch(b, static_cast<uint64>(b->dim) * sizeof(T));
  if (s && b->lane >= 0 && b->lane < b->dim) reinterpret_cast<T*>(s)[b->lane] = v;
  b->sync(b);
  return reinterpret_cast<const T*>(s);
}

// The leader's v in every lane (a no-op without lanes). Every running lane must call it.
template <typename T> WP_FUNC void lane_broadcast(const launch_context_t* ctx, T& v) {
  lane_block_t* b = lanes_of(ctx);
  if (!b) return;
  char* s = b->scratch(b, sizeof(T));
  if (s && b->lane == b->leader) *reinterpret_cast<T*>(s) = v;
  b->sync(b);
  if (s && b->lane != b->leader) v = *reinterpret_cast<const T*>(s);
  b->sync(b);
}

}  // namespace wp
