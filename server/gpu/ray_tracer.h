// Hardware ray tracing of batches of rays against a triangle set (issue 19's Vulkan gather):
// a bottom-level acceleration structure over the triangles, a top-level one with one
// instance of it, and a ray-tracing pipeline (shaders/trace.rgen, trace.rmiss, trace.rchit)
// that writes the nearest hit of each ray. The answer is what RayScene::Intersect gives
// (rays/ray_scene.h): the triangle, its t and the barycentrics (u, v) of p0 + u·e1 + v·e2.
//
// It needs VK_KHR_acceleration_structure and VK_KHR_ray_tracing_pipeline (gpu::Capability::
// kRayTracing). The issue named VK_KHR_ray_query in a compute pass; the GPUs this project
// could test on (an NVIDIA H200, driver 580.159) expose the pipeline and the acceleration
// structures but not ray queries, and lavapipe (Mesa 22.3) neither.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <memory>
#include <span>
#include <string>
#include <vector>

namespace penumbra::gpu {

enum class DeviceKind;

// 32 bytes, as the shader reads it: origin and tmin, direction and tmax.
struct TraceRay {
    glm::vec3 origin;
    float tmin = 0.0f;
    glm::vec3 dir;
    float tmax = 3.0e38f;
};

// 16 bytes, as the shader writes it; triangle kMissed where the ray met nothing.
struct TraceHit {
    static constexpr uint32_t kMissed = 0xFFFFFFFFu;
    uint32_t triangle = kMissed;
    float t = 0.0f, u = 0.0f, v = 0.0f;
};

class RayTracer {
  public:
    // On the device of `kind` that can trace rays; throws penumbra::Error naming what is
    // missing (no Vulkan, or each device and what it lacks).
    RayTracer(DeviceKind kind, bool validation);
    ~RayTracer();
    RayTracer(const RayTracer&) = delete;
    RayTracer& operator=(const RayTracer&) = delete;

    const std::string& DeviceName() const;
    // (Re)builds the acceleration structures over `corners`: three a triangle, triangle k at
    // 3k, 3k + 1, 3k + 2 (p0, p0 + e1, p0 + e2), both sides hit. Throws penumbra::Error.
    void Build(std::span<const glm::vec3> corners);
    // The nearest hit of each ray (in batches of up to a million rays a dispatch).
    std::vector<TraceHit> Trace(std::span<const TraceRay> rays);
    // Milliseconds the last Build and the last Trace took on the host's clock, transfers in.
    double BuildMs() const;
    double TraceMs() const;
    // Validation-layer messages seen so far (warnings and errors).
    std::vector<std::string> ValidationMessages() const;

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace penumbra::gpu
