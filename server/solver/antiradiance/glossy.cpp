// Glossy lobes on the bins, mirror bins and the lights' direct light through the lobes.
#include "solver/antiradiance/glossy.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

#include "base/check.h"
#include "solver/antiradiance/model.h"

namespace penumbra {

namespace {

// The discretised lobe of exponent n (GlossyLobe): rows of cosⁿ∠(ω_b, ω_j) above the cutoff,
// padded to one width, normalised by the largest cosine-weighted row sum.
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

}  // namespace

void FillMirror(AntiradianceModel& model, uint32_t g) {
    const int bins = model.Bins();
    const glm::vec3 n = model.leaves[model.glossyLeaves[g]].normal;
    uint32_t* row = model.mirror.data() + size_t(g) * bins;
    // ω_l travels towards the surface; its mirror image ω_l − 2⟨n|ω_l⟩n leaves it.
    for (int l = 0; l < bins; ++l) {
        glm::vec3 w = model.dirs.Direction(l);
        row[l] = model.dirs.Lookup(w - 2.0f * glm::dot(n, w) * n);
    }
}

void BuildGlossy(AntiradianceModel& model, const Scene& scene) {
    model.glossy.clear();
    model.glossyLeaves.clear();
    model.mirror.clear();
    model.lobes.clear();
    model.lobeWeights.clear();
    const int bins = model.Bins();
    const float maxExponent = MaxLobeExponent(bins);
    std::vector<float> exponents;  // of model.lobes, to share them between materials
    for (uint32_t i = 0; i < model.leaves.size(); ++i) {
        LeafAttributes& leaf = model.leaves[i];
        leaf.flags &= kLeafTwoSided;
        const Material& mat = scene.materials[model.surfels.materials[leaf.surfel]];
        if (!mat.Glossy()) continue;
        const float n = std::min(mat.phongExponent, maxExponent);
        auto it = std::find(exponents.begin(), exponents.end(), n);
        uint32_t lobe = static_cast<uint32_t>(it - exponents.begin());
        if (it == exponents.end()) {
            exponents.push_back(n);
            model.lobes.push_back(MakeLobe(model.dirs, n, model.lobeWeights));
        }
        const uint32_t g = static_cast<uint32_t>(model.glossy.size());
        leaf.flags |= kLeafGlossy | (g << kGlossyShift);
        model.glossy.push_back({mat.specular, lobe});
        model.glossyLeaves.push_back(i);
        model.mirror.resize(model.mirror.size() + bins);
        FillMirror(model, g);
    }
    model.glossyDirect.assign(model.glossy.size() * bins, glm::vec4(0.0f));
}

bool GlossyMatches(const AntiradianceModel& model, const Scene& scene) {
    const float maxExponent = MaxLobeExponent(model.Bins());
    for (const LeafAttributes& leaf : model.leaves) {
        const Material& mat = scene.materials[model.surfels.materials[leaf.surfel]];
        if (mat.Glossy() != ((leaf.flags & kLeafGlossy) != 0)) return false;
        if (!mat.Glossy()) continue;
        const GlossyLeaf& g = model.glossy[leaf.flags >> kGlossyShift];
        if (g.specular != mat.specular ||
            model.lobes[g.lobe].exponent != std::min(mat.phongExponent, maxExponent))
            return false;
    }
    return true;
}

void GlossyDirect(AntiradianceModel& model, const std::vector<PunctualLight>& lights,
                  const std::vector<float>& perLight) {
    const int bins = model.Bins();
    const size_t leaves = model.leaves.size();
    PENUMBRA_CHECK_EQ(perLight.size(), lights.size() * leaves * 4);
    tbb::parallel_for(size_t(0), model.glossy.size(), [&](size_t g) {
        const LeafAttributes& leaf = model.leaves[model.glossyLeaves[g]];
        const float n = model.lobes[model.glossy[g].lobe].exponent;
        const glm::vec3 p = model.surfels.positions[leaf.surfel];
        glm::vec4* row = model.glossyDirect.data() + g * bins;
        std::fill(row, row + bins, glm::vec4(0.0f));
        float w[Directions::kMaxBins];
        for (size_t k = 0; k < lights.size(); ++k) {
            const float* e = perLight.data() + (k * leaves + model.glossyLeaves[g]) * 4;
            if (e[0] <= 0.0f && e[1] <= 0.0f && e[2] <= 0.0f) continue;
            const PunctualLight& light = lights[k];
            glm::vec3 toLight = light.type == LightType::kDirectional
                                    ? -light.direction
                                    : glm::normalize(light.position - p);
            glm::vec3 r = 2.0f * glm::dot(leaf.normal, toLight) * leaf.normal - toLight;
            double sum = 0.0;
            for (int j = 0; j < bins; ++j) {
                float c = glm::dot(r, model.dirs.Direction(j));
                w[j] = c > 0.0f ? std::pow(c, n) : 0.0f;
                sum += double(w[j]) * std::max(c, 0.0f);
            }
            if (!(sum > 0.0)) continue;
            const glm::vec4 scaled =
                glm::vec4(e[0], e[1], e[2], 0.0f) / float(sum * model.dirs.BinSolidAngle());
            for (int j = 0; j < bins; ++j) row[j] += w[j] * scaled;
        }
    });
}

}  // namespace penumbra
