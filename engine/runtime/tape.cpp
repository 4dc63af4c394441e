// Tape bookkeeping.
#include "engine/runtime/tape.h"

namespace weft {

void Tape::Touch(const std::shared_ptr<Allocation>& a) {
  if (!a) return;
  for (auto& w : touched)
    if (auto p = w.lock(); p && p.get() == a.get()) return;
  touched.push_back(a);
}

}  // namespace weft
