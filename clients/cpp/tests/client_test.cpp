// Tests of libweft-client against a real weftd: sessions, devices, every array operation
// (create/free/describe, read/write zero-copy and chunked, copy, fill, batches, synchronize,
// export/import, stats), error values for bad input, TCP with a token, and a client killed
// while holding arrays. The daemon is $WEFT_DAEMON, else this build's bin/weftd; tests that
// need it are skipped when it does not exist. The binary doubles as a child client:
// `weft_client_tests --hold-arrays ADDRESS` connects, creates arrays, prints "ready", waits.
#include <fcntl.h>
#include <glob.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <optional>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "weft/client.h"
#include "weft/client/raw.h"

namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

// ---------------------------------------------------------------------------------------------
// A weftd child process on a temp Unix socket or TCP port.

fs::path DaemonBinary() {
  if (const char* env = std::getenv("WEFT_DAEMON"); env && *env) return env;
  return fs::path(WEFT_BUILD_BIN_DIR) / "weftd";
}

int FreeTcpPort() {
  int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  addr.sin_port = 0;
  ::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr);
  socklen_t len = sizeof addr;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len);
  ::close(fd);
  return ntohs(addr.sin_port);
}

std::vector<std::string> Glob(const std::string& pattern) {
  glob_t g{};
  std::vector<std::string> out;
  if (::glob(pattern.c_str(), 0, nullptr, &g) == 0)
    for (size_t i = 0; i < g.gl_pathc; ++i) out.emplace_back(g.gl_pathv[i]);
  ::globfree(&g);
  return out;
}

class Daemon {
 public:
  // Starts weftd; `tcp` listens on 127.0.0.1 with a token file instead of a Unix socket;
  // `extra`: more weftd flags.
  static std::unique_ptr<Daemon> Start(bool tcp, std::string* error, const std::vector<std::string>& extra = {}) {
    auto d = std::unique_ptr<Daemon>(new Daemon());
    char tmpl[] = "/tmp/weft-client-test-XXXXXX";
    if (::mkdtemp(tmpl) == nullptr) {
      *error = "mkdtemp failed";
      return nullptr;
    }
    d->dir_ = tmpl;
    std::vector<std::string> args = {DaemonBinary().string()};
    if (tcp) {
      d->token_ = "test-token-" + std::to_string(::getpid()) + "-" +
                  std::to_string(std::random_device{}());
      const fs::path token_file = d->dir_ / "token";
      std::ofstream(token_file) << d->token_ << "\n";
      fs::permissions(token_file, fs::perms::owner_read | fs::perms::owner_write);
      d->address_ = "127.0.0.1:" + std::to_string(FreeTcpPort());
      args.insert(args.end(), {"--listen", "tcp:" + d->address_, "--token-file",
                               token_file.string()});
    } else {
      d->address_ = "unix:" + (d->dir_ / "weftd.sock").string();
      args.insert(args.end(), {"--listen", d->address_});
    }
    args.insert(args.end(), {"--cache-dir", (d->dir_ / "cache").string(), "--log-level", "info"});
    args.insert(args.end(), extra.begin(), extra.end());
    d->log_ = d->dir_ / "weftd.log";

    // Everything the child needs is prepared before fork: gRPC threads may hold locks.
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    const std::string log_path = d->log_.string();
    const pid_t pid = ::fork();
    if (pid == 0) {
      const int fd = ::open(log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
      ::dup2(fd, 1);
      ::dup2(fd, 2);
      ::execv(argv[0], argv.data());
      ::_exit(127);
    }
    d->pid_ = pid;
    // Ready when a session can be opened.
    const auto deadline = std::chrono::steady_clock::now() + 30s;
    while (std::chrono::steady_clock::now() < deadline) {
      int status = 0;
      if (::waitpid(pid, &status, WNOHANG) == pid) {
        d->pid_ = 0;
        *error = "weftd exited at start (status " + std::to_string(status) + "):\n" + d->Log();
        return nullptr;
      }
      weft::ConnectOptions o = d->Options();
      o.connect_timeout = 500ms;
      if (auto c = weft::Client::Connect(o); c.ok()) return d;
    }
    *error = "weftd did not answer at " + d->address_ + " within 30 s:\n" + d->Log();
    return nullptr;
  }

  ~Daemon() {
    Stop();
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }

  // SIGTERM and wait; returns the exit status (-1 when it had to be killed).
  int Stop() {
    if (pid_ == 0) return exit_status_;
    ::kill(pid_, SIGTERM);
    const auto deadline = std::chrono::steady_clock::now() + 15s;
    int status = 0;
    while (::waitpid(pid_, &status, WNOHANG) == 0) {
      if (std::chrono::steady_clock::now() > deadline) {
        ::kill(pid_, SIGKILL);
        ::waitpid(pid_, &status, 0);
        pid_ = 0;
        return exit_status_ = -1;
      }
      std::this_thread::sleep_for(20ms);
    }
    pid_ = 0;
    return exit_status_ = status;
  }

  weft::ConnectOptions Options() const {
    weft::ConnectOptions o;
    o.address = address_;
    o.token = token_;
    o.client_name = "weft_client_tests";
    return o;
  }
  weft::Expected<weft::Client> Connect() const { return weft::Client::Connect(Options()); }

  std::string Log() const {
    std::ifstream in(log_);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
  }
  std::vector<std::string> ShmFiles() const {
    return Glob("/dev/shm/weft-" + std::to_string(pid_) + "-*");
  }
  const std::string& address() const { return address_; }
  const std::string& token() const { return token_; }
  pid_t pid() const { return pid_; }

 private:
  Daemon() = default;
  fs::path dir_;
  fs::path log_;
  std::string address_;
  std::string token_;
  pid_t pid_ = 0;
  int exit_status_ = 0;
};

// One daemon of each kind for the whole binary, started on first use.
struct Daemons {
  std::unique_ptr<Daemon> unix_daemon, tcp_daemon;
  std::string unix_error, tcp_error;
  bool started = false;
};
Daemons& Shared() {
  static Daemons d;
  return d;
}

Daemon* UnixDaemon() {
  auto& d = Shared();
  if (!d.unix_daemon && d.unix_error.empty()) {
    d.unix_daemon = Daemon::Start(false, &d.unix_error);
    if (!d.unix_daemon && d.unix_error.empty()) d.unix_error = "weftd failed to start";
  }
  return d.unix_daemon.get();
}

Daemon* TcpDaemon() {
  auto& d = Shared();
  if (!d.tcp_daemon && d.tcp_error.empty()) {
    d.tcp_daemon = Daemon::Start(true, &d.tcp_error);
    if (!d.tcp_daemon && d.tcp_error.empty()) d.tcp_error = "weftd failed to start";
  }
  return d.tcp_daemon.get();
}

#define REQUIRE_DAEMON_BINARY()                                                      \
  do {                                                                               \
    if (!fs::exists(DaemonBinary()))                                                 \
      GTEST_SKIP() << "weftd not built: " << DaemonBinary()                          \
                   << " (set WEFT_DAEMON or build the weftd target)";                \
  } while (0)

#define ASSERT_OK(expr)                                              \
  do {                                                               \
    const auto& _st = (expr);                                        \
    ASSERT_TRUE(_st.ok()) << #expr << ": " << _st.ToString();        \
  } while (0)

#define ASSERT_OK_E(expr)                                            \
  do {                                                               \
    const auto& _ex = (expr);                                        \
    ASSERT_TRUE(_ex.ok()) << #expr << ": " << _ex.status().ToString(); \
  } while (0)

// A connected client of the shared Unix-socket daemon.
class ClientTest : public ::testing::Test {
 protected:
  void SetUp() override {
    REQUIRE_DAEMON_BINARY();
    daemon_ = UnixDaemon();
    ASSERT_NE(daemon_, nullptr) << Shared().unix_error;
    auto c = daemon_->Connect();
    ASSERT_TRUE(c.ok()) << c.status().ToString();
    client_ = std::move(c).value();
  }

  weft::DaemonStats Stats() {
    auto s = client_.Stats();
    EXPECT_TRUE(s.ok()) << s.status().ToString();
    return s.ok() ? *s : weft::DaemonStats{};
  }

  Daemon* daemon_ = nullptr;
  weft::Client client_;
  std::mt19937_64 rng_{0x5eed1234u + static_cast<unsigned>(::getpid())};
};

template <typename T>
std::vector<T> RandomValues(std::mt19937_64& rng, size_t n) {
  std::vector<T> v(n);
  if constexpr (std::is_floating_point_v<T>) {
    std::uniform_real_distribution<double> dist(-1e3, 1e3);
    for (auto& x : v) x = static_cast<T>(dist(rng));
  } else {
    std::uniform_int_distribution<long long> dist(std::numeric_limits<T>::min(),
                                                  std::numeric_limits<T>::max());
    for (auto& x : v) x = static_cast<T>(dist(rng));
  }
  return v;
}

std::vector<std::byte> Bytes(const void* p, size_t n) {
  const auto* b = static_cast<const std::byte*>(p);
  return std::vector<std::byte>(b, b + n);
}

// ---------------------------------------------------------------------------------------------
// No daemon needed.

TEST(ClientOfflineTest, AddressResolution) {
  weft::ConnectOptions o;
  o.address = "unix:/tmp/x.sock";
  EXPECT_EQ(weft::ResolveAddress(o), "unix:/tmp/x.sock");
  o.address = "/tmp/y.sock";
  EXPECT_EQ(weft::ResolveAddress(o), "unix:/tmp/y.sock");
  o.address = "tcp:10.0.0.1:7000";
  EXPECT_EQ(weft::ResolveAddress(o), "10.0.0.1:7000");
  o.address = "gpu-box:7000";
  EXPECT_EQ(weft::ResolveAddress(o), "gpu-box:7000");

  o.address.clear();
  ::setenv("WEFT_ADDRESS", "unix:/tmp/from-env.sock", 1);
  EXPECT_EQ(weft::ResolveAddress(o), "unix:/tmp/from-env.sock");
  ::unsetenv("WEFT_ADDRESS");

  // Default: $XDG_RUNTIME_DIR/weft/weftd.sock when it is set (and nothing exists elsewhere).
  char tmpl[] = "/tmp/weft-xdg-XXXXXX";
  ASSERT_NE(::mkdtemp(tmpl), nullptr);
  const std::string tmp_default = "/tmp/weft-" + std::to_string(::getuid()) + "/weftd.sock";
  ::setenv("XDG_RUNTIME_DIR", tmpl, 1);
  if (!fs::exists(tmp_default)) {
    EXPECT_EQ(weft::ResolveAddress(o), std::string("unix:") + tmpl + "/weft/weftd.sock");
  }
  ::unsetenv("XDG_RUNTIME_DIR");
  EXPECT_EQ(weft::ResolveAddress(o), "unix:" + tmp_default);
  fs::remove_all(tmpl);
}

TEST(ClientOfflineTest, ConnectToNothingIsUnavailable) {
  weft::ConnectOptions o;
  o.address = "unix:/tmp/weft-no-such-dir/none.sock";
  o.connect_timeout = 200ms;
  auto c = weft::Client::Connect(o);
  ASSERT_FALSE(c.ok());
  EXPECT_EQ(c.status().code(), weft::StatusCode::kUnavailable);
  EXPECT_NE(c.status().message().find("none.sock"), std::string::npos) << c.status().ToString();
}

TEST(ClientOfflineTest, UnconnectedClientReturnsErrors) {
  weft::Client c;
  EXPECT_FALSE(c.connected());
  EXPECT_EQ(c.ListDevices().status().code(), weft::StatusCode::kFailedPrecondition);
  EXPECT_EQ(c.Zeros(weft::dtypes::float32(), {4}).status().code(),
            weft::StatusCode::kFailedPrecondition);
  EXPECT_EQ(c.Synchronize().code(), weft::StatusCode::kFailedPrecondition);
  weft::Array a;
  EXPECT_FALSE(a.valid());
  float x = 0;
  EXPECT_EQ(a.Read(&x, 4).code(), weft::StatusCode::kFailedPrecondition);
  EXPECT_TRUE(a.Free().ok());   // freeing nothing is a no-op
}

TEST(ClientOfflineTest, DTypeSizesAndNames) {
  EXPECT_EQ(weft::dtypes::float32().element_size(), 4u);
  EXPECT_EQ(weft::dtypes::vec3().element_size(), 12u);
  EXPECT_EQ(weft::dtypes::mat33().element_size(), 36u);
  EXPECT_EQ(weft::DType::Matrix(2, 3, weft::ScalarType::kFloat64).element_size(), 48u);
  EXPECT_EQ(weft::DType::Scalar(weft::ScalarType::kBool).element_size(), 1u);
  EXPECT_EQ(weft::DType::Struct("m.P", 20).element_size(), 20u);
  EXPECT_EQ(weft::dtypes::vec3().ToString(), "vec(3,float32)");
  EXPECT_EQ(weft::DType::Matrix(3, 3, weft::ScalarType::kFloat64).ToString(), "mat(3,3,float64)");
  EXPECT_EQ(weft::dtypes::quat().ToString(), "quat(float32)");
  EXPECT_EQ(weft::DType::Struct("m.P", 20).ToString(), "struct(m.P)");
  EXPECT_EQ(weft::DTypeOf<std::uint16_t>().ToString(), "uint16");
  EXPECT_FALSE(weft::DType{}.Validate().ok());
  EXPECT_FALSE(weft::DType::Vector(0, weft::ScalarType::kFloat32).Validate().ok());
  EXPECT_FALSE((weft::DType{weft::ScalarType::kFloat32, {2, 2, 2}, {}, 0}).Validate().ok());
}

TEST(ClientOfflineTest, HalfConversionMatchesCompiler) {
  // Every half round-trips through float exactly (NaNs stay NaN).
  for (uint32_t h = 0; h < 65536; ++h) {
    const float f = weft::HalfToFloat(static_cast<uint16_t>(h));
    _Float16 ref;
    const uint16_t bits = static_cast<uint16_t>(h);
    std::memcpy(&ref, &bits, 2);
    if (std::isnan(f)) {
      ASSERT_TRUE(std::isnan(static_cast<float>(ref))) << h;
      continue;
    }
    ASSERT_EQ(f, static_cast<float>(ref)) << h;
    ASSERT_EQ(weft::FloatToHalf(f), h) << h;
  }
  // Random floats over the whole range (subnormals, overflow, ties) round like the compiler.
  std::mt19937 rng(7);
  for (int i = 0; i < 2000000; ++i) {
    const uint32_t bits = static_cast<uint32_t>(rng());
    float f;
    std::memcpy(&f, &bits, 4);
    if (std::isnan(f)) continue;
    const _Float16 ref = static_cast<_Float16>(f);
    uint16_t ref_bits;
    std::memcpy(&ref_bits, &ref, 2);
    ASSERT_EQ(weft::FloatToHalf(f), ref_bits) << "float bits " << bits;
  }
}

TEST(ClientOfflineTest, EncodeFillValue) {
  auto v = weft::EncodeFillValue(weft::dtypes::vec3(), 2.5);
  ASSERT_OK_E(v);
  ASSERT_EQ(v->size(), 12u);
  float f[3];
  std::memcpy(f, v->data(), 12);
  EXPECT_EQ(f[0], 2.5f);
  EXPECT_EQ(f[2], 2.5f);
  auto i = weft::EncodeFillValue(weft::DType::Scalar(weft::ScalarType::kInt16), -7.9);
  ASSERT_OK_E(i);
  int16_t s;
  std::memcpy(&s, i->data(), 2);
  EXPECT_EQ(s, -7);
  EXPECT_FALSE(weft::EncodeFillValue(weft::DType::Scalar(weft::ScalarType::kUInt8), 300).ok());
  EXPECT_FALSE(weft::EncodeFillValue(weft::DType::Scalar(weft::ScalarType::kUInt32), -1).ok());
  // 2^63 and 2^64 are one past int64 / uint64: refused, never converted (that would be UB).
  EXPECT_FALSE(weft::EncodeFillValue(weft::DType::Scalar(weft::ScalarType::kInt64), 0x1p63).ok());
  EXPECT_FALSE(weft::EncodeFillValue(weft::DType::Scalar(weft::ScalarType::kUInt64), 0x1p64).ok());
  EXPECT_TRUE(weft::EncodeFillValue(weft::DType::Scalar(weft::ScalarType::kInt64), -0x1p63).ok());
  EXPECT_FALSE(weft::EncodeFillValue(weft::DType::Scalar(weft::ScalarType::kInt32), std::nan("")).ok());
  EXPECT_FALSE(weft::EncodeFillValue(weft::DType::Struct("m.P", 8), 1).ok());
  auto b = weft::EncodeFillValue(weft::DType::Scalar(weft::ScalarType::kBool), 3);
  ASSERT_OK_E(b);
  EXPECT_EQ(std::to_integer<int>((*b)[0]), 1);
}

// ---------------------------------------------------------------------------------------------
// Sessions and devices.

TEST_F(ClientTest, SessionIsLocalOverUnixSocket) {
  EXPECT_TRUE(client_.connected());
  EXPECT_FALSE(client_.session().session_id.empty());
  EXPECT_TRUE(client_.session().local);
  EXPECT_TRUE(client_.local());
  EXPECT_EQ(client_.session().daemon_pid, daemon_->pid());
  EXPECT_FALSE(client_.session().daemon_version.empty());
  EXPECT_EQ(client_.session().address, daemon_->address());
}

TEST_F(ClientTest, ListsTheCpuDevice) {
  auto devices = client_.ListDevices();
  ASSERT_OK_E(devices);
  const weft::DeviceInfo* cpu = nullptr;
  for (const auto& d : *devices)
    if (d.name == "cpu") cpu = &d;
  ASSERT_NE(cpu, nullptr);
  EXPECT_EQ(cpu->kind, "cpu");
  EXPECT_GT(cpu->total_memory, 0u);
  EXPECT_LE(cpu->free_memory, cpu->total_memory);
  EXPECT_GT(cpu->cores, 0);
  for (const auto& d : *devices) {
    if (d.kind != "cuda") continue;
    EXPECT_EQ(d.name.rfind("cuda:", 0), 0u) << d.name;
    EXPECT_GT(d.compute_capability_major, 0) << d.name;
  }
}

TEST_F(ClientTest, CloseFreesEverythingAndMakesArraysInert) {
  auto other = daemon_->Connect();
  ASSERT_OK_E(other);
  const auto before = Stats();
  auto a = other->Zeros(weft::dtypes::float64(), {1000});
  auto b = other->Zeros(weft::dtypes::int32(), {10, 10});
  ASSERT_OK_E(a);
  ASSERT_OK_E(b);
  EXPECT_EQ(Stats().arrays, before.arrays + 2);
  ASSERT_OK(other->Close());
  EXPECT_FALSE(other->connected());
  EXPECT_EQ(Stats().arrays, before.arrays);
  std::vector<double> out(1000);
  EXPECT_EQ(a->Read(out.data(), out.size() * 8).code(), weft::StatusCode::kFailedPrecondition);
  EXPECT_EQ(other->ListDevices().status().code(), weft::StatusCode::kFailedPrecondition);
  EXPECT_TRUE(a->Free().ok());   // inert: nothing to free any more
  EXPECT_TRUE(other->Close().ok());   // idempotent
}

// ---------------------------------------------------------------------------------------------
// Creation and transfers.

template <typename T>
void CheckRoundTrip(weft::Client& client, std::mt19937_64& rng, std::vector<int64_t> shape) {
  size_t n = 1;
  for (auto d : shape) n *= static_cast<size_t>(d);
  const auto values = RandomValues<T>(rng, n);
  weft::Expected<weft::Array> a = client.FromData<T>(values, shape);
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  EXPECT_EQ(a->dtype(), weft::DTypeOf<T>());
  EXPECT_EQ(a->shape(), shape);
  EXPECT_EQ(a->byte_size(), n * sizeof(T));
  EXPECT_EQ(a->device(), "cpu");
  // C-contiguous byte strides (any strides describe an empty array).
  ASSERT_EQ(a->strides().size(), shape.size());
  int64_t stride = sizeof(T);
  for (size_t i = shape.size(); i-- > 0 && n != 0;) {
    EXPECT_EQ(a->strides()[i], stride) << i;
    stride *= shape[i];
  }
  auto back = a->ToVector<T>();
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(*back, values);
}

TEST_F(ClientTest, FromDataRoundTripsEveryScalarTypeAndRank) {
  CheckRoundTrip<float>(client_, rng_, {17});
  CheckRoundTrip<double>(client_, rng_, {3, 5});
  CheckRoundTrip<int8_t>(client_, rng_, {2, 3, 4});
  CheckRoundTrip<uint8_t>(client_, rng_, {1, 2, 3, 4});
  CheckRoundTrip<int16_t>(client_, rng_, {33});
  CheckRoundTrip<uint16_t>(client_, rng_, {33});
  CheckRoundTrip<int32_t>(client_, rng_, {7, 9});
  CheckRoundTrip<uint32_t>(client_, rng_, {100});
  CheckRoundTrip<int64_t>(client_, rng_, {6, 6});
  CheckRoundTrip<uint64_t>(client_, rng_, {5});
  CheckRoundTrip<float>(client_, rng_, {0});
  CheckRoundTrip<float>(client_, rng_, {4, 0, 3});
}

TEST_F(ClientTest, ZerosFullAndEmptyHaveTheRightContents) {
  std::vector<int64_t> shape = {4, 5};
  auto z = client_.Zeros(weft::dtypes::vec3(), shape);
  ASSERT_OK_E(z);
  EXPECT_EQ(z->byte_size(), 4u * 5u * 12u);
  EXPECT_EQ(z->dtype(), weft::dtypes::vec3());
  auto zv = z->ToVector<float>();
  ASSERT_OK_E(zv);
  EXPECT_EQ(*zv, std::vector<float>(60, 0.0f));

  auto f = client_.Full(weft::dtypes::mat22(), {3}, -0.25);
  ASSERT_OK_E(f);
  auto fv = f->ToVector<float>();
  ASSERT_OK_E(fv);
  EXPECT_EQ(*fv, std::vector<float>(12, -0.25f));

  auto h = client_.Full(weft::dtypes::float16(), {9}, 1.0 / 3.0);
  ASSERT_OK_E(h);
  auto hv = h->ToVector<uint16_t>();
  ASSERT_OK_E(hv);
  EXPECT_EQ(*hv, std::vector<uint16_t>(9, weft::FloatToHalf(1.0f / 3.0f)));

  const int64_t element[2] = {-5, 1LL << 40};
  auto fb = client_.FullBytes(weft::DType::Vector(2, weft::ScalarType::kInt64), {6}, element,
                              sizeof element);
  ASSERT_OK_E(fb);
  auto fbv = fb->ToVector<int64_t>();
  ASSERT_OK_E(fbv);
  for (int i = 0; i < 6; ++i) {
    EXPECT_EQ((*fbv)[2 * i], -5);
    EXPECT_EQ((*fbv)[2 * i + 1], 1LL << 40);
  }

  auto e = client_.Empty(weft::DType::Scalar(weft::ScalarType::kUInt32), {128});
  ASSERT_OK_E(e);
  EXPECT_EQ(e->byte_size(), 512u);
  EXPECT_EQ(e->size(), 128);
  EXPECT_EQ(e->ndim(), 1);
}

TEST_F(ClientTest, StructArraysCarryTheirByteSize) {
  std::vector<std::byte> data(7 * 20);
  for (size_t i = 0; i < data.size(); ++i) data[i] = std::byte(i * 37 + 1);
  auto s = client_.FromBytes(weft::DType::Struct("test.Particle", 20), {7}, data.data(),
                             data.size());
  ASSERT_OK_E(s);
  EXPECT_EQ(s->byte_size(), 140u);
  EXPECT_EQ(s->dtype().type_name, "struct(test.Particle)");
  std::vector<std::byte> back(140);
  ASSERT_OK(s->Read(back.data(), back.size()));
  EXPECT_EQ(back, data);
}

TEST_F(ClientTest, LocalCpuArraysAreZeroCopy) {
  auto a = client_.Zeros(weft::dtypes::float32(), {1024});
  ASSERT_OK_E(a);
  ASSERT_TRUE(a->mappable());
  auto m1 = a->MapAs<float>();
  ASSERT_OK_E(m1);
  ASSERT_EQ(m1->size(), 1024u);
  auto m2 = a->MapAs<float>();
  ASSERT_OK_E(m2);
  EXPECT_EQ(m1->data(), m2->data());   // one mapping, no copy
  for (size_t i = 0; i < 1024; ++i) (*m1)[i] = static_cast<float>(i) * 0.5f;

  // The daemon sees the writes: a remote-style (stream) client of the same array reads them.
  auto token = a->Export();
  ASSERT_OK_E(token);
  weft::ConnectOptions o = daemon_->Options();
  o.map_shared_memory = false;
  auto streamer = weft::Client::Connect(o);
  ASSERT_OK_E(streamer);
  EXPECT_FALSE(streamer->local());
  auto b = streamer->Import(*token);
  ASSERT_OK_E(b);
  EXPECT_FALSE(b->mappable());
  EXPECT_EQ(b->Map().status().code(), weft::StatusCode::kFailedPrecondition);
  auto bv = b->ToVector<float>();
  ASSERT_OK_E(bv);
  for (size_t i = 0; i < 1024; ++i) ASSERT_EQ((*bv)[i], static_cast<float>(i) * 0.5f) << i;

  // And writes through the stream are visible in a mapping made after the export (the first
  // export moved the array into a slab of its own; docs/security.md).
  auto m3 = a->MapAs<float>();
  ASSERT_OK_E(m3);
  std::vector<float> ones(1024, 1.0f);
  ASSERT_OK(b->Assign(ones));
  ASSERT_OK(client_.Synchronize());
  for (size_t i = 0; i < 1024; ++i) ASSERT_EQ((*m3)[i], 1.0f) << i;
}

TEST_F(ClientTest, LargeArraysTravelThroughMappingAndStreams) {
  const size_t n = (48u << 20) / 8;   // 48 MiB of float64
  std::vector<double> values(n);
  std::mt19937_64 rng(99);
  std::uniform_real_distribution<double> dist(-1, 1);
  for (auto& v : values) v = dist(rng);
  auto a = client_.FromData<double>(values);
  ASSERT_OK_E(a);
  auto token = a->Export();
  ASSERT_OK_E(token);

  weft::ConnectOptions o = daemon_->Options();
  o.map_shared_memory = false;
  o.chunk_size = 3u << 20;   // not a divisor of the size: the last chunk is short
  auto streamer = weft::Client::Connect(o);
  ASSERT_OK_E(streamer);
  auto b = streamer->Import(*token);
  ASSERT_OK_E(b);
  auto bv = b->ToVector<double>();
  ASSERT_OK_E(bv);
  EXPECT_TRUE(*bv == values);

  // A large create through the stream path (remote style) reads back through the mapping.
  for (auto& v : values) v = -v;
  auto c = streamer->FromData<double>(values);
  ASSERT_OK_E(c);
  auto ctoken = c->Export();
  ASSERT_OK_E(ctoken);
  auto cl = client_.Import(*ctoken);
  ASSERT_OK_E(cl);
  auto cv = cl->MapAs<double>();
  ASSERT_OK_E(cv);
  EXPECT_TRUE(std::equal(cv->begin(), cv->end(), values.begin()));
}

TEST_F(ClientTest, ReadAndWriteCheckTheByteCount) {
  auto a = client_.FromData<int32_t>(std::vector<int32_t>{1, 2, 3, 4});
  ASSERT_OK_E(a);
  int32_t small[3] = {9, 9, 9};
  EXPECT_EQ(a->Write(small, sizeof small).code(), weft::StatusCode::kInvalidArgument);
  int32_t big[5] = {};
  EXPECT_EQ(a->Read(big, sizeof big).code(), weft::StatusCode::kInvalidArgument);
  auto v = a->ToVector<int32_t>();
  ASSERT_OK_E(v);
  EXPECT_EQ(*v, (std::vector<int32_t>{1, 2, 3, 4}));
  auto three = client_.FromData<int32_t>(std::vector<int32_t>{1, 2, 3});   // 12 bytes
  ASSERT_OK_E(three);
  EXPECT_EQ(three->ToVector<double>().status().code(), weft::StatusCode::kInvalidArgument);
  EXPECT_EQ(three->MapAs<double>().status().code(), weft::StatusCode::kInvalidArgument);
  EXPECT_FALSE(client_.FromBytes(weft::dtypes::float32(), {3}, small, 8).ok());
  EXPECT_FALSE(client_.FullBytes(weft::dtypes::vec3(), {3}, small, 4).ok());
}

// ---------------------------------------------------------------------------------------------
// Commands: fill, copy, slices, batches, synchronize.

TEST_F(ClientTest, FillZeroAndCopyMatchAReference) {
  const size_t rows = 37, cols = 11;
  auto src_values = RandomValues<float>(rng_, rows * cols);
  auto src = client_.FromData<float>(src_values, {rows, cols});
  auto dst = client_.Zeros(weft::dtypes::float32(), {rows, cols});
  ASSERT_OK_E(src);
  ASSERT_OK_E(dst);
  std::vector<float> ref(rows * cols, 0.0f);

  ASSERT_OK(dst->Fill(3.25));
  std::fill(ref.begin(), ref.end(), 3.25f);
  // Rows [5, 9) from src, row 20 filled with -1, the last 3 rows zeroed via a negative slice.
  auto d59 = dst->Slice(5, 9);
  auto s59 = src->Slice(5, 9);
  ASSERT_OK_E(d59);
  ASSERT_OK_E(s59);
  ASSERT_OK(client_.Copy(*d59, *s59));
  for (size_t i = 5 * cols; i < 9 * cols; ++i) ref[i] = src_values[i];
  auto r20 = dst->Slice(20, 21);
  ASSERT_OK_E(r20);
  float minus_one = -1.0f;
  ASSERT_OK(client_.Fill(*r20, Bytes(&minus_one, 4)));
  for (size_t i = 20 * cols; i < 21 * cols; ++i) ref[i] = -1.0f;
  auto tail = dst->Slice(-3, rows);
  ASSERT_OK_E(tail);
  ASSERT_OK(client_.Fill(*tail, std::vector<std::byte>(4)));
  for (size_t i = (rows - 3) * cols; i < rows * cols; ++i) ref[i] = 0.0f;

  auto got = dst->ToVector<float>();
  ASSERT_OK_E(got);
  EXPECT_EQ(*got, ref);

  // Whole-array copy and zero.
  auto copy = client_.Empty(weft::dtypes::float32(), {rows, cols});
  ASSERT_OK_E(copy);
  ASSERT_OK(copy->CopyFrom(*src));
  auto cv = copy->ToVector<float>();
  ASSERT_OK_E(cv);
  EXPECT_EQ(*cv, src_values);
  ASSERT_OK(copy->Zero());
  cv = copy->ToVector<float>();
  ASSERT_OK_E(cv);
  EXPECT_EQ(*cv, std::vector<float>(rows * cols, 0.0f));

  EXPECT_EQ(dst->Slice(3, 2).status().code(), weft::StatusCode::kOutOfRange);
  EXPECT_EQ(dst->Slice(0, rows + 1).status().code(), weft::StatusCode::kOutOfRange);
}

TEST_F(ClientTest, FillConvertsToEveryScalarType) {
  struct Case { weft::DType dtype; double value; };
  const Case cases[] = {
      {weft::DType::Scalar(weft::ScalarType::kInt8), -100},
      {weft::DType::Scalar(weft::ScalarType::kUInt16), 65535},
      {weft::DType::Scalar(weft::ScalarType::kInt64), -(1LL << 50)},
      {weft::DType::Scalar(weft::ScalarType::kFloat64), 1e-300},
      {weft::DType::Scalar(weft::ScalarType::kBool), 1},
      {weft::DType::Vector(4, weft::ScalarType::kFloat16), 65504},
      {weft::DType::Matrix(3, 3, weft::ScalarType::kFloat64), -2.5},
  };
  for (const auto& c : cases) {
    auto a = client_.Zeros(c.dtype, {13});
    ASSERT_OK_E(a);
    ASSERT_OK(a->Fill(c.value));
    std::vector<std::byte> got(a->byte_size());
    ASSERT_OK(a->Read(got.data(), got.size()));
    auto element = weft::EncodeFillValue(c.dtype, c.value);
    ASSERT_OK_E(element);
    for (size_t i = 0; i < 13; ++i)
      ASSERT_TRUE(std::equal(element->begin(), element->end(),
                             got.begin() + i * element->size()))
          << c.dtype.ToString() << " element " << i;
  }
}

TEST_F(ClientTest, BatchesRunInOrder) {
  auto a = client_.Zeros(weft::dtypes::int32(), {64});
  auto b = client_.Zeros(weft::dtypes::int32(), {64});
  ASSERT_OK_E(a);
  ASSERT_OK_E(b);
  weft::CommandBatch batch;
  // a = 1; b = a; a = 2; then 100 alternating fills, the last one wins.
  int32_t one = 1, two = 2;
  batch.Fill(a->view(), Bytes(&one, 4)).Copy(b->view(), a->view()).Fill(a->view(), Bytes(&two, 4));
  for (int32_t i = 0; i < 100; ++i) {
    auto half = b->Slice(32, 64);
    ASSERT_OK_E(half);
    batch.Fill(*half, Bytes(&i, 4));
  }
  EXPECT_EQ(batch.size(), 103u);
  ASSERT_OK(client_.Submit(std::move(batch)));
  ASSERT_OK(client_.Synchronize());
  auto av = a->ToVector<int32_t>();
  auto bv = b->ToVector<int32_t>();
  ASSERT_OK_E(av);
  ASSERT_OK_E(bv);
  EXPECT_EQ(*av, std::vector<int32_t>(64, 2));
  for (int i = 0; i < 64; ++i) EXPECT_EQ((*bv)[i], i < 32 ? 1 : 99) << i;
}

TEST_F(ClientTest, QueuedCommandsFlushWhenTheQueueIsFull) {
  weft::ConnectOptions o = daemon_->Options();
  o.max_pending_commands = 8;
  auto c = weft::Client::Connect(o);
  ASSERT_OK_E(c);
  auto a = c->Zeros(weft::dtypes::float64(), {100});
  ASSERT_OK_E(a);
  for (int i = 1; i <= 50; ++i) {
    auto s = a->Slice(i - 1, i);
    ASSERT_OK_E(s);
    double v = i;
    ASSERT_OK(c->Fill(*s, Bytes(&v, 8)));
  }
  auto v = a->ToVector<double>();
  ASSERT_OK_E(v);
  for (int i = 0; i < 100; ++i) EXPECT_EQ((*v)[i], i < 50 ? i + 1.0 : 0.0) << i;
}

TEST_F(ClientTest, FailingCommandsSurfaceAtSynchronize) {
  auto a = client_.Zeros(weft::dtypes::float32(), {10});
  auto b = client_.Zeros(weft::dtypes::float32(), {20});
  ASSERT_OK_E(a);
  ASSERT_OK_E(b);
  // Element counts differ: the daemon refuses the copy when it runs it.
  ASSERT_OK(client_.Copy(a->view(), b->view(), {"client_test.cpp", 42}));
  const weft::Status s = client_.Synchronize();
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("client_test.cpp:42"), std::string::npos) << s.ToString();
  // The error is reported once; the session keeps working.
  ASSERT_OK(client_.Synchronize());
  ASSERT_OK(a->Fill(5));
  auto v = a->ToVector<float>();
  ASSERT_OK_E(v);
  EXPECT_EQ(*v, std::vector<float>(10, 5.0f));

  // A fill whose value has the wrong size, and a view outside the allocation.
  ASSERT_OK(client_.Fill(a->view(), std::vector<std::byte>(3)));
  EXPECT_FALSE(client_.Synchronize().ok());
  weft::ArrayView outside = a->view();
  outside.byte_offset = 8;   // 10 elements from byte 8 run past the end
  ASSERT_OK(client_.Fill(outside, std::vector<std::byte>(4)));
  EXPECT_FALSE(client_.Synchronize().ok());
  weft::ArrayView unknown = a->view();
  unknown.handle = 0xdeadbeef;
  ASSERT_OK(client_.Fill(unknown, std::vector<std::byte>(4)));
  EXPECT_FALSE(client_.Synchronize().ok());
  ASSERT_OK(client_.Synchronize());
  v = a->ToVector<float>();
  ASSERT_OK_E(v);
  EXPECT_EQ(*v, std::vector<float>(10, 5.0f));   // nothing changed
}

// ---------------------------------------------------------------------------------------------
// Ownership, describe, gradients, IPC, stats.

TEST_F(ClientTest, ArraysFreeThemselves) {
  const auto before = Stats();
  uint64_t handle = 0;
  {
    auto a = client_.Zeros(weft::dtypes::float32(), {256});
    ASSERT_OK_E(a);
    handle = a->handle();
    EXPECT_EQ(Stats().arrays, before.arrays + 1);
    EXPECT_GE(Stats().array_bytes, before.array_bytes + 1024);
    weft::Array moved = std::move(*a);
    EXPECT_FALSE(a->valid());
    EXPECT_TRUE(moved.valid());
    EXPECT_EQ(Stats().arrays, before.arrays + 1);
  }
  EXPECT_EQ(Stats().arrays, before.arrays);
  EXPECT_EQ(client_.Describe(handle).status().code(), weft::StatusCode::kNotFound);

  // Release keeps the allocation; Client::Free frees it by handle.
  auto b = client_.Zeros(weft::dtypes::float32(), {4});
  ASSERT_OK_E(b);
  const uint64_t released = b->Release();
  EXPECT_FALSE(b->valid());
  EXPECT_TRUE(client_.Describe(released).ok());
  ASSERT_OK(client_.Free(released));
  EXPECT_EQ(client_.Describe(released).status().code(), weft::StatusCode::kNotFound);
  EXPECT_EQ(Stats().arrays, before.arrays);
}

TEST_F(ClientTest, DescribeMatchesCreate) {
  auto a = client_.Zeros(weft::dtypes::mat33(), {2, 3});
  ASSERT_OK_E(a);
  auto d = client_.Describe(a->handle());
  ASSERT_OK_E(d);
  EXPECT_EQ(d->handle, a->handle());
  EXPECT_EQ(d->dtype, weft::dtypes::mat33());
  EXPECT_EQ(d->shape, (std::vector<int64_t>{2, 3}));
  EXPECT_EQ(d->strides, (std::vector<int64_t>{3 * 36, 36}));
  EXPECT_EQ(d->byte_size, 6u * 36u);
  EXPECT_EQ(d->device, "cpu");
  EXPECT_EQ(d->grad_handle, 0u);
  EXPECT_FALSE(d->shm_name.empty());
  EXPECT_LE(d->shm_offset + d->byte_size, d->shm_size);
  auto again = a->Describe();
  ASSERT_OK_E(again);
  EXPECT_EQ(again->shm_name, d->shm_name);
  EXPECT_EQ(a->Grad().status().code(), weft::StatusCode::kFailedPrecondition);
}

TEST_F(ClientTest, RequiresGradGivesAZeroGradient) {
  weft::ArrayOptions opts;
  opts.requires_grad = true;
  auto a = client_.Full(weft::dtypes::vec3(), {5}, 2.0, opts);
  ASSERT_OK_E(a);
  ASSERT_NE(a->info().grad_handle, 0u);
  auto g = a->Grad();
  ASSERT_OK_E(g);
  EXPECT_FALSE(g->owns());
  EXPECT_EQ(g->shape(), a->shape());
  EXPECT_EQ(g->dtype(), a->dtype());
  auto gv = g->ToVector<float>();
  ASSERT_OK_E(gv);
  EXPECT_EQ(*gv, std::vector<float>(15, 0.0f));
}

TEST_F(ClientTest, ExportImportSharesOneAllocation) {
  auto values = RandomValues<double>(rng_, 300);
  auto a = client_.FromData<double>(values, {10, 30});
  ASSERT_OK_E(a);
  auto token = a->Export();
  ASSERT_OK_E(token);
  EXPECT_FALSE(token->empty());

  auto other = daemon_->Connect();
  ASSERT_OK_E(other);
  auto b = other->Import(*token);
  ASSERT_OK_E(b);
  EXPECT_EQ(b->shape(), a->shape());
  EXPECT_EQ(b->dtype(), a->dtype());
  auto bv = b->ToVector<double>();
  ASSERT_OK_E(bv);
  EXPECT_EQ(*bv, values);

  // Same bytes: a fill through one session is seen by the other.
  ASSERT_OK(b->Fill(7.0));
  ASSERT_OK(other->Synchronize());
  auto av = a->ToVector<double>();
  ASSERT_OK_E(av);
  EXPECT_EQ(*av, std::vector<double>(300, 7.0));

  // The memory lives while any session holds it.
  ASSERT_OK(a->Free());
  bv = b->ToVector<double>();
  ASSERT_OK_E(bv);
  EXPECT_EQ(*bv, std::vector<double>(300, 7.0));

  EXPECT_FALSE(other->Import("not-a-token").ok());
}

TEST_F(ClientTest, StatsCountSessionsAndArrays) {
  const auto before = Stats();
  EXPECT_GE(before.sessions, 1u);
  EXPECT_GE(before.sessions_opened_total, 1u);
  {
    auto other = daemon_->Connect();
    ASSERT_OK_E(other);
    auto s = Stats();
    EXPECT_EQ(s.sessions, before.sessions + 1);
    EXPECT_EQ(s.sessions_opened_total, before.sessions_opened_total + 1);
    auto a = other->Zeros(weft::dtypes::float32(), {1 << 16});
    ASSERT_OK_E(a);
    s = Stats();
    EXPECT_EQ(s.arrays, before.arrays + 1);
    EXPECT_GE(s.array_bytes, before.array_bytes + (4u << 16));
    EXPECT_GE(s.cpu_slabs, 1u);
    EXPECT_GE(s.cpu_slab_bytes, s.array_bytes);
  }
  const auto after = Stats();
  EXPECT_EQ(after.sessions, before.sessions);
  EXPECT_EQ(after.arrays, before.arrays);
}

// ---------------------------------------------------------------------------------------------
// Bad input through raw requests: a clear error, and nothing changes.

TEST_F(ClientTest, DaemonRefusesBadRequests) {
  auto chan = weft::RawChannel(client_);
  ASSERT_NE(chan, nullptr);
  auto arrays = weft::v1::ArrayService::NewStub(chan);
  const auto before = Stats();

  auto create = [&](auto fill) {
    weft::v1::CreateArrayRequest req;
    req.mutable_dtype()->set_scalar(weft::v1::FLOAT32);
    req.set_device("cpu");
    fill(req);
    weft::v1::CreateArrayResponse resp;
    auto ctx = weft::RawContext(client_);
    return arrays->Create(ctx.get(), req, &resp);
  };
  using Req = weft::v1::CreateArrayRequest;
  EXPECT_EQ(create([](Req& r) { r.add_shape(-4); }).error_code(), grpc::INVALID_ARGUMENT);
  EXPECT_FALSE(create([](Req& r) { r.add_shape(1LL << 40); r.add_shape(1LL << 40); }).ok());
  EXPECT_FALSE(create([](Req& r) { r.add_shape(1LL << 50); }).ok());
  EXPECT_EQ(create([](Req& r) {
              for (int i = 0; i < 5; ++i) r.add_shape(2);
            }).error_code(),
            grpc::INVALID_ARGUMENT);
  EXPECT_EQ(create([](Req& r) {
              r.add_shape(4);
              r.set_init(Req::DATA);
              r.set_value(std::string(15, 'x'));   // 16 bytes expected
            }).error_code(),
            grpc::INVALID_ARGUMENT);
  EXPECT_EQ(create([](Req& r) {
              r.add_shape(4);
              r.set_init(Req::FILL);
              r.set_value(std::string(3, 'x'));
            }).error_code(),
            grpc::INVALID_ARGUMENT);
  EXPECT_EQ(create([](Req& r) {
              r.mutable_dtype()->set_scalar(weft::v1::SCALAR_UNSPECIFIED);
              r.add_shape(4);
            }).error_code(),
            grpc::INVALID_ARGUMENT);
  EXPECT_FALSE(create([](Req& r) {
                 r.add_shape(4);
                 r.set_device("tpu:7");
               }).ok());
  EXPECT_EQ(Stats().arrays, before.arrays);

  // The typed API refuses sizes that overflow before asking the daemon.
  EXPECT_EQ(client_.Zeros(weft::dtypes::float64(), {1LL << 31, 1LL << 31, 8}).status().code(),
            weft::StatusCode::kInvalidArgument);
  EXPECT_EQ(client_.Zeros(weft::dtypes::float64(), {1LL << 62}).status().code(),
            weft::StatusCode::kInvalidArgument);
  EXPECT_EQ(client_.Zeros(weft::dtypes::float64(), {2, -1}).status().code(),
            weft::StatusCode::kInvalidArgument);
  // Absurd but representable: the daemon refuses it (more than memory + swap).
  EXPECT_FALSE(client_.Zeros(weft::dtypes::float64(), {1LL << 50}).ok());
  EXPECT_EQ(Stats().arrays, before.arrays);

  // Unknown handles.
  EXPECT_EQ(client_.Describe(987654321).status().code(), weft::StatusCode::kNotFound);
  EXPECT_EQ(client_.Free(987654321).code(), weft::StatusCode::kNotFound);

  // Writes and reads outside the allocation change nothing.
  auto a = client_.FromData<float>(std::vector<float>{1, 2, 3, 4});
  ASSERT_OK_E(a);
  {
    weft::v1::WriteArrayResponse resp;
    auto ctx = weft::RawContext(client_);
    auto w = arrays->Write(ctx.get(), &resp);
    weft::v1::WriteArrayRequest req;
    req.set_handle(a->handle());
    req.mutable_chunk()->set_byte_offset(8);
    req.mutable_chunk()->set_data(std::string(12, '\x7f'));   // bytes 8..20 of a 16-byte array
    w->Write(req);
    w->WritesDone();
    const grpc::Status s = w->Finish();
    EXPECT_FALSE(s.ok());
    EXPECT_TRUE(s.error_code() == grpc::OUT_OF_RANGE || s.error_code() == grpc::INVALID_ARGUMENT)
        << s.error_code() << " " << s.error_message();
  }
  {
    weft::v1::ReadArrayRequest req;
    req.set_handle(a->handle());
    req.set_byte_offset(12);
    req.set_byte_count(8);
    auto ctx = weft::RawContext(client_);
    auto r = arrays->Read(ctx.get(), req);
    weft::v1::ArrayChunk chunk;
    while (r->Read(&chunk)) {}
    EXPECT_FALSE(r->Finish().ok());
  }
  auto v = a->ToVector<float>();
  ASSERT_OK_E(v);
  EXPECT_EQ(*v, (std::vector<float>{1, 2, 3, 4}));

  // A request without a session.
  {
    weft::v1::CreateArrayRequest req;
    req.mutable_dtype()->set_scalar(weft::v1::FLOAT32);
    req.add_shape(4);
    weft::v1::CreateArrayResponse resp;
    grpc::ClientContext bare;
    const grpc::Status s = arrays->Create(&bare, req, &resp);
    EXPECT_FALSE(s.ok());
    grpc::ClientContext wrong;
    wrong.AddMetadata("weft-session", "no-such-session");
    EXPECT_FALSE(arrays->Create(&wrong, req, &resp).ok());
  }
  EXPECT_EQ(Stats().arrays, before.arrays + 1);
}

// ---------------------------------------------------------------------------------------------
// Kernels: compile a module from C++ and launch it.

const char* kSaxpySource =
    "def saxpy(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):\n"
    "    i = wp.tid()\n"
    "    y[i] = a * x[i] + y[i] + OFFSET\n";

weft::ModuleDef SaxpyModule() {
  weft::ModuleDef m;
  m.name = "client_test_saxpy";
  m.AddKernel("saxpy", kSaxpySource, {"x", "y", "a"},
              {"array(float32,1)", "array(float32,1)", "float32"});
  m.functions.back().file = "client_test_kernels.py";
  m.functions.back().first_line = 10;
  m.AddConstant("OFFSET", "float32", "0.5");
  return m;
}

TEST_F(ClientTest, CompilesAndLaunchesAKernel) {
  auto compiled = client_.Compile(SaxpyModule(), "cpu");
  ASSERT_OK_E(compiled);
  EXPECT_FALSE(compiled->module_id.empty());
  const weft::KernelInfo* k = compiled->Find("saxpy");
  ASSERT_NE(k, nullptr);
  ASSERT_EQ(k->params.size(), 3u);
  EXPECT_EQ(k->params[0].name, "x");
  EXPECT_EQ(k->params[2].type, "float32");

  const int64_t n = 1000;
  auto xs = RandomValues<float>(rng_, n);
  auto ys = RandomValues<float>(rng_, n);
  auto x = client_.FromData<float>(xs);
  auto y = client_.FromData<float>(ys);
  ASSERT_OK_E(x);
  ASSERT_OK_E(y);
  const float a = 1.75f;
  weft::LaunchSpec launch;
  launch.module_id = compiled->module_id;
  launch.kernel = "saxpy";
  launch.dim = {n};
  launch.args = {x->view(), y->view(), weft::ArgBytes(a)};
  ASSERT_OK(client_.Launch(launch, {"client_test.cpp", 1}));
  ASSERT_OK(client_.Launch(launch, {"client_test.cpp", 2}));   // twice: y = a*x + (a*x + y + .5) + .5
  auto got = y->ToVector<float>();
  ASSERT_OK_E(got);
  for (int64_t i = 0; i < n; ++i) {
    const double ax = static_cast<double>(a) * xs[i];
    const double once = ax + ys[i] + 0.5;
    const double ref = ax + once + 0.5;
    // Six float32 roundings (a*x, two adds per launch, twice): a few ulp of the largest
    // intermediate, not of the result (a*x and y may nearly cancel).
    const double scale = std::abs(ax) + std::abs(static_cast<double>(ys[i])) + std::abs(once) + 1.0;
    ASSERT_NEAR((*got)[i], ref, 8 * 0x1p-24 * scale) << i;
  }

  // The second compile of the same module is a cache hit with the same id.
  auto again = client_.Compile(SaxpyModule(), "cpu");
  ASSERT_OK_E(again);
  EXPECT_EQ(again->module_id, compiled->module_id);
  EXPECT_TRUE(again->cache_hit);

  // An out-of-bounds launch is reported at the sync, with the origin; y is unchanged after.
  auto before = y->ToVector<float>();
  ASSERT_OK_E(before);
  launch.dim = {n + 5};
  ASSERT_OK(client_.Launch(launch, {"client_test.cpp", 3}));
  const weft::Status s = client_.Synchronize();
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("saxpy"), std::string::npos) << s.ToString();
}

// An unchecked session runs in a session host of its own: a module there may turn bounds checks
// off (a read one element past the end then returns whatever lies there instead of an error),
// while a checked session of the same daemon, asking for the same, still gets the bounds error.
TEST(ClientUncheckedTest, UncheckedSessionsRunInASessionHost) {
  std::string error;
  auto daemon = Daemon::Start(false, &error, {"--allow-unchecked"});
  ASSERT_NE(daemon, nullptr) << error;
  weft::ConnectOptions o = daemon->Options();
  o.unchecked = true;
  auto unchecked = weft::Client::Connect(o);
  ASSERT_OK_E(unchecked);
  EXPECT_NE(unchecked->session().daemon_pid, daemon->pid());
  EXPECT_NE(unchecked->session().address.find("/host-"), std::string::npos) << unchecked->session().address;
  EXPECT_TRUE(unchecked->local());
  auto checked = daemon->Connect();
  ASSERT_OK_E(checked);
  EXPECT_EQ(checked->session().daemon_pid, daemon->pid());

  weft::ModuleDef m;
  m.name = "client_test_past_end";
  m.AddKernel("past_end",
              "def past_end(x: wp.array(dtype=float), out: wp.array(dtype=float)):\n"
              "    out[0] = x[wp.tid() + 64]\n",
              {"x", "out"}, {"array(float32,1)", "array(float32,1)"});
  m.options["bounds_checks"] = "false";
  std::mt19937_64 rng(std::random_device{}());
  for (weft::Client* c : {&*unchecked, &*checked}) {
    const bool is_unchecked = c == &*unchecked;
    auto compiled = c->Compile(m, "cpu");
    ASSERT_OK_E(compiled);
    auto x = c->FromData<float>(RandomValues<float>(rng, 64));
    auto out = c->FromData<float>(RandomValues<float>(rng, 1));
    ASSERT_OK_E(x);
    ASSERT_OK_E(out);
    weft::LaunchSpec launch;
    launch.module_id = compiled->module_id;
    launch.kernel = "past_end";
    launch.dim = {1};
    launch.args = {x->view(), out->view()};
    ASSERT_OK(c->Launch(launch, {"client_test.cpp", 1}));
    const weft::Status s = c->Synchronize();
    if (is_unchecked) {
      EXPECT_TRUE(s.ok()) << s.ToString();
    } else {
      EXPECT_FALSE(s.ok());
      EXPECT_NE(s.message().find("past_end"), std::string::npos) << s.ToString();
    }
  }
  ASSERT_OK(unchecked->Close());
  ASSERT_OK(checked->Close());
  EXPECT_EQ(daemon->Stop(), 0) << daemon->Log();
}

// Under --device-hosts two clients that name the CPU get their sessions in one device host (not
// the daemon) and compute there; a device name the daemon does not have is refused at Connect.
TEST(ClientDeviceHostTest, SessionsOfADeviceShareItsProcess) {
  std::string error;
  auto daemon = Daemon::Start(false, &error, {"--device-hosts"});
  ASSERT_NE(daemon, nullptr) << error;
  weft::ConnectOptions o = daemon->Options();
  o.device = "cpu";
  auto first = weft::Client::Connect(o);
  ASSERT_OK_E(first);
  auto second = weft::Client::Connect(o);
  ASSERT_OK_E(second);
  EXPECT_NE(first->session().daemon_pid, daemon->pid());
  EXPECT_EQ(first->session().daemon_pid, second->session().daemon_pid);
  EXPECT_EQ(first->session().address, second->session().address);
  EXPECT_NE(first->session().address.find("/host-"), std::string::npos) << first->session().address;
  std::mt19937_64 rng(std::random_device{}());
  const std::vector<double> values = RandomValues<double>(rng, 1000);
  auto a = first->FromData<double>(values);
  ASSERT_OK_E(a);
  auto back = a->ToVector<double>();
  ASSERT_OK_E(back);
  EXPECT_EQ(*back, values);
  o.device = "cuda:99";
  auto refused = weft::Client::Connect(o);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("session device 'cuda:99'"), std::string::npos)
      << refused.status().ToString();
  ASSERT_OK(first->Close());
  ASSERT_OK(second->Close());
  EXPECT_EQ(daemon->Stop(), 0) << daemon->Log();
}

TEST_F(ClientTest, TapeBackwardGivesTheGradient) {
  weft::ModuleDef m;
  m.name = "client_test_tape";
  m.AddKernel("sum_of_squares",
              "def sum_of_squares(x: wp.array(dtype=float), loss: wp.array(dtype=float)):\n"
              "    i = wp.tid()\n"
              "    wp.atomic_add(loss, 0, x[i] * x[i] * SCALE)\n",
              {"x", "loss"}, {"array(float32,1)", "array(float32,1)"});
  m.AddConstant("SCALE", "float32", "3.0");
  auto compiled = client_.Compile(m, "cpu");
  ASSERT_OK_E(compiled);

  const int64_t n = 257;
  std::vector<float> xs(n);
  std::uniform_real_distribution<float> dist(-2.0f, 2.0f);
  for (auto& v : xs) v = dist(rng_);
  weft::ArrayOptions grad;
  grad.requires_grad = true;
  auto x = client_.FromData<float>(xs, {}, grad);
  auto loss = client_.Zeros(weft::dtypes::float32(), {1}, grad);
  ASSERT_OK_E(x);
  ASSERT_OK_E(loss);

  weft::LaunchSpec launch;
  launch.module_id = compiled->module_id;
  launch.kernel = "sum_of_squares";
  launch.dim = {n};
  launch.args = {x->view(), loss->view()};
  weft::Tape tape(client_);
  ASSERT_OK(tape.Begin());
  ASSERT_OK(client_.Launch(launch, {"client_test.cpp", 100}));
  ASSERT_OK(tape.End());
  ASSERT_OK(tape.Backward(*loss));
  ASSERT_OK(client_.Synchronize());

  double ref_loss = 0;
  for (float v : xs) ref_loss += 3.0 * double(v) * v;
  auto l = loss->ToVector<float>();
  ASSERT_OK_E(l);
  EXPECT_NEAR((*l)[0], ref_loss, 1e-4 * ref_loss);
  auto gx = x->Grad();
  ASSERT_OK_E(gx);
  auto g = gx->ToVector<float>();
  ASSERT_OK_E(g);
  for (int64_t i = 0; i < n; ++i) ASSERT_NEAR((*g)[i], 6.0 * xs[i], 1e-5) << i;

  // Zero clears the gradients; a second backward gives the same gradient again.
  ASSERT_OK(tape.Zero());
  g = gx->ToVector<float>();
  ASSERT_OK_E(g);
  EXPECT_EQ(*g, std::vector<float>(n, 0.0f));
  ASSERT_OK(tape.Backward(*loss));
  g = gx->ToVector<float>();
  ASSERT_OK_E(g);
  for (int64_t i = 0; i < n; ++i) ASSERT_NEAR((*g)[i], 6.0 * xs[i], 1e-5) << i;
}

TEST_F(ClientTest, CompileErrorsNameTheUsersLine) {
  weft::ModuleDef m;
  m.name = "client_test_broken";
  m.AddKernel("broken",
              "def broken(x: wp.array(dtype=float)):\n"
              "    i = wp.tid()\n"
              "    x[i] = undefined_name * 2.0\n",
              {"x"}, {"array(float32,1)"});
  m.functions.back().file = "broken_kernels.py";
  m.functions.back().first_line = 40;
  auto compiled = client_.Compile(m, "cpu");
  ASSERT_FALSE(compiled.ok());
  EXPECT_EQ(compiled.status().code(), weft::StatusCode::kInvalidArgument);
  EXPECT_NE(compiled.status().message().find("broken_kernels.py:42"), std::string::npos)
      << compiled.status().ToString();
  EXPECT_NE(compiled.status().message().find("undefined_name"), std::string::npos)
      << compiled.status().ToString();
}

// ---------------------------------------------------------------------------------------------
// TCP with a token: a remote-style client.

class TcpClientTest : public ::testing::Test {
 protected:
  void SetUp() override {
    REQUIRE_DAEMON_BINARY();
    daemon_ = TcpDaemon();
    ASSERT_NE(daemon_, nullptr) << Shared().tcp_error;
  }
  Daemon* daemon_ = nullptr;
};

TEST_F(TcpClientTest, TokenIsRequired) {
  weft::ConnectOptions o = daemon_->Options();
  o.token = "wrong-" + daemon_->token();
  auto wrong = weft::Client::Connect(o);
  ASSERT_FALSE(wrong.ok());
  EXPECT_EQ(wrong.status().code(), weft::StatusCode::kUnauthenticated) << wrong.status().ToString();
  o.token.clear();
  ::unsetenv("WEFT_TOKEN");
  auto missing = weft::Client::Connect(o);
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), weft::StatusCode::kUnauthenticated);
  // The token from the environment.
  ::setenv("WEFT_TOKEN", daemon_->token().c_str(), 1);
  auto from_env = weft::Client::Connect(o);
  ::unsetenv("WEFT_TOKEN");
  ASSERT_OK_E(from_env);
}

TEST_F(TcpClientTest, RemoteClientReadsAndWritesInChunks) {
  weft::ConnectOptions o = daemon_->Options();
  o.chunk_size = 1u << 20;
  auto c = weft::Client::Connect(o);
  ASSERT_OK_E(c);
  EXPECT_FALSE(c->local());
  EXPECT_FALSE(c->session().local);

  const size_t n = (24u << 20) / 4;   // 24 MiB of uint32: 24 chunks each way
  std::vector<uint32_t> values(n);
  std::mt19937 rng(3);
  for (auto& v : values) v = rng();
  auto a = c->FromData<uint32_t>(values, {static_cast<int64_t>(n / 1024), 1024});
  ASSERT_OK_E(a);
  EXPECT_TRUE(a->info().shm_name.empty());   // remote clients get no slab names
  EXPECT_FALSE(a->mappable());
  EXPECT_EQ(a->Map().status().code(), weft::StatusCode::kFailedPrecondition);
  auto back = a->ToVector<uint32_t>();
  ASSERT_OK_E(back);
  EXPECT_TRUE(*back == values);

  // Commands work the same remotely.
  auto half = a->Slice(0, static_cast<int64_t>(n / 2048));
  ASSERT_OK_E(half);
  uint32_t marker = 0xabcdef01u;
  ASSERT_OK(c->Fill(*half, Bytes(&marker, 4)));
  back = a->ToVector<uint32_t>();
  ASSERT_OK_E(back);
  for (size_t i = 0; i < n; ++i) ASSERT_EQ((*back)[i], i < n / 2 ? marker : values[i]) << i;

  auto devices = c->ListDevices();
  ASSERT_OK_E(devices);
  EXPECT_FALSE(devices->empty());
}

// ---------------------------------------------------------------------------------------------
// A client process killed while holding arrays.

TEST_F(ClientTest, KilledClientIsReapedWithinTenSeconds) {
  const auto before = Stats();
  int out[2];
  ASSERT_EQ(::pipe(out), 0);
  const std::string self = fs::read_symlink("/proc/self/exe");
  const std::string address = daemon_->address();
  const pid_t child = ::fork();
  if (child == 0) {
    ::dup2(out[1], 1);
    ::close(out[0]);
    ::execl(self.c_str(), self.c_str(), "--hold-arrays", address.c_str(), nullptr);
    ::_exit(127);
  }
  ::close(out[1]);
  std::string line;
  char ch;
  while (::read(out[0], &ch, 1) == 1 && ch != '\n') line += ch;
  ::close(out[0]);
  ASSERT_EQ(line, "ready");
  auto held = Stats();
  EXPECT_EQ(held.arrays, before.arrays + 3);
  EXPECT_EQ(held.sessions, before.sessions + 1);

  ::kill(child, SIGKILL);
  ::waitpid(child, nullptr, 0);
  const auto killed_at = std::chrono::steady_clock::now();
  weft::DaemonStats now = held;
  while (std::chrono::steady_clock::now() - killed_at < 10s) {
    now = Stats();
    if (now.arrays == before.arrays && now.sessions == before.sessions) break;
    std::this_thread::sleep_for(100ms);
  }
  EXPECT_EQ(now.arrays, before.arrays);
  EXPECT_EQ(now.sessions, before.sessions);
  EXPECT_EQ(now.sessions_reaped_total, before.sessions_reaped_total + 1);
  // And it keeps serving.
  auto a = client_.Full(weft::dtypes::float32(), {3}, 1.0);
  ASSERT_OK_E(a);
  auto v = a->ToVector<float>();
  ASSERT_OK_E(v);
  EXPECT_EQ(*v, std::vector<float>(3, 1.0f));
}

// A daemon that dies under a client: every call fails with an error, nothing hangs, and the
// client's destructors return.
TEST(ClientDaemonGoneTest, CallsFailInsteadOfHanging) {
  REQUIRE_DAEMON_BINARY();
  std::string error;
  auto daemon = Daemon::Start(false, &error);
  ASSERT_NE(daemon, nullptr) << error;
  auto c = daemon->Connect();
  ASSERT_OK_E(c);
  auto a = c->FromData<float>(std::vector<float>{1, 2, 3});
  ASSERT_OK_E(a);
  auto mapped = a->MapAs<float>();
  ASSERT_OK_E(mapped);
  const pid_t daemon_pid = daemon->pid();
  ::kill(daemon_pid, SIGKILL);
  daemon->Stop();   // reaps the process
  const auto start = std::chrono::steady_clock::now();
  std::vector<float> out(3);
  const weft::Status read = a->Read(out.data(), 12);
  EXPECT_FALSE(read.ok());
  EXPECT_EQ(read.code(), weft::StatusCode::kUnavailable) << read.ToString();
  EXPECT_FALSE(c->ListDevices().ok());
  EXPECT_FALSE(c->Zeros(weft::dtypes::float32(), {4}).ok());
  EXPECT_EQ((*mapped)[2], 3.0f);   // the mapping outlives the daemon
  a = weft::Expected<weft::Array>(weft::Array());
  c = weft::Expected<weft::Client>(weft::Client());
  EXPECT_LT(std::chrono::steady_clock::now() - start, 10s);
  // The killed daemon's slabs are left behind; a later daemon removes them (operations.md).
  const auto leftovers = Glob("/dev/shm/weft-" + std::to_string(daemon_pid) + "-*");
  EXPECT_FALSE(leftovers.empty());
  for (const auto& f : leftovers) fs::remove(f);
}

// Last: the daemon shuts down cleanly and leaves no shared-memory files.
TEST_F(ClientTest, ZzDaemonStopsCleanly) {
  auto a = client_.Zeros(weft::dtypes::float32(), {1 << 20});
  ASSERT_OK_E(a);
  EXPECT_FALSE(daemon_->ShmFiles().empty());
  const pid_t pid = daemon_->pid();
  client_ = weft::Client();   // close first: the daemon's shutdown is then uncontended
  const int status = daemon_->Stop();
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "status " << status;
  EXPECT_TRUE(Glob("/dev/shm/weft-" + std::to_string(pid) + "-*").empty());
  Shared().unix_daemon.reset();
  Shared().unix_error = "stopped by ZzDaemonStopsCleanly";
}

// Child mode for KilledClientIsReapedWithinTenSeconds.
int HoldArrays(const char* address) {
  weft::ConnectOptions o;
  o.address = address;
  auto c = weft::Client::Connect(o);
  if (!c.ok()) return 2;
  std::vector<weft::Array> arrays;
  for (int i = 0; i < 3; ++i) {
    auto a = c->Full(weft::dtypes::float32(), {1000 * (i + 1)}, i);
    if (!a.ok()) return 3;
    arrays.push_back(std::move(a).value());
  }
  std::printf("ready\n");
  std::fflush(stdout);
  for (;;) ::pause();
}

}  // namespace

int main(int argc, char** argv) {
  if (argc == 3 && std::string(argv[1]) == "--hold-arrays") return HoldArrays(argv[2]);
  ::testing::InitGoogleTest(&argc, argv);
  const int result = RUN_ALL_TESTS();
  Shared().unix_daemon.reset();
  Shared().tcp_daemon.reset();
  return result;
}
