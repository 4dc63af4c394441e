// FormatPrintRecords: binary GPU print records (engine/native/print.h) to text.
#include "engine/device/cuda_print.h"

#include <algorithm>
#include <cstdio>
#include <cstring>

#include "engine/native/printf_check.h"

namespace weft {

namespace {

constexpr size_t kLineMax = 1023;   // the CPU's print_line holds 1023 characters
const char kTruncated[] = "\n[weft: kernel print output truncated]\n";
const char kMalformed[] = "[weft: malformed GPU print record; the rest of the output is dropped]\n";

class Reader {
 public:
  Reader(const char* p, size_t n) : p_(p), n_(n) {}
  bool Bytes(size_t k, const char** out) {
    if (k > n_ - pos_) return false;
    *out = p_ + pos_;
    pos_ += k;
    return true;
  }
  template <typename T> bool Value(T* out) {
    const char* b = nullptr;
    if (!Bytes(sizeof(T), &b)) return false;
    std::memcpy(out, b, sizeof(T));
    return true;
  }
  bool done() const { return pos_ == n_; }

 private:
  const char* p_;
  size_t n_;
  size_t pos_ = 0;
};

struct Arg {
  char kind = 0;
  int64_t i = 0;
  double f = 0;
  std::string s;
};

// Formats `fmt` (already checked) with `args`, one conversion at a time.
void FormatPiece(const std::string& fmt, const Arg* args, std::string* line) {
  size_t k = 0;
  char out[4096];
  for (size_t i = 0; i < fmt.size(); ++i) {
    if (fmt[i] != '%') {
      line->push_back(fmt[i]);
      continue;
    }
    if (i + 1 < fmt.size() && fmt[i + 1] == '%') {
      line->push_back('%');
      ++i;
      continue;
    }
    // The checked form: flags, width, precision, optional ll, conversion character.
    size_t j = i + 1;
    while (j < fmt.size() && std::strchr("-+ #0.0123456789l", fmt[j]) != nullptr) ++j;
    if (j >= fmt.size()) return;
    const std::string spec = fmt.substr(i, j - i + 1);
    const Arg& a = args[k++];
    int w = 0;
    if (a.kind == 'i') w = std::snprintf(out, sizeof(out), spec.c_str(), static_cast<int>(a.i));
    else if (a.kind == 'I') w = std::snprintf(out, sizeof(out), spec.c_str(), static_cast<long long>(a.i));
    else if (a.kind == 'f') w = std::snprintf(out, sizeof(out), spec.c_str(), a.f);
    else if (a.kind == 's') w = std::snprintf(out, sizeof(out), "%s", a.s.c_str());
    if (w > 0) line->append(out, std::min<size_t>(static_cast<size_t>(w), sizeof(out) - 1));
    i = j;
  }
}

// One piece of a record; false when it is malformed.
bool DecodePiece(Reader& r, std::string* line) {
  uint16_t flen = 0;
  const char* f = nullptr;
  uint8_t nargs = 0;
  const char* kinds = nullptr;
  if (!r.Value(&flen) || !r.Bytes(flen, &f) || !r.Value(&nargs) || !r.Bytes(nargs, &kinds)) return false;
  std::string fmt(f, flen);
  if (fmt.find('\0') != std::string::npos) return false;
  std::string kind_text(kinds, nargs);
  if (kind_text.find('\0') != std::string::npos) return false;
  Arg args[256];
  for (uint8_t k = 0; k < nargs; ++k) {
    Arg& a = args[k];
    a.kind = kinds[k];
    if (a.kind == 'i' || a.kind == 'I') {
      if (!r.Value(&a.i)) return false;
      if (a.kind == 'i') a.i = static_cast<int32_t>(static_cast<uint64_t>(a.i) & 0xffffffffu);
    } else if (a.kind == 'f') {
      if (!r.Value(&a.f)) return false;
    } else if (a.kind == 's') {
      uint16_t slen = 0;
      const char* s = nullptr;
      if (!r.Value(&slen) || !r.Bytes(slen, &s)) return false;
      a.s.assign(s, slen);
      if (a.s.find('\0') != std::string::npos) return false;
    } else {
      return false;
    }
  }
  // A string goes only through the exact format "%s"; every other piece passes the same check
  // as wp.printf's formats.
  const bool has_string = kind_text.find('s') != std::string::npos;
  if (has_string ? (nargs != 1 || fmt != "%s") : !wp::printf_format_ok(fmt.c_str(), kind_text.c_str()))
    return false;
  FormatPiece(fmt, args, line);
  return true;
}

}  // namespace

std::string FormatPrintRecords(const char* data, uint64_t used, uint64_t capacity) {
  std::string out;
  const uint64_t limit = used < capacity ? used : capacity;
  uint64_t pos = 0;
  bool dropped = used > capacity;
  while (pos < limit) {
    uint32_t size = 0;
    if (limit - pos < 4) {
      dropped = true;
      break;
    }
    std::memcpy(&size, data + pos, 4);
    if (size < 4 || size > limit - pos) {
      // A record that did not fit is left out with only its size written.
      if (size >= 4 && used > capacity && pos + size > capacity) {
        dropped = true;
      } else {
        out += kMalformed;
      }
      break;
    }
    Reader r(data + pos + 4, size - 4);
    std::string line;
    bool ok = true;
    while (ok && !r.done()) ok = DecodePiece(r, &line);
    if (!ok) {
      out += kMalformed;
      break;
    }
    if (line.size() > kLineMax) line.resize(kLineMax);
    out += line;
    pos += size;
  }
  if (dropped) out += kTruncated;
  return out;
}

}  // namespace weft
