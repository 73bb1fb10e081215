// Shared by the benchmarks that talk to a server through the client library: times,
// percentiles and a streamed frame as `compare` reads it.
#pragma once

#include <algorithm>
#include <chrono>
#include <vector>

#include "client/client.h"
#include "output/irradiance_writer.h"

namespace penumbra::bench {

using Clock = std::chrono::steady_clock;

inline double Ms(Clock::duration d) { return std::chrono::duration<double, std::milli>(d).count(); }

// The value below which a fraction `p` of `v` lies (nearest rank); 0 for none.
inline double Percentile(std::vector<double> v, double p) {
    if (v.empty()) return 0.0;
    std::sort(v.begin(), v.end());
    size_t i = std::min(v.size() - 1, static_cast<size_t>(p * (v.size() - 1) + 0.5));
    return v[i];
}

// A streamed frame of the indirect channel as `compare` reads it.
inline IrradianceFile FrameToFile(const client::Frame& f) {
    IrradianceFile file;
    file.solver = "antiradiance";
    file.channel = "indirect";
    for (const auto& p : f.primitives) {
        IrradianceRecord r{p.node, p.mesh, p.primitive, {}};
        for (size_t i = 0; i + 2 < p.rgb.size(); i += 3)
            r.irradiance.emplace_back(p.rgb[i], p.rgb[i + 1], p.rgb[i + 2]);
        file.primitives.push_back(std::move(r));
    }
    return file;
}

}  // namespace penumbra::bench
