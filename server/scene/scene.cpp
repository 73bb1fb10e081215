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

std::vector<std::string> SceneWarnings(const Scene& scene) {
    std::vector<std::string> out = scene.warnings;
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
    for (uint32_t p : scene.nodes[node].primitives) n += scene.primitives[p].positions.size();
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
            const size_t v = p.positions.size();
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
            if (normals.empty()) {
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
            for (size_t i = 0; i < v; ++i) {
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
        for (size_t i = 0; i < rest.size(); ++i) {
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

namespace {

// Distance from `p` to triangle abc (closest point by Voronoi regions, Ericson 5.1.5).
float PointTriangleDistance(const glm::vec3& p, const glm::vec3& a, const glm::vec3& b,
                            const glm::vec3& c) {
    glm::vec3 ab = b - a, ac = c - a, ap = p - a;
    float d1 = glm::dot(ab, ap), d2 = glm::dot(ac, ap);
    if (d1 <= 0 && d2 <= 0) return glm::length(ap);
    glm::vec3 bp = p - b;
    float d3 = glm::dot(ab, bp), d4 = glm::dot(ac, bp);
    if (d3 >= 0 && d4 <= d3) return glm::length(bp);
    float vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0) return glm::length(p - (a + ab * (d1 / (d1 - d3))));
    glm::vec3 cp = p - c;
    float d5 = glm::dot(ab, cp), d6 = glm::dot(ac, cp);
    if (d6 >= 0 && d5 <= d6) return glm::length(cp);
    float vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0) return glm::length(p - (a + ac * (d2 / (d2 - d6))));
    float va = d3 * d6 - d5 * d4;
    if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0)
        return glm::length(p - (b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)))));
    float denom = 1.0f / (va + vb + vc);
    return glm::length(p - (a + ab * (vb * denom) + ac * (vc * denom)));
}

struct OrientedMesh {
    std::vector<glm::vec3> points;      // welded positions
    std::vector<glm::uvec3> triangles;  // wound so the front is where vertex normals point
};

// A mesh's triangles split into shells: the surfaces of separate solids, joined across the
// edges where they pair. An edge of two triangles joins them. Where several solids of one
// mesh meet at an edge (boxes stacked with their sides flush, a shelf's board against its
// side), its triangles are paired about the edge: going round it, each triangle is joined to
// its neighbour across its back (the solid's inside between them), faces that lie in one
// plane ordered so that the gap between two touching solids is outside both. `count` 0: an
// edge that does not pair up (a triangle wound against its neighbour, an odd fan), so the
// mesh bounds no solid.
struct Shells {
    std::vector<uint32_t> of;  // per triangle
    uint32_t count = 0;
    // The open edges (a, b) as their one triangle runs them, each with that triangle.
    std::vector<std::array<uint32_t, 3>> open;
};

Shells SplitShells(const OrientedMesh& m) {
    const size_t n = m.triangles.size();
    std::vector<uint32_t> parent(n);
    for (size_t t = 0; t < n; ++t) parent[t] = uint32_t(t);
    auto find = [&](uint32_t t) {
        while (parent[t] != t) t = parent[t] = parent[parent[t]];
        return t;
    };
    // Undirected edge (low << 32 | high) → its triangles, each with its corner off the edge
    // and whether it runs low → high.
    struct Wing {
        uint32_t triangle, corner;
        bool forward;
    };
    std::unordered_map<uint64_t, std::vector<Wing>> edges;
    for (size_t t = 0; t < n; ++t)
        for (int e = 0; e < 3; ++e) {
            const uint32_t a = m.triangles[t][e], b = m.triangles[t][(e + 1) % 3],
                           c = m.triangles[t][(e + 2) % 3];
            const uint32_t lo = std::min(a, b), hi = std::max(a, b);
            edges[uint64_t(lo) << 32 | hi].push_back({uint32_t(t), c, a == lo});
        }
    constexpr double kTwoPi = 6.283185307179586, kTie = 1e-4;
    struct Around {
        double angle;
        bool frontAhead;  // its front faces the way the angle grows: the inside lies behind
        uint32_t wing;
    };
    std::vector<Around> around;
    std::vector<std::array<uint32_t, 3>> open;
    for (const auto& [key, wings] : edges) {
        if (wings.size() == 1) {  // an open edge: the shell's boundary
            const uint32_t lo = uint32_t(key >> 32), hi = uint32_t(key);
            open.push_back(wings[0].forward ? std::array<uint32_t, 3>{lo, hi, wings[0].triangle}
                                            : std::array<uint32_t, 3>{hi, lo, wings[0].triangle});
            continue;
        }
        if (wings.size() == 2) {
            if (wings[0].forward == wings[1].forward) return {};
            parent[find(wings[0].triangle)] = find(wings[1].triangle);
            continue;
        }
        // The triangles' half-planes about the edge, by angle from the first one's.
        const glm::dvec3 pa(m.points[key >> 32]), pb(m.points[uint32_t(key)]);
        const glm::dvec3 axis = glm::normalize(pb - pa);
        auto across = [&](const Wing& w) {
            const glm::dvec3 q = glm::dvec3(m.points[w.corner]) - pa;
            return q - glm::dot(q, axis) * axis;
        };
        const glm::dvec3 u = glm::normalize(across(wings[0])), v = glm::cross(axis, u);
        around.clear();
        for (uint32_t k = 0; k < wings.size(); ++k) {
            const glm::dvec3 w = across(wings[k]);
            if (!(glm::length(w) > 0.0)) return {};
            double angle = std::atan2(glm::dot(w, v), glm::dot(w, u));
            if (angle < 0.0) angle += kTwoPi;
            if (angle > kTwoPi - kTie) angle -= kTwoPi;  // in one plane with the first
            const glm::uvec3& t = m.triangles[wings[k].triangle];
            const glm::dvec3 normal =
                glm::cross(glm::dvec3(m.points[t.y]) - glm::dvec3(m.points[t.x]),
                           glm::dvec3(m.points[t.z]) - glm::dvec3(m.points[t.x]));
            around.push_back({angle, glm::dot(normal, glm::cross(axis, w)) > 0.0, k});
        }
        std::sort(around.begin(), around.end(),
                  [](const Around& x, const Around& y) { return x.angle < y.angle; });
        // Faces in one plane: those whose inside lies behind (the lower angles) first.
        for (size_t i = 0; i < around.size();) {
            size_t j = i + 1;
            while (j < around.size() && around[j].angle - around[j - 1].angle < kTie) ++j;
            std::stable_sort(
                around.begin() + long(i), around.begin() + long(j),
                [](const Around& x, const Around& y) { return x.frontAhead && !y.frontAhead; });
            i = j;
        }
        const size_t count = around.size();
        for (size_t i = 0; i < count; ++i) {
            const Around& x = around[i];
            const Around& y =
                x.frontAhead ? around[(i + count - 1) % count] : around[(i + 1) % count];
            // Its neighbour must turn its inside back to it, and run the edge the other way.
            if (y.frontAhead == x.frontAhead || wings[x.wing].forward == wings[y.wing].forward)
                return {};
            parent[find(wings[x.wing].triangle)] = find(wings[y.wing].triangle);
        }
    }
    Shells shells;
    shells.open = std::move(open);
    shells.of.assign(n, 0);
    std::vector<uint32_t> id(n, UINT32_MAX);
    for (size_t t = 0; t < n; ++t) {
        uint32_t& r = id[find(uint32_t(t))];
        if (r == UINT32_MAX) r = shells.count++;
        shells.of[t] = r;
    }
    return shells;
}

}  // namespace

std::vector<bool> ClosedNodes(const Scene& scene) {
    const float diameter = std::max(scene.Diameter(), 1e-6f);
    const float cell = diameter * 1e-6f;   // welds positions far closer than any element
    const float touch = diameter * 1e-4f;  // an open edge this close to a surface is sealed
    struct KeyHash {
        size_t operator()(const std::array<int64_t, 3>& k) const {
            return size_t(k[0] * 73856093) ^ size_t(k[1] * 19349663) ^ size_t(k[2] * 83492791);
        }
    };
    // Each node's triangles, welded and wound front-out.
    std::vector<OrientedMesh> meshes(scene.nodes.size());
    std::vector<glm::vec3> lo(scene.nodes.size(), glm::vec3(1e30f)),
        hi(lo.size(), glm::vec3(-1e30f));
    for (size_t n = 0; n < scene.nodes.size(); ++n) {
        OrientedMesh& m = meshes[n];
        std::unordered_map<std::array<int64_t, 3>, uint32_t, KeyHash> ids;
        for (uint32_t p : scene.nodes[n].primitives) {
            const Primitive& prim = scene.primitives[p];
            std::vector<uint32_t> id(prim.positions.size());
            for (size_t i = 0; i < prim.positions.size(); ++i) {
                glm::vec3 q = glm::round(prim.positions[i] / cell);
                std::array<int64_t, 3> k{int64_t(q.x), int64_t(q.y), int64_t(q.z)};
                auto [it, added] = ids.emplace(k, uint32_t(m.points.size()));
                if (added) m.points.push_back(prim.positions[i]);
                id[i] = it->second;
                lo[n] = glm::min(lo[n], prim.positions[i]);
                hi[n] = glm::max(hi[n], prim.positions[i]);
            }
            for (size_t t = 0; t + 2 < prim.indices.size(); t += 3) {
                uint32_t i0 = prim.indices[t], i1 = prim.indices[t + 1], i2 = prim.indices[t + 2];
                const glm::vec3 &a = prim.positions[i0], &b = prim.positions[i1];
                const glm::vec3& c = prim.positions[i2];
                glm::vec3 normal = prim.normals[i0] + prim.normals[i1] + prim.normals[i2];
                if (glm::dot(glm::cross(b - a, c - a), normal) < 0.0f) std::swap(i1, i2);
                glm::uvec3 v(id[i0], id[i1], id[i2]);
                if (v.x == v.y || v.y == v.z || v.z == v.x) continue;  // degenerate
                m.triangles.push_back(v);
            }
        }
    }
    // Per node its shells (SplitShells; empty where an edge does not pair up).
    std::vector<Shells> shells(meshes.size());
    for (size_t n = 0; n < meshes.size(); ++n) shells[n] = SplitShells(meshes[n]);
    // Is `p` on a triangle of another surface than shell `shell` of node `self`: another
    // node's, or another shell of its own (a box standing on a box of the same node)?
    auto onOtherSurface = [&](size_t self, uint32_t shell, const glm::vec3& p) {
        for (size_t o = 0; o < meshes.size(); ++o) {
            if (glm::any(glm::lessThan(p, lo[o] - touch)) ||
                glm::any(glm::greaterThan(p, hi[o] + touch)))
                continue;
            const OrientedMesh& m = meshes[o];
            for (size_t t = 0; t < m.triangles.size(); ++t) {
                if (o == self && shells[o].of[t] == shell) continue;
                const glm::uvec3& v = m.triangles[t];
                if (PointTriangleDistance(p, m.points[v.x], m.points[v.y], m.points[v.z]) <= touch)
                    return true;
            }
        }
        return false;
    };
    // A node closes solids when each of its shells closes one: its area, open edges and
    // volume summed per shell in one pass each (a mesh of many parts has many shells).
    std::vector<bool> closed(scene.nodes.size(), false);
    for (size_t n = 0; n < meshes.size(); ++n) {
        const OrientedMesh& m = meshes[n];
        const Shells& sh = shells[n];
        if (m.triangles.empty() || sh.count == 0) continue;
        std::vector<double> area(sh.count, 0.0), volume(sh.count, 0.0);
        for (size_t t = 0; t < m.triangles.size(); ++t) {
            const glm::uvec3& v = m.triangles[t];
            area[sh.of[t]] += 0.5 * glm::length(glm::cross(m.points[v.y] - m.points[v.x],
                                                           m.points[v.z] - m.points[v.x]));
        }
        // Signed volume (divergence theorem) about a point on the shell's open boundary's cap,
        // so a planar cap adds nothing: positive when the fronts face out.
        std::vector<glm::dvec3> origin(sh.count, glm::dvec3(0.0));
        std::vector<uint32_t> openEdges(sh.count, 0);
        for (const auto& [a, b, t] : sh.open) {
            origin[sh.of[t]] += glm::dvec3(m.points[a]);
            ++openEdges[sh.of[t]];
        }
        for (uint32_t k = 0; k < sh.count; ++k)
            if (openEdges[k] > 0) origin[k] /= double(openEdges[k]);
        for (size_t t = 0; t < m.triangles.size(); ++t) {
            const glm::uvec3& v = m.triangles[t];
            const glm::dvec3& o = origin[sh.of[t]];
            volume[sh.of[t]] +=
                glm::dot(glm::dvec3(m.points[v.x]) - o,
                         glm::cross(glm::dvec3(m.points[v.y]) - o, glm::dvec3(m.points[v.z]) - o)) /
                6.0;
        }
        // Far from flat: a planar open sheet has no volume whatever its boundary touches.
        bool all = true;
        for (uint32_t k = 0; all && k < sh.count; ++k)
            all = volume[k] > 1e-3 * area[k] * std::sqrt(area[k]);
        // An open boundary must be sealed by other surfaces (a box standing on a floor).
        for (size_t e = 0; all && e < sh.open.size(); ++e) {
            const auto& [a, b, t] = sh.open[e];
            const glm::vec3 &pa = m.points[a], &pb = m.points[b];
            all = onOtherSurface(n, sh.of[t], pa) && onOtherSurface(n, sh.of[t], pb) &&
                  onOtherSurface(n, sh.of[t], 0.5f * (pa + pb));
        }
        closed[n] = all;
    }
    return closed;
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
