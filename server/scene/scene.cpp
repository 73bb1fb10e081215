// Scene bounds, counts and normal generation.
#include "scene/scene.h"

#include <limits>

namespace penumbra {

glm::vec3 Scene::BoundsMin() const {
    glm::vec3 lo(std::numeric_limits<float>::max());
    for (const auto& p : primitives)
        for (const auto& v : p.positions) lo = glm::min(lo, v);
    return lo;
}

glm::vec3 Scene::BoundsMax() const {
    glm::vec3 hi(std::numeric_limits<float>::lowest());
    for (const auto& p : primitives)
        for (const auto& v : p.positions) hi = glm::max(hi, v);
    return hi;
}

float Scene::Diameter() const {
    if (VertexCount() == 0) return 0.0f;
    return glm::length(BoundsMax() - BoundsMin());
}

size_t Scene::VertexCount() const {
    size_t n = 0;
    for (const auto& p : primitives) n += p.positions.size();
    return n;
}

size_t Scene::TriangleCount() const {
    size_t n = 0;
    for (const auto& p : primitives) n += p.indices.size() / 3;
    return n;
}

void ComputeVertexNormals(Primitive& primitive) {
    std::vector<glm::vec3> sum(primitive.positions.size(), glm::vec3(0.0f));
    for (size_t t = 0; t + 2 < primitive.indices.size(); t += 3) {
        uint32_t a = primitive.indices[t], b = primitive.indices[t + 1],
                 c = primitive.indices[t + 2];
        // Cross product length is twice the area: area weighting for free.
        glm::vec3 n = glm::cross(primitive.positions[b] - primitive.positions[a],
                                 primitive.positions[c] - primitive.positions[a]);
        sum[a] += n;
        sum[b] += n;
        sum[c] += n;
    }
    primitive.normals.resize(primitive.positions.size());
    for (size_t i = 0; i < sum.size(); ++i) {
        float len = glm::length(sum[i]);
        primitive.normals[i] = len > 0.0f ? sum[i] / len : glm::vec3(0.0f, 0.0f, 1.0f);
    }
}

}  // namespace penumbra
