// ArrayInfo helpers.
#include "weft/client/types.h"

namespace weft {
inline namespace client_v1 {

std::int64_t ArrayInfo::size() const {
  std::int64_t n = 1;
  for (auto d : shape) n *= d;
  return n;
}

}  // namespace client_v1
}  // namespace weft
