// The binary interface between the runtime (engine/runtime) and generated kernel code.
// Owns: launch bounds, the launch context (error slot, print buffer), the array layout and the
// entry-point naming rule. Compiled by clang (CPU JIT), g++ (runtime) and NVRTC: no std headers.
#pragma once

#if defined(__CUDACC__) || defined(__CUDACC_RTC__)
#define WP_CALLABLE __host__ __device__
// Cold paths (error reports) kept out of line: inlined at every call site they multiply the
// code NVRTC optimizes (a geometry query's failure message cost ~10 s of NVRTC per kernel).
#define WP_NOINLINE __noinline__
#define WP_FORCEINLINE __forceinline__
#else
#define WP_CALLABLE
#define WP_NOINLINE __attribute__((noinline))
#define WP_FORCEINLINE inline __attribute__((always_inline))
#endif

// On a CUDA kernel's parameters (the launch context and the argument block), whose addresses the
// kernel body takes: with __grid_constant__ (sm_70 and later) a pointer to them points into the
// parameter space; without it, a pointer that reaches a call not inlined (the out-of-line error
// and geometry paths above) makes every thread copy the parameters into local memory first.
// (-DWP_GRID_CONSTANT= turns it off; a test measures what it saves.)
#ifndef WP_GRID_CONSTANT
#if defined(__CUDA_ARCH__) && __CUDA_ARCH__ < 700
#define WP_GRID_CONSTANT
#else
#define WP_GRID_CONSTANT __grid_constant__
#endif
#endif

namespace wp {

typedef signed char int8;
typedef unsigned char uint8;
typedef short int16;
typedef unsigned short uint16;
typedef int int32;
typedef unsigned int uint32;
typedef long long int64;
typedef unsigned long long uint64;
typedef float float32;
typedef double float64;

constexpr int ARRAY_MAX_DIMS = 4;

// Launch grid: wp.tid() of flat index i is unravelled from shape[0..ndim).
struct launch_bounds_t {
  int32 ndim;
  int32 _pad;
  int64 shape[ARRAY_MAX_DIMS];
  int64 size;  // product of shape
};

// Kinds of runtime errors a kernel can report.
enum launch_error_kind : int32 {
  LAUNCH_OK = 0,
  LAUNCH_OUT_OF_BOUNDS = 1,   // array index outside its shape
  LAUNCH_NULL_ARRAY = 2,      // access to an empty (None) array
  LAUNCH_EXPECT_FAILED = 3,   // wp.expect_eq and friends
  LAUNCH_BAD_GEOMETRY = 4,    // a geometry id that names no live object of this kind (message)
  LAUNCH_BAD_VALUE = 5,       // a value the operation cannot take, e.g. a slice step of 0 (message)
};

// First error of a launch wins (the writer sets `kind` with an atomic CAS from 0).
struct launch_error_t {
  int32 kind;
  int32 line;            // user source line
  int32 array_param;     // index of the kernel parameter (array) involved, -1 if none
  int32 ndim;            // number of indices used
  int64 index[ARRAY_MAX_DIMS];
  int64 shape[ARRAY_MAX_DIMS];
  int32 function_id;     // index into the module's function table (which func/kernel)
  int32 _pad;
  // Optional text (expect failures on the CPU, geometry and value errors). On a GPU a failed
  // expectation stores its values here as one print record (print.h) after the byte
  // EXPECT_RECORD, which the daemon formats at the synchronize, or the byte EXPECT_IN_OUTPUT
  // when the record did not fit (it went to the kernel's print output instead).
  char message[256];
};
constexpr char EXPECT_RECORD = 0x01;
constexpr char EXPECT_IN_OUTPUT = 0x02;

// Kernel print output; writers reserve space with an atomic add on `used`.
struct print_buffer_t {
  char* data;
  uint64 capacity;
  uint64 used;
};

struct geometry_table_t;   // geometry_abi.h

// The lanes of one CPU block (Warp's cooperative CPU blocks, wp.config.enable_cpu_blocks): the
// block's block_dim threads run as fibers on one worker thread, each to its next lane_sync in
// turn (engine/runtime/cpu_lanes.cpp). Tile ops that combine the lanes' values exchange them
// through `scratch` between two syncs (engine/native/lanes.h). Null on GPUs and for kernels
// compiled for one thread per block.
struct lane_block_t {
  int32 lane;            // the lane running now
  int32 count;           // lanes of this block: dim, fewer in the launch's last block
  int32 dim;             // block_dim the kernel was compiled for
  int32 leader;          // the lowest lane still running: it performs the block's memory writes
  const unsigned char* running;   // [count]: 1 for the lanes that had not returned when this round began
  // Returns once every running lane of the block has called it as often as this one.
  void (*sync)(lane_block_t* block);
  // At least `bytes` of memory the lanes of the block share (zeroed when first handed out);
  // valid until the block ends. Null when more than the runtime gives a block.
  char* (*scratch)(lane_block_t* block, uint64 bytes);
  void* runtime;
};

struct launch_context_t {
  launch_bounds_t bounds;
  launch_error_t* error;
  print_buffer_t* print;
  uint32 flags;          // LAUNCH_FLAG_*
  // CPU: the launch's block_dim under wp.config.enable_cpu_blocks (what wp.block_dim() gives a
  // kernel that runs one thread per block because its module has no tiles); 0 otherwise.
  // GPUs read blockDim.x instead.
  uint32 block_dim;
  // Non-zero once the launch must stop (its session closed, or its time limit passed); the
  // runtime sets it, loops in generated code poll it (cg_loop_poll). Null: never cancelled.
  // On a GPU it must be null or point at memory the device can read (mapped host memory).
  const int32* cancel;
  // The launching session's geometry objects on the launch device (geometry_abi.h); null when
  // it has none (every geometry id is then an error).
  const geometry_table_t* geometry;
  // Null on the CPU. On a GPU, a word of mapped host memory of the launching stream: a thread
  // that reports an error or appends print output stores 1 there (a plain store), so at a
  // synchronize the daemon reads the error slots and the print header back only when it is set.
  int32* report_flag;
  // Null but on the CPU for a kernel compiled with lanes (lane_block_t): this worker's block.
  lane_block_t* lanes;
};

constexpr uint32 LAUNCH_FLAG_NO_BOUNDS_CHECK = 1u;

// array_t::flags. ARRAY_FLAG_CONSUME_ADJOINT, on a gradient array an adjoint launch gets: it
// is the gradient of the array in that slot (a tape's backward, or an explicit adjoint launch
// given the array's own .grad), so reversing a store a[i] = v moves adj_a[i] into adj_v and
// clears it: the overwritten value's gradient is consumed (Warp's adj_array_store).
constexpr int32 ARRAY_FLAG_CONSUME_ADJOINT = 1;
// array_t::flags of a primal array passed with retain_grad (Warp's): its gradient is never
// consumed; read by the daemon when it packs the adjoint arrays.
constexpr int32 ARRAY_FLAG_RETAIN_GRAD = 2;

// Arrays as kernels see them (all backends). Strides are in bytes. data == nullptr for None.
template <typename T>
struct array_t {
  T* data;
  T* grad;
  int64 shape[ARRAY_MAX_DIMS];
  int64 strides[ARRAY_MAX_DIMS];
  int32 ndim;
  int32 flags;
};

// Untyped twin the runtime fills; same layout as every array_t<T>.
struct array_abi_t {
  void* data;
  void* grad;
  int64 shape[ARRAY_MAX_DIMS];
  int64 strides[ARRAY_MAX_DIMS];
  int32 ndim;
  int32 flags;
};

}  // namespace wp

// Entry points of a module (C linkage), per kernel K:
//   CPU:  void weft_K_cpu_forward(const wp::launch_context_t* ctx, const void* args,
//                                 wp::int64 begin, wp::int64 end);
//         runs flat indices [begin, end) of the launch grid.
//         void weft_K_cpu_backward(const wp::launch_context_t* ctx, const void* args,
//                                  const void* adj_args, wp::int64 begin, wp::int64 end);
//   CUDA: extern "C" __global__ void weft_K_cuda_forward(const WP_GRID_CONSTANT wp::launch_context_t ctx,
//                                                       const WP_GRID_CONSTANT <args struct> args);
// `args` points at the packed argument block whose layout the compiler reports per parameter
// (KernelInfo: offset, size); arrays occupy sizeof(wp::array_abi_t) = 88 bytes, 8-aligned.
