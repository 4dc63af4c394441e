// client_bench: what the C++ client's basic operations cost against a running weftd, each row
// with its time AND a check of the bytes against a reference (max abs error, must be 0).
// Usage: weft_client_bench UNIX_ADDRESS [TCP_ADDRESS TOKEN] [--mib N] [--chunk-kib K]
//   UNIX_ADDRESS  e.g. unix:/run/user/1000/weft/weftd.sock (local: zero-copy rows)
//   TCP_ADDRESS   e.g. 127.0.0.1:7070 with its token (remote: chunked rows)
#include <weft/client.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <string>
#include <vector>

namespace {

using Clock = std::chrono::steady_clock;

double Ms(Clock::duration d) { return std::chrono::duration<double, std::milli>(d).count(); }

// Median of `reps` timed runs of f, in ms.
double MedianMs(int reps, const std::function<void()>& f) {
  std::vector<double> t;
  for (int i = 0; i < reps; ++i) {
    const auto start = Clock::now();
    f();
    t.push_back(Ms(Clock::now() - start));
  }
  std::sort(t.begin(), t.end());
  return t[t.size() / 2];
}

void Row(const char* what, double ms, const std::string& per, double error) {
  std::printf("| %-48s | %12.3f | %-16s | %9.3g |\n", what, ms, per.c_str(), error);
}

std::string Throughput(double bytes, double ms) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.2f GB/s", bytes / (ms * 1e6));
  return buf;
}

int Fail(const weft::Status& s, const char* what) {
  std::fprintf(stderr, "%s: %s\n", what, s.ToString().c_str());
  return 1;
}

// Max |a - b| over float32 values.
double MaxError(const float* a, const float* b, size_t n) {
  double e = 0;
  for (size_t i = 0; i < n; ++i) e = std::max(e, std::abs(double(a[i]) - double(b[i])));
  return e;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s UNIX_ADDRESS [TCP_ADDRESS TOKEN] [--mib N]\n", argv[0]);
    return 2;
  }
  std::string unix_address = argv[1], tcp_address, token;
  size_t big_mib = 1024, remote_mib = 256, chunk_kib = 1024;
  for (int i = 2; i < argc; ++i) {
    if (std::strcmp(argv[i], "--mib") == 0 && i + 1 < argc) {
      big_mib = remote_mib = std::strtoul(argv[++i], nullptr, 10);
    } else if (std::strcmp(argv[i], "--chunk-kib") == 0 && i + 1 < argc) {
      chunk_kib = std::strtoul(argv[++i], nullptr, 10);
    } else if (tcp_address.empty()) {
      tcp_address = argv[i];
    } else {
      token = argv[i];
    }
  }

  std::printf("| %-48s | %12s | %-16s | %9s |\n", "operation", "median ms", "rate", "max error");
  std::printf("|%s|%s|%s|%s|\n", std::string(50, '-').c_str(), std::string(14, '-').c_str(),
              std::string(18, '-').c_str(), std::string(11, '-').c_str());

  weft::ConnectOptions local;
  local.address = unix_address;
  // Session open (+ Attach thread) and close.
  double open_ms = MedianMs(20, [&] {
    auto c = weft::Client::Connect(local);
    if (!c.ok()) std::exit(Fail(c.status(), "connect"));
  });
  Row("session open + close (unix)", open_ms, "", 0);

  auto client = weft::Client::Connect(local);
  if (!client.ok()) return Fail(client.status(), "connect");

  double create_ms = MedianMs(200, [&] {
    auto a = client->Zeros(weft::dtypes::float32(), {1024});
    if (!a.ok()) std::exit(Fail(a.status(), "create"));
  });
  Row("array create (zeros, 4 KiB) + free", create_ms, "", 0);

  // A big CPU array: create, fill through the mapping, view it zero-copy.
  const size_t n = (big_mib << 20) / 4;
  std::vector<float> ref(n);
  for (size_t i = 0; i < n; ++i) ref[i] = static_cast<float>(i % 1000003) * 0.25f;
  auto big = client->Zeros(weft::dtypes::float32(), {static_cast<int64_t>(n)});
  if (!big.ok()) return Fail(big.status(), "create big");
  std::span<float> view;
  const auto first = Clock::now();
  auto mapped = big->MapAs<float>();
  const double first_map_ms = Ms(Clock::now() - first);
  if (!mapped.ok()) return Fail(mapped.status(), "map");
  view = *mapped;
  std::memcpy(view.data(), ref.data(), n * 4);
  double map_ms = MedianMs(100, [&] {
    auto m = big->MapAs<float>();
    if (!m.ok() || m->data() != view.data()) std::exit(Fail(m.status(), "map again"));
  });
  auto check = big->MapAs<float>();
  const std::string label = "Map() of a " + std::to_string(big_mib) + " MiB array (first)";
  Row(label.c_str(), first_map_ms, "", MaxError(check->data(), ref.data(), n));
  const std::string label2 = "Map() of a " + std::to_string(big_mib) + " MiB array (cached)";
  Row(label2.c_str(), map_ms, "", 0);

  std::vector<float> out(n);
  double read_ms = MedianMs(3, [&] {
    if (auto s = big->Read(out.data(), n * 4); !s.ok()) std::exit(Fail(s, "read"));
  });
  const std::string label3 = "Read() (sync + memcpy) " + std::to_string(big_mib) + " MiB, local";
  Row(label3.c_str(), read_ms, Throughput(n * 4.0, read_ms), MaxError(out.data(), ref.data(), n));

  double fill_ms = MedianMs(3, [&] {
    if (auto s = big->Fill(1.5); !s.ok()) std::exit(Fail(s, "fill"));
    if (auto s = client->Synchronize(); !s.ok()) std::exit(Fail(s, "sync"));
  });
  double fill_err = 0;
  for (size_t i = 0; i < n; ++i) fill_err = std::max(fill_err, std::abs(double(view[i]) - 1.5));
  const std::string label4 = "Fill + Synchronize " + std::to_string(big_mib) + " MiB";
  Row(label4.c_str(), fill_ms, Throughput(n * 4.0, fill_ms), fill_err);

  if (!tcp_address.empty()) {
    weft::ConnectOptions remote;
    remote.address = tcp_address;
    remote.token = token;
    remote.chunk_size = chunk_kib << 10;
    double ropen_ms = MedianMs(10, [&] {
      auto c = weft::Client::Connect(remote);
      if (!c.ok()) std::exit(Fail(c.status(), "connect tcp"));
    });
    Row("session open + close (tcp, token)", ropen_ms, "", 0);
    auto rc = weft::Client::Connect(remote);
    if (!rc.ok()) return Fail(rc.status(), "connect tcp");
    const size_t rn = (remote_mib << 20) / 4;
    std::vector<float> rref(ref.begin(), ref.begin() + std::min(rn, n));
    rref.resize(rn, 2.0f);
    auto ra = rc->Empty(weft::dtypes::float32(), {static_cast<int64_t>(rn)});
    if (!ra.ok()) return Fail(ra.status(), "create remote");
    double write_ms = MedianMs(3, [&] {
      if (auto s = ra->Write(rref.data(), rn * 4); !s.ok()) std::exit(Fail(s, "write tcp"));
    });
    std::vector<float> rout(rn);
    double rread_ms = MedianMs(3, [&] {
      if (auto s = ra->Read(rout.data(), rn * 4); !s.ok()) std::exit(Fail(s, "read tcp"));
    });
    const std::string chunk = std::to_string(chunk_kib) + " KiB chunks";
    const std::string w = "chunked Write " + std::to_string(remote_mib) + " MiB (tcp, " + chunk + ")";
    const std::string r = "chunked Read " + std::to_string(remote_mib) + " MiB (tcp, " + chunk + ")";
    Row(w.c_str(), write_ms, Throughput(rn * 4.0, write_ms), 0);
    Row(r.c_str(), rread_ms, Throughput(rn * 4.0, rread_ms),
        MaxError(rout.data(), rref.data(), rn));
  }
  return 0;
}
