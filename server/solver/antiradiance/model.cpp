// Builds the antiradiance model: refine, cluster, bin, link, and per-leaf attributes.
#include "solver/antiradiance/model.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <numbers>

#include "base/check.h"
#include "direct/environment_light.h"

namespace penumbra {

AntiradianceModel BuildAntiradianceModel(const Scene& scene, const SolverSettings& settings,
                                         const ProgressFn& progress) {
    AntiradianceModel model;
    model.dirs = Directions(settings.bins);
    float h = settings.elementSize > 0.0f ? settings.elementSize
                                          : scene.Diameter() * kDefaultElementFraction;
    if (!(h > 0.0f) || !std::isfinite(h))
        throw Error("element size must be a positive number of metres");
    model.elementSize = h;
    if (progress) progress("refining", 0.0);
    model.surfels = RefineScene(scene, h);
    // Surfaces that do not close a solid occlude from both sides when asked (solver.h).
    bool back = settings.backOcclusion == BackOcclusion::kOn ||
                (settings.backOcclusion == BackOcclusion::kAuto && scene.environment.Present());
    if (back) {
        std::vector<bool> closed = ClosedNodes(scene);
        Surfels& s = model.surfels;
        s.twoSided.assign(s.size(), 0);
        for (size_t p = 0; p < scene.primitives.size(); ++p) {
            size_t end = p + 1 < scene.primitives.size() ? s.firstSurfel[p + 1] : s.size();
            int node = scene.primitives[p].nodeIndex;
            bool open = node < 0 || !closed[node];
            for (size_t i = s.firstSurfel[p]; i < end; ++i) s.twoSided[i] = open;
        }
    }
    if (progress) progress("clustering", 0.0);
    model.hierarchy = BuildHierarchy(model.surfels);

    LinkSettings ls;
    ls.oracle = settings.oracle;
    ls.receiverOracle = settings.receiverOracle;
    ls.mode = settings.paperOracle ? LinkOracle::kPaper : LinkOracle::kConservative;
    ls.threads = settings.threads;
    LeafNorms norms = ComputeLeafNorms(model.hierarchy, model.dirs);
    NearField near = BuildNearField(model.surfels);
    model.links = BuildLinks(model.hierarchy, model.dirs, norms, near, ls, [&](double f) {
        if (progress) progress("linking", f);
    });

    const auto& nodes = model.hierarchy.nodes;
    model.leftChild.assign(nodes.size(), kNoParent);
    model.rightChild.assign(nodes.size(), kNoParent);
    for (uint32_t i = 0; i < nodes.size(); ++i) {
        if (nodes[i].IsLeaf()) continue;
        model.leftChild[i] = i + 1;
        model.rightChild[i] = nodes[i + 1].end;
    }

    model.leaves.reserve(model.hierarchy.leaves.size());
    for (uint32_t node : model.hierarchy.leaves) {
        const HierarchyNode& n = nodes[node];
        uint32_t s = n.surfel;
        const Material& mat = scene.materials[model.surfels.materials[s]];
        LeafAttributes leaf{};
        leaf.normal = model.surfels.normals[s];
        leaf.area = model.surfels.areas[s];
        leaf.albedo = mat.albedo;
        leaf.emission = mat.emission;
        leaf.cosNormIn = norms.in[node];
        leaf.cosNormOut = norms.out[node];
        leaf.node = node;
        leaf.parent = n.parent;
        leaf.surfel = s;
        leaf.flags =
            !model.surfels.twoSided.empty() && model.surfels.twoSided[s] ? kLeafTwoSided : 0;
        model.leaves.push_back(leaf);
    }
    model.leafDirect.assign(model.leaves.size(), glm::vec4(0.0f));
    BuildGlossy(model, scene);
    model.environment = direct::EnvironmentBins(scene.environment, model.dirs);
    return model;
}

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
        // ω_l travels towards the surface; its mirror image ω_l − 2⟨n|ω_l⟩n leaves it.
        for (int l = 0; l < bins; ++l) {
            glm::vec3 w = model.dirs.Direction(l);
            model.mirror.push_back(
                model.dirs.Lookup(w - 2.0f * glm::dot(leaf.normal, w) * leaf.normal));
        }
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

LocalMode ModeOfIteration(const SolverSettings& settings, int i) {
    if (settings.scheme == Scheme::kSymmetric) return kBoth;
    // Asymmetric (Eqs. 13, 14): one radiance step, then antiradiance steps with L frozen.
    return i % (1 + settings.antiradianceSteps) == 0 ? kReflect : kAntiradiance;
}

}  // namespace penumbra
