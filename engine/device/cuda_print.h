// Kernel print output of a GPU: the text of the binary print records that generated CUDA code
// appends to a launch's print buffer (engine/native/print.h, print_record). The buffer is
// written by kernels and may hold anything (a kernel with bounds checks off can overwrite it):
// every length is checked, every piece's format is re-checked against its argument kinds
// (engine/native/printf_check.h) and formatted one conversion at a time with the host's
// snprintf, and a malformed record ends the decoding with a marker line.
#pragma once

#include <cstdint>
#include <string>

namespace weft {

// `data` holds the first min(used, capacity) bytes of the buffer; `used` is the buffer's
// reservation counter (more than `capacity` when records were left out). Returns the text,
// each record's line at most 1023 characters (as on the CPU), followed by
// "[weft: kernel print output truncated]" when output was dropped.
std::string FormatPrintRecords(const char* data, uint64_t used, uint64_t capacity);

}  // namespace weft
