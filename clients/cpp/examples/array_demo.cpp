// array_demo: connect to weftd, create an array, fill it, read it back, print it.
// Usage: weft_array_demo [ADDRESS]   (default: $WEFT_ADDRESS, then the default socket)
#include <weft/client.h>

#include <cstdio>

int main(int argc, char** argv) {
  weft::ConnectOptions options;
  if (argc > 1) options.address = argv[1];
  auto client = weft::Client::Connect(options);
  if (!client.ok()) {
    std::fprintf(stderr, "connect: %s\n", client.status().ToString().c_str());
    return 1;
  }
  std::printf("session %s on %s (daemon %s, %s)\n", client->session().session_id.c_str(),
              client->session().address.c_str(), client->session().daemon_version.c_str(),
              client->local() ? "local: zero-copy" : "remote: chunked transfers");

  auto devices = client->ListDevices();
  if (devices.ok())
    for (const auto& d : *devices)
      std::printf("device %-8s %s, %llu MiB\n", d.name.c_str(), d.description.c_str(),
                  static_cast<unsigned long long>(d.total_memory >> 20));

  // A 2x4 float32 array: fill with 1.5, then overwrite the second row with 7.
  auto a = client->Empty(weft::dtypes::float32(), {2, 4});
  if (!a.ok()) {
    std::fprintf(stderr, "create: %s\n", a.status().ToString().c_str());
    return 1;
  }
  weft::Status s = a->Fill(1.5);
  auto row1 = a->Slice(1, 2);
  if (s.ok() && row1.ok()) {
    auto seven = weft::EncodeFillValue(a->dtype(), 7.0);
    s = client->Fill(*row1, *seven);
  }
  auto values = s.ok() ? a->ToVector<float>() : weft::Expected<std::vector<float>>(s);
  if (!values.ok()) {
    std::fprintf(stderr, "fill/read: %s\n", values.status().ToString().c_str());
    return 1;
  }
  std::printf("array %llu, shape (2, 4), float32:\n",
              static_cast<unsigned long long>(a->handle()));
  for (int r = 0; r < 2; ++r) {
    for (int c = 0; c < 4; ++c) std::printf(" %5.2f", (*values)[r * 4 + c]);
    std::printf("\n");
  }
  return 0;   // the Array frees its allocation, the Client closes the session
}
