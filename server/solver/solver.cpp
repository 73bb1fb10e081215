// The shared helpers of the solver interface (the factory is in registry.cpp).
#include "solver/solver.h"

#include <cmath>
#include <cstdio>

#include "base/check.h"

namespace penumbra {

void SolverStats::SetDetail(const std::string& name, double value) {
    for (auto& [n, v] : details)
        if (n == name) return void(v = value);
    details.emplace_back(name, value);
}

void SolverStats::SetDetail(const std::string& name, const std::string& value) {
    for (auto& [n, v] : details)
        if (n == name) return void(v = value);
    details.emplace_back(name, value);
}

double SolverStats::Number(const std::string& name) const {
    for (const auto& [n, v] : details)
        if (n == name && std::holds_alternative<double>(v)) return std::get<double>(v);
    return 0.0;
}

std::string SolverStats::Text(const std::string& name) const {
    for (const auto& [n, v] : details)
        if (n == name && std::holds_alternative<std::string>(v)) return std::get<std::string>(v);
    return {};
}

DeviceChoice ParseDevice(const std::string& name) {
    if (name == "auto") return DeviceChoice::kAuto;
    if (name == "gpu") return DeviceChoice::kGpu;
    if (name == "lavapipe") return DeviceChoice::kLavapipe;
    if (name == "cpu") return DeviceChoice::kCpu;
    throw Error("unknown device '" + name + "' (use auto, gpu, lavapipe or cpu)");
}

Channel ParseChannel(const std::string& name) {
    if (name == "indirect") return Channel::kIndirect;
    if (name == "direct") return Channel::kDirect;
    if (name == "total") return Channel::kTotal;
    throw Error("unknown channel '" + name + "' (use indirect, direct or total)");
}

BackOcclusion ParseBackOcclusion(const std::string& name) {
    if (name == "auto") return BackOcclusion::kAuto;
    if (name == "on") return BackOcclusion::kOn;
    if (name == "off") return BackOcclusion::kOff;
    throw Error("unknown back occlusion '" + name + "' (use auto, on or off)");
}

const char* ChannelName(Channel channel) {
    return channel == Channel::kDirect  ? "direct"
           : channel == Channel::kTotal ? "total"
                                        : "indirect";
}

std::vector<glm::vec3> PrimitiveIrradiance(const Surfels& surfels,
                                           const std::vector<glm::vec3>& surfelIrradiance,
                                           const Scene& scene, size_t p) {
    PENUMBRA_CHECK_EQ(surfelIrradiance.size(), surfels.size());
    const Primitive& prim = scene.primitives[p];
    uint32_t first = surfels.firstSurfel[p];
    std::vector<glm::vec3> out = ToInputVertices(
        prim, std::vector<glm::vec3>(surfelIrradiance.begin() + first,
                                     surfelIrradiance.begin() + first + prim.positions.size()));
    // Antiradiance that over-cancels (behind occluders, where the bins blur) can leave
    // a slightly negative sum; irradiance cannot be negative.
    for (auto& e : out) e = glm::max(e, glm::vec3(0.0f));
    return out;
}

double RelativeChange(const std::vector<glm::vec3>& now, const std::vector<glm::vec3>& before) {
    if (now.size() != before.size()) return 1.0;
    double changed = 0.0, total = 0.0;
    for (size_t i = 0; i < now.size(); ++i)
        for (int c = 0; c < 3; ++c) {
            total += std::abs(now[i][c]);
            changed += std::abs(now[i][c] - before[i][c]);
        }
    return total > 0.0 ? changed / total : 0.0;
}

float ElementSize(const Scene& scene, const SolverSettings& settings) {
    const float fraction = settings.behindGather ? kGatherElementFraction : kDefaultElementFraction;
    const float h =
        settings.elementSize > 0.0f ? settings.elementSize : scene.Diameter() * fraction;
    if (!(h > 0.0f) || !std::isfinite(h))
        throw Error("element size must be a positive number of metres");
    return h;
}

std::string RefinementMismatch(const Scene& scene, int lights, const Surfels& surfels,
                               float elementSize, Surfels& now) {
    if (scene.lights.size() != static_cast<size_t>(lights))
        return "the number of punctual lights changed";
    if (scene.primitives.size() != surfels.firstSurfel.size())
        return "the scene has other primitives than the solver was built for";
    now = RefineScene(scene, elementSize);
    if (now.size() != surfels.size() || now.refinedTriangles != surfels.refinedTriangles)
        return "the moved surfaces refine into other elements";
    return {};
}

Convergence IterateUntilConverged(Solver& solver, double tolerance, int maxIterations,
                                  const ProgressFn& progress) {
    Convergence c;
    std::vector<glm::vec3> last = solver.SurfelIrradiance(Channel::kTotal);
    // Two quiet iterations in a row: a solver may take an iteration to pass light on (the
    // antiradiance solver reflects the punctual lights' direct light into its exitant tables
    // in the local pass after its first gather, so a scene lit only by punctual lights does
    // not change in the first iteration at all).
    int quiet = 0;
    while (c.iterations < maxIterations) {
        solver.Iterate(1);
        const SolverStats stats = solver.Stats();
        if (!stats.divergence.empty()) break;
        ++c.iterations;
        std::vector<glm::vec3> now = solver.SurfelIrradiance(Channel::kTotal);
        c.change = RelativeChange(now, last);
        last = std::move(now);
        if (progress) {
            char stage[64];
            std::snprintf(stage, sizeof stage, "iterating, change %.2g", c.change);
            progress(stage, static_cast<double>(c.iterations) / maxIterations);
        }
        // Work an edit left (Stats::catchingUp) is not a quiet iteration however small.
        quiet = c.change < tolerance && stats.catchingUp.empty() ? quiet + 1 : 0;
        if (quiet >= 2) {
            c.converged = true;
            break;
        }
    }
    return c;
}

}  // namespace penumbra
