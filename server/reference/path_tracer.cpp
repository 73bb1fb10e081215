// Path tracer on Embree 3: bounces sampled from each surface's BRDF (cosine-weighted for
// the diffuse part, the Phong lobe for glossy materials), next-event estimation on emitting
// triangles chosen by power, the two combined by MIS, Russian roulette after the second
// bounce.
#include "reference/path_tracer.h"

#include <embree3/rtcore.h>
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

namespace penumbra {
namespace {

constexpr float kPi = std::numbers::pi_v<float>;
// Vertices are estimated this far (× the scene's diameter) inside their own surface.
constexpr float kVertexInset = 1e-3f;

// PCG32 (O'Neill 2014): small state, good statistics, one stream per vertex.
class Rng {
  public:
    Rng(uint64_t seed, uint64_t stream) : inc_((stream << 1u) | 1u) {
        Next();
        state_ += seed;
        Next();
    }
    uint32_t Next() {
        uint64_t old = state_;
        state_ = old * 6364136223846793005ULL + inc_;
        uint32_t xorshifted = static_cast<uint32_t>(((old >> 18u) ^ old) >> 27u);
        uint32_t rot = static_cast<uint32_t>(old >> 59u);
        return (xorshifted >> rot) | (xorshifted << ((-rot) & 31));
    }
    // Uniform in [0, 1).
    float Uniform() { return static_cast<float>(Next() >> 8) * (1.0f / 16777216.0f); }

  private:
    uint64_t state_ = 0;
    uint64_t inc_;
};

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

float Luminance(const glm::vec3& c) { return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z; }

// A material's BRDF at a surface point seen from `wo` (Material, scene.h): ρ_d/π plus the
// normalised Phong lobe F0 (n + 2)/(2π) cosⁿθ_r, θ_r the angle between the incoming
// direction and the mirror image of `wo`. The lobe exponent is the material's own: no
// widening to bins, this is the ground truth. Sampled by choosing the diffuse part or the
// lobe in proportion to their albedos.
struct Bsdf {
    glm::vec3 n, mirror, kd, ks;
    float exponent = 0.0f;
    float pLobe = 0.0f;  // probability of sampling the lobe

    Bsdf(const Material& m, const glm::vec3& normal, const glm::vec3& wo)
        : n(normal), kd(m.albedo), ks(m.specular), exponent(m.phongExponent) {
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

struct Triangle {
    glm::vec3 p0, e1, e2;  // p0 + u·e1 + v·e2
    glm::vec3 normal;      // unit, on the side the vertex normals point to
    float area;
    uint32_t material;
};

class Tracer {
  public:
    Tracer(const Scene& scene, const ReferenceSettings& s) : scene_(scene), s_(s) {
        device_ = rtcNewDevice(nullptr);
        if (!device_) throw Error("Embree: cannot create a device");
        rtcSetDeviceErrorFunction(device_, &Tracer::OnError, this);
        rtcScene_ = rtcNewScene(device_);
        eps_ = 1e-4f * std::max(scene.Diameter(), 1e-6f);
        Build();
    }
    ~Tracer() {
        if (rtcScene_) rtcReleaseScene(rtcScene_);
        if (device_) rtcReleaseDevice(device_);
    }

    // One sample of the irradiance at `x` over the hemisphere of `n`: an emitter point and
    // a cosine-sampled path, combined by multiple importance sampling (Veach 1997, power
    // heuristic) so that neither the 1/d² of nearby emitters nor small far ones blow up.
    glm::vec3 Sample(const glm::vec3& x, const glm::vec3& n, Rng& rng, uint64_t& rays) const {
        glm::vec3 e = NextEvent(x, n, nullptr, rng, rays);
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
            glm::vec3 toLight, span;
            float scale;
            if (light.type == LightType::kDirectional) {
                toLight = -light.direction;
                span = toLight * (4.0f * std::max(scene_.Diameter(), 1e-3f));
                scale = 1.0f;
            } else {
                span = light.position - x;
                float d2 = glm::dot(span, span);
                if (!(d2 > 0.0f)) continue;
                float d = std::sqrt(d2);
                toLight = span / d;
                scale = LightAttenuation(light, -toLight, d) / d2;
            }
            float cosine = glm::dot(n, toLight);
            if (cosine <= 0.0f || scale <= 0.0f) continue;
            ++rays;
            glm::vec3 from = x + eps_ * n;
            if (Occluded(from, x + span - from)) continue;
            glm::vec3 f = bsdf ? bsdf->Eval(toLight) : glm::vec3(1.0f);
            e += f * light.color * (light.intensity * scale * cosine);
        }
        return e;
    }

  private:
    static void OnError(void* self, RTCError code, const char* what) {
        auto* t = static_cast<Tracer*>(self);
        if (t->error_.empty())
            t->error_ = "Embree error " + std::to_string(int(code)) + ": " + (what ? what : "");
    }
    void CheckError() const {
        if (!error_.empty()) throw Error(error_);
    }

    void Build() {
        for (const auto& prim : scene_.primitives) {
            for (size_t i = 0; i + 2 < prim.indices.size(); i += 3) {
                uint32_t a = prim.indices[i], b = prim.indices[i + 1], c = prim.indices[i + 2];
                Triangle t;
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
        auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0,
                                                              RTC_FORMAT_FLOAT3, 3 * sizeof(float),
                                                              3 * tris_.size()));
        auto* idx = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(
            geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(uint32_t), tris_.size()));
        CheckError();
        for (size_t i = 0; i < tris_.size(); ++i) {
            const Triangle& t = tris_[i];
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

    static float PowerHeuristic(float a, float b) { return a * a / (a * a + b * b); }

    // Direct irradiance at `x` (normal `n`) from one emitter point: L_e cosθ_x cosθ_y / d²
    // over the area pdf, weighted against the cosine sampling of the same direction; with
    // `bsdf`, the radiance it reflects (times f, weighted against sampling the BRDF).
    glm::vec3 NextEvent(const glm::vec3& x, const glm::vec3& n, const Bsdf* bsdf, Rng& rng,
                        uint64_t& rays) const {
        if (emitters_.empty()) return glm::vec3(0.0f);
        float u = rng.Uniform();
        size_t k =
            std::min<size_t>(std::lower_bound(cdf_.begin(), cdf_.end(), double(u)) - cdf_.begin(),
                             emitters_.size() - 1);
        const uint32_t ti = emitters_[k];
        const Triangle& t = tris_[ti];
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
        if (Occluded(from, to - from)) return glm::vec3(0.0f);
        float pdfArea = areaPdf_[ti];
        float weight = PowerHeuristic(pdfArea * dist2 / cy, bsdf ? bsdf->Pdf(w) : cx / kPi);
        glm::vec3 le = scene_.materials[t.material].emission;
        if (bsdf) le *= bsdf->Eval(w);
        return le * (weight * cx * cy / (dist2 * pdfArea));
    }

    // Radiance arriving at `x` (normal `n`) from direction `dir`, sampled with pdf cosθ/π:
    // the emission of what the ray hits (MIS-weighted against NextEvent) and the light that
    // surface reflects, followed bounce by bounce.
    glm::vec3 Incoming(glm::vec3 x, glm::vec3 n, glm::vec3 dir, Rng& rng, uint64_t& rays) const {
        glm::vec3 radiance(0.0f), throughput(1.0f);
        float pdfDir = glm::dot(n, dir) / kPi;  // the pdf `dir` was drawn with
        for (int depth = 0; depth <= s_.maxDepth; ++depth) {
            RTCRayHit rh;
            Ray(rh.ray, x + eps_ * n, dir, std::numeric_limits<float>::infinity());
            rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
            RTCIntersectContext ctx;
            rtcInitIntersectContext(&ctx);
            rtcIntersect1(rtcScene_, &ctx, &rh);
            ++rays;
            if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) {
                // Escaped: the environment's radiance from that direction (no next-event
                // estimate for the sky, so no MIS weight either).
                if (sky_) radiance += throughput * scene_.environment.Radiance(dir);
                break;
            }
            const uint32_t ti = rh.hit.primID;
            const Triangle& t = tris_[ti];
            float cy = -glm::dot(t.normal, dir);
            if (cy <= 0.0f) break;  // a back side: opaque and black
            const Material& mat = scene_.materials[t.material];
            if (areaPdf_[ti] > 0.0f) {
                float dist = rh.ray.tfar;
                float pdfLight = areaPdf_[ti] * dist * dist / cy;
                float weight = PowerHeuristic(pdfDir, pdfLight);
                radiance += throughput * weight * mat.emission;
            }
            if (depth == s_.maxDepth) break;
            const Bsdf bsdf(mat, t.normal, -dir);
            if (bsdf.Black()) break;
            x = t.p0 + rh.hit.u * t.e1 + rh.hit.v * t.e2;
            n = t.normal;
            // Reflected: next-event estimates of emitters and punctual lights, then one
            // direction drawn from the BRDF carries the rest (throughput f·cos/pdf).
            radiance += throughput *
                        (NextEvent(x, n, &bsdf, rng, rays) + PunctualDirect(x, n, rays, &bsdf));
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

    static void Ray(RTCRay& r, const glm::vec3& o, const glm::vec3& d, float tfar) {
        r.org_x = o.x, r.org_y = o.y, r.org_z = o.z;
        r.dir_x = d.x, r.dir_y = d.y, r.dir_z = d.z;
        r.tnear = 0.0f;
        r.tfar = tfar;
        r.time = 0.0f;
        r.mask = ~0u;
        r.id = 0;
        r.flags = 0;
    }

    bool Occluded(const glm::vec3& from, const glm::vec3& span) const {
        RTCRay r;
        Ray(r, from, span, 1.0f - 1e-4f);
        RTCIntersectContext ctx;
        rtcInitIntersectContext(&ctx);
        rtcOccluded1(rtcScene_, &ctx, &r);
        return r.tfar < 0.0f;
    }

    const Scene& scene_;
    const ReferenceSettings& s_;
    RTCDevice device_ = nullptr;
    RTCScene rtcScene_ = nullptr;
    std::string error_;
    float eps_;
    bool sky_ = scene_.environment.Active();
    std::vector<Triangle> tris_;
    std::vector<uint32_t> emitters_;
    std::vector<double> cdf_;
    std::vector<float> areaPdf_;  // per triangle: P(chosen) / area; 0 for non-emitters
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
    std::vector<std::vector<glm::vec3>> points;
    const float inset = kVertexInset * scene.Diameter();
    for (uint32_t p = 0; p < scene.primitives.size(); ++p) {
        const Primitive& prim = scene.primitives[p];
        size_t n = prim.positions.size();
        result.irradiance.emplace_back(n, glm::vec3(0.0f));
        result.standardError.emplace_back(n, glm::vec3(0.0f));
        for (uint32_t i = 0; i < n; ++i) vertices.emplace_back(p, i);
        // Estimate just inside the primitive's own surface: a vertex on an edge where
        // another wall meets it would otherwise see that wall's back side.
        std::vector<glm::vec3> towards(n, glm::vec3(0.0f));
        for (size_t t = 0; t + 2 < prim.indices.size(); t += 3) {
            glm::vec3 c = (prim.positions[prim.indices[t]] + prim.positions[prim.indices[t + 1]] +
                           prim.positions[prim.indices[t + 2]]) /
                          3.0f;
            for (int k = 0; k < 3; ++k) {
                uint32_t v = prim.indices[t + k];
                glm::vec3 d = c - prim.positions[v];
                float len = glm::length(d);
                if (len > 0.0f) towards[v] += d / len;
            }
        }
        std::vector<glm::vec3>& pts = points.emplace_back(prim.positions);
        for (uint32_t i = 0; i < n; ++i) {
            glm::vec3 d = towards[i] - glm::dot(towards[i], prim.normals[i]) * prim.normals[i];
            float len = glm::length(d);
            if (len > 1e-6f) pts[i] += std::min(1.0f, len) * inset * (d / len);
        }
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
                    direct = tracer.PunctualDirect(points[p][i], prim.normals[i], r);
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

}  // namespace penumbra
