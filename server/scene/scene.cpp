// Scene bounds, counts and normal generation.
#include "scene/scene.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <unordered_map>

#include "base/check.h"
#include "base/numeric.h"

namespace penumbra {

void DeriveReflectance(Material& m) {
    const float metallic = glm::clamp(m.metallic, 0.0f, 1.0f);
    const float alpha = m.roughness * m.roughness;
    const float alpha2 = alpha * alpha;
    const float n = alpha2 > 0.0f ? 0.5f / alpha2 - 0.5f : kMaxPhongExponent;
    const glm::vec3 f0 = glm::mix(glm::vec3(0.04f), m.baseColor, metallic);
    if (n >= 1.0f) {
        // Glossy: the dielectric's diffuse layer keeps 1 − 0.04 (glTF's 1 − F at normal
        // incidence), so ρ_d + F0 ≤ 1 whenever the base colour is.
        m.albedo = m.baseColor * (1.0f - metallic) * (1.0f - 0.04f);
        m.specular = f0;
        m.phongExponent = std::min(n, kMaxPhongExponent);
    } else {
        // Nearly uniform lobe: the metal's share reflects diffusely, the dielectric's 4% is
        // left out.
        m.albedo = m.baseColor;  // (1 − m) · base + m · base
        m.specular = glm::vec3(0.0f);
        m.phongExponent = 0.0f;
    }
    // What passes straight through is neither reflected nor absorbed.
    m.transmittance = glm::vec3(1.0f - m.coverage) + m.coverage * m.transmission * m.baseColor;
    m.albedo *= m.coverage * (1.0f - m.transmission);
    m.specular *= m.coverage;
}

Material PbrMaterial(const std::string& name, glm::vec3 baseColor, float metallic, float roughness,
                     glm::vec3 emission) {
    Material m;
    m.name = name;
    m.baseColor = baseColor;
    m.metallic = metallic;
    m.roughness = roughness;
    m.emission = emission;
    DeriveReflectance(m);
    return m;
}

void PassThrough(Material& m, float coverage, float transmission) {
    m.coverage = coverage;
    m.transmission = transmission;
    m.emission *= coverage;
    DeriveReflectance(m);
}

Material DiffuseMaterial(const std::string& name, glm::vec3 albedo, glm::vec3 emission) {
    return PbrMaterial(name, albedo, 0.0f, 1.0f, emission);
}

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

bool AnyMapped(const Scene& scene) {
    return std::any_of(scene.materials.begin(), scene.materials.end(),
                       [](const Material& m) { return m.Mapped(); });
}

const std::vector<glm::vec2>* MapCoordinates(const Primitive& prim, int map, int set) {
    if (map < 0 || set < 0 || set >= static_cast<int>(prim.texcoords.size()) ||
        prim.texcoords[set].size() != prim.positions.size())
        return nullptr;
    return &prim.texcoords[set];
}

Tints TintsAt(const Scene& scene, uint32_t p, const glm::uvec3& abc, float u, float v) {
    const Primitive& prim = scene.primitives[p];
    const Material& m = scene.materials[prim.material];
    Tints out;
    auto at = [&](int map, int set) {
        const std::vector<glm::vec2>* coordinates = MapCoordinates(prim, map, set);
        if (!coordinates) return glm::vec3(1.0f);
        const std::vector<glm::vec2>& uv = *coordinates;
        const glm::vec2 x = uv[abc.x] + u * (uv[abc.y] - uv[abc.x]) + v * (uv[abc.z] - uv[abc.x]);
        return scene.maps[map].At(x);
    };
    if (!m.Mapped()) return out;
    out.albedo = at(m.baseColorMap, m.baseColorSet);
    out.emission = at(m.emissionMap, m.emissionSet);
    return out;
}

std::vector<std::string> SceneWarnings(const Scene& scene, bool lightFromScene) {
    std::vector<std::string> out = scene.warnings;
    // Surfaces that pass light: what each stage makes of them (docs/MATERIALS.md).
    std::string passing;
    size_t count = 0;
    for (const Material& m : scene.materials)
        if (m.Passes() && passing.find("'" + m.name + "'") == std::string::npos && ++count <= 3)
            passing += (passing.empty() ? "'" : ", '") + m.name + "'";
    if (count > 0)
        out.push_back("material(s) " + passing + (count > 3 ? " and others" : "") +
                      " pass light (alpha coverage, transmission): the direct light, the final "
                      "gather, a sky map's sun, the light-field solver and the reference let it "
                      "through tinted, the first shot to emitters untinted; the antiradiance and "
                      "implicit solvers' own "
                      "bounces treat them as opaque; their own reflection is left out where a "
                      "ray looks through them");
    if (!lightFromScene) return out;
    const bool emits = std::any_of(
        scene.materials.begin(), scene.materials.end(),
        [](const auto& m) { return glm::any(glm::greaterThan(m.emission, glm::vec3(0.0f))); });
    if (!emits && scene.lights.empty() && !scene.environment.Active())
        out.push_back(
            "no light (no emissive material, punctual light or sky): the irradiance is "
            "zero everywhere");
    return out;
}

int FindNode(const Scene& scene, const std::string& name) {
    for (size_t i = 0; i < scene.nodes.size(); ++i)
        if (scene.nodes[i].name == name) return static_cast<int>(i);
    return -1;
}

namespace {

// Node `node` of `scene`; throws penumbra::Error when there is none.
const SceneNode& NodeAt(const Scene& scene, int node) {
    if (node < 0 || node >= static_cast<int>(scene.nodes.size()))
        throw Error("node index " + std::to_string(node) + " does not exist");
    return scene.nodes[node];
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

LightArrival PunctualArrival(const PunctualLight& light, const glm::vec3& x, const glm::vec3& n,
                             float sceneDiameter) {
    LightArrival a;
    if (light.type == LightType::kDirectional) {
        a.toLight = -light.direction;
        a.span = a.toLight * (4.0f * std::max(sceneDiameter, 1e-3f));
        a.scale = 1.0f;
    } else {
        a.span = light.position - x;
        const float d2 = glm::dot(a.span, a.span);
        if (!(d2 > 0.0f)) return a;
        const float d = std::sqrt(d2);
        a.toLight = a.span / d;
        a.scale = LightAttenuation(light, -a.toLight, d) / d2;
    }
    a.cosine = glm::dot(n, a.toLight);
    a.reaches = a.cosine > 0.0f;
    if (a.reaches) a.irradiance = light.color * (light.intensity * a.scale * a.cosine);
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
    const SceneNode& n = NodeAt(scene, node);
    if (!Finite(local)) throw Error("transform of '" + n.name + "' has NaN or infinity");
    // glTF node transforms are affine: the bottom row (0, 0, 0, 1).
    if (std::abs(local[0][3]) > 1e-6f || std::abs(local[1][3]) > 1e-6f ||
        std::abs(local[2][3]) > 1e-6f || std::abs(local[3][3] - 1.0f) > 1e-6f)
        throw Error("transform of '" + n.name +
                    "' is not affine (its bottom row must be 0, 0, 0, 1: a projective matrix "
                    "cannot place geometry)");
    glm::mat4 parentWorld = n.parent >= 0 ? scene.nodes[n.parent].world : glm::mat4(1.0f);
    // Check every new world matrix before changing anything.
    std::vector<std::pair<int, glm::mat4>> world;
    PlaceSubtree(scene, node, parentWorld, local, world);
    for (const auto& [i, w] : world) {
        if (!Finite(w)) throw Error("transform of '" + n.name + "' overflows to infinity");
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

size_t NodeVertexCount(const Scene& scene, int node) {
    if (node < 0 || node >= static_cast<int>(scene.nodes.size())) return 0;
    size_t n = 0;
    for (uint32_t p : scene.nodes[node].primitives) n += scene.primitives[p].InputVertexCount();
    return n;
}

void SetNodeVertices(Scene& scene, int node, const std::vector<glm::vec3>& positions,
                     const std::vector<glm::vec3>& normals) {
    const SceneNode& n = NodeAt(scene, node);
    const size_t count = NodeVertexCount(scene, node);
    if (count == 0) throw Error("node '" + n.name + "' has no triangles to deform");
    if (positions.size() != count)
        throw Error("node '" + n.name + "' has " + std::to_string(count) + " vertices; " +
                    std::to_string(positions.size()) + " positions were given");
    if (!normals.empty() && normals.size() != count)
        throw Error("node '" + n.name + "' has " + std::to_string(count) + " vertices; " +
                    std::to_string(normals.size()) + " normals were given (give none or all)");
    auto finite = [](const glm::vec3& v) {
        return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
    };
    for (size_t i = 0; i < count; ++i) {
        if (!finite(positions[i]))
            throw Error("position " + std::to_string(i) + " of '" + n.name +
                        "' has NaN or infinity");
        if (!normals.empty() && !(finite(normals[i]) && glm::length(normals[i]) > 1e-12f))
            throw Error("normal " + std::to_string(i) + " of '" + n.name +
                        "' is zero, NaN or infinite");
    }
    const glm::mat4& w = n.world;
    const glm::mat3 normalMatrix = glm::transpose(glm::inverse(glm::mat3(w)));
    // The loader wound a mirrored node's triangles for the world: in its own space their
    // cross products point inwards.
    const float winding = glm::determinant(glm::mat3(w)) < 0.0f ? -1.0f : 1.0f;
    for (const bool apply : {false, true}) {  // every world position checked, then placed
        size_t at = 0;
        for (uint32_t pi : n.primitives) {
            Primitive& p = scene.primitives[pi];
            const size_t v = p.InputVertexCount();
            if (!apply) {
                for (size_t i = 0; i < v; ++i)
                    if (!finite(glm::vec3(w * glm::vec4(positions[at + i], 1.0f))))
                        throw Error("position " + std::to_string(at + i) + " of '" + n.name +
                                    "' overflows to infinity in the world");
                at += v;
                continue;
            }
            if (p.restPositions.empty()) {
                p.restPositions = p.objectPositions;
                p.restNormals = p.objectNormals;
            }
            p.objectPositions.assign(positions.begin() + at, positions.begin() + at + v);
            for (uint32_t i : p.copyOf) p.objectPositions.push_back(positions[at + i]);
            // A mesh split for flat normals keeps them flat (given normals are per input
            // vertex, not per plane).
            if (normals.empty() || !p.copyOf.empty()) {
                Primitive own;  // the deformed triangles' normals, in own space
                own.positions = p.objectPositions;
                own.indices = p.indices;
                ComputeVertexNormals(own);
                p.objectNormals = std::move(own.normals);
                for (glm::vec3& m : p.objectNormals) m *= winding;
            } else {
                p.objectNormals.assign(normals.begin() + at, normals.begin() + at + v);
                for (glm::vec3& m : p.objectNormals) m = glm::normalize(m);
            }
            for (size_t i = 0; i < p.positions.size(); ++i) {
                p.positions[i] = glm::vec3(w * glm::vec4(p.objectPositions[i], 1.0f));
                p.normals[i] = glm::normalize(normalMatrix * p.objectNormals[i]);
            }
            ++p.shape;
            at += v;
        }
    }
}

size_t NodeMorphTargets(const Scene& scene, int node) {
    if (node < 0 || node >= static_cast<int>(scene.nodes.size())) return 0;
    const SceneNode& n = scene.nodes[node];
    return n.primitives.empty() ? 0 : scene.primitives[n.primitives[0]].morphPositions.size();
}

void SetNodeMorphWeights(Scene& scene, int node, const std::vector<float>& weights) {
    const SceneNode& n = NodeAt(scene, node);
    const size_t targets = NodeMorphTargets(scene, node);
    if (targets == 0) throw Error("node '" + n.name + "' has no morph targets");
    if (weights.size() != targets)
        throw Error("node '" + n.name + "' has " + std::to_string(targets) + " morph targets; " +
                    std::to_string(weights.size()) + " weights were given");
    for (float x : weights)
        if (!std::isfinite(x)) throw Error("morph weights must be finite numbers");
    std::vector<glm::vec3> positions, normals;
    bool withNormals = true;  // every target of every primitive displaces the normals
    for (uint32_t pi : n.primitives)
        for (size_t t = 0; t < targets; ++t)
            withNormals = withNormals && t < scene.primitives[pi].morphNormals.size() &&
                          !scene.primitives[pi].morphNormals[t].empty();
    for (uint32_t pi : n.primitives) {
        const Primitive& p = scene.primitives[pi];
        const std::vector<glm::vec3>& rest = p.RestPositions();
        const std::vector<glm::vec3>& restNormals = p.RestNormals();
        for (size_t i = 0; i < p.InputVertexCount(); ++i) {  // copies follow their vertex
            glm::vec3 x = rest[i], m = restNormals[i];
            for (size_t t = 0; t < targets; ++t) {
                x += weights[t] * p.morphPositions[t][i];
                if (withNormals) m += weights[t] * p.morphNormals[t][i];
            }
            positions.push_back(x);
            if (withNormals) normals.push_back(glm::length(m) > 1e-12f ? m : restNormals[i]);
        }
    }
    SetNodeVertices(scene, node, positions, withNormals ? normals : std::vector<glm::vec3>{});
    scene.nodes[node].morphWeights = weights;
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

void SplitForFlatNormals(Primitive& p) {
    PENUMBRA_CHECK(p.copyOf.empty());
    const size_t n = p.positions.size(), triangles = p.indices.size() / 3;
    // Each vertex's triangles (CSR).
    std::vector<uint32_t> start(n + 1, 0), around(triangles * 3);
    for (size_t c = 0; c < triangles * 3; ++c) ++start[p.indices[c] + 1];
    for (size_t v = 0; v < n; ++v) start[v + 1] += start[v];
    std::vector<uint32_t> fill(start.begin(), start.end() - 1);
    for (size_t c = 0; c < triangles * 3; ++c) around[fill[p.indices[c]]++] = uint32_t(c);
    std::vector<glm::vec3> facing(triangles, glm::vec3(0.0f));  // unit, or zero when degenerate
    for (size_t t = 0; t < triangles; ++t) {
        const glm::vec3& a = p.positions[p.indices[t * 3]];
        const glm::vec3 c = glm::cross(p.positions[p.indices[t * 3 + 1]] - a,
                                       p.positions[p.indices[t * 3 + 2]] - a);
        const float len = glm::length(c);
        if (len > 0.0f && std::isfinite(len)) facing[t] = c / len;
    }
    constexpr float kSamePlane = 0.9999f;  // cos 0.81°
    auto copy = [&](uint32_t v) {
        const uint32_t k = static_cast<uint32_t>(p.positions.size());
        for (auto& set : p.texcoords)  // the per-vertex lists (a set not read is empty)
            if (set.size() == k) set.push_back(set[v]);
        for (auto* targets : {&p.morphPositions, &p.morphNormals})
            for (auto& target : *targets)
                if (target.size() == k) target.push_back(target[v]);
        p.positions.push_back(p.positions[v]);
        p.copyOf.push_back(v);
        return k;
    };
    std::vector<glm::vec3> planes;  // this vertex's, one vertex each
    std::vector<uint32_t> vertexOf;
    for (uint32_t v = 0; v < n; ++v) {
        planes.clear();
        vertexOf.clear();
        for (uint32_t i = start[v]; i < start[v + 1]; ++i) {
            const uint32_t corner = around[i];
            const glm::vec3& f = facing[corner / 3];
            if (f == glm::vec3(0.0f)) continue;  // degenerate: keeps v, the first plane's
            size_t g = 0;
            while (g < planes.size() && glm::dot(planes[g], f) < kSamePlane) ++g;
            if (g == planes.size()) {
                planes.push_back(f);
                vertexOf.push_back(planes.size() == 1 ? v : copy(v));
            }
            p.indices[corner] = vertexOf[g];
        }
    }
    ComputeVertexNormals(p);
}

std::vector<float> VertexAreas(const Primitive& p) {
    std::vector<float> area(p.positions.size(), 0.0f);
    for (size_t t = 0; t + 2 < p.indices.size(); t += 3) {
        const glm::vec3& a = p.positions[p.indices[t]];
        const float third = glm::length(glm::cross(p.positions[p.indices[t + 1]] - a,
                                                   p.positions[p.indices[t + 2]] - a)) /
                            6.0f;
        for (int c = 0; c < 3; ++c) area[p.indices[t + c]] += third;
    }
    return area;
}

std::vector<glm::vec3> ToInputVertices(const Primitive& p, std::vector<glm::vec3> perVertex) {
    PENUMBRA_CHECK_EQ(perVertex.size(), p.positions.size());
    const size_t n = p.InputVertexCount();
    if (p.copyOf.empty()) return perVertex;  // moved out: no copy on a frame's path
    const std::vector<float> area = VertexAreas(p);
    std::vector<glm::vec3> sum(n, glm::vec3(0.0f));
    std::vector<float> weight(n, 0.0f);
    for (size_t k = 0; k < perVertex.size(); ++k) {
        const uint32_t i = p.InputVertex(k);
        sum[i] += area[k] * perVertex[k];
        weight[i] += area[k];
    }
    // A vertex on degenerate triangles only has no area: its own value.
    for (size_t i = 0; i < n; ++i) sum[i] = weight[i] > 0.0f ? sum[i] / weight[i] : perVertex[i];
    return sum;
}

}  // namespace penumbra
