// Scene bounds, counts and normal generation.
#include "scene/scene.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "base/check.h"

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

int FindNode(const Scene& scene, const std::string& name) {
    for (size_t i = 0; i < scene.nodes.size(); ++i)
        if (scene.nodes[i].name == name) return static_cast<int>(i);
    return -1;
}

namespace {

bool IsFinite(const glm::mat4& m) {
    for (int c = 0; c < 4; ++c)
        for (int r = 0; r < 4; ++r)
            if (!std::isfinite(m[c][r])) return false;
    return true;
}

// World transforms of `node`'s subtree under `parentWorld`, written into `world`.
void PlaceSubtree(const Scene& scene, int node, const glm::mat4& parentWorld,
                  const glm::mat4& local, std::vector<std::pair<int, glm::mat4>>& world) {
    glm::mat4 w = parentWorld * local;
    world.emplace_back(node, w);
    for (int c : scene.nodes[node].children) PlaceSubtree(scene, c, w, scene.nodes[c].local, world);
}

}  // namespace

float LightAttenuation(const PunctualLight& light, const glm::vec3& toPoint, float d) {
    if (light.type == LightType::kDirectional) return 1.0f;
    float a = 1.0f;
    if (light.range > 0.0f) {
        float x = d / light.range;
        float w = std::clamp(1.0f - x * x * x * x, 0.0f, 1.0f);
        a = w * w;
    }
    if (light.type == LightType::kSpot) {
        float cosOuter = std::cos(light.outerCone);
        float scale = 1.0f / std::max(1e-3f, std::cos(light.innerCone) - cosOuter);
        float t = std::clamp((glm::dot(light.direction, toPoint) - cosOuter) * scale, 0.0f, 1.0f);
        a *= t * t;
    }
    return a;
}

void PlaceLight(PunctualLight& light, const glm::mat4& world) {
    light.position = glm::vec3(world[3]);
    glm::vec3 d = glm::mat3(world) * glm::vec3(0.0f, 0.0f, -1.0f);
    float len = glm::length(d);
    if (!(len > 1e-12f) || !std::isfinite(len))
        throw Error("light '" + light.name + "' has a singular transform (no direction)");
    light.direction = d / len;
}

int FindLight(const Scene& scene, const std::string& name) {
    for (size_t i = 0; i < scene.lights.size(); ++i)
        if (scene.nodes[scene.lights[i].node].name == name || scene.lights[i].name == name)
            return static_cast<int>(i);
    return -1;
}

void SetNodeTransform(Scene& scene, int node, const glm::mat4& local) {
    if (node < 0 || node >= static_cast<int>(scene.nodes.size()))
        throw Error("node index " + std::to_string(node) + " does not exist");
    const SceneNode& n = scene.nodes[node];
    if (!IsFinite(local)) throw Error("transform of '" + n.name + "' has NaN or infinity");
    glm::mat4 parentWorld = n.parent >= 0 ? scene.nodes[n.parent].world : glm::mat4(1.0f);
    // Check every new world matrix before changing anything.
    std::vector<std::pair<int, glm::mat4>> world;
    PlaceSubtree(scene, node, parentWorld, local, world);
    for (const auto& [i, w] : world) {
        if (!IsFinite(w)) throw Error("transform of '" + n.name + "' overflows to infinity");
        for (const PunctualLight& light : scene.lights)
            if (light.node == i) {
                PunctualLight moved = light;
                PlaceLight(moved, w);  // throws for a singular transform
            }
        if (scene.nodes[i].primitives.empty()) continue;
        float det = glm::determinant(glm::mat3(w));
        if (!(std::abs(det) >= 1e-12f))
            throw Error("transform of '" + n.name + "' is singular (zero scale)");
        // Triangle winding was fixed for the file's handedness at load time.
        if ((det < 0.0f) != (glm::determinant(glm::mat3(scene.nodes[i].world)) < 0.0f))
            throw Error("transform of '" + n.name +
                        "' would mirror it (a negative scale); mirroring a loaded node is not "
                        "supported");
    }
    scene.nodes[node].local = local;
    for (const auto& [i, w] : world) {
        scene.nodes[i].world = w;
        for (PunctualLight& light : scene.lights)
            if (light.node == i) PlaceLight(light, w);
        glm::mat3 normalMatrix = glm::transpose(glm::inverse(glm::mat3(w)));
        for (uint32_t pi : scene.nodes[i].primitives) {
            Primitive& p = scene.primitives[pi];
            for (size_t v = 0; v < p.positions.size(); ++v) {
                p.positions[v] = glm::vec3(w * glm::vec4(p.objectPositions[v], 1.0f));
                p.normals[v] = glm::normalize(normalMatrix * p.objectNormals[v]);
            }
        }
    }
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
