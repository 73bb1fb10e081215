// Rigid motion of dynamic nodes (Sec. 3.3): groups, checks, placement and carry-over.
#include "scene/motion.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

#include "base/check.h"

namespace penumbra {

float MotionSlack(const Scene& scene) { return 1e-4f * std::max(scene.Diameter(), 1e-3f); }

bool OutsideBounds(const Scene& scene, const std::vector<uint32_t>& primitives,
                   const MotionBounds& bounds) {
    const float slack = MotionSlack(scene);
    for (uint32_t p : primitives)
        for (const glm::vec3& v : scene.primitives[p].positions)
            if (glm::any(glm::lessThan(v, bounds.min - slack)) ||
                glm::any(glm::greaterThan(v, bounds.max + slack)))
                return true;
    return false;
}

bool OutsideBounds(const Scene& scene, const SceneNode& node) {
    return node.hasMotionBounds &&
           OutsideBounds(scene, node.primitives, MotionBounds{node.boundsMin, node.boundsMax});
}

const char* NotRigid(const glm::mat4& delta) {
    const glm::mat3 a(delta);
    const glm::mat3 ata = glm::transpose(a) * a;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            if (!(std::abs(ata[i][j] - (i == j ? 1.0f : 0.0f)) <= 1e-3f))
                return "was scaled or sheared, not moved rigidly";
    if (!(glm::determinant(a) > 0.0f)) return "was mirrored";
    return nullptr;
}

std::optional<glm::mat3> RigidRotation(const glm::mat4& delta) {
    if (NotRigid(delta)) return std::nullopt;
    return glm::mat3(delta);
}

std::vector<MotionBounds> SurfelMotion::Bounds() const {
    std::vector<MotionBounds> out;
    for (const MotionGroup& g : groups) out.push_back(g.bounds);
    return out;
}

std::vector<glm::mat4> SurfelMotion::BuiltFrames() const {
    std::vector<glm::mat4> out;
    for (const MotionGroup& g : groups) out.push_back(g.built);
    return out;
}

SurfelMotion AssignMotionGroups(const Scene& scene, Surfels& s) {
    SurfelMotion motion;
    motion.primitiveGroup.assign(scene.primitives.size(), 0);
    for (const Primitive& p : scene.primitives) motion.primitiveShape.push_back(p.shape);
    std::vector<uint32_t> groupOfNode(scene.nodes.size(), 0);
    for (size_t p = 0; p < scene.primitives.size(); ++p) {
        const int node = scene.primitives[p].nodeIndex;
        if (node < 0 || !scene.nodes[node].dynamic) continue;
        if (!groupOfNode[node]) {
            const SceneNode& n = scene.nodes[node];
            MotionGroup g;
            g.node = node;
            g.bounds = n.hasMotionBounds ? MotionBounds{n.boundsMin, n.boundsMax}
                                         : MotionBounds{scene.BoundsMin(), scene.BoundsMax()};
            g.built = g.placed = n.world;
            motion.groups.push_back(g);
            groupOfNode[node] = static_cast<uint32_t>(motion.groups.size());
        }
        motion.primitiveGroup[p] = groupOfNode[node];
    }
    if (motion.empty()) return motion;
    s.groups.assign(s.size(), 0);
    for (size_t p = 0; p < scene.primitives.size(); ++p)
        for (size_t i = s.firstSurfel[p]; i < s.End(p); ++i) s.groups[i] = motion.primitiveGroup[p];
    motion.restPositions = s.positions;
    motion.restNormals = s.normals;
    motion.restCentroids = s.centroids;
    return motion;
}

std::string MotionMismatch(const SurfelMotion& motion, const Surfels& sf, const Scene& scene) {
    if (motion.empty())
        return "the surfaces were prepared without motion bounds (no dynamic surfaces, or "
               "motion links off)";
    if (scene.primitives.size() != sf.firstSurfel.size())
        return "the scene has other primitives than the surfaces were prepared for";
    for (size_t p = 0; p < scene.primitives.size(); ++p) {
        const Primitive& prim = scene.primitives[p];
        const uint32_t g = motion.primitiveGroup[p];
        if (g == 0) {
            // Static: input vertices are the primitive's first surfels, as made.
            for (size_t i = 0; i < prim.positions.size(); ++i)
                if (prim.positions[i] != motion.restPositions[sf.firstSurfel[p] + i])
                    return "static surfaces of node '" + prim.node + "' moved";
            continue;
        }
        const MotionGroup& group = motion.groups[g - 1];
        if (prim.shape != motion.primitiveShape[p])
            return "node '" + prim.node +
                   "' changed shape (its vertices were replaced), not "
                   "only its place";
        if (const char* why = NotRigid(scene.nodes[group.node].world * glm::inverse(group.built)))
            return "node '" + prim.node + "' " + why;
        if (OutsideBounds(scene, {uint32_t(p)}, group.bounds))
            return "node '" + prim.node + "' left its motion bounds";
    }
    return {};
}

Placement PlaceSurfels(SurfelMotion& motion, Surfels& sf, const Scene& scene) {
    PENUMBRA_CHECK(MotionMismatch(motion, sf, scene).empty());
    Placement out;
    out.moved.assign(motion.size() + 1, 0);
    out.delta.assign(motion.size() + 1, glm::mat4(1.0f));
    for (size_t g = 0; g < motion.size(); ++g) {
        MotionGroup& group = motion.groups[g];
        const glm::mat4& world = scene.nodes[group.node].world;
        if (world == group.placed) continue;
        group.placed = world;
        out.moved[g + 1] = 1;
        out.delta[g + 1] = world * glm::inverse(group.built);
    }
    tbb::parallel_for(size_t(0), sf.size(), [&](size_t i) {
        const uint32_t g = sf.groups[i];
        if (!out.moved[g]) return;
        const glm::mat4& d = out.delta[g];
        sf.positions[i] = glm::vec3(d * glm::vec4(motion.restPositions[i], 1.0f));
        sf.centroids[i] = glm::vec3(d * glm::vec4(motion.restCentroids[i], 1.0f));
        sf.normals[i] = glm::normalize(glm::mat3(d) * motion.restNormals[i]);
    });
    return out;
}

SurfelCarry CarrySurfels(const Scene& before, const Surfels& was, const Scene& after,
                         const Surfels& now) {
    SurfelCarry carry;
    carry.from.assign(now.size(), SurfelCarry::kNone);
    carry.turn.assign(now.size(), 0);
    if (before.primitives.size() != after.primitives.size() ||
        was.firstSurfel.size() != before.primitives.size() ||
        now.firstSurfel.size() != after.primitives.size())
        return carry;
    for (size_t p = 0; p < after.primitives.size(); ++p) {
        const size_t b0 = was.firstSurfel[p], n0 = now.firstSurfel[p];
        const size_t count = now.End(p) - n0;
        if (was.End(p) - b0 != count) continue;
        uint32_t turn = 0;
        if (before.primitives[p].positions != after.primitives[p].positions) {
            const int n = after.primitives[p].nodeIndex;
            if (n < 0 || n >= int(before.nodes.size()) || n >= int(after.nodes.size())) continue;
            const std::optional<glm::mat3> r =
                RigidRotation(after.nodes[n].world * glm::inverse(before.nodes[n].world));
            if (!r) continue;
            turn = static_cast<uint32_t>(carry.turns.size());
            carry.turns.push_back(*r);
            carry.turned += count;
        }
        for (size_t i = 0; i < count; ++i) {
            carry.from[n0 + i] = int64_t(b0 + i);
            carry.turn[n0 + i] = turn;
        }
        carry.kept += count;
    }
    return carry;
}

}  // namespace penumbra
