// Stackful fibers on one thread: a saved execution context, preparing a context that starts a
// function on a stack of its own, and switching from the running context to another. On x86-64
// a switch saves and restores the callee-saved registers, the floating-point control words
// and the stack pointer (a few instructions, no system call); elsewhere it is ucontext's
// swapcontext. Used by the lanes of cooperative CPU blocks (cpu_lanes.h).
#pragma once

#include <cstddef>

#if !defined(__x86_64__)
#include <ucontext.h>
#endif

namespace weft {

struct FiberContext {
#if defined(__x86_64__)
  void* sp = nullptr;   // the saved stack pointer (registers are saved on that stack)
#else
  ucontext_t uc{};
#endif
};

// Makes `f` run entry() on [stack, stack + size) when it is first switched to. entry must
// never return: it ends by switching to another context for good.
void FiberPrepare(FiberContext* f, void* stack, size_t size, void (*entry)());

// Saves the running context into `from` and resumes `to`; returns when something switches
// back to `from`.
void FiberSwitch(FiberContext* from, FiberContext* to);

}  // namespace weft
