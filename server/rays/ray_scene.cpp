// Embree 3 BVH over the scene's triangles (ray_scene.h).
#include "rays/ray_scene.h"

#include <embree3/rtcore.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "base/check.h"
#include "rays/sampling.h"

namespace penumbra {
namespace {

void OnError(void* self, RTCError code, const char* what) {
    auto* error = static_cast<std::string*>(self);
    if (error->empty())
        *error = "Embree error " + std::to_string(int(code)) + ": " + (what ? what : "");
}

void InitRay(RTCRay& r, const glm::vec3& o, const glm::vec3& d, float tfar) {
    r.org_x = o.x, r.org_y = o.y, r.org_z = o.z;
    r.dir_x = d.x, r.dir_y = d.y, r.dir_z = d.z;
    r.tnear = 0.0f;
    r.tfar = tfar;
    r.time = 0.0f;
    r.mask = ~0u;
    r.id = 0;
    r.flags = 0;
}

// Ray i of a packet of 8 (Embree's SoA layout, RTCRay8 or the ray of RTCRayHit8).
template <typename Ray8>
void SetRay8(Ray8& r, int i, const glm::vec3& o, const glm::vec3& d, float tfar) {
    r.org_x[i] = o.x, r.org_y[i] = o.y, r.org_z[i] = o.z;
    r.dir_x[i] = d.x, r.dir_y[i] = d.y, r.dir_z[i] = d.z;
    r.tnear[i] = 0.0f;
    r.tfar[i] = tfar;
    r.time[i] = 0.0f;
    r.mask[i] = ~0u;
    r.id[i] = 0;
    r.flags[i] = 0;
}

// The context of RayScene::AllHits: Embree's, then where the filter puts what it meets.
struct AllHitsContext {
    RTCIntersectContext ctx;
    std::vector<RayHit>* hits;
};

// Records each hit the traversal finds and rejects it, so that the ray goes on to the next.
void RecordHit(const RTCFilterFunctionNArguments* args) {
    auto* context = reinterpret_cast<AllHitsContext*>(args->context);
    for (unsigned i = 0; i < args->N; ++i) {
        if (args->valid[i] == 0) continue;
        RayHit h;
        h.hit = true;
        h.triangle = RTCHitN_primID(args->hit, args->N, i);
        h.t = RTCRayN_tfar(args->ray, args->N, i);
        h.u = RTCHitN_u(args->hit, args->N, i);
        h.v = RTCHitN_v(args->hit, args->N, i);
        context->hits->push_back(h);
        args->valid[i] = 0;
    }
}

// The context of a query through passing surfaces (Material::transmittance): Embree's, then
// what the filter gathers. An occlusion query multiplies `through` by each passing surface it
// meets and goes on (an opaque one ends it); an intersection query records each passing hit
// (they come in no order) and goes on to the nearest opaque one.
struct PassContext {
    RTCIntersectContext ctx;
    const RayScene* rays = nullptr;
    glm::vec3 through{1.0f};
    // Passing triangles met: Embree can meet one twice (its spatial splits).
    uint32_t seen[16];
    int seenCount = 0;
    std::vector<std::pair<float, uint32_t>>* passed = nullptr;  // intersection: (t, triangle)

    bool Seen(uint32_t triangle) {
        for (int i = 0; i < seenCount; ++i)
            if (seen[i] == triangle) return true;
        if (seenCount < 16) seen[seenCount++] = triangle;
        return false;
    }
};

void PassFilter(const RTCFilterFunctionNArguments* args) {
    auto* c = reinterpret_cast<PassContext*>(args->context);
    for (unsigned i = 0; i < args->N; ++i) {
        if (args->valid[i] == 0) continue;
        const uint32_t t = RTCHitN_primID(args->hit, args->N, i);
        const glm::vec3& pass = c->rays->MaterialOf(t).transmittance;
        if (pass == glm::vec3(0.0f)) continue;  // opaque: the hit stands
        if (c->passed)
            c->passed->emplace_back(RTCRayN_tfar(args->ray, args->N, i), t);
        else if (!c->Seen(t))
            c->through *= pass;
        args->valid[i] = 0;
    }
}

}  // namespace

RayScene::RayScene(const Scene& scene) : scene_(scene), mapped_(AnyMapped(scene)) {
    for (uint32_t p = 0; p < scene_.primitives.size(); ++p) {
        const Primitive& prim = scene_.primitives[p];
        for (size_t i = 0; i + 2 < prim.indices.size(); i += 3) {
            uint32_t a = prim.indices[i], b = prim.indices[i + 1], c = prim.indices[i + 2];
            AddTriangle(prim.positions[a], prim.positions[b], prim.positions[c],
                        prim.normals[a] + prim.normals[b] + prim.normals[c], p);
            if (mapped_) vertices_.emplace_back(a, b, c);
        }
    }
    Build();
}

RayScene::RayScene(const Scene& scene, const Surfels& surfels)
    : scene_(scene),
      mapped_(!surfels.albedoTints.empty()),
      albedoTints_(surfels.albedoTints),
      emissionTints_(surfels.emissionTints) {
    if (surfels.firstSurfel.size() != scene.primitives.size())
        throw Error("RayScene: the surfels were refined from another scene");
    const auto& t = surfels.refinedTriangles;
    size_t p = 0;  // the primitive of the triangles' surfels (surfels run primitive by primitive)
    for (size_t i = 0; i + 2 < t.size(); i += 3) {
        const uint32_t a = t[i], b = t[i + 1], c = t[i + 2];
        while (p + 1 < surfels.firstSurfel.size() && a >= surfels.firstSurfel[p + 1]) ++p;
        while (p > 0 && a < surfels.firstSurfel[p]) --p;
        AddTriangle(surfels.positions[a], surfels.positions[b], surfels.positions[c],
                    surfels.normals[a] + surfels.normals[b] + surfels.normals[c],
                    static_cast<uint32_t>(p));
        corners_.emplace_back(a, b, c);
    }
    Build();
}

void RayScene::Update(const Surfels& surfels) {
    if (corners_.empty() || surfels.refinedTriangles.size() != 3 * corners_.size())
        throw Error("RayScene: Update needs the refined mesh it was built over");
    const std::vector<RayTriangle> before = std::move(tris_);
    tris_.clear();
    for (size_t i = 0; i < corners_.size(); ++i) {
        const glm::uvec3& c = corners_[i];
        AddTriangle(surfels.positions[c.x], surfels.positions[c.y], surfels.positions[c.z],
                    surfels.normals[c.x] + surfels.normals[c.y] + surfels.normals[c.z],
                    before[i].primitive);
    }
    emitters_.clear(), cdf_.clear(), emitterPrimitives_.clear();
    eps_ = 1e-4f * std::max(scene_.Diameter(), 1e-6f);
    Sample();
    RTCGeometry geom = rtcGetGeometry(rtcScene_, 0);
    WriteVertices(static_cast<float*>(rtcGetGeometryBufferData(geom, RTC_BUFFER_TYPE_VERTEX, 0)));
    rtcUpdateGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0);
    // A move's rebuild at medium quality: a quarter of the high-quality build's time, for the
    // few rays a move traces again (bench/results/FINDINGS.md, "Constants in the code").
    rtcSetSceneBuildQuality(rtcScene_, RTC_BUILD_QUALITY_MEDIUM);
    rtcCommitGeometry(geom);
    rtcCommitScene(rtcScene_);
    CheckError();
}

void RayScene::AddTriangle(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c,
                           const glm::vec3& normalSum, uint32_t primitive) {
    RayTriangle t;
    t.p0 = a;
    t.e1 = b - a;
    t.e2 = c - a;
    glm::vec3 cr = glm::cross(t.e1, t.e2);
    float len = glm::length(cr);
    t.area = 0.5f * len;
    t.normal = len > 0.0f ? cr / len : glm::vec3(0.0f, 0.0f, 1.0f);
    if (glm::dot(normalSum, t.normal) < 0.0f) t.normal = -t.normal;
    t.primitive = primitive;
    t.material = scene_.primitives[primitive].material;
    tris_.push_back(t);
}

RayScene::~RayScene() {
    if (rtcScene_) rtcReleaseScene(rtcScene_);
    if (device_) rtcReleaseDevice(device_);
}

void RayScene::CheckError() const {
    if (!error_.empty()) throw Error(error_);
}

void RayScene::Build() {
    device_ = rtcNewDevice(nullptr);
    if (!device_) throw Error("Embree: cannot create a device");
    rtcSetDeviceErrorFunction(device_, &OnError, &error_);
    rtcScene_ = rtcNewScene(device_);
    // AllHits' filter runs from its own context only (other queries pass none). Robust:
    // watertight triangle tests, so a ray through an edge two triangles share (a tiled roof,
    // a grid of quads met along an axis) hits one of them instead of slipping through both.
    rtcSetSceneFlags(rtcScene_, RTC_SCENE_FLAG_CONTEXT_FILTER_FUNCTION | RTC_SCENE_FLAG_ROBUST);
    eps_ = 1e-4f * std::max(scene_.Diameter(), 1e-6f);
    passing_ = false;
    for (const Material& m : scene_.materials) passing_ = passing_ || m.Passes();
    Sample();
    BuildBvh();
}

Tints RayScene::TintsAt(uint32_t t, float u, float v) const {
    if (!mapped_) return Tints{};
    if (!corners_.empty()) {
        const glm::uvec3& c = corners_[t];
        const float w = 1.0f - u - v;
        return {w * albedoTints_[c.x] + u * albedoTints_[c.y] + v * albedoTints_[c.z],
                w * emissionTints_[c.x] + u * emissionTints_[c.y] + v * emissionTints_[c.z]};
    }
    return penumbra::TintsAt(scene_, tris_[t].primitive, vertices_[t], u, v);
}

glm::vec3 RayScene::MeanEmissionTint(uint32_t t) const {
    if (!mapped_) return glm::vec3(1.0f);
    if (!corners_.empty()) {
        const glm::uvec3& c = corners_[t];
        return (emissionTints_[c.x] + emissionTints_[c.y] + emissionTints_[c.z]) / 3.0f;
    }
    const Primitive& prim = scene_.primitives[tris_[t].primitive];
    const Material& m = scene_.materials[prim.material];
    const std::vector<glm::vec2>* coordinates = MapCoordinates(prim, m.emissionMap, m.emissionSet);
    if (!coordinates) return glm::vec3(1.0f);
    const std::vector<glm::vec2>& uv = *coordinates;
    const glm::uvec3& i = vertices_[t];
    return scene_.maps[m.emissionMap].Over(uv[i.x], uv[i.y], uv[i.z]);
}

glm::vec2 RayScene::Barycentrics(uint32_t t, const glm::vec3& origin, const glm::vec3& dir) const {
    // Möller–Trumbore without the range tests: the hit was found before.
    const RayTriangle& tri = tris_[t];
    const glm::vec3 p = glm::cross(dir, tri.e2);
    const float det = glm::dot(tri.e1, p);
    if (det == 0.0f) return glm::vec2(1.0f / 3.0f);
    const glm::vec3 s = origin - tri.p0, q = glm::cross(s, tri.e1);
    const float u = glm::dot(s, p) / det, v = glm::dot(dir, q) / det;
    return glm::clamp(glm::vec2(u, v), 0.0f, 1.0f);
}

void RayScene::Sample() {
    // Emitters, chosen in proportion to their power (area × summed radiance, the emission
    // maps' tints averaged over the triangle).
    double total = 0.0;
    for (uint32_t i = 0; i < tris_.size(); ++i) {
        const glm::vec3 le = scene_.materials[tris_[i].material].emission * MeanEmissionTint(i);
        double power = double(tris_[i].area) * (le.x + le.y + le.z);
        if (power <= 0.0) continue;
        total += power;
        emitters_.push_back(i);
        cdf_.push_back(total);
    }
    for (auto& c : cdf_) c /= total;
    emitterSlot_.assign(scene_.primitives.size(), -1);
    for (uint32_t e : emitters_) {
        const uint32_t p = tris_[e].primitive;
        if (emitterSlot_[p] >= 0) continue;
        emitterSlot_[p] = static_cast<int>(emitterPrimitives_.size());
        emitterPrimitives_.push_back(p);
    }
    areaPdf_.assign(tris_.size(), 0.0f);
    for (uint32_t k = 0; k < emitters_.size(); ++k)
        areaPdf_[emitters_[k]] =
            float(cdf_[k] - (k ? cdf_[k - 1] : 0.0)) / tris_[emitters_[k]].area;
}

void RayScene::WriteVertices(float* v) const {
    for (size_t i = 0; i < tris_.size(); ++i) {
        const RayTriangle& t = tris_[i];
        const glm::vec3 p[3] = {t.p0, t.p0 + t.e1, t.p0 + t.e2};
        for (int k = 0; k < 3; ++k) {
            v[9 * i + 3 * k] = p[k].x;
            v[9 * i + 3 * k + 1] = p[k].y;
            v[9 * i + 3 * k + 2] = p[k].z;
        }
    }
}

void RayScene::BuildBvh() {
    RTCGeometry geom = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_TRIANGLE);
    auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(
        geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), 3 * tris_.size()));
    auto* idx = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(
        geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(uint32_t), tris_.size()));
    CheckError();
    WriteVertices(v);
    for (size_t i = 0; i < 3 * tris_.size(); ++i) idx[i] = static_cast<uint32_t>(i);
    rtcCommitGeometry(geom);
    rtcAttachGeometry(rtcScene_, geom);
    rtcReleaseGeometry(geom);
    rtcSetSceneBuildQuality(rtcScene_, RTC_BUILD_QUALITY_HIGH);
    rtcCommitScene(rtcScene_);
    CheckError();
}

bool Bounds::Meets(const glm::vec3& origin, const glm::vec3& dir, float tmax) const {
    if (Empty()) return false;
    float t0 = 0.0f, t1 = tmax;
    for (int a = 0; a < 3; ++a) {
        if (dir[a] == 0.0f) {
            if (origin[a] < lo[a] || origin[a] > hi[a]) return false;
            continue;
        }
        const float inv = 1.0f / dir[a];
        float near = (lo[a] - origin[a]) * inv, far = (hi[a] - origin[a]) * inv;
        if (near > far) std::swap(near, far);
        t0 = std::max(t0, near);
        t1 = std::min(t1, far);
        if (t0 > t1) return false;
    }
    return true;
}

bool CanCut(const glm::vec3& x, const Ball& by, const Ball& to) {
    const glm::vec3 va = by.centre - x, vb = to.centre - x;
    const float da = glm::length(va), db = glm::length(vb);
    if (da <= by.radius || db <= to.radius) return true;
    if (da - by.radius > db + to.radius) return false;
    const float sa = by.radius / da, sb = to.radius / db;
    // The angle between the axes at most the sum of the half-angles (the sum below π).
    const float cosAxes = glm::dot(va, vb) / (da * db);
    return cosAxes >= std::sqrt(1.0f - sa * sa) * std::sqrt(1.0f - sb * sb) - sa * sb;
}

BallCone::BallCone(const glm::vec3& origin, const Ball& ball) {
    const glm::vec3 v = ball.centre - origin;
    const float d = glm::length(v);
    if (d <= ball.radius) return;
    inside_ = false;
    axis_ = v / d;
    const float s = ball.radius / d;
    cos2_ = 1.0f - s * s;
    near2_ = (d - ball.radius) * (d - ball.radius);
}

size_t RayScene::PickEmitter(float u) const {
    PENUMBRA_CHECK(!emitters_.empty());
    size_t k = std::lower_bound(cdf_.begin(), cdf_.end(), double(u)) - cdf_.begin();
    return std::min(k, emitters_.size() - 1);
}

std::vector<glm::vec3> RayScene::Vertices() const {
    std::vector<glm::vec3> v;
    v.reserve(3 * tris_.size());
    for (const RayTriangle& t : tris_) v.insert(v.end(), {t.p0, t.p0 + t.e1, t.p0 + t.e2});
    return v;
}

bool RayScene::Occluded(const glm::vec3& from, const glm::vec3& span) const {
    if (passing_) return Transmittance(from, span) == glm::vec3(0.0f);
    RTCRay r;
    InitRay(r, from, span, 1.0f - 1e-4f);
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    rtcOccluded1(rtcScene_, &ctx, &r);
    return r.tfar < 0.0f;
}

glm::vec3 RayScene::Transmittance(const glm::vec3& from, const glm::vec3& span) const {
    RTCRay r;
    InitRay(r, from, span, 1.0f - 1e-4f);
    PassContext context;
    rtcInitIntersectContext(&context.ctx);
    if (passing_) {
        context.ctx.filter = &PassFilter;
        context.rays = this;
    }
    rtcOccluded1(rtcScene_, &context.ctx, &r);
    return r.tfar < 0.0f ? glm::vec3(0.0f) : context.through;
}

RayHit RayScene::IntersectThrough(const glm::vec3& origin, const glm::vec3& dir, float tfar,
                                  glm::vec3& through) const {
    through = glm::vec3(1.0f);
    std::vector<std::pair<float, uint32_t>> passed;
    PassContext context;
    rtcInitIntersectContext(&context.ctx);
    context.ctx.filter = &PassFilter;
    context.rays = this;
    context.passed = &passed;
    RTCRayHit rh;
    InitRay(rh.ray, origin, dir, tfar);
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(rtcScene_, &context.ctx, &rh);
    RayHit hit;
    if (rh.hit.geomID != RTC_INVALID_GEOMETRY_ID) {
        hit.hit = true;
        hit.triangle = rh.hit.primID;
        hit.t = rh.ray.tfar;
        hit.u = rh.hit.u;
        hit.v = rh.hit.v;
    }
    // The passing surfaces before the hit (all of them when the ray escapes), each once.
    std::sort(passed.begin(), passed.end(),
              [](const auto& a, const auto& b) { return a.second < b.second; });
    for (size_t i = 0; i < passed.size(); ++i)
        if ((i == 0 || passed[i].second != passed[i - 1].second) &&
            (!hit.hit || passed[i].first < hit.t))
            through *= MaterialOf(passed[i].second).transmittance;
    return hit;
}

RayHit RayScene::Intersect(const glm::vec3& origin, const glm::vec3& dir, float tfar,
                           glm::vec3* through) const {
    if (passing_) {
        glm::vec3 t;
        const RayHit hit = IntersectThrough(origin, dir, tfar, t);
        if (through) *through = t;
        return hit;
    }
    if (through) *through = glm::vec3(1.0f);
    RTCRayHit rh;
    InitRay(rh.ray, origin, dir, tfar);
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    rtcIntersect1(rtcScene_, &ctx, &rh);
    RayHit hit;
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return hit;
    hit.hit = true;
    hit.triangle = rh.hit.primID;
    hit.t = rh.ray.tfar;
    hit.u = rh.hit.u;
    hit.v = rh.hit.v;
    return hit;
}

void RayScene::OccludedFrom(const glm::vec3& from, const glm::vec3* spans, size_t count,
                            uint8_t* out) const {
    if (passing_) {
        for (size_t i = 0; i < count; ++i) out[i] = Occluded(from, spans[i]) ? 1 : 0;
        return;
    }
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    for (size_t k = 0; k < count; k += 8) {
        const size_t c = std::min<size_t>(8, count - k);
        alignas(32) RTCRay8 r;
        alignas(32) int valid[8];
        for (size_t i = 0; i < 8; ++i) {
            valid[i] = i < c ? -1 : 0;
            SetRay8(r, int(i), from, i < c ? spans[k + i] : glm::vec3(0.0f, 0.0f, 1.0f),
                    1.0f - 1e-4f);
        }
        rtcOccluded8(valid, rtcScene_, &ctx, &r);
        for (size_t i = 0; i < c; ++i) out[k + i] = r.tfar[i] < 0.0f ? 1 : 0;
    }
}

void RayScene::IntersectFrom(const glm::vec3& origin, const glm::vec3* dirs, size_t count,
                             float tfar, RayHit* out, glm::vec3* through) const {
    if (passing_) {
        for (size_t i = 0; i < count; ++i) {
            glm::vec3 t;
            out[i] = IntersectThrough(origin, dirs[i], tfar, t);
            if (through) through[i] = t;
        }
        return;
    }
    if (through) std::fill(through, through + count, glm::vec3(1.0f));
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    for (size_t k = 0; k < count; k += 8) {
        const size_t c = std::min<size_t>(8, count - k);
        alignas(32) RTCRayHit8 rh;
        alignas(32) int valid[8];
        for (size_t i = 0; i < 8; ++i) {
            valid[i] = i < c ? -1 : 0;
            SetRay8(rh.ray, int(i), origin, i < c ? dirs[k + i] : glm::vec3(0.0f, 0.0f, 1.0f),
                    tfar);
            rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
        }
        rtcIntersect8(valid, rtcScene_, &ctx, &rh);
        for (size_t i = 0; i < c; ++i) {
            RayHit& hit = out[k + i];
            hit = RayHit();
            if (rh.hit.geomID[i] == RTC_INVALID_GEOMETRY_ID) continue;
            hit.hit = true;
            hit.triangle = rh.hit.primID[i];
            hit.t = rh.ray.tfar[i];
            hit.u = rh.hit.u[i];
            hit.v = rh.hit.v[i];
        }
    }
}

void RayScene::AllHits(const glm::vec3& origin, const glm::vec3& dir, float tfar,
                       std::vector<RayHit>& hits) const {
    hits.clear();
    AllHitsContext context;
    rtcInitIntersectContext(&context.ctx);
    context.ctx.filter = &RecordHit;
    context.hits = &hits;
    RTCRayHit rh;
    InitRay(rh.ray, origin, dir, tfar);
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(rtcScene_, &context.ctx, &rh);
    if (hits.size() < 2) return;
    // Nearest first; a triangle met in two BVH leaves (spatial splits) at the same t once.
    std::sort(hits.begin(), hits.end(), [](const RayHit& a, const RayHit& b) {
        return a.t < b.t || (a.t == b.t && a.triangle < b.triangle);
    });
    hits.erase(std::unique(hits.begin(), hits.end(),
                           [](const RayHit& a, const RayHit& b) {
                               return a.triangle == b.triangle && a.t == b.t;
                           }),
               hits.end());
}

std::vector<std::vector<glm::vec3>> VertexEstimatePoints(const Scene& scene) {
    std::vector<std::vector<glm::vec3>> points;
    const float inset = kVertexInset * scene.Diameter();
    for (const Primitive& prim : scene.primitives) {
        const size_t n = prim.positions.size();
        std::vector<glm::vec3> towards(n, glm::vec3(0.0f));
        // At most half way to the nearest of its triangles' centroids: on a small part (a
        // door handle's facets, a few millimetres) the scene's inset would leave the part.
        std::vector<float> reach(n, inset);
        for (size_t t = 0; t + 2 < prim.indices.size(); t += 3) {
            glm::vec3 c = (prim.positions[prim.indices[t]] + prim.positions[prim.indices[t + 1]] +
                           prim.positions[prim.indices[t + 2]]) /
                          3.0f;
            for (int k = 0; k < 3; ++k) {
                uint32_t v = prim.indices[t + k];
                glm::vec3 d = c - prim.positions[v];
                float len = glm::length(d);
                if (len > 0.0f) towards[v] += d / len, reach[v] = std::min(reach[v], 0.5f * len);
            }
        }
        std::vector<glm::vec3>& pts = points.emplace_back(prim.positions);
        for (size_t i = 0; i < n; ++i) {
            glm::vec3 d = towards[i] - glm::dot(towards[i], prim.normals[i]) * prim.normals[i];
            float len = glm::length(d);
            if (len > 1e-6f) pts[i] += std::min(1.0f, len) * reach[i] * (d / len);
        }
    }
    return points;
}

glm::vec3 VertexLightDirect(const RayScene& rays, const std::vector<PunctualLight>& lights,
                            const glm::vec3& x, const glm::vec3& n, float diameter,
                            uint64_t* count) {
    constexpr int kRim = 4, kSpread = 16;
    constexpr float kGoldenAngle = 2.39996323f;
    glm::vec3 t, s;
    Basis(n, t, s);
    const float radius = 0.1f * rays.Epsilon();
    const glm::vec3 lift = rays.Epsilon() * n;
    uint64_t traced = 0;
    glm::vec3 e(0.0f);
    for (const PunctualLight& light : lights) {
        const LightArrival a = PunctualArrival(light, x, n, diameter);
        if (!a.reaches) continue;
        // What of the light reaches the disc's point x + offset (per channel: through glass,
        // its transmittance): a directional light along the same span, a point or spot light
        // at its place.
        auto lit = [&](const glm::vec3& offset) {
            ++traced;
            const glm::vec3 span = light.type == LightType::kDirectional ? a.span : a.span - offset;
            return rays.Transmittance(x + offset + lift, span);
        };
        const glm::vec3 centre = lit(glm::vec3(0.0f));
        bool agree = true;
        for (int k = 0; k < kRim && agree; ++k) {
            const float phi = k * (2.0f * kPi / kRim);
            agree = lit(radius * (std::cos(phi) * t + std::sin(phi) * s)) == centre;
        }
        glm::vec3 seen = centre;
        if (!agree) {
            // Vogel's spiral: even over the disc, no two points at one radius.
            seen = glm::vec3(0.0f);
            for (int k = 0; k < kSpread; ++k) {
                const float r = radius * std::sqrt((k + 0.5f) / kSpread), phi = k * kGoldenAngle;
                seen += lit(r * (std::cos(phi) * t + std::sin(phi) * s));
            }
            seen /= float(kSpread);
        }
        e += seen * a.irradiance;
    }
    if (count) *count += traced;
    return e;
}

}  // namespace penumbra
