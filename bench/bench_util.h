// Shared by the benchmarks: what machine a result was measured on.
#pragma once

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <vector>

namespace penumbra::bench {

inline std::string CpuModel() {
    std::ifstream in("/proc/cpuinfo");
    std::string line;
    while (std::getline(in, line))
        if (line.rfind("model name", 0) == 0) return line.substr(line.find(':') + 2);
    return "unknown";
}

inline double Median(std::vector<double> v) {
    if (v.empty()) return 0.0;
    std::sort(v.begin(), v.end());
    size_t n = v.size();
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

// Writes `report` as `folder/name` (pretty JSON) and says so; throws on failure.
inline void WriteReport(const nlohmann::json& report, const std::string& folder,
                        const std::string& name) {
    std::filesystem::create_directories(folder);
    std::string path = folder + "/" + name;
    std::ofstream file(path);
    if (!file) throw std::runtime_error(path + ": cannot write");
    file << report.dump(2) << "\n";
    std::printf("wrote %s\n", path.c_str());
}

}  // namespace penumbra::bench
