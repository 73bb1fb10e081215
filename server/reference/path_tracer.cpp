// Path tracer on Embree 3: bounces sampled from each surface's BRDF (cosine-weighted for
// the diffuse part, the Phong lobe for glossy materials), next-event estimation on emitting
// triangles chosen by power and on an environment map's bright pixels (SkySampler), each
// combined with the BRDF's sampling by MIS, Russian roulette after the second bounce.
#include "reference/path_tracer.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <memory>
#include <mutex>
#include <numbers>
#include <string>

#include "base/check.h"
#include "base/image.h"
#include "base/numeric.h"
#include "base/pcg.h"
#include "rays/ray_scene.h"

namespace penumbra {
namespace {

using Rng = Pcg32;  // one stream per vertex

// An orthonormal frame around unit `n` (Duff et al. 2017).
void Frame(const glm::vec3& n, glm::vec3& t, glm::vec3& b) {
    float sign = std::copysign(1.0f, n.z);
    float a = -1.0f / (sign + n.z);
    float c = n.x * n.y * a;
    t = glm::vec3(1.0f + sign * n.x * n.x * a, sign * c, -sign * n.x);
    b = glm::vec3(c, sign + n.y * n.y * a, -n.y);
}

// Cosine-weighted direction about `n`: pdf cosθ/π, so E = π · E[L].
glm::vec3 CosineSample(const glm::vec3& n, Rng& rng) {
    float u1 = rng.Uniform(), u2 = rng.Uniform();
    float r = std::sqrt(u1), phi = 2.0f * kPi * u2;
    glm::vec3 t, b;
    Frame(n, t, b);
    return r * std::cos(phi) * t + r * std::sin(phi) * b + std::sqrt(std::max(0.0f, 1.0f - u1)) * n;
}

// A material's BRDF at a surface point seen from `wo` (Material, scene.h): ρ_d/π plus the
// normalised Phong lobe F0 (n + 2)/(2π) cosⁿθ_r, θ_r the angle between the incoming
// direction and the mirror image of `wo`. The lobe exponent is the material's own: no
// widening to bins, this is the ground truth. Sampled by choosing the diffuse part or the
// lobe in proportion to their albedos.
struct Bsdf {
    glm::vec3 n, mirror, kd, ks;
    float exponent = 0.0f;
    float pLobe = 0.0f;  // probability of sampling the lobe

    // `albedoTint`: the base colour map's tint at the point (Tints).
    Bsdf(const Material& m, const glm::vec3& normal, const glm::vec3& wo,
         const glm::vec3& albedoTint = glm::vec3(1.0f))
        : n(normal), kd(m.albedo * albedoTint), ks(m.specular), exponent(m.phongExponent) {
        mirror = 2.0f * glm::dot(n, wo) * n - wo;
        if (m.Glossy()) {
            float d = Luminance(kd), s = Luminance(ks);
            pLobe = d + s > 0.0f ? s / (d + s) : 0.0f;
        }
    }
    bool Black() const { return glm::all(glm::lessThanEqual(kd + ks, glm::vec3(0.0f))); }
    float Lobe(const glm::vec3& wi) const {
        float c = glm::dot(mirror, wi);
        return c > 0.0f ? std::pow(c, exponent) : 0.0f;
    }
    glm::vec3 Eval(const glm::vec3& wi) const {
        if (glm::dot(n, wi) <= 0.0f) return glm::vec3(0.0f);
        glm::vec3 f = kd * (1.0f / kPi);
        if (pLobe > 0.0f) f += ks * ((exponent + 2.0f) / (2.0f * kPi) * Lobe(wi));
        return f;
    }
    float Pdf(const glm::vec3& wi) const {
        float c = glm::dot(n, wi);
        if (c <= 0.0f) return 0.0f;
        float p = (1.0f - pLobe) * c / kPi;
        if (pLobe > 0.0f) p += pLobe * (exponent + 1.0f) / (2.0f * kPi) * Lobe(wi);
        return p;
    }
    // A direction drawn from Pdf (it may point below the surface: then Eval is 0).
    glm::vec3 Sample(Rng& rng) const {
        if (pLobe <= 0.0f || rng.Uniform() >= pLobe) return CosineSample(n, rng);
        float u1 = rng.Uniform(), u2 = rng.Uniform();
        float c = std::pow(u1, 1.0f / (exponent + 1.0f));
        float r = std::sqrt(std::max(0.0f, 1.0f - c * c)), phi = 2.0f * kPi * u2;
        glm::vec3 t, b;
        Frame(mirror, t, b);
        return r * std::cos(phi) * t + r * std::sin(phi) * b + c * mirror;
    }
};

class Tracer {
  public:
    Tracer(const Scene& scene, const ReferenceSettings& s)
        : scene_(scene), s_(s), rays_(scene), tris_(rays_.Triangles()), eps_(rays_.Epsilon()) {}

    // One sample of the irradiance at `x` over the hemisphere of `n`: an emitter point and
    // a cosine-sampled path, combined by multiple importance sampling (Veach 1997, power
    // heuristic) so that neither the 1/d² of nearby emitters nor small far ones blow up.
    glm::vec3 Sample(const glm::vec3& x, const glm::vec3& n, Rng& rng, uint64_t& rays) const {
        glm::vec3 e = NextEvent(x, n, nullptr, rng, rays) + SkyEvent(x, n, nullptr, rng, rays);
        return e + kPi * Incoming(x, n, CosineSample(n, rng), rng, rays);
    }

    // Irradiance at `x` (normal `n`) straight from the punctual lights: Σ Φ·att·cosθ/d²
    // (point, spot) or E⊥·cosθ (directional), each behind one shadow ray, or with `bsdf` the
    // radiance reflected towards its `wo`: Σ f(toLight) · E. Delta lights: no sampling, no
    // MIS.
    glm::vec3 PunctualDirect(const glm::vec3& x, const glm::vec3& n, uint64_t& rays,
                             const Bsdf* bsdf = nullptr) const {
        glm::vec3 e(0.0f);
        for (const PunctualLight& light : scene_.lights) {
            const LightArrival a = PunctualArrival(light, x, n, diameter_);
            if (!a.reaches || a.scale <= 0.0f) continue;
            ++rays;
            glm::vec3 from = x + eps_ * n;
            const glm::vec3 pass = rays_.Transmittance(from, x + a.span - from);
            if (pass == glm::vec3(0.0f)) continue;
            e += (bsdf ? bsdf->Eval(a.toLight) : glm::vec3(1.0f)) * pass * a.irradiance;
        }
        return e;
    }

    // The punctual lights' irradiance at a vertex's estimate point (VertexLightDirect: a
    // vertex on a shadow's edge reads the mean of its two sides).
    glm::vec3 VertexDirect(const glm::vec3& x, const glm::vec3& n, uint64_t& rays) const {
        return VertexLightDirect(rays_, scene_.lights, x, n, diameter_, &rays);
    }

  private:
    static float PowerHeuristic(float a, float b) { return a * a / (a * a + b * b); }

    // Direct irradiance at `x` (normal `n`) from one emitter point: L_e cosθ_x cosθ_y / d²
    // over the area pdf, weighted against the cosine sampling of the same direction; with
    // `bsdf`, the radiance it reflects (times f, weighted against sampling the BRDF).
    glm::vec3 NextEvent(const glm::vec3& x, const glm::vec3& n, const Bsdf* bsdf, Rng& rng,
                        uint64_t& rays) const {
        if (rays_.Emitters().empty()) return glm::vec3(0.0f);
        const uint32_t ti = rays_.Emitters()[rays_.PickEmitter(rng.Uniform())];
        const RayTriangle& t = tris_[ti];
        float a = rng.Uniform(), b = rng.Uniform();
        if (a + b > 1.0f) a = 1.0f - a, b = 1.0f - b;
        glm::vec3 y = t.p0 + a * t.e1 + b * t.e2;
        glm::vec3 d = y - x;
        float dist2 = glm::dot(d, d);
        if (dist2 <= 0.0f) return glm::vec3(0.0f);
        glm::vec3 w = d / std::sqrt(dist2);
        float cx = glm::dot(n, w), cy = -glm::dot(t.normal, w);
        if (cx <= 0.0f || cy <= 0.0f) return glm::vec3(0.0f);
        glm::vec3 from = x + eps_ * n, to = y + eps_ * t.normal;
        ++rays;
        const glm::vec3 pass = rays_.Transmittance(from, to - from);
        if (pass == glm::vec3(0.0f)) return glm::vec3(0.0f);
        float pdfArea = rays_.AreaPdf(ti);
        float weight = PowerHeuristic(pdfArea * dist2 / cy, bsdf ? bsdf->Pdf(w) : cx / kPi);
        glm::vec3 le = scene_.materials[t.material].emission * rays_.TintsAt(ti, a, b).emission;
        if (bsdf) le *= bsdf->Eval(w);
        return pass * le * (weight * cx * cy / (dist2 * pdfArea));
    }

    // The environment map's light at `x` (normal `n`) along one direction drawn by the map's
    // brightness (SkySampler), weighted against the BRDF's (or the cosine's) sampling of the
    // same direction; with `bsdf`, the radiance it reflects. 0 for a constant sky (drawn by
    // the cosine alone: a map's density would only add noise to it).
    glm::vec3 SkyEvent(const glm::vec3& x, const glm::vec3& n, const Bsdf* bsdf, Rng& rng,
                       uint64_t& rays) const {
        if (!skySampler_.Usable() || !sky_) return glm::vec3(0.0f);
        float pdf;
        const float u = rng.Uniform(), v = rng.Uniform();
        const glm::vec3 w = skySampler_.Sample({u, v}, pdf);
        const float cx = glm::dot(n, w);
        if (!(pdf > 0.0f) || cx <= 0.0f) return glm::vec3(0.0f);
        ++rays;
        const glm::vec3 pass = rays_.Transmittance(x + eps_ * n, w * (2.0f * diameter_));
        if (pass == glm::vec3(0.0f)) return glm::vec3(0.0f);
        const float weight = PowerHeuristic(pdf, bsdf ? bsdf->Pdf(w) : cx / kPi);
        glm::vec3 l = pass * scene_.environment.Radiance(w);
        if (bsdf) l *= bsdf->Eval(w);
        return l * (weight * cx / pdf);
    }

    // Radiance arriving at `x` (normal `n`) from direction `dir`, sampled with pdf cosθ/π:
    // the emission of what the ray hits (MIS-weighted against NextEvent) and the light that
    // surface reflects, followed bounce by bounce.
    glm::vec3 Incoming(glm::vec3 x, glm::vec3 n, glm::vec3 dir, Rng& rng, uint64_t& rays) const {
        glm::vec3 radiance(0.0f), throughput(1.0f);
        float pdfDir = glm::dot(n, dir) / kPi;  // the pdf `dir` was drawn with
        for (int depth = 0; depth <= s_.maxDepth; ++depth) {
            // Surfaces that pass light are looked through, their transmittance carried along
            // (what they reflect themselves is left out: docs/MATERIALS.md).
            glm::vec3 pass;
            const RayHit hit =
                rays_.Intersect(x + eps_ * n, dir, std::numeric_limits<float>::infinity(), &pass);
            ++rays;
            throughput *= pass;
            if (!hit.hit) {
                // Escaped: the environment's radiance from that direction, weighted against
                // the map's next-event estimate (SkyEvent) where there is one.
                if (sky_) {
                    const float weight =
                        skySampler_.Usable() ? PowerHeuristic(pdfDir, skySampler_.Pdf(dir)) : 1.0f;
                    radiance += throughput * weight * scene_.environment.Radiance(dir);
                }
                break;
            }
            const uint32_t ti = hit.triangle;
            const RayTriangle& t = tris_[ti];
            float cy = -glm::dot(t.normal, dir);
            if (cy <= 0.0f) break;  // a back side: opaque and black
            const Material& mat = scene_.materials[t.material];
            // The colour maps' tints at the hit: the texture itself, the truth the solvers'
            // per-surfel averages approach.
            const Tints tints = rays_.TintsAt(ti, hit.u, hit.v);
            if (rays_.AreaPdf(ti) > 0.0f) {
                float dist = hit.t;
                float pdfLight = rays_.AreaPdf(ti) * dist * dist / cy;
                float weight = PowerHeuristic(pdfDir, pdfLight);
                radiance += throughput * weight * mat.emission * tints.emission;
            }
            if (depth == s_.maxDepth) break;
            const Bsdf bsdf(mat, t.normal, -dir, tints.albedo);
            if (bsdf.Black()) break;
            x = t.p0 + hit.u * t.e1 + hit.v * t.e2;
            n = t.normal;
            // Reflected: next-event estimates of emitters and punctual lights, then one
            // direction drawn from the BRDF carries the rest (throughput f·cos/pdf).
            radiance +=
                throughput * (NextEvent(x, n, &bsdf, rng, rays) + SkyEvent(x, n, &bsdf, rng, rays) +
                              PunctualDirect(x, n, rays, &bsdf));
            dir = bsdf.Sample(rng);
            pdfDir = bsdf.Pdf(dir);
            float cosine = glm::dot(n, dir);
            if (!(pdfDir > 0.0f) || cosine <= 0.0f) break;
            throughput *= bsdf.Eval(dir) * (cosine / pdfDir);
            if (depth >= 2) {
                float q = std::min(0.95f, std::max({throughput.x, throughput.y, throughput.z}));
                if (rng.Uniform() >= q) break;
                throughput /= q;
            }
        }
        return radiance;
    }

    const Scene& scene_;
    const ReferenceSettings& s_;
    RayScene rays_;
    const std::vector<RayTriangle>& tris_;
    float eps_;
    bool sky_ = scene_.environment.Active();
    SkySampler skySampler_{scene_.environment};
    float diameter_ = scene_.Diameter();  // where directional lights' shadow rays end
};

}  // namespace

ReferenceResult RenderReference(const Scene& scene, const ReferenceSettings& settings) {
    if (settings.samples < 2) throw Error("--samples must be at least 2 (for a standard error)");
    if (settings.maxDepth < 0 || settings.maxDepth > 100000)
        throw Error("--max-depth must be between 0 and 100000");
    if (settings.threads < 0) throw Error("--threads must be 0 (all cores) or more");
    std::unique_ptr<tbb::global_control> limit;
    if (settings.threads > 0)
        limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                      settings.threads);

    auto start = std::chrono::steady_clock::now();
    Tracer tracer(scene, settings);

    // Every input vertex, as (primitive, index), numbered for the random streams.
    std::vector<std::pair<uint32_t, uint32_t>> vertices;
    ReferenceResult result;
    const std::vector<std::vector<glm::vec3>> points = VertexEstimatePoints(scene);
    for (uint32_t p = 0; p < scene.primitives.size(); ++p) {
        size_t n = scene.primitives[p].positions.size();
        result.irradiance.emplace_back(n, glm::vec3(0.0f));
        result.standardError.emplace_back(n, glm::vec3(0.0f));
        for (uint32_t i = 0; i < n; ++i) vertices.emplace_back(p, i);
    }

    tbb::enumerable_thread_specific<uint64_t> rays(0);
    std::atomic<size_t> done{0};
    std::mutex progressLock;
    tbb::parallel_for(
        tbb::blocked_range<size_t>(0, vertices.size(), 1),
        [&](const tbb::blocked_range<size_t>& range) {
            uint64_t& r = rays.local();
            for (size_t v = range.begin(); v != range.end(); ++v) {
                auto [p, i] = vertices[v];
                const Primitive& prim = scene.primitives[p];
                Rng rng(settings.seed, v);
                glm::dvec3 sum(0.0), sum2(0.0);
                glm::vec3 direct(0.0f);
                if (settings.channel != Channel::kIndirect)
                    direct = tracer.VertexDirect(points[p][i], prim.normals[i], r);
                for (int s = 0; s < settings.samples && settings.channel != Channel::kDirect; ++s) {
                    glm::dvec3 e(tracer.Sample(points[p][i], prim.normals[i], rng, r));
                    sum += e;
                    sum2 += e * e;
                }
                double n = settings.samples;
                glm::dvec3 mean = sum / n;
                glm::dvec3 var = glm::max((sum2 - n * mean * mean) / (n - 1.0), glm::dvec3(0.0));
                result.irradiance[p][i] = glm::vec3(mean) + direct;
                result.standardError[p][i] = glm::vec3(glm::sqrt(var / n));
            }
            size_t d = done.fetch_add(range.size()) + range.size();
            if (settings.progress && progressLock.try_lock()) {
                double f = double(d) / vertices.size();
                double elapsed =
                    std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
                settings.progress(f, f > 0 ? elapsed * (1.0 - f) / f : 0.0);
                progressLock.unlock();
            }
        });
    // A vertex split for flat normals: the area-weighted mean of its copies, as the solvers'.
    for (uint32_t p = 0; p < scene.primitives.size(); ++p) {
        const Primitive& prim = scene.primitives[p];
        if (prim.copyOf.empty()) continue;
        const std::vector<float> area = VertexAreas(prim);
        std::vector<glm::dvec3> variance(prim.InputVertexCount(), glm::dvec3(0.0));
        std::vector<double> weight(prim.InputVertexCount(), 0.0);
        for (size_t k = 0; k < prim.positions.size(); ++k) {
            const glm::dvec3 se(result.standardError[p][k]);
            variance[prim.InputVertex(k)] += double(area[k]) * double(area[k]) * se * se;
            weight[prim.InputVertex(k)] += area[k];
        }
        result.irradiance[p] = ToInputVertices(prim, std::move(result.irradiance[p]));
        result.standardError[p].resize(prim.InputVertexCount());
        for (size_t i = 0; i < weight.size(); ++i)
            if (weight[i] > 0.0)
                result.standardError[p][i] = glm::vec3(glm::sqrt(variance[i]) / weight[i]);
    }

    ReferenceStats& st = result.stats;
    st.samples = settings.samples;
    st.maxDepth = settings.maxDepth;
    st.seed = settings.seed;
    st.threads = settings.threads > 0 ? settings.threads
                                      : static_cast<int>(tbb::global_control::active_value(
                                            tbb::global_control::max_allowed_parallelism));
    st.vertices = vertices.size();
    for (uint64_t r : rays) st.rays += r;
    st.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return result;
}

IrradianceFile ReferenceFile(const Scene& scene, const ReferenceSettings& settings) {
    IrradianceResult result;
    result.solver = "reference";
    result.channel = ChannelName(settings.channel);
    result.primitives = RenderReference(scene, settings).irradiance;
    return ToIrradianceFile(scene, result);
}

}  // namespace penumbra
