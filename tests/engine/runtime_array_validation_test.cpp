// The one array validation (ValidateArray) and the checked arithmetic under it: shape products
// that would wrap 64 bits are refused, views stay inside their allocation, struct element sizes
// come from the compiled layout (not the client's struct_size), adjoint arrays must match the
// primal's shape and element type, and a same-allocation copy through a stride-0 view needs no
// temporary sized by the view's element count.
#include <gtest/gtest.h>

#include "engine/core/checked_math.h"
#include "engine/runtime/array_validation.h"
#include "engine/runtime/launch_args.h"
#include "runtime_test_support.h"

namespace weft {
namespace {

using namespace weft::testing;

TEST(CheckedMath, AddAndMulReportOverflow) {
  uint64_t u = 0;
  EXPECT_TRUE(CheckedMul(uint64_t{1} << 31, uint64_t{1} << 31, &u));
  EXPECT_EQ(u, uint64_t{1} << 62);
  EXPECT_FALSE(CheckedMul(uint64_t{1} << 32, uint64_t{1} << 32, &u));
  EXPECT_FALSE(CheckedAdd(~uint64_t{0}, uint64_t{1}, &u));
  int64_t s = 0;
  EXPECT_FALSE(CheckedMul(int64_t{1} << 62, int64_t{2}, &s));
  EXPECT_TRUE(CheckedAdd(int64_t{-5}, int64_t{3}, &s));
  EXPECT_EQ(s, -2);
}

TEST(CheckedMath, ShapeProductRefusesWrapsAndNegatives) {
  uint64_t n = 0;
  EXPECT_TRUE(CheckedShapeProduct({2, 3, 4}, 8, &n));
  EXPECT_EQ(n, 192u);
  // 2^32 * 2^32 * 4 wraps to 0 in 64 bits: refused, not "0 bytes".
  EXPECT_FALSE(CheckedShapeProduct({int64_t{1} << 32, int64_t{1} << 32}, 4, &n));
  // 2^61 * 8 = 2^64 wraps to 0.
  EXPECT_FALSE(CheckedShapeProduct({int64_t{1} << 61}, 8, &n));
  EXPECT_FALSE(CheckedShapeProduct({4, -1}, 4, &n));
  // A zero extent makes the product 0, but the other extents must still be sane (strides).
  EXPECT_TRUE(CheckedShapeProduct({0, 1000}, 4, &n));
  EXPECT_EQ(n, 0u);
  EXPECT_FALSE(CheckedShapeProduct({0, int64_t{1} << 62, int64_t{1} << 62}, 4, &n));
  EXPECT_TRUE(CheckedShapeProduct({}, 12, &n));
  EXPECT_EQ(n, 12u);
}

// An engine-made allocation of `count` float32 (the validation checks allocation consistency).
std::shared_ptr<Allocation> Floats(Engine& e, Session& s, int64_t count) {
  CreateArrayParams p;
  p.dtype = F32();
  p.shape = {count};
  p.init = CreateArrayParams::Init::kZeros;
  auto d = e.CreateArray(s, p);
  EXPECT_TRUE(d.ok()) << d.status().ToString();
  return s.Find(d->handle);
}

TEST(ArrayValidation, WrappingViewShapeIsRefusedBeforeAnyWork) {
  auto e = MakeEngine();
  auto s = e->OpenSession(Local());
  auto a = Floats(*e, *s, 4);
  ArrayRequirement req;
  req.what = "fill dst";
  // Stride 0 keeps every element at byte 0; the element count 2^64 would wrap to 0.
  ArrayRef wrap{a->handle, 0, {int64_t{1} << 32, int64_t{1} << 32}, {0, 0}};
  auto v = ValidateArray(a, wrap, req);
  ASSERT_FALSE(v.ok());
  EXPECT_EQ(v.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(v.status().message().find("too many elements"), std::string::npos) << v.status().ToString();
  // Contiguous strides of such a shape would overflow int64 too.
  ArrayRef wrap2{a->handle, 0, {int64_t{1} << 40, int64_t{1} << 40}, {}};
  EXPECT_EQ(ValidateArray(a, wrap2, req).status().code(), StatusCode::kInvalidArgument);
}

TEST(ArrayValidation, SameAllocationStrideZeroCopyNeedsNoViewSizedTemporary) {
  auto e = MakeEngine();
  auto s = e->OpenSession(Local());
  auto a = Floats(*e, *s, 4);
  reinterpret_cast<float*>(a->data())[0] = 3.0f;
  ArrayRequirement req;
  req.what = "copy";
  // 2^20 elements of a stride-0 source, written to a stride-0 destination in the same array.
  auto src = ValidateArray(a, {a->handle, 0, {1 << 20}, {0}}, req);
  auto dst = ValidateArray(a, {a->handle, 12, {1 << 20}, {0}}, req);
  ASSERT_TRUE(src.ok() && dst.ok());
  ASSERT_TRUE(CopyView(*dst, *src).ok());
  EXPECT_EQ(reinterpret_cast<float*>(a->data())[3], 3.0f);
}

TEST(ArrayValidation, ElementSizeComesFromTheCompiledLayout) {
  auto e = MakeEngine();
  auto s = e->OpenSession(Local());
  CreateArrayParams p;
  p.dtype.type_name = "struct(m.Big)";
  p.dtype.struct_size = 1;   // the client claims 1-byte elements
  p.shape = {16};
  auto d = e->CreateArray(*s, p);
  ASSERT_TRUE(d.ok()) << d.status().ToString();
  auto a = s->Find(d->handle);
  ArrayRequirement req;
  req.what = "kernel 'k' parameter 'a'";
  req.dtype = "struct(m.Big)";
  req.element_size = 4096;   // what the kernel was compiled for
  req.ndim = 1;
  auto v = ValidateArray(a, {}, req);
  ASSERT_FALSE(v.ok());
  EXPECT_EQ(v.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(v.status().message().find("4096 bytes per element"), std::string::npos) << v.status().ToString();
  req.element_size = 1;
  EXPECT_TRUE(ValidateArray(a, {}, req).ok());
}

TEST(ArrayValidation, DtypeDeviceNdimAndShapeAreChecked) {
  auto e = MakeEngine();
  auto s = e->OpenSession(Local());
  auto a = Floats(*e, *s, 8);
  ArrayRequirement req;
  req.what = "x";
  req.dtype = "float64";
  EXPECT_EQ(ValidateArray(a, {}, req).status().code(), StatusCode::kInvalidArgument);
  req.dtype = "float32";
  req.ndim = 2;
  EXPECT_EQ(ValidateArray(a, {}, req).status().code(), StatusCode::kInvalidArgument);
  req.ndim = 1;
  std::vector<int64_t> primal = {4};
  req.shape = &primal;
  auto v = ValidateArray(a, {}, req);
  ASSERT_FALSE(v.ok());
  EXPECT_NE(v.status().message().find("primal"), std::string::npos);
  EXPECT_TRUE(ValidateArray(a, {a->handle, 0, {4}, {8}}, req).ok());   // every other element: shape (4,)
  req.shape = nullptr;
  req.device = "cuda:0";
  EXPECT_EQ(ValidateArray(a, {}, req).status().code(), StatusCode::kInvalidArgument);
  req.device = "cpu";
  // A far stride is outside the allocation.
  EXPECT_EQ(ValidateArray(a, {a->handle, 0, {2}, {int64_t{1} << 40}}, req).status().code(), StatusCode::kOutOfRange);
}

TEST(ArrayValidation, AdjointArgumentsMatchThePrimal) {
  auto e = MakeEngine();
  auto s = e->OpenSession(Local());
  auto x = Floats(*e, *s, 8);
  auto small = Floats(*e, *s, 2);
  CreateArrayParams ip;
  ip.dtype.scalar = ScalarType::kInt32;
  ip.shape = {8};
  auto idesc = e->CreateArray(*s, ip);
  ASSERT_TRUE(idesc.ok());
  auto ints = s->Find(idesc->handle);

  KernelLayout k;
  k.name = "k";
  k.params = {ArrayParam("x", "float32", 1, 0)};
  k.params[0].array_elem_size = 4;
  k.args_size = sizeof(wp::array_abi_t);
  ArrayRef x_ref, adj_ref;   // what the launch command would name
  x_ref.handle = x->handle;
  ResolvedArg fx;
  fx.kind = ArgValue::Kind::kArray;
  fx.ref = &x_ref;
  fx.alloc = x;
  auto primal = PackArgs(k, {fx});
  ASSERT_TRUE(primal.ok()) << primal.status().ToString();

  ResolvedArg adj = fx;
  adj.ref = &adj_ref;
  adj_ref.handle = small->handle;
  adj.alloc = small;   // shape (2,) against the primal's (8,)
  auto r = PackAdjointArgs(k, *primal, {adj});
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("primal"), std::string::npos) << r.status().ToString();

  adj_ref.handle = ints->handle;
  adj.alloc = ints;    // right shape, wrong element type
  r = PackAdjointArgs(k, *primal, {adj});
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("int32"), std::string::npos) << r.status().ToString();

  auto good = Floats(*e, *s, 8);
  adj_ref.handle = good->handle;
  adj.alloc = good;
  EXPECT_TRUE(PackAdjointArgs(k, *primal, {adj}).ok());
}

// An adjoint value slot starts at the value sent (Warp's adj_inputs), so its bytes get the
// primal's size check: a short or long value is refused, none leaves the slot zero.
TEST(ArrayValidation, AdjointValuesAreSizeCheckedAndCopied) {
  KernelLayout k;
  k.name = "k";
  k.params = {ValueParam("s", "float32", 0, 4)};
  k.args_size = 4;
  ResolvedArg v;
  v.kind = ArgValue::Kind::kRaw;
  const float seven = 7.0f;
  v.raw.assign(reinterpret_cast<const char*>(&seven), 4);
  auto primal = PackArgs(k, {v});
  ASSERT_TRUE(primal.ok()) << primal.status().ToString();
  ResolvedArg adj = v;
  const float two = 2.0f;
  adj.raw.assign(reinterpret_cast<const char*>(&two), 4);
  auto r = PackAdjointArgs(k, *primal, {adj});
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  float got = 0;
  std::memcpy(&got, r->block.data(), 4);
  EXPECT_EQ(got, 2.0f);
  for (size_t n : {size_t{3}, size_t{5}, size_t{4096}}) {
    adj.raw.assign(n, '\x7f');
    r = PackAdjointArgs(k, *primal, {adj});
    ASSERT_FALSE(r.ok()) << n;
    EXPECT_NE(r.status().message().find("bytes, expected 4"), std::string::npos) << r.status().ToString();
  }
  adj.kind = ArgValue::Kind::kArray;   // no value sent: zero
  adj.raw.clear();
  r = PackAdjointArgs(k, *primal, {adj});
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  std::memcpy(&got, r->block.data(), 4);
  EXPECT_EQ(got, 0.0f);
}

}  // namespace
}  // namespace weft
