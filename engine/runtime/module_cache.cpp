// Module cache: keys, artifact (de)serialization, verified disk files, memory LRU, coalescing.
#include "engine/runtime/module_cache.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <tuple>

#include "spdlog/spdlog.h"

#include "engine/core/sha256.h"

namespace weft {
namespace {

namespace fs = std::filesystem;

// ---- canonical text ------------------------------------------------------------------------

// Appends tagged, length-prefixed fields: "tag=<len>:<bytes>\n".
class CanonicalWriter {
 public:
  void Field(std::string_view tag, std::string_view value) {
    out_.append(tag);
    out_ += '=';
    out_ += std::to_string(value.size());
    out_ += ':';
    out_.append(value);
    out_ += '\n';
  }
  void Field(std::string_view tag, uint64_t value) { Field(tag, std::to_string(value)); }
  std::string Take() { return std::move(out_); }

 private:
  std::string out_;
};

const char* SymbolKindName(Symbol::Kind kind) {
  switch (kind) {
    case Symbol::Kind::kConstant: return "constant";
    case Symbol::Kind::kFunction: return "function";
    case Symbol::Kind::kType: return "type";
    case Symbol::Kind::kBuiltinModule: return "builtin_module";
  }
  return "?";
}

// ---- binary payload ------------------------------------------------------------------------

class ByteWriter {
 public:
  void U32(uint32_t v) { Raw(&v, sizeof v); }
  void U64(uint64_t v) { Raw(&v, sizeof v); }
  void Str(std::string_view s) {
    U64(s.size());
    Raw(s.data(), s.size());
  }
  void Raw(const void* data, size_t size) { out_.append(static_cast<const char*>(data), size); }
  std::string& out() { return out_; }

 private:
  std::string out_;
};

class ByteReader {
 public:
  explicit ByteReader(std::string_view in) : in_(in) {}
  bool U32(uint32_t* v) { return Raw(v, sizeof *v); }
  bool U64(uint64_t* v) { return Raw(v, sizeof *v); }
  bool Str(std::string* s) {
    uint64_t size = 0;
    if (!U64(&size) || size > in_.size() - at_) return false;
    s->assign(in_.data() + at_, size);
    at_ += size;
    return true;
  }
  bool Count(uint64_t* n) {  // an element count can't exceed the bytes left
    return U64(n) && *n <= in_.size() - at_;
  }
  bool AtEnd() const { return at_ == in_.size(); }

 private:
  bool Raw(void* out, size_t size) {
    if (size > in_.size() - at_) return false;
    std::memcpy(out, in_.data() + at_, size);
    at_ += size;
    return true;
  }
  std::string_view in_;
  size_t at_ = 0;
};

constexpr char kPayloadMagic[8] = {'W', 'E', 'F', 'T', 'A', 'R', 'T', '1'};
constexpr char kFileMagic[8] = {'W', 'E', 'F', 'T', 'M', 'O', 'D', '\n'};
constexpr size_t kHeaderSize = 8 + 4 + 4 + 8 + 32;  // magic, version, reserved, size, sha256

void WriteParam(ByteWriter& w, const ParamLayout& p) {
  w.Str(p.name);
  w.Str(p.type);
  w.U32(p.offset);
  w.U32(p.size);
  w.U32(p.align);
  w.U32(p.is_array ? 1 : 0);
  w.Str(p.array_dtype);
  w.U32(uint32_t(p.array_ndim));
  w.U32(p.array_elem_size);
  w.U64(p.fields.size());
  for (const auto& f : p.fields) WriteParam(w, f);
}

bool ReadParam(ByteReader& r, ParamLayout* p, int depth) {
  if (depth > 64) return false;
  uint32_t is_array = 0, ndim = 0;
  uint64_t nfields = 0;
  if (!(r.Str(&p->name) && r.Str(&p->type) && r.U32(&p->offset) && r.U32(&p->size) &&
        r.U32(&p->align) && r.U32(&is_array) && r.Str(&p->array_dtype) && r.U32(&ndim) &&
        r.U32(&p->array_elem_size) && r.Count(&nfields)))
    return false;
  p->is_array = is_array != 0;
  p->array_ndim = int(ndim);
  p->fields.resize(nfields);
  for (auto& f : p->fields)
    if (!ReadParam(r, &f, depth + 1)) return false;
  return true;
}

// ---- files ---------------------------------------------------------------------------------

Expected<std::string> ReadWholeFile(const std::string& path) {
  int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    if (errno == ENOENT) return NotFound("no file " + path);
    return Unavailable("cannot open " + path + ": " + std::strerror(errno));
  }
  std::string data;
  char buffer[1 << 16];
  for (;;) {
    ssize_t n = ::read(fd, buffer, sizeof buffer);
    if (n < 0) {
      if (errno == EINTR) continue;
      int err = errno;
      ::close(fd);
      return Unavailable("cannot read " + path + ": " + std::strerror(err));
    }
    if (n == 0) break;
    data.append(buffer, size_t(n));
  }
  ::close(fd);
  return data;
}

// Writes `data` to a temporary file in the same directory, then renames it onto `path`.
Status WriteFileAtomically(const std::string& path, std::string_view data) {
  static std::atomic<uint64_t> counter{0};
  std::string tmp = path + ".tmp." + std::to_string(::getpid()) + "." +
                    std::to_string(counter.fetch_add(1));
  int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
  if (fd < 0) return Unavailable("cannot create " + tmp + ": " + std::strerror(errno));
  size_t written = 0;
  while (written < data.size()) {
    ssize_t n = ::write(fd, data.data() + written, data.size() - written);
    if (n < 0) {
      if (errno == EINTR) continue;
      int err = errno;
      ::close(fd);
      ::unlink(tmp.c_str());
      return Unavailable("cannot write " + tmp + ": " + std::strerror(err));
    }
    written += size_t(n);
  }
  if (::close(fd) != 0 || ::rename(tmp.c_str(), path.c_str()) != 0) {
    int err = errno;
    ::unlink(tmp.c_str());
    return Unavailable("cannot store " + path + ": " + std::strerror(err));
  }
  return Status::Ok();
}

}  // namespace

// ---- keys ----------------------------------------------------------------------------------

std::string CanonicalModuleText(const ModuleSource& source) {
  CanonicalWriter w;
  w.Field("format", "weft-module-source/1");
  w.Field("name", source.name);
  w.Field("functions", source.functions.size());
  for (const auto& f : source.functions) {
    w.Field("fn.name", f.name);
    w.Field("fn.key", f.key);
    w.Field("fn.file", f.file);
    w.Field("fn.line", f.first_line);
    w.Field("fn.kernel", f.is_kernel ? 1 : 0);
    w.Field("fn.return", f.return_type);
    w.Field("fn.params", f.param_types.size());
    for (const auto& t : f.param_types) w.Field("fn.param_type", t);
    w.Field("fn.param_names", f.param_names.size());
    for (const auto& n : f.param_names) w.Field("fn.param_name", n);
    w.Field("fn.source", f.source);
  }
  std::vector<const Symbol*> symbols;
  for (const auto& s : source.symbols) symbols.push_back(&s);
  std::sort(symbols.begin(), symbols.end(), [](const Symbol* a, const Symbol* b) {
    return std::tie(a->name, a->kind, a->constant.type, a->constant.value, a->target) <
           std::tie(b->name, b->kind, b->constant.type, b->constant.value, b->target);
  });
  w.Field("symbols", symbols.size());
  for (const Symbol* s : symbols) {
    w.Field("sym.name", s->name);
    w.Field("sym.kind", SymbolKindName(s->kind));
    w.Field("sym.const_type", s->constant.type);
    w.Field("sym.const_value", s->constant.value);
    w.Field("sym.target", s->target);
  }
  w.Field("structs", source.structs.size());
  for (const auto& s : source.structs) {
    w.Field("struct.name", s.name);
    w.Field("struct.fields", s.fields.size());
    for (const auto& f : s.fields) {
      w.Field("field.name", f.name);
      w.Field("field.type", f.type);
    }
  }
  w.Field("options", source.options.size());  // std::map: already sorted
  for (const auto& [k, v] : source.options) {
    w.Field("opt.key", k);
    w.Field("opt.value", v);
  }
  return w.Take();
}

std::string ModuleCacheKey(const ModuleSource& source, const CodegenOptions& codegen,
                           const ModuleKeyContext& context) {
  CanonicalWriter w;
  w.Field("key", "weft-module-key/1");
  w.Field("target", codegen.target == Target::kCpu ? "cpu" : "cuda");
  w.Field("backward", codegen.enable_backward ? 1 : 0);
  w.Field("bounds_checks", codegen.bounds_checks ? 1 : 0);
  if (!codegen.loop_cancel_poll) w.Field("cancel_poll", 0);
  if (!codegen.grid_stride) w.Field("grid_stride", 0);
  if (codegen.cpu_lanes > 1) w.Field("cpu_lanes", uint64_t{codegen.cpu_lanes});
  if (codegen.trust_tid_indices) w.Field("trust_tid_indices", 1);
  w.Field("native", context.native_version);
  w.Field("target_id", context.target_id);
  w.Field("build", context.build_id);
  w.Field("verified_for_cuda", context.verified_for_cuda ? 1 : 0);
  Sha256 hash;
  hash.Update(w.Take());
  hash.Update(CanonicalModuleText(source));
  return ToHex(hash.Finish());
}

Expected<std::string> NativeLibraryVersion(const std::string& native_dir) {
  std::error_code ec;
  std::vector<std::string> files;
  for (auto it = fs::recursive_directory_iterator(native_dir, ec);
       !ec && it != fs::recursive_directory_iterator(); it.increment(ec)) {
    if (it->is_regular_file(ec)) files.push_back(fs::relative(it->path(), native_dir, ec).string());
  }
  if (ec) return NotFound("cannot list the native library at " + native_dir + ": " + ec.message());
  if (files.empty()) return NotFound("no native library headers in " + native_dir);
  std::sort(files.begin(), files.end());
  CanonicalWriter w;
  for (const auto& f : files) {
    WEFT_ASSIGN_OR_RETURN(std::string contents, ReadWholeFile((fs::path(native_dir) / f).string()));
    w.Field("path", f);
    w.Field("contents", contents);
  }
  return Sha256Hex(w.Take());
}

// ---- artifacts -----------------------------------------------------------------------------

std::string SerializeArtifact(const ModuleArtifact& artifact) {
  ByteWriter w;
  w.Raw(kPayloadMagic, sizeof kPayloadMagic);
  w.U64(artifact.kernels.size());
  for (const auto& k : artifact.kernels) {
    w.Str(k.name);
    w.Str(k.forward_symbol);
    w.Str(k.backward_symbol);
    w.Str(k.adjoint_refused);
    w.U32((k.grid_stride ? 1u : 0u) | (k.lanes > 1 ? k.lanes << 1 : 0u));   // layout flags
    w.U32(k.args_size);
    w.U32(k.args_align);
    w.U64(k.params.size());
    for (const auto& p : k.params) WriteParam(w, p);
    w.U64(k.tid_indexed_params.size());
    for (uint32_t p : k.tid_indexed_params) w.U32(p);
    w.Str(k.coarse_symbol);
    w.U32(k.coarse_loaded_bytes);
  }
  w.U64(artifact.function_names.size());
  for (const auto& n : artifact.function_names) w.Str(n);
  w.Str(artifact.object);
  w.Str(artifact.generated_source);
  return std::move(w.out());
}

Expected<ModuleArtifact> DeserializeArtifact(std::string_view payload) {
  auto bad = [] { return DataLoss("malformed module artifact"); };
  if (payload.size() < sizeof kPayloadMagic ||
      std::memcmp(payload.data(), kPayloadMagic, sizeof kPayloadMagic) != 0)
    return bad();
  ByteReader r(payload.substr(sizeof kPayloadMagic));
  ModuleArtifact a;
  uint64_t nkernels = 0;
  if (!r.Count(&nkernels)) return bad();
  a.kernels.resize(nkernels);
  for (auto& k : a.kernels) {
    uint64_t nparams = 0;
    uint32_t flags = 1;
    if (!(r.Str(&k.name) && r.Str(&k.forward_symbol) && r.Str(&k.backward_symbol) && r.Str(&k.adjoint_refused) &&
          r.U32(&flags) && (flags >> 1) <= 1024 && r.U32(&k.args_size) && r.U32(&k.args_align) && r.Count(&nparams)))
      return bad();
    k.grid_stride = (flags & 1u) != 0;
    k.lanes = (flags >> 1) > 1 ? flags >> 1 : 1;

    k.params.resize(nparams);
    for (auto& p : k.params)
      if (!ReadParam(r, &p, 0)) return bad();
    uint64_t ntrusted = 0;
    if (!r.Count(&ntrusted)) return bad();
    k.tid_indexed_params.resize(ntrusted);
    for (auto& p : k.tid_indexed_params)
      if (!r.U32(&p) || p >= k.params.size()) return bad();
    if (!r.Str(&k.coarse_symbol) || !r.U32(&k.coarse_loaded_bytes)) return bad();
  }
  uint64_t nnames = 0;
  if (!r.Count(&nnames)) return bad();
  a.function_names.resize(nnames);
  for (auto& n : a.function_names)
    if (!r.Str(&n)) return bad();
  if (!(r.Str(&a.object) && r.Str(&a.generated_source) && r.AtEnd())) return bad();
  return a;
}

// ---- disk ----------------------------------------------------------------------------------

Status DiskModuleCache::Init() const {
  if (dir_.empty()) return Status::Ok();
  std::error_code ec;
  fs::create_directories(dir_, ec);
  if (ec) return Unavailable("cannot create the module cache directory " + dir_ + ": " + ec.message());
  return Status::Ok();
}

std::string DiskModuleCache::PathFor(const std::string& key) const {
  return (fs::path(dir_) / (key + ".wmod")).string();
}

Expected<ModuleArtifact> DiskModuleCache::Load(const std::string& key) const {
  if (dir_.empty()) return NotFound("no disk cache");
  const std::string path = PathFor(key);
  WEFT_ASSIGN_OR_RETURN(std::string file, ReadWholeFile(path));
  auto corrupt = [&](const std::string& why) {
    ::unlink(path.c_str());
    return DataLoss("cached module " + path + " is " + why + "; removed");
  };
  if (file.size() < kHeaderSize) return corrupt("truncated (no header)");
  if (std::memcmp(file.data(), kFileMagic, sizeof kFileMagic) != 0) return corrupt("not a module file");
  uint32_t version = 0;
  uint64_t payload_size = 0;
  std::memcpy(&version, file.data() + 8, 4);
  std::memcpy(&payload_size, file.data() + 16, 8);
  if (version != kFormatVersion) return corrupt("of format " + std::to_string(version));
  if (payload_size != file.size() - kHeaderSize) return corrupt("truncated");
  std::string_view payload(file.data() + kHeaderSize, payload_size);
  Sha256 hash;
  hash.Update(payload);
  Sha256::Digest digest = hash.Finish();
  if (std::memcmp(digest.data(), file.data() + 24, digest.size()) != 0)
    return corrupt("corrupted (hash mismatch)");
  auto artifact = DeserializeArtifact(payload);
  if (!artifact.ok()) return corrupt("malformed");
  ::utimensat(AT_FDCWD, path.c_str(), nullptr, 0);   // mark as recently used (LRU bound)
  return artifact;
}

size_t DiskModuleCache::EvictToCapacity(const std::string& keep) const {
  if (dir_.empty() || capacity_bytes_ == 0) return 0;
  struct Entry {
    std::string key;
    uint64_t bytes = 0;
    fs::file_time_type used;
  };
  std::map<std::string, Entry> entries;
  uint64_t total = 0;
  std::error_code ec;
  for (auto it = fs::directory_iterator(dir_, ec); !ec && it != fs::directory_iterator(); it.increment(ec)) {
    const fs::path& p = it->path();
    const std::string ext = p.extension().string();
    if (ext != ".wmod" && ext != ".cpp") continue;
    std::error_code e2;
    uint64_t size = it->file_size(e2);
    if (e2) continue;
    Entry& entry = entries[p.stem().string()];
    entry.key = p.stem().string();
    entry.bytes += size;
    if (ext == ".wmod") entry.used = it->last_write_time(e2);
    total += size;
  }
  if (total <= capacity_bytes_) return 0;
  std::vector<Entry*> order;
  for (auto& [k, e] : entries)
    if (k != keep) order.push_back(&e);
  std::sort(order.begin(), order.end(), [](const Entry* a, const Entry* b) { return a->used < b->used; });
  size_t removed = 0;
  for (Entry* e : order) {
    if (total <= capacity_bytes_) break;
    ::unlink(PathFor(e->key).c_str());
    ::unlink((fs::path(dir_) / (e->key + ".cpp")).string().c_str());
    total -= e->bytes;
    ++removed;
  }
  return removed;
}

Status DiskModuleCache::Store(const std::string& key, const ModuleArtifact& artifact) const {
  if (dir_.empty()) return Status::Ok();
  std::string payload = SerializeArtifact(artifact);
  Sha256 hash;
  hash.Update(payload);
  Sha256::Digest digest = hash.Finish();
  std::string file;
  file.reserve(kHeaderSize + payload.size());
  file.append(kFileMagic, sizeof kFileMagic);
  uint32_t version = kFormatVersion, reserved = 0;
  uint64_t size = payload.size();
  file.append(reinterpret_cast<const char*>(&version), 4);
  file.append(reinterpret_cast<const char*>(&reserved), 4);
  file.append(reinterpret_cast<const char*>(&size), 8);
  file.append(reinterpret_cast<const char*>(digest.data()), digest.size());
  file += payload;
  WEFT_RETURN_IF_ERROR(Init());
  // The generated source next to the binary, for people (never read back).
  (void)WriteFileAtomically((fs::path(dir_) / (key + ".cpp")).string(), artifact.generated_source);
  WEFT_RETURN_IF_ERROR(WriteFileAtomically(PathFor(key), file));
  EvictToCapacity(key);
  return Status::Ok();
}

// ---- memory + coalescing -------------------------------------------------------------------

ModuleCache::ModuleCache(std::string dir, size_t memory_capacity, uint64_t disk_capacity_bytes)
    : disk_(std::move(dir), disk_capacity_bytes), capacity_(memory_capacity) {}

ModuleCache::Module ModuleCache::Peek(const std::string& key) {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = index_.find(key);
  if (it == index_.end()) return nullptr;
  lru_.splice(lru_.begin(), lru_, it->second);
  return it->second->second;
}

void ModuleCache::InsertLocked(const std::string& key, Module module) {
  if (auto it = index_.find(key); it != index_.end()) {
    lru_.erase(it->second);
    index_.erase(it);
  }
  lru_.emplace_front(key, std::move(module));
  index_[key] = lru_.begin();
  while (lru_.size() > capacity_) {
    index_.erase(lru_.back().first);
    lru_.pop_back();
  }
}

Expected<ModuleCache::Module> ModuleCache::Get(const std::string& key, const Callbacks& callbacks,
                                               Source* source,
                                               std::vector<Diagnostic>* diagnostics) {
  std::unique_lock<std::mutex> lock(mutex_);
  if (auto it = index_.find(key); it != index_.end()) {
    lru_.splice(lru_.begin(), lru_, it->second);
    ++stats_.memory_hits;
    if (source) *source = Source::kMemory;
    return it->second->second;
  }
  if (auto it = in_flight_.find(key); it != in_flight_.end()) {
    std::shared_ptr<InFlight> flight = it->second;
    build_done_.wait(lock, [&] { return flight->done; });
    if (diagnostics)
      diagnostics->insert(diagnostics->end(), flight->diagnostics.begin(), flight->diagnostics.end());
    if (!flight->status.ok()) return flight->status;
    ++stats_.memory_hits;
    if (source) *source = Source::kMemory;
    return flight->module;
  }
  auto flight = std::make_shared<InFlight>();
  in_flight_[key] = flight;
  lock.unlock();

  Source from = Source::kBuilt;
  std::vector<Diagnostic> diags;
  Expected<Module> result = LoadOrBuild(key, callbacks, &from, &diags);

  lock.lock();
  if (from == Source::kDisk && result.ok()) {
    ++stats_.disk_hits;
  } else {
    ++stats_.misses;
  }
  if (result.ok()) {
    flight->module = *result;
    InsertLocked(key, *result);
  } else {
    flight->status = result.status();
  }
  flight->diagnostics = diags;
  flight->done = true;
  in_flight_.erase(key);
  build_done_.notify_all();
  lock.unlock();

  if (diagnostics) diagnostics->insert(diagnostics->end(), diags.begin(), diags.end());
  if (source) *source = from;
  return result;
}

Expected<ModuleCache::Module> ModuleCache::LoadOrBuild(const std::string& key,
                                                       const Callbacks& callbacks, Source* source,
                                                       std::vector<Diagnostic>* diagnostics) {
  if (disk_.enabled()) {
    auto artifact = disk_.Load(key);
    if (artifact.ok()) {
      auto module = callbacks.load(*artifact);
      if (module.ok()) {
        *source = Source::kDisk;
        return module;
      }
      spdlog::warn("module cache: {} from disk did not load ({}); rebuilding", key,
                   module.status().ToString());
    } else if (artifact.status().code() != StatusCode::kNotFound) {
      spdlog::warn("module cache: {}; rebuilding", artifact.status().ToString());
    }
  }
  *source = Source::kBuilt;
  auto artifact = callbacks.build(diagnostics);
  if (!artifact.ok()) return artifact.status();
  if (disk_.enabled()) {
    Status stored = disk_.Store(key, *artifact);
    if (!stored.ok()) spdlog::warn("module cache: {}", stored.ToString());
  }
  return callbacks.load(*artifact);
}

ModuleStoreStats ModuleCache::stats() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return stats_;
}

}  // namespace weft
