// weftd entry point: parses the command line and runs the daemon (filled in step by step).
#include <cstdio>

int main() {
  std::puts("weftd " WEFT_VERSION);
  return 0;
}
