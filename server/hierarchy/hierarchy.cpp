// Top-down median splits along the widest of three spatial and three normal axes.
#include "hierarchy/hierarchy.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "base/check.h"

namespace penumbra {
namespace {

struct Builder {
    const Surfels& s;
    Hierarchy& h;
    std::vector<uint32_t> ids;  // sorted by group: a group is a contiguous range

    // Moving groups are clustered by their own-space centroids and normals
    // (Surfels::ownCentroids, the same at every pose); frames[g − 1] maps group g's own space
    // to the world as built. Null: cluster everything in world space.
    const std::vector<glm::mat4>* frames = nullptr;

    uint32_t Group(uint32_t id) const { return s.groups.empty() ? 0 : s.groups[id]; }

    // Builds the subtree over ids[begin, end) and returns its node index.
    uint32_t Build(size_t begin, size_t end, uint32_t parent, uint32_t depth) {
        uint32_t index = static_cast<uint32_t>(h.nodes.size());
        h.nodes.emplace_back();
        const uint32_t group =
            Group(ids[begin]) == Group(ids[end - 1]) ? Group(ids[begin]) : kMixedGroup;
        // A moving group is clustered in its own frame: the same clusters whatever its pose.
        const bool own = group != 0 && group != kMixedGroup && frames;
        const std::vector<glm::vec3>& pos = own ? s.ownCentroids : s.centroids;
        const std::vector<glm::vec3>& nrm = own ? s.ownNormals : s.normals;
        glm::vec3 lo(1e30f), hi(-1e30f), nlo(2.0f), nhi(-2.0f), nsum(0.0f);
        float area = 0.0f, maxDisc = 0.0f;
        for (size_t i = begin; i < end; ++i) {
            uint32_t id = ids[i];
            lo = glm::min(lo, pos[id]);
            hi = glm::max(hi, pos[id]);
            nlo = glm::min(nlo, nrm[id]);
            nhi = glm::max(nhi, nrm[id]);
            nsum += s.areas[id] * s.normals[id];
            area += s.areas[id];
            maxDisc = std::max(maxDisc, std::sqrt(s.areas[id] / std::numbers::pi_v<float>));
        }
        glm::vec3 centre = 0.5f * (lo + hi);
        if (own) centre = glm::vec3((*frames)[group - 1] * glm::vec4(centre, 1.0f));
        float radius = 0.0f;
        for (size_t i = begin; i < end; ++i)
            radius = std::max(radius, glm::length(s.centroids[ids[i]] - centre));
        radius += maxDisc;

        HierarchyNode node{};
        node.center = centre;
        node.radius = radius;
        node.area = area;
        node.discRadius = std::min(radius, std::sqrt(area / std::numbers::pi_v<float>));
        node.parent = parent;
        node.depth = depth;
        node.surfel = kNoSurfel;
        node.group = group;
        if (end - begin == 1) {
            node.surfel = ids[begin];
            node.normal = s.normals[ids[begin]];
            node.coneCos = 1.0f;
            node.twoSided = !s.twoSided.empty() && s.twoSided[ids[begin]];
            node.end = index + 1;
            h.nodes[index] = node;
            return index;
        }
        float len = glm::length(nsum);
        node.normal = len > 1e-12f ? nsum / len : glm::vec3(0.0f, 0.0f, 1.0f);
        node.coneCos = 1.0f;
        if (len <= 1e-12f) {
            node.coneCos = -1.0f;
        } else {
            for (size_t i = begin; i < end; ++i)
                node.coneCos = std::min(node.coneCos, glm::dot(node.normal, s.normals[ids[i]]));
        }

        // Split axis: widest spatial extent, or normal extent weighted by half the
        // spatial size (a compact cluster with mixed normals splits by orientation).
        glm::vec3 ext = hi - lo;
        float size = std::max(ext.x, std::max(ext.y, ext.z));
        glm::vec3 next = (nhi - nlo) * (0.5f * size);
        int axis = 0;
        float best = -1.0f;
        for (int a = 0; a < 3; ++a) {
            if (ext[a] > best) best = ext[a], axis = a;
            if (next[a] > best) best = next[a], axis = 3 + a;
        }
        auto key = [&](uint32_t id) { return axis < 3 ? pos[id][axis] : nrm[id][axis - 3]; };
        size_t mid = begin + (end - begin) / 2;
        if (node.group == kMixedGroup) {
            // Separate the groups: split at the group boundary nearest the middle.
            size_t best = end;
            for (size_t i = begin + 1; i < end; ++i)
                if (Group(ids[i]) != Group(ids[i - 1]) &&
                    (best == end ||
                     (i > mid ? i - mid : mid - i) < (best > mid ? best - mid : mid - best)))
                    best = i;
            mid = best;
        } else {
            std::nth_element(ids.begin() + begin, ids.begin() + mid, ids.begin() + end,
                             [&](uint32_t a, uint32_t b) { return key(a) < key(b); });
        }
        h.nodes[index] = node;
        Build(begin, mid, index, depth + 1);
        Build(mid, end, index, depth + 1);
        h.nodes[index].end = static_cast<uint32_t>(h.nodes.size());
        h.nodes[index].twoSided =
            h.nodes[index + 1].twoSided || h.nodes[h.nodes[index + 1].end].twoSided;
        return index;
    }
};

}  // namespace

Hierarchy BuildHierarchy(const Surfels& surfels, const std::vector<glm::mat4>& frames) {
    Hierarchy h;
    Builder b{surfels, h, {}, nullptr};
    if (!frames.empty() && !surfels.groups.empty() && !surfels.ownCentroids.empty())
        b.frames = &frames;
    for (uint32_t i = 0; i < surfels.size(); ++i)
        if (surfels.areas[i] > 0.0f) b.ids.push_back(i);
    if (b.ids.empty()) throw Error("the scene has no surface area to light");
    if (!surfels.groups.empty())
        std::stable_sort(b.ids.begin(), b.ids.end(), [&](uint32_t x, uint32_t y) {
            return surfels.groups[x] < surfels.groups[y];
        });
    h.nodes.reserve(2 * b.ids.size());
    b.Build(0, b.ids.size(), kNoParent, 0);

    h.leafOfSurfel.assign(surfels.size(), kNoParent);
    for (uint32_t i = 0; i < h.nodes.size(); ++i) {
        const auto& n = h.nodes[i];
        if (n.IsLeaf()) {
            h.leafOfSurfel[n.surfel] = i;
            h.leaves.push_back(i);
        } else {
            h.interior.push_back(i);
        }
        if (n.depth >= h.byDepth.size()) h.byDepth.resize(n.depth + 1);
        h.byDepth[n.depth].push_back(i);
    }
    return h;
}

void RefitHierarchy(Hierarchy& h, const Surfels& s) {
    // Children come after their parent in preorder: walk backwards, leaves before clusters.
    for (size_t k = h.nodes.size(); k-- > 0;) {
        HierarchyNode& n = h.nodes[k];
        if (n.IsLeaf()) {
            const uint32_t i = n.surfel;
            n.center = s.centroids[i];
            n.area = s.areas[i];
            n.discRadius = std::sqrt(n.area / std::numbers::pi_v<float>);
            n.radius = n.discRadius;
            n.normal = s.normals[i];
            n.coneCos = 1.0f;
            continue;
        }
        const HierarchyNode& a = h.nodes[k + 1];
        const HierarchyNode& b = h.nodes[a.end];
        // The smallest sphere around both children's spheres.
        const glm::vec3 d = b.center - a.center;
        const float dist = glm::length(d);
        if (dist + b.radius <= a.radius) {
            n.center = a.center, n.radius = a.radius;
        } else if (dist + a.radius <= b.radius) {
            n.center = b.center, n.radius = b.radius;
        } else {
            n.radius = 0.5f * (dist + a.radius + b.radius);
            n.center = a.center + d * ((n.radius - a.radius) / dist);
        }
        n.area = a.area + b.area;
        n.discRadius = std::min(n.radius, std::sqrt(n.area / std::numbers::pi_v<float>));
        const glm::vec3 sum = a.area * a.normal + b.area * b.normal;
        const float len = glm::length(sum);
        if (len <= 1e-12f || a.coneCos < -0.5f || b.coneCos < -0.5f) {
            n.normal = len > 1e-12f ? sum / len : glm::vec3(0.0f, 0.0f, 1.0f);
            n.coneCos = -1.0f;
            continue;
        }
        n.normal = sum / len;
        // Each child's cone around the new axis: its own axis' angle plus its half angle.
        float cone = 0.0f;
        for (const HierarchyNode* c : {&a, &b}) {
            const float axis = std::acos(std::clamp(glm::dot(n.normal, c->normal), -1.0f, 1.0f));
            cone = std::max(cone, axis + std::acos(std::clamp(c->coneCos, -1.0f, 1.0f)));
        }
        n.coneCos = cone >= std::numbers::pi_v<float> ? -1.0f : std::cos(cone);
    }
}

}  // namespace penumbra
