// Tests of the GPU print path without a GPU: records built by the device-side encoder
// (wp::print_record, engine/native/print.h, compiled here for the host) and decoded by
// FormatPrintRecords (engine/device/cuda_print.h) read exactly as the host's snprintf of the
// same format and values; hostile buffers (lengths past the end, formats that do not match
// their kinds, %s / %n smuggled in, unknown kinds, embedded NULs) end the output with a marker
// and never read outside the buffer; dropped output is marked.
#include <gtest/gtest.h>

#include <cstdarg>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <random>
#include <string>

#include "engine/device/cuda_print.h"
#include "engine/native/weft.h"

namespace {

using weft::FormatPrintRecords;

std::string Snprintf(const char* fmt, ...) __attribute__((format(printf, 1, 2)));
std::string Snprintf(const char* fmt, ...) {
  char buf[4096];
  va_list args;
  va_start(args, fmt);
  int n = std::vsnprintf(buf, sizeof(buf), fmt, args);
  va_end(args);
  return std::string(buf, n > 0 ? static_cast<size_t>(n) : 0);
}

std::string Bytes(wp::print_record& r) { return std::string(r.bytes(), static_cast<size_t>(r.size())); }

std::string Decode(const std::string& buf) { return FormatPrintRecords(buf.data(), buf.size(), buf.size() + 16); }

TEST(CudaPrint, RecordsReadLikeSnprintfOfTheSameValues) {
  std::mt19937_64 rng(0x5eed1234u);
  std::uniform_real_distribution<double> u(-1e6, 1e6);
  for (int trial = 0; trial < 200; ++trial) {
    const float f = static_cast<float>(u(rng));
    const double d = u(rng) * 1e-3;
    const int32_t i = static_cast<int32_t>(rng());
    const uint32_t ui = static_cast<uint32_t>(rng());
    const int64_t l = static_cast<int64_t>(rng());
    const uint64_t ul = rng();
    wp::print_record r;
    r.add("%g", static_cast<double>(f));
    r.add(" ");
    r.add("%d", i);
    r.add(" %u %x", ui, ui);
    r.add(" %lld %llu", (long long)l, (unsigned long long)ul);
    r.add(" %+08.3f|%-10.2e|%#o", d, d, i);
    r.add(" %s", "ignored");   // not the exact "%s": the decoder refuses it (below)
    std::string want = Snprintf("%g", static_cast<double>(f)) + " " + Snprintf("%d", i) + Snprintf(" %u %x", ui, ui) +
                       Snprintf(" %lld %llu", (long long)l, (unsigned long long)ul) +
                       Snprintf(" %+08.3f|%-10.2e|%#o", d, d, i);
    // The last piece (" %s" with a string) is malformed on purpose: everything before it in the
    // same record is dropped with it, and the marker says so.
    std::string got = Decode(Bytes(r));
    EXPECT_NE(got.find("malformed"), std::string::npos) << got;

    wp::print_record ok;
    ok.add("%g", static_cast<double>(f));
    ok.add(" ");
    ok.add("%d", i);
    ok.add(" %u %x", ui, ui);
    ok.add(" %lld %llu", (long long)l, (unsigned long long)ul);
    ok.add(" %+08.3f|%-10.2e|%#o", d, d, i);
    ok.add("%s", "True");
    ok.add("%%\n");
    EXPECT_EQ(Decode(Bytes(ok)), want + "True%\n") << "trial " << trial;
  }
}

TEST(CudaPrint, PrintArgPromotionsMatchTheCpuPath) {
  // print_arg widens float to double, bool to int, 8/16-bit integers to 32 bits.
  wp::print_record r;
  r.add("%g %d %d %u %u\n", wp::print_arg(1.5f), wp::print_arg(true), wp::print_arg((wp::int8)-7),
        wp::print_arg((wp::uint8)200), wp::print_arg((wp::uint16)65535));
  EXPECT_EQ(Decode(Bytes(r)), "1.5 1 -7 200 65535\n");
}

TEST(CudaPrint, SeveralRecordsInOrderAndLongLinesCutLikeTheCpu) {
  std::string buf;
  for (int k = 0; k < 50; ++k) {
    wp::print_record r;
    r.add("line %d of %lld\n", k, (long long)50);
    buf += Bytes(r);
  }
  std::string want;
  for (int k = 0; k < 50; ++k) want += Snprintf("line %d of %lld\n", k, (long long)50);
  EXPECT_EQ(Decode(buf), want);

  wp::print_record big;
  for (int k = 0; k < 200; ++k) big.add("%.3f ", 1.0 / (k + 1));   // more than the record holds
  EXPECT_LE(big.size(), wp::PRINT_RECORD_MAX);
  std::string text = Decode(Bytes(big));
  EXPECT_LE(text.size(), 1023u);
  EXPECT_EQ(text.find("malformed"), std::string::npos);
  EXPECT_EQ(text.rfind("1.000 0.500 0.333 ", 0), 0u) << text;
}

TEST(CudaPrint, DroppedOutputIsMarked) {
  wp::print_record r;
  r.add("kept %d\n", 1);
  std::string buf = Bytes(r);
  // A second record that did not fit: only its size field was written.
  uint32_t size = 200;
  buf.append(reinterpret_cast<const char*>(&size), 4);
  const uint64_t capacity = buf.size();
  std::string got = FormatPrintRecords(buf.data(), capacity + 196, capacity);
  EXPECT_EQ(got, "kept 1\n\n[weft: kernel print output truncated]\n");
  // Reservations past the end without even a size field.
  got = FormatPrintRecords(buf.data(), 10 * capacity, r.size());
  EXPECT_EQ(got, "kept 1\n\n[weft: kernel print output truncated]\n");
}

// A record holding one piece with the given format, kinds and raw argument bytes.
std::string RawRecord(const std::string& fmt, const std::string& kinds, const std::string& args) {
  std::string body;
  uint16_t flen = static_cast<uint16_t>(fmt.size());
  body.append(reinterpret_cast<const char*>(&flen), 2);
  body += fmt;
  body.push_back(static_cast<char>(kinds.size()));
  body += kinds;
  body += args;
  uint32_t size = static_cast<uint32_t>(body.size() + 4);
  return std::string(reinterpret_cast<const char*>(&size), 4) + body;
}

std::string Word(int64_t v) { return std::string(reinterpret_cast<const char*>(&v), 8); }

TEST(CudaPrint, HostileRecordsAreRefusedWithoutReadingPastTheBuffer) {
  const std::string marker = "[weft: malformed GPU print record; the rest of the output is dropped]\n";
  const std::string good = RawRecord("ok %d\n", "i", Word(5));
  EXPECT_EQ(Decode(good), "ok 5\n");
  const std::string bad[] = {
      RawRecord("%s\n", "i", Word(0x1000)),            // a pointer-taking conversion
      RawRecord("%n", "i", Word(0)),                   // a writing conversion
      RawRecord("%d %d", "i", Word(1)),                // more conversions than arguments
      RawRecord("%d", "ii", Word(1) + Word(2)),        // more arguments than conversions
      RawRecord("%f", "i", Word(1)),                   // kind mismatch
      RawRecord("%lld", "i", Word(1)),                 // width mismatch
      RawRecord("%*d", "ii", Word(1) + Word(2)),       // star width
      RawRecord("%d", "z", Word(1)),                   // unknown kind
      RawRecord("%d", "i", "abc"),                     // argument cut short
      RawRecord("%s", "s", std::string("\x05\x00", 2) + "ab"),   // string past its piece
      RawRecord("%s %d", "s", std::string("\x01\x00", 2) + "a"), // a string with other conversions
      RawRecord(std::string("a\0b", 3), "", ""),       // NUL inside the format
      RawRecord("%1000d", "i", Word(1)),               // width over 3 digits
  };
  for (const std::string& b : bad) {
    EXPECT_EQ(Decode(good + b + good), "ok 5\n" + marker) << "record bytes: " << b.size();
  }
  // Sizes that point outside the buffer or below the size field itself.
  for (uint32_t size : {0u, 1u, 3u, 0xffffffffu, static_cast<uint32_t>(good.size() + 1)}) {
    std::string b = good;
    std::memcpy(b.data(), &size, 4);
    std::string got = FormatPrintRecords(b.data(), b.size(), b.size() + 64);
    EXPECT_EQ(got, marker) << size;
  }
  // Random garbage: never crashes, never reads outside (run under ASan in test-asan).
  std::mt19937 rng(7);
  for (int trial = 0; trial < 2000; ++trial) {
    std::string b(rng() % 64, '\0');
    for (char& c : b) c = static_cast<char>(rng());
    if (b.size() >= 4 && trial % 2) {
      uint32_t size = static_cast<uint32_t>(b.size());
      std::memcpy(b.data(), &size, 4);
    }
    (void)FormatPrintRecords(b.data(), b.size(), b.size());
  }
}

}  // namespace
