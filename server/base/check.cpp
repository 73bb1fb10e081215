// Failure path of PENUMBRA_CHECK: prints where and what, then aborts.
#include "base/check.h"

#include <cstdio>
#include <cstdlib>

namespace penumbra {

void CheckFailed(const char* file, int line, const std::string& what) {
    std::fprintf(stderr, "CHECK failed at %s:%d: %s\n", file, line, what.c_str());
    std::fflush(stderr);
    std::abort();
}

}  // namespace penumbra
