// Moves in place (Sec. 3.3): the placed surfels carried to nodes, leaves and links.
#include "solvers/antiradiance/moves.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "base/check.h"
#include "solvers/antiradiance/model.h"

namespace penumbra {

std::vector<uint8_t> PlaceGroups(AntiradianceModel& model, const Scene& scene,
                                 std::vector<uint32_t>* movedLeaves) {
    const Placement placed = PlaceSurfels(model.motion, model.surfels, scene);
    const std::vector<uint8_t>& moved = placed.moved;
    const std::vector<glm::mat4>& delta = placed.delta;
    const Surfels& sf = model.surfels;
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

}  // namespace penumbra
