// ArrayView: range/alignment validation (clear messages) and strided fill/copy against a
// reference computed element by element on fresh random data.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstring>
#include <random>

#include "engine/runtime/array_validation.h"
#include "engine/runtime/array_view.h"

namespace weft {
namespace {

struct Fixture {
  ShmSlabPool pool{[] {
    ShmSlabPoolOptions o;
    o.name_prefix = "/weft-" + std::to_string(getpid()) + "-viewtest-";
    return o;
  }()};
  std::shared_ptr<Allocation> Make(std::vector<int64_t> shape, ScalarType s = ScalarType::kFloat32,
                                   std::vector<uint32_t> elem = {}) {
    auto a = std::make_shared<Allocation>();
    static uint64_t next = 1;
    a->handle = next++;
    a->dtype.scalar = s;
    a->dtype.elem_shape = elem;
    a->shape = shape;
    a->strides = ContiguousStrides(shape, a->dtype.ElementSize());
    a->byte_size = a->dtype.ElementSize() * a->element_count();
    a->block = *pool.Allocate(a->byte_size);
    ShmSlabPool* p = &pool;
    a->release = [p](const ShmSlabPool::Block& b) { p->Free(b); };
    return a;
  }
};

TEST(ArrayView, EmptyShapeMeansWholeArray) {
  Fixture f;
  auto a = f.Make({3, 4});
  auto v = MakeView(a, ArrayRef{a->handle, 0, {}, {}}, "x");
  ASSERT_TRUE(v.ok());
  EXPECT_EQ(v->shape, (std::vector<int64_t>{3, 4}));
  EXPECT_TRUE(v->contiguous());
}

TEST(ArrayView, RejectsViewsOutsideTheAllocation) {
  Fixture f;
  auto a = f.Make({3, 4});   // 48 bytes
  struct Case { ArrayRef ref; StatusCode code; const char* text; };
  std::vector<Case> cases = {
      {{a->handle, 0, {13}, {}}, StatusCode::kOutOfRange, "reaches outside"},
      {{a->handle, 4, {12}, {}}, StatusCode::kOutOfRange, "reaches outside"},
      {{a->handle, 8, {3}, {20}}, StatusCode::kOutOfRange, "reaches outside"},
      {{a->handle, 0, {2}, {-4}}, StatusCode::kOutOfRange, "reaches outside"},
      {{a->handle, 2, {2}, {}}, StatusCode::kInvalidArgument, "not a multiple"},
      {{a->handle, 0, {2}, {6}}, StatusCode::kInvalidArgument, "not a multiple"},
      {{a->handle, 0, {-1}, {}}, StatusCode::kInvalidArgument, "negative"},
      {{a->handle, 0, {1, 1, 1, 1, 1}, {}}, StatusCode::kInvalidArgument, "at most 4"},
      {{a->handle, 0, {2, 2}, {4}}, StatusCode::kInvalidArgument, "strides"},
      {{a->handle, 52, {0}, {}}, StatusCode::kOutOfRange, "past the end"},
      {{a->handle, 0, {2}, {1ll << 62}}, StatusCode::kOutOfRange, "reaches outside"},
      // 2^62 float32 elements are 2^64 bytes: refused before any span is computed.
      {{a->handle, 0, {1ll << 62}, {1ll << 62}}, StatusCode::kInvalidArgument, "too many elements"},
  };
  for (auto& c : cases) {
    auto v = MakeView(a, c.ref, "dst");
    ASSERT_FALSE(v.ok()) << ShapeString(c.ref.shape);
    EXPECT_EQ(v.status().code(), c.code) << v.status().ToString();
    EXPECT_NE(v.status().message().find(c.text), std::string::npos) << v.status().message();
  }
  // Legal edge cases: the last element exactly, negative strides inside, empty views.
  EXPECT_TRUE(MakeView(a, {a->handle, 44, {1}, {}}, "x").ok());
  EXPECT_TRUE(MakeView(a, {a->handle, 44, {12}, {-4}}, "x").ok());
  EXPECT_TRUE(MakeView(a, {a->handle, 48, {0}, {}}, "x").ok());
  EXPECT_TRUE(MakeView(a, {a->handle, 0, {3, 2}, {16, 8}}, "x").ok());
}

template <typename T>
std::vector<T> Read(const Allocation& a) {
  std::vector<T> v(a.byte_size / sizeof(T));
  std::memcpy(v.data(), a.data(), a.byte_size);
  return v;
}

TEST(ArrayView, StridedFillMatchesReference) {
  Fixture f;
  std::mt19937 rng(7);
  for (int trial = 0; trial < 50; ++trial) {
    int64_t r = 1 + rng() % 9, c = 1 + rng() % 9;
    auto a = f.Make({r, c}, ScalarType::kFloat64);
    std::vector<double> ref(r * c);
    for (auto& x : ref) x = std::uniform_real_distribution<double>(-1, 1)(rng);
    std::memcpy(a->data(), ref.data(), a->byte_size);
    // A random sub-grid a[r0::sr, c0::sc].
    int64_t r0 = rng() % r, c0 = rng() % c, sr = 1 + rng() % 3, sc = 1 + rng() % 3;
    int64_t nr = (r - r0 + sr - 1) / sr, nc = (c - c0 + sc - 1) / sc;
    ArrayRef ref_view{a->handle, static_cast<uint64_t>((r0 * c + c0) * 8), {nr, nc}, {sr * c * 8, sc * 8}};
    auto v = MakeView(a, ref_view, "dst");
    ASSERT_TRUE(v.ok()) << v.status().ToString();
    double value = 1000.0 + trial;
    ASSERT_TRUE(FillView(*v, std::string(reinterpret_cast<char*>(&value), 8)).ok());
    for (int64_t i = 0; i < nr; ++i)
      for (int64_t j = 0; j < nc; ++j) ref[(r0 + i * sr) * c + c0 + j * sc] = value;
    EXPECT_EQ(Read<double>(*a), ref);
  }
}

TEST(ArrayView, FillRejectsWrongValueSize) {
  Fixture f;
  auto a = f.Make({4}, ScalarType::kFloat32, {3});
  auto v = MakeView(a, {}, "dst");
  ASSERT_TRUE(v.ok());
  Status s = FillView(*v, std::string(4, '\0'));
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("12"), std::string::npos) << s.message();
  // A vec3 fill of a contiguous array: every component set.
  float xyz[3] = {1.5f, -2.0f, 3.25f};
  ASSERT_TRUE(FillView(*v, std::string(reinterpret_cast<char*>(xyz), 12)).ok());
  auto out = Read<float>(*a);
  for (int i = 0; i < 12; ++i) EXPECT_EQ(out[i], xyz[i % 3]);
}

TEST(ArrayView, StridedCopyMatchesReferenceIncludingOverlap) {
  Fixture f;
  std::mt19937 rng(11);
  for (int trial = 0; trial < 50; ++trial) {
    auto src = f.Make({6, 5}, ScalarType::kInt32);
    auto dst = f.Make({5, 6}, ScalarType::kInt32);
    std::vector<int32_t> s(30), d(30);
    for (auto& x : s) x = static_cast<int32_t>(rng());
    for (auto& x : d) x = static_cast<int32_t>(rng());
    std::memcpy(src->data(), s.data(), 120);
    std::memcpy(dst->data(), d.data(), 120);
    // src: column block [:, 1:4] transposed (shape (3, 6), strides (4, 20)); dst: rows 1..3 reversed.
    auto sv = MakeView(src, {src->handle, 4, {3, 6}, {4, 20}}, "src");
    auto dv = MakeView(dst, {dst->handle, 3 * 24, {3, 6}, {-24, 4}}, "dst");
    ASSERT_TRUE(sv.ok() && dv.ok()) << sv.status().ToString() << dv.status().ToString();
    ASSERT_TRUE(CopyView(*dv, *sv).ok());
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 6; ++j) d[(3 - i) * 6 + j] = s[j * 5 + 1 + i];
    EXPECT_EQ(Read<int32_t>(*dst), d);
  }
  // Overlapping copy inside one allocation: a[1:] = a[:-1] behaves like NumPy (source read first).
  auto a = f.Make({10}, ScalarType::kInt64);
  std::vector<int64_t> ref(10);
  for (int i = 0; i < 10; ++i) ref[i] = i * i;
  std::memcpy(a->data(), ref.data(), 80);
  auto dv = MakeView(a, {a->handle, 8, {9}, {}}, "dst");
  auto sv = MakeView(a, {a->handle, 0, {9}, {}}, "src");
  ASSERT_TRUE(CopyView(*dv, *sv).ok());
  std::vector<int64_t> expect = ref;
  for (int i = 1; i < 10; ++i) expect[i] = ref[i - 1];
  EXPECT_EQ(Read<int64_t>(*a), expect);
  // Reverse-strided overlapping copy: a[::-1] = a.
  std::memcpy(a->data(), ref.data(), 80);
  auto rv = MakeView(a, {a->handle, 72, {10}, {-8}}, "dst");
  auto fv = MakeView(a, {a->handle, 0, {10}, {}}, "src");
  ASSERT_TRUE(CopyView(*rv, *fv).ok());
  for (int i = 0; i < 10; ++i) expect[i] = ref[9 - i];
  EXPECT_EQ(Read<int64_t>(*a), expect);
}

// A copy moves bytes between any two element types of one size (Warp's rule); element sizes
// or counts that differ are refused.
TEST(ArrayView, CopyRejectsMismatchedSizesAndCounts) {
  Fixture f;
  auto a = f.Make({4}, ScalarType::kFloat32);
  auto b = f.Make({4}, ScalarType::kInt32);
  auto c = f.Make({5}, ScalarType::kFloat32);
  auto d = f.Make({4}, ScalarType::kFloat64);
  const int32_t bits[4] = {0x3f800000, -1, 7, 0x7f7fffff};
  std::memcpy(b->data(), bits, sizeof(bits));
  ASSERT_TRUE(CopyView(*MakeView(a, {}, "dst"), *MakeView(b, {}, "src")).ok());
  EXPECT_EQ(std::memcmp(a->data(), bits, sizeof(bits)), 0);
  Status s1 = CopyView(*MakeView(d, {}, "dst"), *MakeView(a, {}, "src"));
  EXPECT_EQ(s1.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s1.message().find("element sizes differ"), std::string::npos);
  Status s2 = CopyView(*MakeView(a, {}, "dst"), *MakeView(c, {}, "src"));
  EXPECT_EQ(s2.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s2.message().find("elements"), std::string::npos);
}

// array.view(dtype): the bytes read as another element type, checked with that type's size and
// alignment; structs, bool over wider types, invalid types and a view without a shape refused.
TEST(ArrayView, ViewsAsAnotherDtypeAreCheckedWithThatType) {
  Fixture f;
  auto vecs = f.Make({4}, ScalarType::kFloat32, {3});   // 48 bytes
  auto as = [](ScalarType s, std::vector<uint32_t> elem = {}) {
    DType d;
    d.scalar = s;
    d.elem_shape = std::move(elem);
    return d;
  };
  ArrayRef floats{vecs->handle, 0, {4, 3}, {12, 4}};
  floats.view_dtype = as(ScalarType::kFloat32);
  auto v = MakeView(vecs, floats, "x");
  ASSERT_TRUE(v.ok()) << v.status().ToString();
  EXPECT_EQ(v->dtype().Name(), "float32");
  EXPECT_EQ(vecs->dtype.Name(), "vec(3,float32)");
  EXPECT_TRUE(v->contiguous());   // (12, 4) is C order for float32 of shape (4, 3)
  ArrayRef flat{vecs->handle, 0, {12}, {}};
  flat.view_dtype = as(ScalarType::kUInt32);
  auto w = MakeView(vecs, flat, "x");
  ASSERT_TRUE(w.ok()) << w.status().ToString();
  EXPECT_TRUE(w->contiguous());
  EXPECT_EQ(w->element_count(), 12u);

  auto floats16 = f.Make({4});   // 16 bytes
  ArrayRef too_far{floats16->handle, 0, {2}, {}};
  too_far.view_dtype = as(ScalarType::kFloat32, {3});   // 24 bytes of vec3
  EXPECT_EQ(MakeView(floats16, too_far, "x").status().code(), StatusCode::kOutOfRange);
  ArrayRef misaligned{floats16->handle, 4, {1}, {}};
  misaligned.view_dtype = as(ScalarType::kFloat64);
  EXPECT_EQ(MakeView(floats16, misaligned, "x").status().code(), StatusCode::kInvalidArgument);
  ArrayRef as_bool{floats16->handle, 0, {4}, {}};
  as_bool.view_dtype = as(ScalarType::kBool);
  EXPECT_EQ(MakeView(floats16, as_bool, "x").status().code(), StatusCode::kInvalidArgument);
  ArrayRef unknown{floats16->handle, 0, {4}, {}};
  unknown.view_dtype = as(static_cast<ScalarType>(99));
  EXPECT_EQ(MakeView(floats16, unknown, "x").status().code(), StatusCode::kInvalidArgument);
  ArrayRef structs{floats16->handle, 0, {1}, {}};
  DType s;
  s.type_name = "struct(m.S)";
  s.struct_size = 16;
  structs.view_dtype = s;
  EXPECT_EQ(MakeView(floats16, structs, "x").status().code(), StatusCode::kInvalidArgument);
  ArrayRef whole{floats16->handle, 0, {}, {}};
  whole.view_dtype = as(ScalarType::kInt32);
  EXPECT_EQ(MakeView(floats16, whole, "x").status().code(), StatusCode::kInvalidArgument);

  // the one validation: a kernel parameter of the view's type accepts it, the allocation's does not
  ArrayRequirement req;
  req.what = "kernel 'k' parameter 'a'";
  req.dtype = "uint32";
  req.element_size = 4;
  EXPECT_TRUE(ValidateArray(vecs, flat, req).ok());
  req.dtype = "vec(3,float32)";
  req.element_size = 12;
  EXPECT_EQ(ValidateArray(vecs, flat, req).status().code(), StatusCode::kInvalidArgument);
}

// HasContiguousStrides answers exactly `strides == ContiguousStrides(shape, size)` on random
// shapes (zero extents included) with one stride changed or not, and refuses strides whose
// product would overflow instead of wrapping.
TEST(ArrayView, ContiguityCheckMatchesTheBuiltStrides) {
  std::mt19937_64 rng(std::random_device{}());
  for (int trial = 0; trial < 2000; ++trial) {
    std::vector<int64_t> shape(1 + rng() % 4);
    for (auto& d : shape) d = static_cast<int64_t>(rng() % 6);   // 0..5
    const uint64_t size = 1ull << (rng() % 5);
    std::vector<int64_t> strides = ContiguousStrides(shape, size);
    if (rng() % 2) strides[rng() % strides.size()] += 1 + static_cast<int64_t>(rng() % 3);
    EXPECT_EQ(HasContiguousStrides(shape, strides, size), strides == ContiguousStrides(shape, size));
  }
  EXPECT_FALSE(HasContiguousStrides({2, 3}, {12}, 4));   // rank mismatch
  const int64_t big = int64_t{1} << 40;
  EXPECT_FALSE(HasContiguousStrides({big, big, 4}, {0, 16, 4}, 4));   // would overflow
  EXPECT_TRUE(HasContiguousStrides({big, 4}, {16, 4}, 4));
}

// A kernel parameter's element type matches an allocation's dtype by its type name or by the
// structural name formatted on the stack; every other name is refused, including the largest
// matrix's name and near misses.
TEST(ArrayView, DtypeMatchesParametersByNameOrStructure) {
  DType f;
  f.scalar = ScalarType::kFloat32;
  EXPECT_TRUE(f.MatchesParam("float32"));
  EXPECT_TRUE(f.MatchesParam("any"));
  EXPECT_FALSE(f.MatchesParam("float64"));
  DType v = f;
  v.elem_shape = {3};
  EXPECT_TRUE(v.MatchesParam("vec(3,float32)"));
  EXPECT_FALSE(v.MatchesParam("vec(4,float32)"));
  EXPECT_FALSE(v.MatchesParam("vec(3,float32"));
  v.type_name = "vec3f";
  EXPECT_TRUE(v.MatchesParam("vec3f"));
  EXPECT_TRUE(v.MatchesParam("vec(3,float32)"));
  DType m;
  m.scalar = ScalarType::kFloat64;
  m.elem_shape = {64, 64};
  EXPECT_EQ(m.StructuralName(), "mat(64,64,float64)");
  EXPECT_TRUE(m.MatchesParam("mat(64,64,float64)"));
  EXPECT_FALSE(m.MatchesParam("mat(64,64,float32)"));
  DType st;
  st.struct_size = 12;
  st.type_name = "struct(P)";
  EXPECT_TRUE(st.MatchesParam("struct(P)"));
  EXPECT_FALSE(st.MatchesParam("struct(Q)"));
}

}  // namespace
}  // namespace weft
