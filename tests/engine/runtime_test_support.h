// Test support for runtime tests: a ModuleStore that serves hand-written C++ "kernels" (no
// compiler involved), and helpers to make engines, arrays and views.
#pragma once

#include <gtest/gtest.h>

#include <cstring>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "engine/native/launch_abi.h"
#include "engine/runtime/engine.h"

namespace weft::testing {

class FakeModuleStore : public ModuleStore {
 public:
  std::map<std::string, std::shared_ptr<LoadedModule>> forward, backward;
  int backward_requests = 0;
  Expected<std::shared_ptr<const LoadedModule>> Compile(const ModuleSource&, const std::string&,
                                                        CompileReport*) override {
    return Unimplemented("fake store compiles nothing");
  }
  std::shared_ptr<const LoadedModule> Find(const std::string& id) const override {
    auto it = forward.find(id);
    return it == forward.end() ? nullptr : it->second;
  }
  Expected<std::shared_ptr<const LoadedModule>> WithBackward(const std::string& id) override {
    ++backward_requests;
    auto it = backward.find(id);
    if (it == backward.end()) return NotFound("no module " + id);
    return std::shared_ptr<const LoadedModule>(it->second);
  }
  ModuleStoreStats stats() const override { return {}; }
};

inline ParamLayout ArrayParam(const std::string& name, const std::string& dtype, int ndim, uint32_t offset) {
  ParamLayout p;
  p.name = name;
  p.type = "array(" + dtype + "," + std::to_string(ndim) + ")";
  p.offset = offset;
  p.size = sizeof(wp::array_abi_t);
  p.align = 8;
  p.is_array = true;
  p.array_dtype = dtype;
  p.array_ndim = ndim;
  return p;
}

inline ParamLayout ValueParam(const std::string& name, const std::string& type, uint32_t offset, uint32_t size) {
  ParamLayout p;
  p.name = name;
  p.type = type;
  p.offset = offset;
  p.size = size;
  p.align = size;
  return p;
}

inline std::unique_ptr<Engine> MakeEngine(FakeModuleStore** store_out = nullptr, int threads = 2) {
  auto store = std::make_unique<FakeModuleStore>();
  if (store_out) *store_out = store.get();
  EngineOptions o;
  o.cpu_threads = threads;
  o.remove_stale_slabs = false;
  auto e = Engine::Create(o, std::move(store));
  EXPECT_TRUE(e.ok()) << e.status().ToString();
  return std::move(e).value();
}

inline SessionOptions Local(const std::string& name = "test") {
  SessionOptions o;
  o.client_name = name;
  o.local = true;
  o.principal = "unix-uid:0";
  return o;
}

inline DType F32() {
  DType d;
  d.scalar = ScalarType::kFloat32;
  return d;
}

inline CreateArrayParams FromFloats(const std::vector<float>& v, bool requires_grad = false) {
  CreateArrayParams p;
  p.dtype = F32();
  p.shape = {static_cast<int64_t>(v.size())};
  p.init = CreateArrayParams::Init::kData;
  p.value.assign(reinterpret_cast<const char*>(v.data()), v.size() * 4);
  p.requires_grad = requires_grad;
  return p;
}

// The whole array's elements as T (the array's element size must be sizeof(T)).
template <typename T>
std::vector<T> ReadValues(Engine& e, Session& s, uint64_t handle) {
  std::vector<T> out;
  Status st = e.ReadArray(s, handle, 0, 0, 0, [&](uint64_t, const char* d, size_t n) {
    size_t k = out.size();
    out.resize(k + n / sizeof(T));
    std::memcpy(out.data() + k, d, n);
    return true;
  });
  EXPECT_TRUE(st.ok()) << st.ToString();
  return out;
}

inline std::vector<float> ReadFloats(Engine& e, Session& s, uint64_t handle) { return ReadValues<float>(e, s, handle); }

// A fill of the whole array `handle` (float32 elements) with 1.0.
inline Command FillOnes(uint64_t handle) {
  Command c;
  FillCommand f;
  f.dst.handle = handle;
  float one = 1.0f;
  f.value.assign(reinterpret_cast<const char*>(&one), sizeof(one));
  c.kind = f;
  return c;
}

// A copy of the whole array `src` into the whole array `dst`.
inline Command CopyCmd(uint64_t dst, uint64_t src) {
  Command c;
  CopyCommand cp;
  cp.dst.handle = dst;
  cp.src.handle = src;
  c.kind = cp;
  return c;
}

inline ArgValue ArrayArg(uint64_t handle) {
  ArgValue a;
  a.kind = ArgValue::Kind::kArray;
  a.array.handle = handle;
  return a;
}

template <typename T>
ArgValue RawArg(T v) {
  ArgValue a;
  a.kind = ArgValue::Kind::kRaw;
  a.raw.assign(reinterpret_cast<const char*>(&v), sizeof(T));
  return a;
}

inline Command Cmd(LaunchCommand l) {
  Command c;
  c.kind = std::move(l);
  return c;
}

inline Command Cmd(TapeCommand t) {
  Command c;
  c.kind = std::move(t);
  return c;
}

}  // namespace weft::testing
