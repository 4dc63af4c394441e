// CubinInfo: a bounds-checked walk over the CUBIN's ELF section headers, symbol table and
// .nv.info attribute records.
#include "engine/jit/cuda/cubin_info.h"

#include <cstring>
#include <map>

namespace weft::jit {
namespace {

// .nv.info records: {uint8 format, uint8 attribute, uint16 value-or-size}, then `size` bytes
// when the format is EIFMT_SVAL.
constexpr uint8_t kFormatSval = 0x04;
constexpr uint8_t kAttrRegCount = 0x2f;    // EIATTR_REGCOUNT: {uint32 symbol, uint32 registers}
constexpr uint8_t kAttrFrameSize = 0x11;   // EIATTR_FRAME_SIZE: {uint32 symbol, uint32 bytes}

class Reader {
 public:
  explicit Reader(std::string_view bytes) : bytes_(bytes) {}
  bool Has(uint64_t offset, uint64_t size) const {
    return offset <= bytes_.size() && size <= bytes_.size() - offset;
  }
  template <typename T>
  T At(uint64_t offset) const {   // callers check Has first
    T value;
    std::memcpy(&value, bytes_.data() + offset, sizeof(T));
    return value;
  }
  // The NUL-terminated string at `offset` inside [table, table + table_size).
  bool String(uint64_t table, uint64_t table_size, uint64_t offset, std::string* out) const {
    if (!Has(table, table_size) || offset >= table_size) return false;
    std::string_view t = bytes_.substr(table, table_size);
    size_t end = t.find('\0', offset);
    if (end == std::string_view::npos) return false;
    *out = std::string(t.substr(offset, end - offset));
    return true;
  }
  std::string_view bytes() const { return bytes_; }

 private:
  std::string_view bytes_;
};

struct Section {
  std::string name;
  uint32_t type = 0;
  uint64_t offset = 0;
  uint64_t size = 0;
  uint32_t link = 0;
};

Status Bad(const std::string& what) { return InvalidArgument("not a valid CUBIN: " + what); }

}  // namespace

Expected<CubinInfo> ParseCubin(std::string_view image) {
  Reader r(image);
  if (!r.Has(0, 64) || image.substr(0, 4) != std::string_view("\x7f" "ELF", 4)) return Bad("no ELF header");
  if (image[4] != 2 || image[5] != 1) return Bad("not a 64-bit little-endian ELF");
  CubinInfo info;
  const uint8_t abi_version = static_cast<uint8_t>(image[8]);
  const uint32_t flags = r.At<uint32_t>(0x30);
  info.sm = abi_version >= 8 ? (flags >> 8) & 0xff : flags & 0xff;
  const uint64_t shoff = r.At<uint64_t>(0x28);
  const uint16_t shentsize = r.At<uint16_t>(0x3a);
  const uint16_t shnum = r.At<uint16_t>(0x3c);
  const uint16_t shstrndx = r.At<uint16_t>(0x3e);
  if (shentsize < 64 || shnum == 0 || shstrndx >= shnum) return Bad("bad section header table");
  if (!r.Has(shoff, uint64_t{shentsize} * shnum)) return Bad("section headers outside the image");

  std::vector<Section> sections(shnum);
  for (uint16_t i = 0; i < shnum; ++i) {
    const uint64_t h = shoff + uint64_t{i} * shentsize;
    Section& s = sections[i];
    s.type = r.At<uint32_t>(h + 4);
    s.offset = r.At<uint64_t>(h + 24);
    s.size = r.At<uint64_t>(h + 32);
    s.link = r.At<uint32_t>(h + 40);
    constexpr uint32_t kNoBits = 8;
    if (s.type != kNoBits && !r.Has(s.offset, s.size)) return Bad("section " + std::to_string(i) + " outside the image");
  }
  const Section& strtab = sections[shstrndx];
  for (uint16_t i = 0; i < shnum; ++i) {
    const uint64_t h = shoff + uint64_t{i} * shentsize;
    if (!r.String(strtab.offset, strtab.size, r.At<uint32_t>(h), &sections[i].name))
      return Bad("section name outside the string table");
  }

  // Symbol names by index (the .nv.info records name functions by symbol index).
  std::vector<std::string> symbols;
  for (const Section& s : sections) {
    constexpr uint32_t kSymTab = 2;
    if (s.type != kSymTab) continue;
    if (s.link >= shnum) return Bad("symbol table without a string table");
    if (!r.Has(s.offset, s.size)) return Bad("symbol table outside the image");
    const Section& names = sections[s.link];
    for (uint64_t at = s.offset; at + 24 <= s.offset + s.size; at += 24) {
      std::string name;
      if (!r.String(names.offset, names.size, r.At<uint32_t>(at), &name)) return Bad("symbol name outside its table");
      symbols.push_back(std::move(name));
    }
    break;
  }

  std::map<std::string, CubinKernelInfo> kernels;
  auto kernel = [&](const std::string& symbol) -> CubinKernelInfo& {
    CubinKernelInfo& k = kernels[symbol];
    k.symbol = symbol;
    return k;
  };
  auto suffix = [](const std::string& name, std::string_view prefix, std::string* rest) {
    if (name.size() <= prefix.size() || name.compare(0, prefix.size(), prefix) != 0) return false;
    *rest = name.substr(prefix.size());
    return true;
  };
  for (const Section& s : sections) {
    std::string fn;
    if (suffix(s.name, ".text.", &fn)) kernel(fn).code_bytes = s.size;
  }
  for (const Section& s : sections) {
    std::string fn;
    if (suffix(s.name, ".nv.shared.", &fn) && kernels.count(fn)) kernel(fn).shared_bytes = s.size;
    if (suffix(s.name, ".nv.constant0.", &fn) && kernels.count(fn)) kernel(fn).const_bytes = s.size;
    if (s.name != ".nv.info" && s.name.rfind(".nv.info.", 0) != 0) continue;
    if (!r.Has(s.offset, s.size)) return Bad(s.name + " outside the image");
    for (uint64_t at = s.offset; at + 4 <= s.offset + s.size;) {
      const uint8_t format = static_cast<uint8_t>(image[at]);
      const uint8_t attribute = static_cast<uint8_t>(image[at + 1]);
      const uint16_t value = r.At<uint16_t>(at + 2);
      at += 4;
      if (format != kFormatSval) continue;
      if (value > s.offset + s.size - at) return Bad("attribute record outside " + s.name);
      if ((attribute == kAttrRegCount || attribute == kAttrFrameSize) && value == 8) {
        const uint32_t symbol = r.At<uint32_t>(at);
        const uint32_t amount = r.At<uint32_t>(at + 4);
        if (symbol < symbols.size() && kernels.count(symbols[symbol])) {
          CubinKernelInfo& k = kernel(symbols[symbol]);
          if (attribute == kAttrRegCount) k.registers = amount;
          else k.local_bytes = amount;
        }
      }
      at += value;
    }
  }
  for (auto& [name, k] : kernels) info.kernels.push_back(std::move(k));
  return info;
}

}  // namespace weft::jit
