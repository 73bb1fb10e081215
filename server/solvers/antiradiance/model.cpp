// Builds the antiradiance model: refine, cluster, bin, link, and per-leaf attributes.
#include "solvers/antiradiance/model.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>

#include "base/check.h"
#include "direct/environment_light.h"

namespace penumbra {

AntiradianceModel BuildAntiradianceModel(const Scene& scene, const SolverSettings& settings,
                                         const AntiradianceSettings& own,
                                         const ProgressFn& progress) {
    AntiradianceModel model;
    model.dirs = Directions(own.bins);
    const float h = ElementSize(scene, settings);
    model.elementSize = h;
    if (progress) progress("refining", 0.0);
    model.surfels = RefineScene(scene, h);
    // Surfaces that do not close a solid occlude from both sides when asked (scene/surfels.h).
    if (BackOcclusionOn(settings.backOcclusion, scene.environment))
        MarkTwoSided(scene, model.surfels);
    LinkSettings ls;
    if (settings.prepareMoves) {
        model.motion = AssignMotionGroups(scene, model.surfels);
        ls.motion = model.motion.Bounds();
    }
    if (progress) progress("clustering", 0.0);
    model.hierarchy = BuildHierarchy(model.surfels, model.motion.BuiltFrames());

    ls.oracle = own.oracle;
    ls.receiverOracle = own.receiverOracle;
    ls.mode = own.linkOracle;
    ls.threads = settings.threads;
    ls.dynamicBudget = own.motionLinkBudget;
    model.norms = ComputeLeafNorms(model.hierarchy, model.dirs);
    const LeafNorms& norms = model.norms;
    model.near = BuildNearField(model.surfels);
    model.links = BuildLinks(model.hierarchy, model.dirs, norms, model.near, ls, [&](double f) {
        if (progress) progress("linking", f);
    });
    if (model.links.overBudget) {
        // Motion links cost links: the ones touching the groups outnumbered the others by more
        // than the budget (BuildLinks stopped there), so build the usual links instead (moves
        // will rebuild).
        SolverSettings plain = settings;
        plain.prepareMoves = false;
        AntiradianceModel fallback = BuildAntiradianceModel(scene, plain, own, progress);
        const double still = double(std::max<size_t>(1, model.links.staticLinks));
        char why[200];
        std::snprintf(why, sizeof why,
                      "more than %.0f links would touch the dynamic nodes, over %.2f× the other "
                      "%.0f (budget %.2f×)",
                      double(model.links.dynamicSeen), double(model.links.dynamicSeen) / still,
                      still, own.motionLinkBudget);
        fallback.motionDeclined = why;
        return fallback;
    }
    if (!model.motion.empty()) {
        for (const HierarchyNode& n : model.hierarchy.nodes) {
            model.restCenters.push_back(n.center);
            model.restNodeNormals.push_back(n.normal);
        }
    }

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
        leaf.albedo = model.surfels.Albedo(mat, s);
        leaf.emission = model.surfels.Emission(mat, s);
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

AntiradianceModel BuildAntiradianceModel(const Scene& scene, const SolverSettings& settings,
                                         const ProgressFn& progress) {
    return BuildAntiradianceModel(scene, settings, ReadAntiradianceSettings(settings), progress);
}

LocalMode ModeOfIteration(const AntiradianceSettings& settings, int i) {
    if (settings.scheme == Scheme::kSymmetric) return kBoth;
    // Asymmetric (Eqs. 13, 14): one radiance step, then antiradiance steps with L frozen.
    return i % (1 + settings.antiradianceSteps) == 0 ? kReflect : kAntiradiance;
}

}  // namespace penumbra
