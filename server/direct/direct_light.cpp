// Shadow views of punctual lights, and the CPU twins of the shadow and direct passes.
// shaders/shadow.{vert,frag} and shaders/direct.comp are the Vulkan side of the same
// arithmetic; keep them in step.
#include "direct/direct_light.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <glm/gtc/matrix_transform.hpp>
#include <unordered_map>

#include "base/check.h"
#include "base/numeric.h"
#include "direct/direct_stage.h"

namespace penumbra::direct {
namespace {

// An up vector that is not parallel to `forward`.
glm::vec3 UpFor(const glm::vec3& forward) {
    return std::abs(forward.y) > 0.9f ? glm::vec3(0.0f, 0.0f, 1.0f) : glm::vec3(0.0f, 1.0f, 0.0f);
}

GpuShadowView PerspectiveView(const glm::vec3& eye, const glm::vec3& forward, float tanHalf,
                              float nearZ, float farZ, int size) {
    GpuShadowView v{};
    glm::mat4 view = glm::lookAtRH(eye, eye + forward, UpFor(forward));
    glm::mat4 proj = glm::perspectiveRH_ZO(2.0f * std::atan(tanHalf), 1.0f, nearZ, farZ);
    v.viewProj = proj * view;
    v.eye = glm::vec4(eye, 0.0f);
    v.forward = glm::vec4(forward, 2.0f * tanHalf / static_cast<float>(size));
    return v;
}

// Branchless orthonormal basis around a unit normal (Duff et al. 2017); direct.glsl has
// the same lines.
void TangentBasis(const glm::vec3& n, glm::vec3& t, glm::vec3& b) {
    float sign = n.z >= 0.0f ? 1.0f : -1.0f;
    float a = -1.0f / (sign + n.z);
    float c = n.x * n.y * a;
    t = glm::vec3(1.0f + sign * n.x * n.x * a, sign * c, -sign * n.x);
    b = glm::vec3(c, sign + n.y * n.y * a, -n.y);
}

}  // namespace

bool CubeNdc(const GpuLight& light, int face, const glm::vec3& q, glm::vec3& ndc) {
    glm::vec3 forward(0.0f);
    forward[face / 2] = face % 2 ? -1.0f : 1.0f;
    const glm::vec3 up = std::abs(forward.y) > 0.9f ? glm::vec3(0, 0, 1) : glm::vec3(0, 1, 0);
    const glm::vec3 right = glm::cross(forward, up), top = glm::cross(right, forward);
    const glm::vec3 v = q - glm::vec3(light.position);
    const float depth = glm::dot(forward, v);
    if (!(depth > 0.0f)) return false;
    ndc = glm::vec3(glm::dot(right, v) * light.cube.z / depth,
                    glm::dot(top, v) * light.cube.z / depth, light.cube.x - light.cube.y / depth);
    return true;
}

namespace {

// Which face of a cube light sees the point at v from the light: 0…5 for +x, −x, +y, −y,
// +z, −z (PlanShadows's order).
int CubeFace(const glm::vec3& v) {
    glm::vec3 a = glm::abs(v);
    if (a.x >= a.y && a.x >= a.z) return v.x >= 0.0f ? 0 : 1;
    if (a.y >= a.z) return v.y >= 0.0f ? 2 : 3;
    return v.z >= 0.0f ? 4 : 5;
}

// The lit fraction of a bilinear 2×2 footprint of view `vi`'s map around `ndc`.
float MapVisibility(const Plan& plan, const float* maps, int vi, const glm::vec3& ndc) {
    if (std::abs(ndc.x) > 1.0f || std::abs(ndc.y) > 1.0f || ndc.z < 0.0f || ndc.z > 1.0f)
        return 1.0f;
    const int size = plan.mapSize;
    float u = (ndc.x * 0.5f + 0.5f) * size - 0.5f, v = (ndc.y * 0.5f + 0.5f) * size - 0.5f;
    float fu = std::floor(u), fv = std::floor(v);
    float wu = u - fu, wv = v - fv;
    int x0 = static_cast<int>(fu), y0 = static_cast<int>(fv);
    const float* map = maps + size_t(vi) * size * size;
    auto lit = [&](int x, int y) {
        x = std::clamp(x, 0, size - 1);
        y = std::clamp(y, 0, size - 1);
        return ndc.z <= map[size_t(y) * size + x] ? 1.0f : 0.0f;
    };
    return (1.0f - wv) * ((1.0f - wu) * lit(x0, y0) + wu * lit(x0 + 1, y0)) +
           wv * ((1.0f - wu) * lit(x0, y0 + 1) + wu * lit(x0 + 1, y0 + 1));
}

// Fraction of a tap at q that a single-view light reaches (its view loaded once a
// receiver). `toLight` is the unit direction to the light, n the receiver's normal (for
// the offset against acne).
float ViewTapVisibility(const Plan& plan, const float* maps, int vi, const GpuShadowView& view,
                        glm::vec3 q, const glm::vec3& n, const glm::vec3& toLight) {
    float texel =
        view.eye.w > 0.5f
            ? view.forward.w
            : view.forward.w *
                  std::max(glm::dot(q - glm::vec3(view.eye), glm::vec3(view.forward)), 0.0f);
    q += n * (2.0f * texel) + toLight * texel;
    glm::vec4 clip = view.viewProj * glm::vec4(q, 1.0f);
    if (!(clip.w > 0.0f)) return 1.0f;
    return MapVisibility(plan, maps, vi, glm::vec3(clip) / clip.w);
}

// The same for a cube light: the tap's face and its projection from the light's `cube`
// parameters, the face's frame as glm::lookAtRH builds it (PerspectiveView, UpFor), so no
// view is loaded per tap (on lavapipe, 24 texel fetches).
float CubeTapVisibility(const Plan& plan, const float* maps, const GpuLight& light, glm::vec3 q,
                        const glm::vec3& n, const glm::vec3& toLight) {
    const glm::vec3 eye(light.position);
    const int face = CubeFace(q - eye);
    // Depth along the face's axis: the largest |coordinate|, the one CubeFace picked.
    float texel = light.cube.w * std::abs((q - eye)[face / 2]);
    q += n * (2.0f * texel) + toLight * texel;
    glm::vec3 ndc;
    if (!CubeNdc(light, face, q, ndc)) return 1.0f;
    return MapVisibility(plan, maps, static_cast<int>(light.cone.z) + face, ndc);
}

// One screen-space triangle: texel coordinates and NDC depth.
struct ScreenTriangle {
    glm::vec3 a, b, c;
    float minX, maxX, minY, maxY;
};

// Clips a clip-space triangle to z >= 0 (the ZO near plane) and appends the resulting
// screen triangles (one polygon, fanned).
void ClipAndProject(const glm::vec4 in[3], int size, std::vector<ScreenTriangle>& out) {
    glm::vec4 poly[4];
    int n = 0;
    for (int i = 0; i < 3; ++i) {
        const glm::vec4& p = in[i];
        const glm::vec4& q = in[(i + 1) % 3];
        bool pIn = p.z >= 0.0f, qIn = q.z >= 0.0f;
        if (pIn) poly[n++] = p;
        if (pIn != qIn) poly[n++] = p + (q - p) * (p.z / (p.z - q.z));
    }
    if (n < 3) return;
    glm::vec3 s[4];
    for (int i = 0; i < n; ++i) {
        if (!(poly[i].w > 0.0f)) return;
        glm::vec3 ndc = glm::vec3(poly[i]) / poly[i].w;
        s[i] = glm::vec3((ndc.x * 0.5f + 0.5f) * size, (ndc.y * 0.5f + 0.5f) * size, ndc.z);
    }
    for (int i = 1; i + 1 < n; ++i) {
        ScreenTriangle t{s[0], s[i], s[i + 1], 0, 0, 0, 0};
        t.minX = std::min({t.a.x, t.b.x, t.c.x});
        t.maxX = std::max({t.a.x, t.b.x, t.c.x});
        t.minY = std::min({t.a.y, t.b.y, t.c.y});
        t.maxY = std::max({t.a.y, t.b.y, t.c.y});
        if (t.maxX < 0.0f || t.minX > size || t.maxY < 0.0f || t.minY > size) continue;
        out.push_back(t);
    }
}

// Depth-only rasterisation of `tris` into rows [y0, y1) of `map`: pixel centres at
// (x + ½, y + ½), both windings, nearest depth kept, depths outside [0, 1] dropped.
void RasterRows(const std::vector<ScreenTriangle>& tris, int size, int y0, int y1, float* map) {
    for (const ScreenTriangle& t : tris) {
        if (t.maxY < y0 || t.minY > y1) continue;
        float area = (t.b.x - t.a.x) * (t.c.y - t.a.y) - (t.b.y - t.a.y) * (t.c.x - t.a.x);
        if (area == 0.0f || !std::isfinite(area)) continue;
        float inv = 1.0f / area;
        int xa = std::max(0, static_cast<int>(std::floor(t.minX - 0.5f)));
        int xb = std::min(size - 1, static_cast<int>(std::ceil(t.maxX - 0.5f)));
        int ya = std::max(y0, static_cast<int>(std::floor(t.minY - 0.5f)));
        int yb = std::min(y1 - 1, static_cast<int>(std::ceil(t.maxY - 0.5f)));
        for (int y = ya; y <= yb; ++y) {
            float py = y + 0.5f;
            for (int x = xa; x <= xb; ++x) {
                float px = x + 0.5f;
                // Barycentric weights, made positive for either winding by 1/area.
                float w0 = ((t.b.x - px) * (t.c.y - py) - (t.b.y - py) * (t.c.x - px)) * inv;
                float w1 = ((t.c.x - px) * (t.a.y - py) - (t.c.y - py) * (t.a.x - px)) * inv;
                float w2 = 1.0f - w0 - w1;
                if (w0 < 0.0f || w1 < 0.0f || w2 < 0.0f) continue;
                float z = w0 * t.a.z + w1 * t.b.z + w2 * t.c.z;
                if (z < 0.0f || z > 1.0f) continue;
                float& d = map[size_t(y) * size + x];
                d = std::min(d, z);
            }
        }
    }
}

}  // namespace

int AutoMapSize(float diameter, float elementSize) {
    float want = elementSize > 0.0f ? 4.0f * diameter / elementSize : 2048.0f;
    int size = 256;
    while (size < 2048 && size < want) size *= 2;
    return size;
}

Plan PlanShadows(const Scene& scene, int mapSize) {
    if (mapSize < 16 || mapSize > 8192) throw Error("shadow map size must be 16…8192 texels");
    Plan plan;
    plan.mapSize = mapSize;
    glm::vec3 lo = scene.BoundsMin(), hi = scene.BoundsMax();
    glm::vec3 centre = 0.5f * (lo + hi);
    float radius = 0.5f * glm::length(hi - lo) * 1.01f + 1e-4f;
    float margin = 1.0f + 4.0f / static_cast<float>(mapSize);  // texels past the cone's edge
    for (const PunctualLight& light : scene.lights) {
        GpuLight g{};
        float type = light.type == LightType::kPoint  ? 0.0f
                     : light.type == LightType::kSpot ? 1.0f
                                                      : 2.0f;
        g.position = glm::vec4(light.position, type);
        g.direction = glm::vec4(light.direction, light.range);
        g.radiant = glm::vec4(light.color * light.intensity, 0.0f);
        float cosOuter = std::cos(light.outerCone);
        g.cone = glm::vec4(cosOuter, 1.0f / std::max(1e-3f, std::cos(light.innerCone) - cosOuter),
                           static_cast<float>(plan.views.size()), 1.0f);
        if (light.type == LightType::kDirectional) {
            GpuShadowView v{};
            glm::vec3 eye = centre - light.direction * (2.0f * radius);
            glm::mat4 view = glm::lookAtRH(eye, centre, UpFor(light.direction));
            glm::mat4 proj =
                glm::orthoRH_ZO(-radius, radius, -radius, radius, radius, 3.0f * radius);
            v.viewProj = proj * view;
            v.eye = glm::vec4(eye, 1.0f);
            v.forward = glm::vec4(light.direction, 2.0f * radius / static_cast<float>(mapSize));
            plan.views.push_back(v);
        } else {
            float farZ = 0.0f;
            for (int c = 0; c < 8; ++c) {
                glm::vec3 corner((c & 1) ? hi.x : lo.x, (c & 2) ? hi.y : lo.y,
                                 (c & 4) ? hi.z : lo.z);
                farZ = std::max(farZ, glm::length(corner - light.position));
            }
            float nearZ = std::max(1e-4f, 1e-3f * radius);
            farZ = std::max(farZ * 1.01f, 2.0f * nearZ);
            if (light.type == LightType::kSpot && light.outerCone <= kMaxSpotViewCone) {
                plan.views.push_back(PerspectiveView(light.position, light.direction,
                                                     std::tan(light.outerCone) * margin, nearZ,
                                                     farZ, mapSize));
            } else {
                static const glm::vec3 kAxes[6] = {{1, 0, 0},  {-1, 0, 0}, {0, 1, 0},
                                                   {0, -1, 0}, {0, 0, 1},  {0, 0, -1}};
                for (const glm::vec3& axis : kAxes)
                    plan.views.push_back(
                        PerspectiveView(light.position, axis, margin, nearZ, farZ, mapSize));
                g.cone.w = 6.0f;
                // The faces' projection (glm::perspectiveRH_ZO: NDC depth = f/(f−n) −
                // n f/(f−n) / depth).
                g.cube = glm::vec4(farZ / (farZ - nearZ), nearZ * farZ / (farZ - nearZ),
                                   1.0f / margin, 2.0f * margin / static_cast<float>(mapSize));
            }
        }
        plan.lights.push_back(g);
    }
    return plan;
}

std::vector<glm::vec3> SceneTriangles(const Scene& scene) {
    std::vector<glm::vec3> tris;
    tris.reserve(scene.TriangleCount() * 3);
    for (const Primitive& p : scene.primitives)
        for (uint32_t i : p.indices) tris.push_back(p.positions[i]);
    return tris;
}

void ViewTriangles(const glm::mat4& viewProj, const std::vector<glm::vec3>& triangles,
                   std::vector<uint32_t>& indices) {
    indices.clear();
    for (size_t t = 0; t + 2 < triangles.size(); t += 3) {
        // Bit k set: the vertex is beyond plane k.
        uint32_t all = 0x3f;
        for (int k = 0; k < 3; ++k) {
            const glm::vec4 c = viewProj * glm::vec4(triangles[t + k], 1.0f);
            all &= (c.x < -c.w ? 1u : 0u) | (c.x > c.w ? 2u : 0u) | (c.y < -c.w ? 4u : 0u) |
                   (c.y > c.w ? 8u : 0u) | (c.z < 0.0f ? 16u : 0u) | (c.z > c.w ? 32u : 0u);
        }
        if (all) continue;
        for (int k = 0; k < 3; ++k) indices.push_back(static_cast<uint32_t>(t + k));
    }
}

namespace {

// Distance from p to the segment ab.
float SegmentDistance(const glm::vec3& p, const glm::vec3& a, const glm::vec3& b) {
    const glm::vec3 ab = b - a;
    const float len2 = glm::dot(ab, ab);
    const float t = len2 > 0.0f ? std::clamp(glm::dot(p - a, ab) / len2, 0.0f, 1.0f) : 0.0f;
    return glm::length(p - (a + t * ab));
}

// Per surfel, the largest footprint radius that keeps its disc on its own surface: ½√area,
// or less where a boundary edge of the refined mesh (an edge of one triangle) passes closer
// to its centroid, for the surfels of every triangle at that edge's ends.
std::vector<float> FootprintRadii(const Surfels& surfels) {
    std::vector<float> radius(surfels.size());
    for (size_t s = 0; s < surfels.size(); ++s) radius[s] = 0.5f * std::sqrt(surfels.areas[s]);
    const std::vector<uint32_t>& t = surfels.refinedTriangles;
    std::unordered_map<uint64_t, uint32_t> edges;  // (low << 32 | high) → triangles on it
    for (size_t i = 0; i + 2 < t.size(); i += 3)
        for (int k = 0; k < 3; ++k) {
            const uint32_t a = t[i + k], b = t[i + (k + 1) % 3];
            ++edges[uint64_t(std::min(a, b)) << 32 | std::max(a, b)];
        }
    std::vector<uint32_t> firstAt(surfels.size() + 1, 0), at(t.size());  // triangles a surfel
    for (uint32_t v : t) ++firstAt[v + 1];
    for (size_t s = 0; s < surfels.size(); ++s) firstAt[s + 1] += firstAt[s];
    std::vector<uint32_t> fill(firstAt.begin(), firstAt.end() - 1);
    for (size_t i = 0; i < t.size(); ++i) at[fill[t[i]]++] = uint32_t(i / 3);
    for (const auto& [key, count] : edges) {
        if (count != 1) continue;
        const uint32_t a = uint32_t(key >> 32), b = uint32_t(key);
        const glm::vec3 &pa = surfels.positions[a], &pb = surfels.positions[b];
        for (uint32_t end : {a, b})
            for (uint32_t k = firstAt[end]; k < firstAt[end + 1]; ++k)
                for (int c = 0; c < 3; ++c) {
                    const uint32_t s = t[size_t(at[k]) * 3 + c];
                    radius[s] = std::min(radius[s], SegmentDistance(surfels.centroids[s], pa, pb));
                }
    }
    return radius;
}

}  // namespace

std::vector<GpuReceiver> MakeReceivers(const Surfels& surfels, const std::vector<uint32_t>& order) {
    std::vector<GpuReceiver> out;
    out.reserve(order.size());
    const std::vector<float> radius = FootprintRadii(surfels);
    for (uint32_t s : order) {
        GpuReceiver r{};
        r.position = glm::vec4(surfels.positions[s], radius[s]);
        r.normal = glm::vec4(surfels.normals[s], 0.0f);
        r.centroid = glm::vec4(surfels.centroids[s], 0.0f);
        out.push_back(r);
    }
    return out;
}

void RasterShadowMaps(const Plan& plan, const std::vector<glm::vec3>& triangles,
                      std::vector<float>& maps) {
    const int size = plan.mapSize;
    maps.assign(plan.MapTexels(), 1.0f);
    std::vector<std::vector<ScreenTriangle>> screen(plan.views.size());
    tbb::parallel_for(size_t(0), plan.views.size(), [&](size_t v) {
        const glm::mat4& m = plan.views[v].viewProj;
        for (size_t t = 0; t + 2 < triangles.size(); t += 3) {
            glm::vec4 clip[3] = {m * glm::vec4(triangles[t], 1.0f),
                                 m * glm::vec4(triangles[t + 1], 1.0f),
                                 m * glm::vec4(triangles[t + 2], 1.0f)};
            ClipAndProject(clip, size, screen[v]);
        }
    });
    constexpr int kBand = 32;
    const int bands = (size + kBand - 1) / kBand;
    tbb::parallel_for(size_t(0), plan.views.size() * bands, [&](size_t job) {
        size_t v = job / bands;
        int y0 = static_cast<int>(job % bands) * kBand;
        RasterRows(screen[v], size, y0, std::min(size, y0 + kBand),
                   maps.data() + v * size_t(size) * size);
    });
}

namespace {

// The direct pass over `receivers` (DirectIrradiance's outputs), with each tap's visibility
// from `visible(light index, tap q, normal n, unit direction to the light, footprint radius)`.
template <class TapVisible>
void Irradiance(const Plan& plan, const std::vector<GpuReceiver>& receivers, float* out,
                float* perLight, const TapVisible& visible) {
    tbb::parallel_for(size_t(0), receivers.size(), [&](size_t i) {
        const GpuReceiver& r = receivers[i];
        const glm::vec3 p(r.position), n(r.normal), c(r.centroid);
        glm::vec3 t, b;
        TangentBasis(n, t, b);
        glm::vec3 e(0.0f);
        for (size_t li = 0; li < plan.lights.size(); ++li) {
            const GpuLight& light = plan.lights[li];
            float* mine = perLight ? perLight + (li * receivers.size() + i) * 4 : nullptr;
            if (mine) std::fill(mine, mine + 4, 0.0f);
            glm::vec3 toLight;
            float scale;
            if (light.position.w == 2.0f) {
                toLight = -glm::vec3(light.direction);
                scale = 1.0f;
            } else {
                glm::vec3 v = glm::vec3(light.position) - p;
                float d2 = glm::dot(v, v);
                if (!(d2 > 1e-12f)) continue;
                float d = std::sqrt(d2);
                toLight = v / d;
                // LightAttenuation (scene.cpp), as the shaders have it.
                scale = 1.0f / d2;
                if (light.direction.w > 0.0f) {
                    float x = d / light.direction.w;
                    float w = std::clamp(1.0f - x * x * x * x, 0.0f, 1.0f);
                    scale *= w * w;
                }
                if (light.position.w == 1.0f) {
                    float s =
                        std::clamp((glm::dot(glm::vec3(light.direction), -toLight) - light.cone.x) *
                                       light.cone.y,
                                   0.0f, 1.0f);
                    scale *= s * s;
                }
            }
            float cosine = glm::dot(n, toLight);
            if (cosine <= 0.0f || scale <= 0.0f) continue;
            glm::vec3 seen(0.0f);  // per channel: a tap behind glass sees its transmittance
            for (int k = 0; k < kTaps; ++k) {
                float rr = r.position.w * std::sqrt((k + 0.5f) / kTaps);
                float phi = 2.3999632f * k;  // the golden angle: a Vogel disc
                glm::vec3 q = c + rr * (std::cos(phi) * t + std::sin(phi) * b);
                glm::vec3 qToLight = light.position.w == 2.0f
                                         ? toLight
                                         : glm::normalize(glm::vec3(light.position) - q);
                seen += visible(li, q, n, qToLight, r.position.w);
            }
            glm::vec3 ek = glm::vec3(light.radiant) * seen * (scale * cosine / kTaps);
            e += ek;
            if (mine) mine[0] = ek.x, mine[1] = ek.y, mine[2] = ek.z;
        }
        out[i * 4] = e.x;
        out[i * 4 + 1] = e.y;
        out[i * 4 + 2] = e.z;
        out[i * 4 + 3] = 0.0f;
    });
}

}  // namespace

void DirectIrradiance(const Plan& plan, const float* maps,
                      const std::vector<GpuReceiver>& receivers, float* out, float* perLight) {
    Irradiance(
        plan, receivers, out, perLight,
        [&](size_t li, const glm::vec3& q, const glm::vec3& n, const glm::vec3& toLight, float) {
            const GpuLight& light = plan.lights[li];
            const int first = static_cast<int>(light.cone.z);
            return light.cone.w >= 6.0f
                       ? CubeTapVisibility(plan, maps, light, q, n, toLight)
                       : ViewTapVisibility(plan, maps, first, plan.views[first], q, n, toLight);
        });
}

void DirectIrradianceByRays(const Plan& plan, const RayScene& rays,
                            const std::vector<GpuReceiver>& receivers, float* out,
                            float* perLight) {
    // A directional light's rays reach 4 scene diameters (LightArrival).
    const float far = 4.0f * std::max(rays.GetScene().Diameter(), 1e-6f);
    Irradiance(plan, receivers, out, perLight,
               [&](size_t li, const glm::vec3& q, const glm::vec3& n, const glm::vec3& toLight,
                   float radius) {
                   const GpuLight& light = plan.lights[li];
                   const glm::vec3 from = q + n * (0.1f * radius + rays.Epsilon());
                   const glm::vec3 span =
                       light.position.w == 2.0f ? toLight * far : glm::vec3(light.position) - from;
                   return rays.Transmittance(from, span);
               });
}

CpuDirect::CpuDirect(const Scene& scene, std::vector<GpuReceiver> receivers, int mapSize)
    : receivers_(std::move(receivers)) {
    if (mapSize < 16 || mapSize > 8192) throw Error("shadow map size must be 16…8192 texels");
    out_.assign(receivers_.size() * 4, 0.0f);
    Trace(scene);
    Update(scene);
}

void CpuDirect::Trace(const Scene& scene) {
    const auto start = std::chrono::steady_clock::now();
    rays_.reset();
    geometry_ = Scene{};
    geometry_.primitives = scene.primitives;
    geometry_.materials = scene.materials;
    geometry_.nodes = scene.nodes;
    rays_ = std::make_unique<RayScene>(geometry_);
    msShadow = MsSince(start);
}

void CpuDirect::Move(const Scene& scene, std::vector<GpuReceiver> receivers) {
    PENUMBRA_CHECK(receivers.size() == receivers_.size());
    receivers_ = std::move(receivers);
    Trace(scene);
    Update(scene);
}

void CpuDirect::Update(const Scene& scene) {
    const Plan plan = PlanShadows(scene, 16);  // the lights as the pass reads them
    views = 0;
    const auto start = std::chrono::steady_clock::now();
    perLight_.assign(plan.lights.size() * receivers_.size() * 4, 0.0f);
    DirectIrradianceByRays(plan, *rays_, receivers_, out_.data(), perLight_.data());
    msDirect = MsSince(start);
}

}  // namespace penumbra::direct
