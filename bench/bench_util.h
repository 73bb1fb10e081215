// Shared by the benchmarks: what machine a result was measured on.
#pragma once

#include <fstream>
#include <string>

namespace penumbra::bench {

inline std::string CpuModel() {
    std::ifstream in("/proc/cpuinfo");
    std::string line;
    while (std::getline(in, line))
        if (line.rfind("model name", 0) == 0) return line.substr(line.find(':') + 2);
    return "unknown";
}

}  // namespace penumbra::bench
