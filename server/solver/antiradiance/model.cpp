// Builds the antiradiance model: refine, cluster, bin, link, and per-leaf attributes.
#include "solver/antiradiance/model.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>

#include "base/check.h"
#include "direct/environment_light.h"

namespace penumbra {

namespace {

// Sec. 3.3: one motion group per dynamic scene node with surfaces, bounded by the node's
// motion bounds or else the scene's box (the whole scene is where it may go).
void AssignMotionGroups(AntiradianceModel& model, const Scene& scene,
                        std::vector<MotionBounds>& bounds) {
    Surfels& s = model.surfels;
    model.primitiveGroup.assign(scene.primitives.size(), 0);
    std::vector<uint32_t> groupOfNode(scene.nodes.size(), 0);
    for (size_t p = 0; p < scene.primitives.size(); ++p) {
        int node = scene.primitives[p].nodeIndex;
        if (node < 0 || !scene.nodes[node].dynamic) continue;
        if (!groupOfNode[node]) {
            const SceneNode& n = scene.nodes[node];
            MotionGroup g;
            g.node = node;
            g.bounds = n.hasMotionBounds ? MotionBounds{n.boundsMin, n.boundsMax}
                                         : MotionBounds{scene.BoundsMin(), scene.BoundsMax()};
            g.built = g.placed = n.world;
            model.motion.push_back(g);
            bounds.push_back(g.bounds);
            groupOfNode[node] = static_cast<uint32_t>(model.motion.size());
        }
        model.primitiveGroup[p] = groupOfNode[node];
    }
    if (model.motion.empty()) return;
    s.groups.assign(s.size(), 0);
    for (size_t p = 0; p < scene.primitives.size(); ++p) {
        size_t end = p + 1 < scene.primitives.size() ? s.firstSurfel[p + 1] : s.size();
        for (size_t i = s.firstSurfel[p]; i < end; ++i) s.groups[i] = model.primitiveGroup[p];
    }
}

}  // namespace

AntiradianceModel BuildAntiradianceModel(const Scene& scene, const SolverSettings& settings,
                                         const AntiradianceSettings& own,
                                         const ProgressFn& progress) {
    AntiradianceModel model;
    model.dirs = Directions(own.bins);
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
    LinkSettings ls;
    if (settings.motionLinks) AssignMotionGroups(model, scene, ls.motion);
    if (progress) progress("clustering", 0.0);
    std::vector<glm::mat4> frames;
    for (const MotionGroup& g : model.motion) frames.push_back(g.built);
    model.hierarchy = BuildHierarchy(model.surfels, frames);

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
        plain.motionLinks = false;
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
        model.restPositions = model.surfels.positions;
        model.restNormals = model.surfels.normals;
        model.restCentroids = model.surfels.centroids;
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

// Glossy leaf g's mirror bin of every incoming bin, for its current normal.
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

std::string MotionMismatch(const AntiradianceModel& model, const Scene& scene) {
    if (model.motion.empty())
        return "the links were built without motion bounds (no dynamic surfaces, or motion "
               "links off)";
    const Surfels& sf = model.surfels;
    if (scene.primitives.size() != sf.firstSurfel.size())
        return "the scene has other primitives than the links were built for";
    const float slack = 1e-4f * std::max(scene.Diameter(), 1e-3f);
    for (size_t p = 0; p < scene.primitives.size(); ++p) {
        const Primitive& prim = scene.primitives[p];
        const uint32_t g = model.primitiveGroup[p];
        if (g == 0) {
            // Static: input vertices are the primitive's first surfels, as built.
            for (size_t i = 0; i < prim.positions.size(); ++i)
                if (prim.positions[i] != model.restPositions[sf.firstSurfel[p] + i])
                    return "static surfaces of node '" + prim.node + "' moved";
            continue;
        }
        const MotionGroup& group = model.motion[g - 1];
        const glm::mat4 delta = scene.nodes[group.node].world * glm::inverse(group.built);
        const glm::mat3 a(delta);
        const glm::mat3 ata = glm::transpose(a) * a;
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j)
                if (std::abs(ata[i][j] - (i == j ? 1.0f : 0.0f)) > 1e-3f)
                    return "node '" + prim.node + "' was scaled or sheared, not moved rigidly";
        if (glm::determinant(a) <= 0.0f) return "node '" + prim.node + "' was mirrored";
        for (const glm::vec3& v : prim.positions)
            if (glm::any(glm::lessThan(v, group.bounds.min - slack)) ||
                glm::any(glm::greaterThan(v, group.bounds.max + slack)))
                return "node '" + prim.node + "' left its motion bounds";
    }
    return {};
}

std::vector<uint8_t> PlaceGroups(AntiradianceModel& model, const Scene& scene,
                                 std::vector<uint32_t>* movedLeaves) {
    PENUMBRA_CHECK(MotionMismatch(model, scene).empty());
    // Each group's rigid motion from where it was built to where its node is now.
    std::vector<uint8_t> moved(model.motion.size() + 1, 0);
    std::vector<glm::mat4> delta(model.motion.size() + 1, glm::mat4(1.0f));
    for (size_t g = 0; g < model.motion.size(); ++g) {
        MotionGroup& group = model.motion[g];
        const glm::mat4& world = scene.nodes[group.node].world;
        if (world == group.placed) continue;
        group.placed = world;
        moved[g + 1] = 1;
        delta[g + 1] = world * glm::inverse(group.built);
    }
    Surfels& sf = model.surfels;
    tbb::parallel_for(size_t(0), sf.size(), [&](size_t i) {
        const uint32_t g = sf.groups[i];
        if (!moved[g]) return;
        const glm::mat3 r(delta[g]);
        sf.positions[i] = glm::vec3(delta[g] * glm::vec4(model.restPositions[i], 1.0f));
        sf.centroids[i] = glm::vec3(delta[g] * glm::vec4(model.restCentroids[i], 1.0f));
        sf.normals[i] = glm::normalize(r * model.restNormals[i]);
    });
    auto& nodes = model.hierarchy.nodes;
    tbb::parallel_for(size_t(0), nodes.size(), [&](size_t i) {
        HierarchyNode& n = nodes[i];
        if (n.group == kMixedGroup || !moved[n.group]) return;
        const glm::mat3 r(delta[n.group]);
        n.center = glm::vec3(delta[n.group] * glm::vec4(model.restCenters[i], 1.0f));
        n.normal = glm::normalize(r * model.restNodeNormals[i]);
        if (model.norms.in[i] != 0.0f) {  // oriented (ComputeLeafNorms)
            model.norms.in[i] = model.dirs.CosineNorm(-n.normal);
            model.norms.out[i] = model.dirs.CosineNorm(n.normal);
        }
    });
    for (uint32_t i = 0; i < model.leaves.size(); ++i) {
        LeafAttributes& leaf = model.leaves[i];
        if (!moved[sf.groups[leaf.surfel]]) continue;
        leaf.normal = sf.normals[leaf.surfel];
        leaf.cosNormIn = model.norms.in[leaf.node];
        leaf.cosNormOut = model.norms.out[leaf.node];
        if (leaf.flags & kLeafGlossy) FillMirror(model, leaf.flags >> kGlossyShift);
        if (movedLeaves) movedLeaves->push_back(i);
    }
    model.near.surfels = &model.surfels;
    return moved;
}

std::vector<uint32_t> TouchedLinks(const AntiradianceModel& model,
                                   const std::vector<uint8_t>& moved) {
    const auto& nodes = model.hierarchy.nodes;
    const Links& links = model.links;
    std::vector<uint32_t> touched;
    for (size_t k = 0; k < links.dynamic.size(); ++k) {
        const uint32_t r = links.dynamicReceivers[k];
        const uint32_t s = links.links[links.dynamic[k]].sender;
        if (moved[nodes[r].group] || moved[nodes[s].group]) touched.push_back(uint32_t(k));
    }
    return touched;
}

void RedoLinks(AntiradianceModel& model, const std::vector<uint32_t>& touched) {
    model.near.surfels = &model.surfels;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, touched.size(), 256),
                      [&](const tbb::blocked_range<size_t>& range) {
                          for (size_t i = range.begin(); i != range.end(); ++i) {
                              const uint32_t k = touched[i];
                              Link& link = model.links.links[model.links.dynamic[k]];
                              link = MakeLink(model.hierarchy, model.dirs, model.norms, model.near,
                                              model.links.dynamicReceivers[k], link.sender);
                          }
                      });
}

size_t MoveGroups(AntiradianceModel& model, const Scene& scene,
                  std::vector<uint32_t>* movedLeaves) {
    const std::vector<uint32_t> touched =
        TouchedLinks(model, PlaceGroups(model, scene, movedLeaves));
    RedoLinks(model, touched);
    return touched.size();
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
