#pragma once
#include <cmath>
#include <string>

#include "twin/core/error.hpp"

/// TWIN_DEMAND(cond): a broken invariant throws InternalError (never aborts:
/// the twin may run inside another program's process as an FMU).
#define TWIN_DEMAND(cond)                                                        \
  do {                                                                           \
    if (!(cond))                                                                 \
      throw ::twin::InternalError(std::string("internal error: ") + #cond +      \
                                  " failed at " + __FILE__ + ":" +               \
                                  std::to_string(__LINE__));                     \
  } while (false)

namespace twin {
inline bool all_finite(double v) { return std::isfinite(v); }
template <class... T>
bool all_finite(double v, T... rest) {
  return std::isfinite(v) && all_finite(rest...);
}
}  // namespace twin
