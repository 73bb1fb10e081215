// Builds the antiradiance model: refine, cluster, bin, link, and per-leaf attributes.
#include "solver/antiradiance/model.h"

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
                (settings.backOcclusion == BackOcclusion::kAuto &&
                 (scene.environment.image || scene.environment.constant != glm::vec3(0.0f)));
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
    model.environment = direct::EnvironmentBins(scene.environment, model.dirs);
    return model;
}

LocalMode ModeOfIteration(const SolverSettings& settings, int i) {
    if (settings.scheme == Scheme::kSymmetric) return kBoth;
    // Asymmetric (Eqs. 13, 14): one radiance step, then antiradiance steps with L frozen.
    return i % (1 + settings.antiradianceSteps) == 0 ? kReflect : kAntiradiance;
}

}  // namespace penumbra
