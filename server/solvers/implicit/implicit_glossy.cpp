// The implicit-visibility solver's glossy leaves (implicit_solver.h). Dong et al. 2007 (Sec. 5)
// reflect only the direct light glossily and treat every bounce as diffuse; here a glossy
// leaf reflects everything its links bring through its Phong lobe on the bins, as the
// antiradiance solver's Eq. 18 does: what arrives from bin ω_l (its closest sender's radiance
// L, weighted cos θ · Ω) is collected where its mirror image leaves, and the light leaving
// along ω_j is F0 · Σ_m w(ω_j, ω_m) · arrived(ω_m), w the lobe normalised so that reflection
// returns at most F0 (solvers/bin_lobes.h). The punctual lights' direct light goes through the
// lobe at its exact mirror direction. Senders read a glossy leaf's light along the bin towards
// the receiver, beside its diffuse radiance.
#include <tbb/parallel_for.h>

#include <algorithm>

#include "base/check.h"
#include "solvers/implicit/implicit_solver.h"

namespace penumbra {

void ImplicitSolver::ReadGlossy() {
    const size_t leaves = hierarchy_.leaves.size();
    const int bins = dirs_.Count();
    const float sharpest = MaxLobeExponent(bins);
    std::vector<uint32_t> before;  // the glossy leaves so far, whose arrived rows are kept
    for (const GlossySlot& g : glossy_) before.push_back(g.leaf);
    glossyOf_.assign(leaves, kNotGlossy);
    glossy_.clear();
    lobes_.clear();
    lobeWeights_.clear();
    std::vector<float> exponents;  // of lobes_, shared between materials
    for (size_t i = 0; i < leaves; ++i) {
        const Material& m = materials_[surfels_.materials[light_.surfel[i]]];
        if (!m.Glossy()) continue;
        const float n = std::min(m.phongExponent, sharpest);
        const auto it = std::find(exponents.begin(), exponents.end(), n);
        const uint32_t lobe = static_cast<uint32_t>(it - exponents.begin());
        if (it == exponents.end()) {
            exponents.push_back(n);
            lobes_.push_back(MakeLobe(dirs_, n, lobeWeights_));
        }
        glossyOf_[i] = static_cast<uint32_t>(glossy_.size());
        glossy_.push_back({static_cast<uint32_t>(i), m.specular, lobe});
    }
    glossyLeaving_.assign(glossy_.size() * bins, glm::vec3(0.0f));
    // What arrived stays over an edit of F0 or the lobe (the next bounce gathers it anew);
    // other slots start dark.
    bool same = before.size() == glossy_.size();
    for (size_t g = 0; same && g < glossy_.size(); ++g) same = before[g] == glossy_[g].leaf;
    if (!same) glossyArrived_.assign(glossy_.size() * bins, glm::vec3(0.0f));
    glossyNode_.assign(hierarchy_.size(), 0);
    for (const GlossySlot& g : glossy_) glossyNode_[hierarchy_.leaves[g.leaf]] = 1;
    for (size_t n = hierarchy_.size(); n-- > 0;)  // preorder: children after their parent
        if (!hierarchy_.nodes[n].IsLeaf())
            glossyNode_[n] = glossyNode_[n + 1] | glossyNode_[hierarchy_.nodes[n + 1].end];
    MirrorRows();
    GlossyDirectRows();
}

void ImplicitSolver::MirrorRows() {
    const int bins = dirs_.Count();
    mirror_.resize(glossy_.size() * bins);
    tbb::parallel_for(size_t(0), glossy_.size(), [&](size_t g) {
        const glm::vec3 n = hierarchy_.nodes[hierarchy_.leaves[glossy_[g].leaf]].normal;
        // A link's bin points towards its sender: the light travels along the opposite bin,
        // and leaves along that one's mirror image.
        uint32_t image[Directions::kMaxBins];
        MirrorBins(dirs_, n, image);
        uint32_t* row = mirror_.data() + g * bins;
        for (int b = 0; b < bins; ++b) row[b] = image[dirs_.Opposite(b)];
    });
}

void ImplicitSolver::GlossyDirectRows() {
    const int bins = dirs_.Count();
    glossyDirect_.assign(glossy_.size() * bins, glm::vec4(0.0f));
    const std::vector<float> perLight =
        directStage_ ? directStage_->PerLight() : std::vector<float>();
    const size_t leaves = hierarchy_.leaves.size();
    PENUMBRA_CHECK_EQ(perLight.size(), directStage_ ? lightPlaces_.size() * leaves * 4 : 0);
    tbb::parallel_for(size_t(0), glossy_.size(), [&](size_t g) {
        const uint32_t i = glossy_[g].leaf;
        const HierarchyNode& leaf = hierarchy_.nodes[hierarchy_.leaves[i]];
        const float n = lobes_[glossy_[g].lobe].exponent;
        const glm::vec3 p = surfels_.positions[leaf.surfel];
        for (size_t k = 0; directStage_ && k < lightPlaces_.size(); ++k) {
            const float* e = perLight.data() + (k * leaves + i) * 4;
            AddLightLobe(dirs_, n, p, leaf.normal, lightPlaces_[k], glm::vec3(e[0], e[1], e[2]),
                         glossyDirect_.data() + g * bins);
        }
        // The light leaving again, with these rows, from what arrived before.
        ReflectGlossy(uint32_t(g));
    });
}

void ImplicitSolver::ReflectGlossy(uint32_t g) {
    const int bins = dirs_.Count();
    const GlossySlot& slot = glossy_[g];
    const GlossyLobe& lobe = lobes_[slot.lobe];
    const glm::vec3 n = hierarchy_.nodes[hierarchy_.leaves[slot.leaf]].normal;
    const glm::vec4* direct = glossyDirect_.data() + size_t(g) * bins;
    const glm::vec3* arrived = glossyArrived_.data() + size_t(g) * bins;
    glm::vec3* leaving = glossyLeaving_.data() + size_t(g) * bins;
    for (int j = 0; j < bins; ++j) {
        if (glm::dot(n, dirs_.Direction(j)) <= 0.0f) {
            leaving[j] = glm::vec3(0.0f);
            continue;
        }
        const BinWeight* row = lobeWeights_.data() + lobe.start + size_t(j) * lobe.width;
        glm::vec3 sum(0.0f);
        for (uint32_t k = 0; k < lobe.width; ++k) sum += row[k].weight * arrived[row[k].bin];
        leaving[j] = slot.specular * (sum + glm::vec3(direct[j]));
    }
}

}  // namespace penumbra
