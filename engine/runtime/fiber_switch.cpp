// Fiber context switches: see fiber_switch.h.
#include "engine/runtime/fiber_switch.h"

#include <cstdint>

#if defined(__x86_64__)
// weft_fiber_switch(void** save_sp, void* load_sp): pushes rbp, rbx, r12-r15 and the SSE / x87
// control words on the running stack, stores the stack pointer in *save_sp, loads load_sp and
// pops the same from there, then returns on the other stack.
extern "C" void weft_fiber_switch(void** save_sp, void* load_sp);
asm(R"(
  .text
  .p2align 4
  .globl weft_fiber_switch
  .hidden weft_fiber_switch
  .type weft_fiber_switch, @function
weft_fiber_switch:
  pushq %rbp
  pushq %rbx
  pushq %r12
  pushq %r13
  pushq %r14
  pushq %r15
  subq $8, %rsp
  stmxcsr (%rsp)
  fnstcw 4(%rsp)
  movq %rsp, (%rdi)
  movq %rsi, %rsp
  ldmxcsr (%rsp)
  fldcw 4(%rsp)
  addq $8, %rsp
  popq %r15
  popq %r14
  popq %r13
  popq %r12
  popq %rbx
  popq %rbp
  ret
  .size weft_fiber_switch, .-weft_fiber_switch
  .section .note.GNU-stack,"",@progbits
  .text
)");
#endif

namespace weft {

#if defined(__x86_64__)

void FiberPrepare(FiberContext* f, void* stack, size_t size, void (*entry)()) {
  // The frame weft_fiber_switch pops, from the new stack pointer up: the control words (the
  // defaults: MXCSR 0x1F80, x87 0x037F), r15 .. r12, rbx, rbp (zero), the return address
  // (entry), and a never-used return slot that leaves rsp = 8 mod 16 at entry, as a call does.
  uintptr_t top = (reinterpret_cast<uintptr_t>(stack) + size) & ~uintptr_t{15};
  auto* sp = reinterpret_cast<uint64_t*>(top) - 9;
  sp[0] = 0x1F80u | (uint64_t{0x037F} << 32);
  for (int k = 1; k <= 6; ++k) sp[k] = 0;
  sp[7] = reinterpret_cast<uint64_t>(entry);
  sp[8] = 0;
  f->sp = sp;
}

void FiberSwitch(FiberContext* from, FiberContext* to) { weft_fiber_switch(&from->sp, to->sp); }

#else

void FiberPrepare(FiberContext* f, void* stack, size_t size, void (*entry)()) {
  getcontext(&f->uc);
  f->uc.uc_stack.ss_sp = stack;
  f->uc.uc_stack.ss_size = size;
  f->uc.uc_link = nullptr;
  makecontext(&f->uc, entry, 0);
}

void FiberSwitch(FiberContext* from, FiberContext* to) { swapcontext(&from->uc, &to->uc); }

#endif

}  // namespace weft
