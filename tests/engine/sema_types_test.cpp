// Type representation: canonical strings both ways (and Warp's short names), C++ spellings,
// sizes and alignments of kernel argument types, literal spelling.
#include <gtest/gtest.h>

#include "engine/sema/types.h"

namespace weft::sema {
namespace {

TEST(SemaTypes, CanonicalStringsRoundTrip) {
  for (const char* s : {"bool", "int8", "uint64", "float16", "float32", "float64", "vec(3,float32)", "vec(17,int32)",
                        "mat(3,4,float64)", "quat(float16)", "transform(float32)", "array(float32,1)",
                        "array(vec(3,float32),4)", "array(mat(2,2,float64),2)", "struct(mymod.Particle)",
                        "array(struct(m.S),1)", "any", "array(any,1)"}) {
    auto t = ParseType(s);
    ASSERT_TRUE(t.ok()) << s << ": " << t.status().message();
    EXPECT_EQ(TypeString(*t), s);
  }
}

// Patterns of generic annotations: typing.Any, wp.Int/Float/Scalar, vectors and matrices of any
// length or scalar category; what each accepts.
TEST(SemaTypes, GenericPatterns) {
  for (const char* s : {"any_int", "any_float", "any_scalar", "vec(any,float32)", "vec(3,any_int)", "vec(any,any)",
                        "mat(any,any,float64)", "mat(2,any,any_scalar)", "quat(any_float)", "transform(any)",
                        "array(vec(any,float32),1)", "tuple(any_int,any_float)"}) {
    auto t = ParseType(s);
    ASSERT_TRUE(t.ok()) << s << ": " << t.status().message();
    EXPECT_EQ(TypeString(*t), s);
    EXPECT_TRUE(ContainsAny(*t)) << s;
  }
  auto accepts = [](const char* p, const char* a) { return GenericAccepts(*ParseType(p), *ParseType(a)); };
  EXPECT_TRUE(accepts("any_int", "int16"));
  EXPECT_TRUE(accepts("any_int", "uint64"));
  EXPECT_FALSE(accepts("any_int", "float32"));
  EXPECT_FALSE(accepts("any_int", "bool"));
  EXPECT_FALSE(accepts("any_int", "vec(3,int32)"));
  EXPECT_TRUE(accepts("any_float", "float16"));
  EXPECT_TRUE(accepts("any_float", "bfloat16"));
  EXPECT_FALSE(accepts("any_float", "int32"));
  EXPECT_TRUE(accepts("any_scalar", "int8"));
  EXPECT_TRUE(accepts("any_scalar", "float64"));
  EXPECT_FALSE(accepts("any_scalar", "bool"));
  EXPECT_TRUE(accepts("vec(any,float32)", "vec(4,float32)"));
  EXPECT_FALSE(accepts("vec(any,float32)", "vec(4,float64)"));
  EXPECT_FALSE(accepts("vec(any,float32)", "mat(2,2,float32)"));
  EXPECT_TRUE(accepts("vec(3,any_int)", "vec(3,int16)"));
  EXPECT_FALSE(accepts("vec(3,any_int)", "vec(4,int16)"));
  EXPECT_FALSE(accepts("vec(3,any_int)", "vec(3,float32)"));
  EXPECT_TRUE(accepts("mat(any,any,float64)", "mat(3,5,float64)"));
  EXPECT_TRUE(accepts("mat(2,any,any_scalar)", "mat(2,7,int64)"));
  EXPECT_FALSE(accepts("mat(2,any,any_scalar)", "mat(3,7,int64)"));
  EXPECT_TRUE(accepts("quat(any_float)", "quat(float64)"));
  EXPECT_TRUE(accepts("array(vec(any,float32),1)", "array(vec(6,float32),1)"));
  EXPECT_FALSE(accepts("array(vec(any,float32),1)", "array(vec(6,float32),2)"));
  EXPECT_TRUE(accepts("any", "struct(m.S)"));
  // A concrete type accepts itself only; a pattern is not equal to a type it accepts.
  EXPECT_TRUE(accepts("vec(3,float32)", "vec(3,float32)"));
  EXPECT_FALSE(accepts("vec(3,float32)", "vec(3,float64)"));
  EXPECT_NE(*ParseType("vec(3,any_int)"), *ParseType("vec(3,int32)"));
  EXPECT_NE(*ParseType("any_int"), *ParseType("any"));
  EXPECT_FALSE(ContainsAny(*ParseType("vec(3,float32)")));
  for (const char* bad : {"vec(any)", "vec(3,anything)", "mat(any,2)", "any_bool", "vec(-1,float32)"})
    EXPECT_FALSE(ParseType(bad).ok()) << bad;
}

// Indexed arrays, fixed-size arrays and wp.Function parameters: strings, C++ spellings, layouts.
TEST(SemaTypes, IndexedFixedAndFunctionTypes) {
  for (const char* s : {"indexedarray(float32,1)", "indexedarray(vec(3,float64),4)", "fixedarray(int32,2,3)",
                        "fixedarray(struct(m.S),4)", "function", "tuple(int32,vec(3,float32))"}) {
    auto t = ParseType(s);
    ASSERT_TRUE(t.ok()) << s << ": " << t.status().message();
    EXPECT_EQ(TypeString(*t), s);
  }
  auto ia = ParseType("indexedarray(float32,2)");
  ASSERT_TRUE(ia.ok());
  EXPECT_TRUE(ia->is_array() && ia->is_indexed_array() && ia->ndim == 2);
  EXPECT_NE(*ia, *ParseType("array(float32,2)"));
  EXPECT_EQ(CppType(*ia), "wp::indexedarray_t<wp::float32>");
  auto il = LayoutOf(*ia, {});
  ASSERT_TRUE(il.ok());
  EXPECT_EQ(il->size, 440u);
  EXPECT_EQ(il->align, 8u);
  auto fa = ParseType("fixedarray(float64,2,3)");
  ASSERT_TRUE(fa.ok());
  EXPECT_TRUE(fa->is_fixed_array() && fa->ndim == 2);
  EXPECT_EQ(CppType(*fa), "wp::fixedarray_t<wp::float64,2,3,0,0>");
  EXPECT_FALSE(LayoutOf(*fa, {}).ok());   // never a kernel argument
  for (const char* bad : {"fixedarray(float32)", "fixedarray(float32,0)", "fixedarray(float32,4097)",
                          "fixedarray(float32,64,64,2)", "fixedarray(float32,1,1,1,1,1)", "indexedarray(float32,5)",
                          "fixedarray(array(float32,1),2)"})
    EXPECT_FALSE(ParseType(bad).ok()) << bad;
}

TEST(SemaTypes, WarpAliases) {
  struct Case {
    const char* in;
    const char* canonical;
  } cases[] = {{"float", "float32"},          {"int", "int32"},
               {"vec3", "vec(3,float32)"},    {"vec3d", "vec(3,float64)"},
               {"vec2i", "vec(2,int32)"},     {"vec4ub", "vec(4,uint8)"},
               {"mat33", "mat(3,3,float32)"}, {"mat44d", "mat(4,4,float64)"},
               {"quatf", "quat(float32)"},    {"quat", "quat(float32)"},
               {"transformd", "transform(float64)"}, {"spatial_vector", "vec(6,float32)"},
               {"spatial_matrixd", "mat(6,6,float64)"}, {"spatial_vector(float64)", "vec(6,float64)"}};
  for (const auto& c : cases) {
    auto t = ParseType(c.in);
    ASSERT_TRUE(t.ok()) << c.in;
    EXPECT_EQ(TypeString(*t), c.canonical) << c.in;
  }
}

TEST(SemaTypes, BadStringsAreErrorsNotCrashes) {
  for (const char* s : {"", "vec(", "vec(3)", "vec(3,float)", "mat(3,float32)", "array(float32,5)",
                        "array(array(float32,1),1)", "struct()", "float33", "vec(3,float32)x", "quat(int32",
                        "array(float32,99999999999)", "vec(-1,float32)", "vec(-2,float32)", "mat(2,-1,float32)"}) {
    auto t = ParseType(s);
    EXPECT_FALSE(t.ok()) << s;
  }
}

TEST(SemaTypes, ZeroLengthIsATypeAnyLengthIsAPattern) {
  auto zero = ParseType("vec(0,float32)");
  ASSERT_TRUE(zero.ok());
  EXPECT_EQ(zero->rows, 0);
  EXPECT_FALSE(ContainsAny(*zero));
  EXPECT_EQ(TypeString(*zero), "vec(0,float32)");
  EXPECT_FALSE(LayoutOf(*zero, {}).ok());   // no bytes: never a kernel argument or field
  auto any = ParseType("vec(any,float32)");
  ASSERT_TRUE(any.ok());
  EXPECT_TRUE(ContainsAny(*any));
  EXPECT_TRUE(GenericAccepts(*any, *zero));
  EXPECT_TRUE(GenericAccepts(*any, *ParseType("vec(3,float32)")));
  EXPECT_FALSE(GenericAccepts(*zero, *ParseType("vec(3,float32)")));
  auto m = ParseType("mat(0,3,float64)");
  ASSERT_TRUE(m.ok());
  EXPECT_FALSE(ContainsAny(*m));
  EXPECT_TRUE(ContainsAny(*ParseType("mat(any,3,float64)")));
}

TEST(SemaTypes, CppSpellings) {
  EXPECT_EQ(CppType(*ParseType("vec(3,float32)")), "wp::vec_t<3,wp::float32>");
  EXPECT_EQ(CppType(*ParseType("mat(2,3,float64)")), "wp::mat_t<2,3,wp::float64>");
  EXPECT_EQ(CppType(*ParseType("array(quat(float32),2)")), "wp::array_t<wp::quat_t<wp::float32>>");
  EXPECT_EQ(CppType(*ParseType("bool")), "bool");
  EXPECT_EQ(CppType(*ParseType("float16")), "wp::float16");
  EXPECT_EQ(CppType(*ParseType("struct(a.B)")), "wp::weft_struct_aZ2EB");
}

TEST(SemaTypes, Layouts) {
  StructTable structs;
  StructInfo inner{"m.Inner", StructCppName("m.Inner"), {{"k", Type::Scalar(ScalarKind::kInt8)}, {"d", Type::Scalar(ScalarKind::kFloat64)}}};
  StructInfo outer{"m.Outer", StructCppName("m.Outer"),
                   {{"flag", Type::Bool()}, {"in", Type::Struct("m.Inner")}, {"a", Type::Array(Type::Float32(), 1)},
                    {"h", Type::Scalar(ScalarKind::kFloat16)}}};
  structs["m.Inner"] = inner;
  structs["m.Outer"] = outer;
  auto l = [&](const Type& t) { return *LayoutOf(t, structs); };
  EXPECT_EQ(l(Type::Bool()).size, 1u);
  EXPECT_EQ(l(Type::Scalar(ScalarKind::kFloat16)).size, 2u);
  EXPECT_EQ(l(Type::Vector(3, ScalarKind::kFloat32)).size, 12u);
  EXPECT_EQ(l(Type::Vector(3, ScalarKind::kFloat32)).align, 4u);
  EXPECT_EQ(l(Type::Matrix(3, 3, ScalarKind::kFloat64)).size, 72u);
  EXPECT_EQ(l(Type::Quat(ScalarKind::kFloat32)).size, 16u);
  EXPECT_EQ(l(Type::Transform(ScalarKind::kFloat64)).size, 56u);
  EXPECT_EQ(l(Type::Array(Type::Vector(3, ScalarKind::kFloat32), 2)).size, 88u);
  EXPECT_EQ(l(Type::Array(Type::Vector(3, ScalarKind::kFloat32), 2)).align, 8u);
  EXPECT_EQ(l(Type::Struct("m.Inner")).size, 16u);  // int8 @0, float64 @8
  EXPECT_EQ(l(Type::Struct("m.Inner")).align, 8u);
  EXPECT_EQ(l(Type::Struct("m.Outer")).size, 8u + 16u + 88u + 8u);  // bool, pad, Inner @8, array @24, half @112 -> 120
  EXPECT_FALSE(LayoutOf(Type::Struct("nope"), structs).ok());
  EXPECT_FALSE(LayoutOf(Type::Any(), structs).ok());
}

TEST(SemaTypes, Predicates) {
  EXPECT_TRUE(IsFloat(ScalarKind::kFloat16));
  EXPECT_FALSE(IsFloat(ScalarKind::kInt64));
  EXPECT_TRUE(IsInt(ScalarKind::kUInt8));
  EXPECT_FALSE(IsInt(ScalarKind::kBool));
  EXPECT_TRUE(IsDifferentiable(Type::Vector(3, ScalarKind::kFloat64)));
  EXPECT_FALSE(IsDifferentiable(Type::Vector(3, ScalarKind::kInt32)));
  EXPECT_FALSE(IsDifferentiable(Type::Array(Type::Float32(), 1)));
  EXPECT_TRUE(ContainsAny(*ParseType("array(any,2)")));
  EXPECT_FALSE(ContainsAny(*ParseType("array(float32,2)")));
}

}  // namespace
}  // namespace weft::sema
