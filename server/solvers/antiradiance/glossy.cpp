// Glossy lobes on the bins, mirror bins and the lights' direct light through the lobes.
#include "solvers/antiradiance/glossy.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

#include "base/check.h"
#include "solvers/antiradiance/model.h"

namespace penumbra {

void FillMirror(AntiradianceModel& model, uint32_t g) {
    const int bins = model.Bins();
    const glm::vec3 n = model.leaves[model.glossyLeaves[g]].normal;
    // ω_l travels towards the surface; its mirror image ω_l − 2⟨n|ω_l⟩n leaves it.
    MirrorBins(model.dirs, n, model.mirror.data() + size_t(g) * bins);
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
        for (size_t k = 0; k < lights.size(); ++k) {
            const float* e = perLight.data() + (k * leaves + model.glossyLeaves[g]) * 4;
            AddLightLobe(model.dirs, n, p, leaf.normal, lights[k], glm::vec3(e[0], e[1], e[2]),
                         row);
        }
    });
}

}  // namespace penumbra
