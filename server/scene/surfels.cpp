// Longest-edge bisection refinement of a Scene into surfels with areas and normals.
#include "scene/surfels.h"

#include <cmath>
#include <unordered_map>

#include "base/check.h"
#include "scene/solids.h"

namespace penumbra {

Surfels RefineScene(const Scene& scene, float elementSize) {
    if (!(elementSize > 0.0f)) throw Error("element size must be a positive number of metres");
    Surfels out;
    std::vector<glm::vec3> moments;  // ∫ φ_s x dA per surfel
    // Dynamic primitives: own-space normals, moments and areas (Surfels::ownCentroids).
    std::vector<glm::vec3> ownNormals, ownMoments;
    std::vector<float> ownAreas;
    bool anyOwn = false;
    const float maxEdge2 = elementSize * elementSize;
    // Colour maps: each surfel's texture coordinates in its base colour and emission maps'
    // sets (interpolated at midpoints like positions) and its tints' area integrals.
    const bool mapped = AnyMapped(scene);
    std::vector<glm::vec2> baseUv, emissionUv;
    std::vector<glm::vec3> albedoSums, emissionSums;
    for (uint32_t pi = 0; pi < scene.primitives.size(); ++pi) {
        const Primitive& prim = scene.primitives[pi];
        const uint32_t base = static_cast<uint32_t>(out.positions.size());
        out.firstSurfel.push_back(base);
        // A dynamic node's primitives are split by their own-space edges in the rest pose
        // (Primitive::restPositions), measured with the metric AᵀA of the node's world matrix
        // rounded to 2⁻²⁰ of its trace: the same splits at every pose (world-space lengths of
        // equal edges differ by rounding noise from pose to pose, and ties would break
        // differently) and every deformation, so a move keeps the surfels (Sec. 3.3) and a
        // deformed mesh its elements (implicit visibility paper, Sec. 4: the hierarchy is
        // refitted, not rebuilt).
        const bool own = prim.nodeIndex >= 0 && scene.nodes[prim.nodeIndex].dynamic &&
                         prim.objectPositions.size() == prim.positions.size();
        anyOwn = anyOwn || own;
        const Material& material = scene.materials[prim.material];
        // The coordinates each tint reads here, if the primitive has them.
        const std::vector<glm::vec2>* baseSet =
            MapCoordinates(prim, material.baseColorMap, material.baseColorSet);
        const std::vector<glm::vec2>* emissionSet =
            MapCoordinates(prim, material.emissionMap, material.emissionSet);
        for (size_t i = 0; i < prim.positions.size(); ++i) {
            if (mapped) {
                baseUv.push_back(baseSet ? (*baseSet)[i] : glm::vec2(0.0f));
                emissionUv.push_back(emissionSet ? (*emissionSet)[i] : glm::vec2(0.0f));
            }
            out.positions.push_back(prim.positions[i]);
            out.normals.push_back(prim.normals[i]);
            out.areas.push_back(0.0f);
            out.materials.push_back(prim.material);
            // The own-space arrays stay aligned with the surfels (zero where not dynamic).
            ownNormals.push_back(own && i < prim.objectNormals.size() ? prim.objectNormals[i]
                                                                      : glm::vec3(0.0f));
            ownMoments.emplace_back(0.0f);
            ownAreas.push_back(0.0f);
        }
        std::vector<glm::vec3> object;  // own-space positions of this primitive's surfels
        std::vector<glm::vec3> rest;    // the same in the rest pose (what splits)
        glm::mat3 metric(1.0f);
        if (own) {
            object = prim.objectPositions;
            rest = prim.RestPositions();
            const glm::mat3 a(scene.nodes[prim.nodeIndex].world);
            metric = glm::transpose(a) * a;
            const float q = (metric[0][0] + metric[1][1] + metric[2][2]) / 1048576.0f;
            for (int i = 0; i < 3; ++i)
                for (int j = 0; j < 3; ++j) metric[i][j] = std::round(metric[i][j] / q) * q;
        }
        // Edge midpoint cache keyed by the sorted surfel pair.
        std::unordered_map<uint64_t, uint32_t> midpoints;
        auto midpoint = [&](uint32_t a, uint32_t b) {
            uint64_t key = a < b ? (uint64_t(a) << 32 | b) : (uint64_t(b) << 32 | a);
            auto it = midpoints.find(key);
            if (it != midpoints.end()) return it->second;
            uint32_t m = static_cast<uint32_t>(out.positions.size());
            moments.emplace_back(0.0f);
            if (mapped) {
                baseUv.push_back(0.5f * (baseUv[a] + baseUv[b]));
                emissionUv.push_back(0.5f * (emissionUv[a] + emissionUv[b]));
            }
            out.positions.push_back(0.5f * (out.positions[a] + out.positions[b]));
            ownMoments.emplace_back(0.0f);
            ownAreas.push_back(0.0f);
            if (own) {
                object.push_back(0.5f * (object[a - base] + object[b - base]));
                rest.push_back(0.5f * (rest[a - base] + rest[b - base]));
                glm::vec3 on = ownNormals[a] + ownNormals[b];
                float ol = glm::length(on);
                ownNormals.push_back(ol > 1e-6f ? on / ol : ownNormals[a]);
            } else {
                ownNormals.emplace_back(0.0f);
            }
            glm::vec3 n = out.normals[a] + out.normals[b];
            float len = glm::length(n);
            out.normals.push_back(len > 1e-6f ? n / len : out.normals[a]);
            out.areas.push_back(0.0f);
            out.materials.push_back(prim.material);
            midpoints.emplace(key, m);
            return m;
        };
        std::vector<glm::uvec3> stack;
        moments.resize(out.positions.size(), glm::vec3(0.0f));
        for (size_t t = 0; t + 2 < prim.indices.size(); t += 3)
            stack.emplace_back(base + prim.indices[t], base + prim.indices[t + 1],
                               base + prim.indices[t + 2]);
        while (!stack.empty()) {
            glm::uvec3 tri = stack.back();
            stack.pop_back();
            const glm::vec3 p[3] = {out.positions[tri[0]], out.positions[tri[1]],
                                    out.positions[tri[2]]};
            float e[3];
            for (int k = 0; k < 3; ++k) {
                if (own) {
                    glm::vec3 d = rest[tri[(k + 1) % 3] - base] - rest[tri[k] - base];
                    e[k] = glm::dot(d, metric * d);
                } else {
                    glm::vec3 d = p[(k + 1) % 3] - p[k];
                    e[k] = glm::dot(d, d);
                }
            }
            int longest = e[0] >= e[1] ? (e[0] >= e[2] ? 0 : 2) : (e[1] >= e[2] ? 1 : 2);
            if (e[longest] > maxEdge2) {
                // Split edge (longest, longest+1) at its midpoint: two triangles.
                uint32_t a = tri[longest], b = tri[(longest + 1) % 3], c = tri[(longest + 2) % 3];
                uint32_t m = midpoint(a, b);
                stack.emplace_back(a, m, c);
                stack.emplace_back(m, b, c);
                continue;
            }
            float area = 0.5f * glm::length(glm::cross(p[1] - p[0], p[2] - p[0]));
            glm::vec3 sum = p[0] + p[1] + p[2];
            if (mapped) {
                // The tints over this triangle, a third of its area to each corner (the
                // integral of a corner's hat function over it, with the tint taken constant).
                albedoSums.resize(out.positions.size(), glm::vec3(0.0f));
                emissionSums.resize(out.positions.size(), glm::vec3(0.0f));
                glm::vec3 albedo(1.0f), emission(1.0f);
                if (baseSet)
                    albedo = scene.maps[material.baseColorMap].Over(baseUv[tri[0]], baseUv[tri[1]],
                                                                    baseUv[tri[2]]);
                if (emissionSet)
                    emission = scene.maps[material.emissionMap].Over(
                        emissionUv[tri[0]], emissionUv[tri[1]], emissionUv[tri[2]]);
                for (int k = 0; k < 3; ++k) {
                    albedoSums[tri[k]] += area / 3.0f * albedo;
                    emissionSums[tri[k]] += area / 3.0f * emission;
                }
            }
            for (int k = 0; k < 3; ++k) {
                out.areas[tri[k]] += area / 3.0f;
                // ∫ φ_k x dA over the triangle = A (2 p_k + p_i + p_j) / 12.
                moments[tri[k]] += area * (sum + p[k]) / 12.0f;
            }
            if (own) {
                const glm::vec3 o[3] = {object[tri[0] - base], object[tri[1] - base],
                                        object[tri[2] - base]};
                float oa = 0.5f * glm::length(glm::cross(o[1] - o[0], o[2] - o[0]));
                glm::vec3 osum = o[0] + o[1] + o[2];
                for (int k = 0; k < 3; ++k) {
                    ownAreas[tri[k]] += oa / 3.0f;
                    ownMoments[tri[k]] += oa * (osum + o[k]) / 12.0f;
                }
            }
            out.refinedTriangles.insert(out.refinedTriangles.end(), {tri[0], tri[1], tri[2]});
        }
    }
    if (anyOwn) {
        out.ownCentroids.resize(out.size());
        out.ownNormals = std::move(ownNormals);
        for (size_t i = 0; i < out.size(); ++i)
            out.ownCentroids[i] =
                ownAreas[i] > 0.0f ? ownMoments[i] / ownAreas[i] : glm::vec3(0.0f);
    }
    if (mapped) {
        albedoSums.resize(out.size(), glm::vec3(0.0f));
        emissionSums.resize(out.size(), glm::vec3(0.0f));
        out.albedoTints.resize(out.size());
        out.emissionTints.resize(out.size());
        for (size_t i = 0; i < out.size(); ++i) {
            const bool some = out.areas[i] > 0.0f;
            out.albedoTints[i] = some ? albedoSums[i] / out.areas[i] : glm::vec3(1.0f);
            out.emissionTints[i] = some ? emissionSums[i] / out.areas[i] : glm::vec3(1.0f);
        }
    }
    out.centroids.resize(out.size());
    for (size_t i = 0; i < out.size(); ++i)
        out.centroids[i] = out.areas[i] > 0.0f ? moments[i] / out.areas[i] : out.positions[i];
    return out;
}

bool BackOcclusionOn(BackOcclusion choice, const Environment& sky) {
    return choice == BackOcclusion::kOn || (choice == BackOcclusion::kAuto && sky.Present());
}

bool BackOcclusionChanges(BackOcclusion choice, const Environment& before,
                          const Environment& after) {
    return BackOcclusionOn(choice, before) != BackOcclusionOn(choice, after);
}

void MarkTwoSided(const Scene& scene, Surfels& s) {
    const std::vector<bool> closed = ClosedNodes(scene);
    s.twoSided.assign(s.size(), 0);
    for (size_t p = 0; p < scene.primitives.size(); ++p) {
        const int node = scene.primitives[p].nodeIndex;
        const bool open = node < 0 || !closed[node];
        for (size_t i = s.firstSurfel[p]; i < s.End(p); ++i) s.twoSided[i] = open;
    }
}

}  // namespace penumbra
