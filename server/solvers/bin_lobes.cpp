// Glossy lobes on direction bins (bin_lobes.h).
#include "solvers/bin_lobes.h"

#include <algorithm>
#include <cmath>

namespace penumbra {

GlossyLobe MakeLobe(const Directions& dirs, float n, std::vector<BinWeight>& weights) {
    const int bins = dirs.Count();
    const float minCos = std::pow(kLobeCutoff, 1.0f / n);
    std::vector<std::vector<BinWeight>> rows(bins);
    double maxSum = 0.0;
    size_t width = 1;
    for (int b = 0; b < bins; ++b) {
        double sum = 0.0;
        for (int j = 0; j < bins; ++j) {
            float c = glm::dot(dirs.Direction(b), dirs.Direction(j));
            if (c < minCos) continue;
            float w = std::pow(c, n);
            rows[b].push_back({static_cast<uint32_t>(j), w});
            sum += double(w) * c;
        }
        maxSum = std::max(maxSum, sum * dirs.BinSolidAngle());
        width = std::max(width, rows[b].size());
    }
    GlossyLobe lobe{static_cast<uint32_t>(weights.size()), static_cast<uint32_t>(width), n,
                    static_cast<float>(1.0 / maxSum)};
    for (int b = 0; b < bins; ++b) {
        for (const BinWeight& w : rows[b]) weights.push_back({w.bin, w.weight * lobe.norm});
        // Padding points at the row's own bin with weight 0.
        weights.resize(weights.size() + width - rows[b].size(), {static_cast<uint32_t>(b), 0.0f});
    }
    return lobe;
}

void MirrorBins(const Directions& dirs, const glm::vec3& n, uint32_t* row) {
    for (int l = 0; l < dirs.Count(); ++l) {
        const glm::vec3 w = dirs.Direction(l);
        row[l] = dirs.Lookup(w - 2.0f * glm::dot(n, w) * n);
    }
}

void AddLightLobe(const Directions& dirs, float n, const glm::vec3& p, const glm::vec3& normal,
                  const PunctualLight& light, const glm::vec3& e, glm::vec4* row) {
    if (e.x <= 0.0f && e.y <= 0.0f && e.z <= 0.0f) return;
    const glm::vec3 toLight = light.type == LightType::kDirectional
                                  ? -light.direction
                                  : glm::normalize(light.position - p);
    const int bins = dirs.Count();
    const glm::vec3 r = 2.0f * glm::dot(normal, toLight) * normal - toLight;
    float w[Directions::kMaxBins];
    double sum = 0.0;
    for (int j = 0; j < bins; ++j) {
        const float c = glm::dot(r, dirs.Direction(j));
        w[j] = c > 0.0f ? std::pow(c, n) : 0.0f;
        sum += double(w[j]) * std::max(c, 0.0f);
    }
    if (!(sum > 0.0)) return;
    const glm::vec4 scaled = glm::vec4(e, 0.0f) / float(sum * dirs.BinSolidAngle());
    for (int j = 0; j < bins; ++j) row[j] += w[j] * scaled;
}

}  // namespace penumbra
