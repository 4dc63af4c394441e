// TidIndicesInRange (engine/runtime/launch_args.h): when a launch may use a kernel's
// trusted-index variant, whose p[wp.tid()] accesses go unchecked. Attacked with every way a
// client could make the proof wrong: a shorter array, an array of another rank, a null array,
// thread counts that overflow or are empty, a layout naming a parameter the block lacks.
#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>
#include <vector>

#include "engine/native/launch_abi.h"
#include "engine/runtime/launch_args.h"

namespace weft {
namespace {

constexpr uint32_t kSlot = sizeof(wp::array_abi_t);

// A kernel of `n` 1-D array parameters, all listed as tid-indexed, and a block whose arrays
// have the given extents (ndim 1 and a non-null data pointer unless changed).
struct Fixture {
  KernelLayout layout;
  PackedArgs args;
  explicit Fixture(const std::vector<int64_t>& extents) {
    args.block = ArgBlock(static_cast<uint32_t>(extents.size()) * kSlot);
    for (size_t p = 0; p < extents.size(); ++p) {
      ParamLayout pl;
      pl.name = "a" + std::to_string(p);
      pl.offset = static_cast<uint32_t>(p) * kSlot;
      pl.size = kSlot;
      layout.params.push_back(pl);
      layout.tid_indexed_params.push_back(static_cast<uint32_t>(p));
      PackedArray slot;
      slot.offset = pl.offset;
      slot.param = pl.name;
      slot.top_param = static_cast<int>(p);
      args.arrays.push_back(slot);
      wp::array_abi_t abi{};
      abi.data = reinterpret_cast<void*>(uintptr_t{0x1000});
      abi.ndim = 1;
      abi.shape[0] = extents[p];
      abi.strides[0] = 4;
      Set(p, abi);
    }
  }
  void Set(size_t p, const wp::array_abi_t& abi) { std::memcpy(args.block.data() + p * kSlot, &abi, sizeof abi); }
  wp::array_abi_t Get(size_t p) const {
    wp::array_abi_t abi{};
    std::memcpy(&abi, args.block.data() + p * kSlot, sizeof abi);
    return abi;
  }
};

TEST(TrustedIndices, EveryListedArrayMustCoverEveryThread) {
  Fixture f({1000, 1024});
  EXPECT_TRUE(TidIndicesInRange(f.layout, f.args, {1000}));
  EXPECT_TRUE(TidIndicesInRange(f.layout, f.args, {10, 100}));   // tid() < dim[0] <= threads
  EXPECT_FALSE(TidIndicesInRange(f.layout, f.args, {1001}));      // the first array is one short
  EXPECT_FALSE(TidIndicesInRange(f.layout, f.args, {1024}));
  EXPECT_FALSE(TidIndicesInRange(f.layout, f.args, {10, 101}));
}

TEST(TrustedIndices, AnythingUnprovenKeepsTheChecks) {
  Fixture f({64});
  EXPECT_FALSE(TidIndicesInRange(f.layout, f.args, {}));
  EXPECT_FALSE(TidIndicesInRange(f.layout, f.args, {0}));
  EXPECT_FALSE(TidIndicesInRange(f.layout, f.args, {-5}));
  EXPECT_FALSE(TidIndicesInRange(f.layout, f.args, {int64_t{1} << 40, int64_t{1} << 40}));   // overflows
  wp::array_abi_t abi = f.Get(0);
  abi.ndim = 2;   // an array of another rank in the slot
  f.Set(0, abi);
  EXPECT_FALSE(TidIndicesInRange(f.layout, f.args, {8}));
  abi.ndim = 1;
  abi.data = nullptr;   // None
  f.Set(0, abi);
  EXPECT_FALSE(TidIndicesInRange(f.layout, f.args, {8}));
  abi.data = reinterpret_cast<void*>(uintptr_t{0x1000});
  abi.shape[0] = -1;
  f.Set(0, abi);
  EXPECT_FALSE(TidIndicesInRange(f.layout, f.args, {8}));
  abi.shape[0] = 64;
  f.Set(0, abi);
  EXPECT_TRUE(TidIndicesInRange(f.layout, f.args, {8}));
  // A parameter the block has no array for, or one past the layout's parameters.
  Fixture missing({64});
  missing.args.arrays.clear();
  EXPECT_FALSE(TidIndicesInRange(missing.layout, missing.args, {8}));
  Fixture past({64});
  past.layout.tid_indexed_params.push_back(7);
  EXPECT_FALSE(TidIndicesInRange(past.layout, past.args, {8}));
  // A struct field's array slot of the same parameter does not stand for the parameter.
  Fixture field({64});
  field.args.arrays[0].param = "a0.inner";
  EXPECT_FALSE(TidIndicesInRange(field.layout, field.args, {8}));
  // A slot whose offset lies outside the block.
  Fixture outside({64});
  outside.args.arrays[0].offset = kSlot;
  EXPECT_FALSE(TidIndicesInRange(outside.layout, outside.args, {8}));
  // Nothing listed: nothing to trust.
  Fixture none({64});
  none.layout.tid_indexed_params.clear();
  EXPECT_FALSE(TidIndicesInRange(none.layout, none.args, {8}));
}

}  // namespace
}  // namespace weft
