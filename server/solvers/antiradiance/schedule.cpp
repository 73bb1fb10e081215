// The antiradiance pass schedule and the divergence bound (schedule.h).
#include "solvers/antiradiance/schedule.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <sstream>

#include "base/numeric.h"

namespace penumbra {

LocalMode PassSchedule::Next() const {
    if (settings_.scheme != Scheme::kAdaptive) return ModeOfIteration(settings_, passes);
    return antiradiance_ ? kAntiradiance : kReflect;
}

bool PassSchedule::Finished(const std::vector<float>& irradiance) {
    const bool wasAntiradiance = NeedsIrradiance() && antiradiance_;
    const LocalMode mode = Next();
    ++passes;
    if (mode & kReflect) ++bounces;
    // Symmetric: every pass is a bounce. Asymmetric: a bounce ends with its last
    // antiradiance step, where the next pass is a radiance step.
    if (!NeedsIrradiance()) return ModeOfIteration(settings_, passes) & kReflect;
    if (!wasAntiradiance) {
        // A radiance step: its irradiance is the baseline of the first antiradiance step.
        last_ = irradiance;
        antiradiance_ = true;
        steps = 0;
        return false;
    }
    ++steps;
    // How far the last antiradiance step moved the leaves' irradiance, against the largest.
    float moved = 0.0f, largest = 0.0f;
    const bool comparable = last_.size() == irradiance.size();
    for (size_t i = 0; i < irradiance.size(); ++i) {
        largest = std::max(largest, std::abs(irradiance[i]));
        moved = std::max(moved, std::abs(irradiance[i] - (comparable ? last_[i] : 0.0f)));
    }
    last_ = irradiance;
    const bool converged = moved <= settings_.antiradianceTolerance * largest;
    const bool capped = steps >= std::max(1, settings_.maxAntiradianceSteps);
    if (converged || capped) {
        if (!converged) ++capHits;
        lastSteps = steps;
        antiradiance_ = false;
        return true;
    }
    return false;
}

float IrradianceBound(const AntiradianceModel& m, float* reflectanceOut) {
    auto maxOf = [](const auto& v) { return std::max({v.x, v.y, v.z}); };
    float emission = 0.0f, diffuse = 0.0f, glossy = 0.0f, direct = 0.0f, lobeDirect = 0.0f;
    for (size_t i = 0; i < m.leaves.size(); ++i) {
        const LeafAttributes& leaf = m.leaves[i];
        emission = std::max(emission, maxOf(leaf.emission));
        diffuse = std::max(diffuse, maxOf(leaf.albedo));
        direct = std::max(direct, maxOf(m.leafDirect[i]));
    }
    const int bins = m.Bins();
    for (size_t g = 0; g < m.glossy.size(); ++g) {
        const float f0 = maxOf(m.glossy[g].specular);
        glossy = std::max(glossy, f0);
        for (int j = 0; j < bins && !m.glossyDirect.empty(); ++j)
            lobeDirect = std::max(lobeDirect, f0 * maxOf(m.glossyDirect[g * bins + j]));
    }
    float sky = 0.0f;
    for (const glm::vec3& e : m.environment) sky = std::max(sky, maxOf(e));
    const float reflectance = diffuse + glossy;
    if (reflectanceOut) *reflectanceOut = reflectance;
    if (reflectance >= 1.0f) return std::numeric_limits<float>::infinity();
    const float source = emission + diffuse * direct / kPi + lobeDirect;
    const float radiance = std::max(source / (1.0f - reflectance), source + reflectance * sky);
    return kPi * std::max(radiance, sky);
}

std::string Divergence(const std::vector<float>& irradiance, float bound) {
    const float limit = kDivergenceMargin * bound;
    for (size_t i = 0; i < irradiance.size(); ++i) {
        const float e = irradiance[i];
        if (std::isfinite(e) && std::abs(e) <= limit) continue;
        std::ostringstream why;
        why << "element " << i / 3 << " receives " << e << " lux";
        if (std::isfinite(e))
            why << ", past " << kDivergenceMargin << " × the bound of " << bound
                << " lux that its emitters, lights, sky and albedos allow";
        return why.str();
    }
    return {};
}

}  // namespace penumbra
