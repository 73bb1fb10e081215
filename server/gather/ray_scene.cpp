// Embree 3 BVH over the scene's triangles (ray_scene.h).
#include "gather/ray_scene.h"

#include <embree3/rtcore.h>

#include <algorithm>
#include <limits>

#include "base/check.h"

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

}  // namespace

RayScene::RayScene(const Scene& scene) : scene_(scene) {
    device_ = rtcNewDevice(nullptr);
    if (!device_) throw Error("Embree: cannot create a device");
    rtcSetDeviceErrorFunction(device_, &OnError, &error_);
    rtcScene_ = rtcNewScene(device_);
    eps_ = 1e-4f * std::max(scene.Diameter(), 1e-6f);
    Build();
}

RayScene::~RayScene() {
    if (rtcScene_) rtcReleaseScene(rtcScene_);
    if (device_) rtcReleaseDevice(device_);
}

void RayScene::CheckError() const {
    if (!error_.empty()) throw Error(error_);
}

void RayScene::Build() {
    for (const auto& prim : scene_.primitives) {
        for (size_t i = 0; i + 2 < prim.indices.size(); i += 3) {
            uint32_t a = prim.indices[i], b = prim.indices[i + 1], c = prim.indices[i + 2];
            RayTriangle t;
            t.p0 = prim.positions[a];
            t.e1 = prim.positions[b] - t.p0;
            t.e2 = prim.positions[c] - t.p0;
            glm::vec3 cr = glm::cross(t.e1, t.e2);
            float len = glm::length(cr);
            t.area = 0.5f * len;
            t.normal = len > 0.0f ? cr / len : glm::vec3(0.0f, 0.0f, 1.0f);
            glm::vec3 vn = prim.normals[a] + prim.normals[b] + prim.normals[c];
            if (glm::dot(vn, t.normal) < 0.0f) t.normal = -t.normal;
            t.material = prim.material;
            tris_.push_back(t);
        }
    }
    // Emitters, chosen in proportion to their power (area × summed radiance).
    double total = 0.0;
    for (uint32_t i = 0; i < tris_.size(); ++i) {
        const glm::vec3& le = scene_.materials[tris_[i].material].emission;
        double power = double(tris_[i].area) * (le.x + le.y + le.z);
        if (power <= 0.0) continue;
        total += power;
        emitters_.push_back(i);
        cdf_.push_back(total);
    }
    for (auto& c : cdf_) c /= total;
    areaPdf_.assign(tris_.size(), 0.0f);
    for (uint32_t k = 0; k < emitters_.size(); ++k)
        areaPdf_[emitters_[k]] =
            float(cdf_[k] - (k ? cdf_[k - 1] : 0.0)) / tris_[emitters_[k]].area;

    RTCGeometry geom = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_TRIANGLE);
    auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(
        geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), 3 * tris_.size()));
    auto* idx = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(
        geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(uint32_t), tris_.size()));
    CheckError();
    for (size_t i = 0; i < tris_.size(); ++i) {
        const RayTriangle& t = tris_[i];
        const glm::vec3 p[3] = {t.p0, t.p0 + t.e1, t.p0 + t.e2};
        for (int k = 0; k < 3; ++k) {
            v[9 * i + 3 * k] = p[k].x;
            v[9 * i + 3 * k + 1] = p[k].y;
            v[9 * i + 3 * k + 2] = p[k].z;
            idx[3 * i + k] = static_cast<uint32_t>(3 * i + k);
        }
    }
    rtcCommitGeometry(geom);
    rtcAttachGeometry(rtcScene_, geom);
    rtcReleaseGeometry(geom);
    rtcSetSceneBuildQuality(rtcScene_, RTC_BUILD_QUALITY_HIGH);
    rtcCommitScene(rtcScene_);
    CheckError();
}

size_t RayScene::PickEmitter(float u) const {
    PENUMBRA_CHECK(!emitters_.empty());
    size_t k = std::lower_bound(cdf_.begin(), cdf_.end(), double(u)) - cdf_.begin();
    return std::min(k, emitters_.size() - 1);
}

bool RayScene::Occluded(const glm::vec3& from, const glm::vec3& span) const {
    RTCRay r;
    InitRay(r, from, span, 1.0f - 1e-4f);
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    rtcOccluded1(rtcScene_, &ctx, &r);
    return r.tfar < 0.0f;
}

RayHit RayScene::Intersect(const glm::vec3& origin, const glm::vec3& dir, float tfar) const {
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

}  // namespace penumbra
