#include "scene/refine_output.h"

#include <cmath>
#include <string>
#include <unordered_map>

#include "base/check.h"

namespace penumbra {

namespace {

glm::vec3 Unit(const glm::vec3& sum, const glm::vec3& fallback) {
    const float len = glm::length(sum);
    return len > 1e-6f ? sum / len : fallback;
}

// Appends to `list` the mean of its entries a and b, if it is a per-vertex list (`count`
// entries); other lists (empty, or a set the material does not read) stay as they are.
template <typename T>
void Mean(std::vector<T>& list, size_t count, uint32_t a, uint32_t b) {
    if (list.size() == count) list.push_back(T(0.5f) * (list[a] + list[b]));
}

void RefinePrimitive(Primitive& p, float edge2, size_t& budget) {
    const size_t inputTriangles = p.indices.size() / 3;
    std::unordered_map<uint64_t, uint32_t> midpoints;  // by sorted vertex pair
    auto midpoint = [&](uint32_t a, uint32_t b) {
        const uint64_t key = a < b ? (uint64_t(a) << 32 | b) : (uint64_t(b) << 32 | a);
        if (auto it = midpoints.find(key); it != midpoints.end()) return it->second;
        const size_t n = p.positions.size();
        const uint32_t m = static_cast<uint32_t>(n);
        // Every list with one entry a vertex, before positions grows.
        Mean(p.objectPositions, n, a, b);
        Mean(p.restPositions, n, a, b);
        for (auto& set : p.texcoords) Mean(set, n, a, b);
        for (auto& target : p.morphPositions) Mean(target, n, a, b);
        for (auto& target : p.morphNormals) Mean(target, n, a, b);
        for (auto* normals : {&p.objectNormals, &p.restNormals})
            if (normals->size() == n)
                normals->push_back(Unit((*normals)[a] + (*normals)[b], (*normals)[a]));
        p.normals.push_back(Unit(p.normals[a] + p.normals[b], p.normals[a]));
        p.positions.push_back(0.5f * (p.positions[a] + p.positions[b]));
        midpoints.emplace(key, m);
        return m;
    };
    auto length2 = [&](uint32_t a, uint32_t b) {
        const glm::vec3 d = p.positions[b] - p.positions[a];
        return glm::dot(d, d);
    };
    std::vector<uint32_t> indices, parents;
    std::vector<std::pair<glm::uvec3, uint32_t>> stack;  // a triangle and its input one
    for (size_t t = inputTriangles; t-- > 0;)
        stack.push_back({{p.indices[3 * t], p.indices[3 * t + 1], p.indices[3 * t + 2]},
                         static_cast<uint32_t>(t)});
    while (!stack.empty()) {
        const auto [tri, parent] = stack.back();
        stack.pop_back();
        const float e[3] = {length2(tri[0], tri[1]), length2(tri[1], tri[2]),
                            length2(tri[2], tri[0])};
        const int k = e[0] >= e[1] ? (e[0] >= e[2] ? 0 : 2) : (e[1] >= e[2] ? 1 : 2);
        if (e[k] > edge2 && std::isfinite(e[k])) {
            // Split the longest edge (k, k+1) at its midpoint: two triangles, same winding.
            if (budget == 0) throw Error("refined output would pass its triangle limit");
            --budget;
            const uint32_t a = tri[k], b = tri[(k + 1) % 3], c = tri[(k + 2) % 3];
            const uint32_t m = midpoint(a, b);
            stack.push_back({{m, b, c}, parent});
            stack.push_back({{a, m, c}, parent});
            continue;
        }
        indices.insert(indices.end(), {tri[0], tri[1], tri[2]});
        parents.push_back(parent);
    }
    if (indices.size() == p.indices.size() && p.copyOf.empty()) return;  // nothing finer
    p.indices = std::move(indices);
    p.parentTriangles = std::move(parents);
    p.copyOf.clear();  // each copy is an output vertex now
    p.refined = true;
}

}  // namespace

void RefineForOutput(Scene& scene, float edge, size_t maxTriangles) {
    if (!(edge > 0.0f) || !std::isfinite(edge))
        throw Error("the refined output's edge must be a positive number of metres, not " +
                    std::to_string(edge));
    size_t triangles = scene.TriangleCount();
    if (triangles >= maxTriangles)
        throw Error("the scene has " + std::to_string(triangles) + " triangles already");
    size_t budget = maxTriangles - triangles;
    try {
        for (Primitive& p : scene.primitives) RefinePrimitive(p, edge * edge, budget);
    } catch (const Error&) {
        throw Error("refining to " + std::to_string(edge) + " m edges would make more than " +
                    std::to_string(maxTriangles) + " triangles: give a longer edge");
    }
}

}  // namespace penumbra
