// Host-side shading, cameras, tone mapping, and the Vulkan raster (gpu::RenderTarget with
// shaders/render.vert/frag).
#include "render/renderer.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <glm/gtc/matrix_transform.hpp>
#include <map>
#include <numbers>
#include <sstream>

#include "base/check.h"
#include "base/numeric.h"
#include "gpu/buffer.h"
#include "gpu/context.h"
#include "gpu/layout.h"
#include "gpu/render_target.h"
#include "shaders/render_frag_spv.h"
#include "shaders/render_vert_spv.h"

namespace penumbra::render {
namespace {

constexpr float kInvPi = 1.0f / std::numbers::pi_v<float>;

// Radiance towards the camera: (ρ_d + F0) E/π + L_e. A glossy lobe is shown as if it
// reflected diffusely (its albedo at normal incidence), since per-vertex irradiance carries
// no direction: metals are not black, but highlights are not drawn. `tints`: the colour
// maps' at the vertex (shading is per vertex, so a texture shows at the mesh's resolution).
glm::vec3 Shade(const Material& m, const Tints& tints, const glm::vec3& e) {
    return (m.albedo * tints.albedo + m.specular) * glm::max(e, glm::vec3(0.0f)) * kInvPi +
           m.emission * tints.emission;
}

// Layout of one vertex in shaders/render.vert.
struct GpuVertex {
    glm::vec4 position, color, normal;
};
struct GpuPush {
    glm::mat4 viewProj;
    glm::vec4 eye;
};
// shaders/render.vert (struct Vertex, push constants).
PENUMBRA_GPU_FIELD(GpuVertex, position, 0);
PENUMBRA_GPU_FIELD(GpuVertex, color, 16);
PENUMBRA_GPU_FIELD(GpuVertex, normal, 32);
PENUMBRA_GPU_FIELD(GpuPush, viewProj, 0);
PENUMBRA_GPU_FIELD(GpuPush, eye, 64);

}  // namespace

Mesh ShadedInputMesh(const Scene& scene, const std::vector<std::vector<glm::vec3>>& irradiance) {
    PENUMBRA_CHECK_EQ(irradiance.size(), scene.primitives.size());
    Mesh mesh;
    for (size_t p = 0; p < scene.primitives.size(); ++p) {
        const Primitive& prim = scene.primitives[p];
        PENUMBRA_CHECK_EQ(irradiance[p].size(), prim.InputVertexCount());
        uint32_t base = static_cast<uint32_t>(mesh.positions.size());
        const Material& mat = scene.materials[prim.material];
        for (size_t i = 0; i < prim.positions.size(); ++i) {
            mesh.positions.push_back(prim.positions[i]);
            mesh.normals.push_back(prim.normals[i]);
            const uint32_t v = static_cast<uint32_t>(i);
            mesh.colors.push_back(
                Shade(mat, TintsAt(scene, static_cast<uint32_t>(p), glm::uvec3(v), 0.0f, 0.0f),
                      irradiance[p][prim.InputVertex(i)]));
        }
        for (uint32_t i : prim.indices) mesh.indices.push_back(base + i);
    }
    return mesh;
}

Mesh ShadedRefinedMesh(const Scene& scene, const Surfels& surfels,
                       const std::vector<glm::vec3>& irradiance) {
    PENUMBRA_CHECK_EQ(irradiance.size(), surfels.size());
    Mesh mesh;
    mesh.positions = surfels.positions;
    mesh.normals = surfels.normals;
    mesh.colors.resize(surfels.size());
    for (size_t s = 0; s < surfels.size(); ++s)
        mesh.colors[s] = Shade(scene.materials[surfels.materials[s]],
                               surfels.albedoTints.empty()
                                   ? Tints{}
                                   : Tints{surfels.albedoTints[s], surfels.emissionTints[s]},
                               irradiance[s]);
    mesh.indices = surfels.refinedTriangles;
    return mesh;
}

std::vector<std::vector<glm::vec3>> IrradianceForScene(const Scene& scene,
                                                       const IrradianceFile& file) {
    std::map<std::tuple<std::string, int, int>, const IrradianceRecord*> byKey;
    for (const IrradianceRecord& r : file.primitives) byKey[{r.node, r.mesh, r.primitive}] = &r;
    std::vector<std::vector<glm::vec3>> out;
    for (const Primitive& prim : scene.primitives) {
        auto it = byKey.find({prim.node, prim.mesh, prim.primitive});
        std::string name = "node '" + prim.node + "' mesh " + std::to_string(prim.mesh) +
                           " primitive " + std::to_string(prim.primitive);
        if (it == byKey.end()) throw Error("the lighting file has no " + name);
        if (it->second->irradiance.size() != prim.InputVertexCount())
            throw Error("the lighting file has " + std::to_string(it->second->irradiance.size()) +
                        " vertices for " + name + ", the scene " +
                        std::to_string(prim.InputVertexCount()));
        out.push_back(it->second->irradiance);
    }
    return out;
}

glm::vec3 HeatColor(float t) {
    t = std::clamp(t, 0.0f, 1.0f);
    static const glm::vec3 stops[] = {{0.0f, 0.0f, 0.5f},
                                      {0.0f, 0.6f, 1.0f},
                                      {0.1f, 0.8f, 0.2f},
                                      {1.0f, 0.9f, 0.0f},
                                      {0.9f, 0.05f, 0.0f}};
    float x = t * 4.0f;
    int i = std::min(3, static_cast<int>(x));
    return glm::mix(stops[i], stops[i + 1], x - i);
}

Mesh ErrorMesh(const Scene& scene, const std::vector<std::vector<glm::vec3>>& a,
               const std::vector<std::vector<glm::vec3>>& b, float scale, float floorFraction) {
    if (!(scale > 0.0f)) throw Error("the error scale must be positive");
    double sum = 0;
    size_t n = 0;
    for (const auto& prim : b)
        for (const glm::vec3& v : prim) sum += glm::length(v), ++n;
    const float floor = n ? static_cast<float>(floorFraction * sum / n) : 0.0f;
    Mesh mesh = ShadedInputMesh(scene, a);  // geometry; colours replaced below
    size_t k = 0;
    for (size_t p = 0; p < a.size(); ++p)
        for (size_t i = 0; i < a[p].size(); ++i, ++k) {
            float rel = glm::length(a[p][i] - b[p][i]) / std::max(glm::length(b[p][i]), floor);
            mesh.colors[k] = HeatColor(rel / scale);
        }
    return mesh;
}

Camera FrameScene(const Scene& scene, float yfov) {
    glm::vec3 lo = scene.BoundsMin(), hi = scene.BoundsMax();
    glm::vec3 centre = 0.5f * (lo + hi);
    float radius = std::max(0.5f * glm::length(hi - lo), 1e-3f);
    Camera c;
    c.name = "framing";
    c.yfov = yfov;
    c.forward = {0.0f, 0.0f, 1.0f};
    c.up = {0.0f, 1.0f, 0.0f};
    c.eye = centre - c.forward * (radius / std::sin(0.5f * yfov));
    return c;
}

Camera ParseCamera(const std::string& text) {
    std::vector<float> v;
    std::stringstream in(text);
    std::string item;
    while (std::getline(in, item, ',')) {
        try {
            size_t used = 0;
            v.push_back(std::stof(item, &used));
            if (used != item.size()) throw std::invalid_argument(item);
        } catch (const std::exception&) {
            throw Error("--camera: '" + item + "' is not a number (want ex,ey,ez,tx,ty,tz,fov)");
        }
    }
    if (v.size() != 7) throw Error("--camera wants 7 numbers: ex,ey,ez,tx,ty,tz,fov");
    for (float x : v)
        if (!std::isfinite(x)) throw Error("--camera numbers must be finite");
    Camera c;
    c.name = "--camera";
    c.eye = {v[0], v[1], v[2]};
    glm::vec3 d = glm::vec3(v[3], v[4], v[5]) - c.eye;
    if (glm::length(d) < 1e-9f) throw Error("--camera: the target is the eye");
    c.forward = glm::normalize(d);
    glm::vec3 up(0.0f, 1.0f, 0.0f);
    if (std::abs(glm::dot(up, c.forward)) > 0.999f)
        up = {0.0f, 0.0f, 1.0f};  // looking straight up/down
    c.up = glm::normalize(up - glm::dot(up, c.forward) * c.forward);
    if (!(v[6] > 0.0f && v[6] < 179.0f)) throw Error("--camera: fov must be in (0, 179) degrees");
    c.yfov = glm::radians(v[6]);
    return c;
}

RenderOutput Rasterize(const Mesh& mesh, const Camera& camera, const RenderSettings& settings) {
    if (settings.width < 1 || settings.height < 1 || settings.width > kMaxImageSide ||
        settings.height > kMaxImageSide)
        throw Error("image size must be 1…" + std::to_string(kMaxImageSide) + " pixels a side");
    if (mesh.indices.empty()) throw Error("nothing to render: the scene has no triangles");
    auto start = std::chrono::steady_clock::now();
    RenderOutput out;
    gpu::DeviceKind kind = settings.lavapipe || !gpu::FindRealGpu(nullptr)
                               ? gpu::DeviceKind::kLavapipe
                               : gpu::DeviceKind::kRealGpu;
    gpu::Context ctx(kind, settings.validation);
    out.device = "vulkan:" + ctx.DeviceName();

    // Unindexed triangles: the vertex shader reads vertex gl_VertexIndex.
    std::vector<GpuVertex> vertices;
    vertices.reserve(mesh.indices.size());
    for (uint32_t i : mesh.indices)
        vertices.push_back({glm::vec4(mesh.positions[i], 1.0f), glm::vec4(mesh.colors[i], 1.0f),
                            glm::vec4(mesh.normals[i], 0.0f)});
    gpu::Buffer vertexBuffer(ctx, vertices.size() * sizeof(GpuVertex));
    vertexBuffer.Upload(vertices);
    const uint32_t w = settings.width, h = settings.height;
    gpu::Buffer pixels(ctx, size_t(w) * h * sizeof(glm::vec4));
    gpu::RenderTarget target(ctx, gpu::Words(kSpirv_render_vert), gpu::Words(kSpirv_render_frag), 1,
                             sizeof(GpuPush), w, h);
    const gpu::Buffer* buffers[] = {&vertexBuffer};
    vk::raii::DescriptorSet set = target.MakeSet(buffers);

    // Near and far planes around the scene's bounding sphere as seen from the eye.
    glm::vec3 lo(1e30f), hi(-1e30f);
    for (const glm::vec3& p : mesh.positions) lo = glm::min(lo, p), hi = glm::max(hi, p);
    glm::vec3 centre = 0.5f * (lo + hi);
    float radius = std::max(0.5f * glm::length(hi - lo), 1e-4f);
    float dist = glm::dot(centre - camera.eye, camera.forward);
    float far = std::max(dist + radius * 1.01f, 1e-3f);
    float near = std::max(dist - radius * 1.01f, far * 1e-4f);
    glm::mat4 view = glm::lookAt(camera.eye, camera.eye + camera.forward, camera.up);
    glm::mat4 proj = glm::perspectiveRH_ZO(camera.yfov, float(w) / float(h), near, far);
    proj[1][1] *= -1.0f;  // Vulkan's y points down: row 0 of the image is the top
    GpuPush push{proj * view, glm::vec4(camera.eye, 1.0f)};
    const float clear[4] = {0.0f, 0.0f, 0.0f, 1.0f};
    ctx.RunNow([&](const vk::raii::CommandBuffer& cb) {
        target.Begin(cb, set, clear);
        target.Push(cb, push);
        cb.draw(static_cast<uint32_t>(vertices.size()), 1, 0, 0);
        target.EndAndCopy(cb, pixels);
    });
    std::vector<glm::vec4> rgba = pixels.Download<glm::vec4>();
    out.image = Image(int(w), int(h));
    for (size_t i = 0; i < out.image.pixels.size(); ++i) out.image.pixels[i] = glm::vec3(rgba[i]);
    out.validationMessages = ctx.ValidationMessages();
    out.ms = MsSince(start);
    return out;
}

std::vector<uint8_t> ToneMap(const Image& image, float exposure, bool autoExposure) {
    float scale = std::exp2(exposure);
    if (autoExposure) {
        const float key = Luminance99(image.pixels);
        if (key > 0.0f) scale /= key;
    }
    auto srgb = [](float v) {
        v = std::clamp(v, 0.0f, 1.0f);
        v = v <= 0.0031308f ? 12.92f * v : 1.055f * std::pow(v, 1.0f / 2.4f) - 0.055f;
        return static_cast<uint8_t>(std::lround(v * 255.0f));
    };
    std::vector<uint8_t> out;
    out.reserve(image.pixels.size() * 3);
    for (const glm::vec3& p : image.pixels) {
        glm::vec3 v = std::isfinite(p.x + p.y + p.z) ? p * scale : glm::vec3(0.0f);
        out.push_back(srgb(v.x));
        out.push_back(srgb(v.y));
        out.push_back(srgb(v.z));
    }
    return out;
}

}  // namespace penumbra::render
