// The gather stage: first shot and final gather (gather_stage.h).
#include "gather/gather_stage.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>

#include "base/check.h"
#include "base/pcg.h"

namespace penumbra {
namespace {

constexpr float kPi = 3.14159265358979f;
// The R2 sequence (emitter_direct.cpp): consecutive points spread evenly over the square.
constexpr double kR2a = 0.7548776662466927, kR2b = 0.5698402909980532;
// Streams of the gather's patterns, apart from the first shot's (which uses stream = surfel).
constexpr uint64_t kGatherStream = 0x9e3779b97f4a7c15ull;

double Ms(std::chrono::steady_clock::time_point since) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - since)
        .count();
}

// Cosine-distributed direction about the unit normal n for a point of the unit square:
// Shirley and Chiu's concentric map to the disk, lifted to the hemisphere (Malley's method),
// in the orthonormal basis of Duff et al. (2017).
glm::vec3 CosineDirection(const glm::vec3& n, float u1, float u2) {
    const float a = 2.0f * u1 - 1.0f, b = 2.0f * u2 - 1.0f;
    float r = 0.0f, phi = 0.0f;
    if (a != 0.0f || b != 0.0f) {
        if (std::abs(a) > std::abs(b)) {
            r = a;
            phi = (kPi / 4.0f) * (b / a);
        } else {
            r = b;
            phi = (kPi / 2.0f) - (kPi / 4.0f) * (a / b);
        }
    }
    const float x = r * std::cos(phi), y = r * std::sin(phi);
    const float z = std::sqrt(std::max(0.0f, 1.0f - x * x - y * y));
    const float sign = std::copysign(1.0f, n.z);
    const float p = -1.0f / (sign + n.z), q = n.x * n.y * p;
    const glm::vec3 t(1.0f + sign * n.x * n.x * p, sign * q, -sign * n.x);
    const glm::vec3 s(q, sign + n.y * n.y * p, -n.y);
    return glm::normalize(x * t + y * s + z * n);
}

bool SameEnvironment(const Environment& a, const Environment& b) {
    return a.source == b.source && a.image == b.image && a.constant == b.constant &&
           a.intensity == b.intensity && a.rotation == b.rotation;
}

}  // namespace

void CheckGatherRays(int rays, const std::string& what) {
    if (rays < 0 || rays > kMaxGatherRays)
        throw Error(what + " takes 0 (off) to " + std::to_string(kMaxGatherRays) +
                    " rays a surfel, not " + std::to_string(rays));
}

GatherStage::GatherStage(std::unique_ptr<Solver> inner, const Scene& scene,
                         const GatherSettings& settings)
    : inner_(std::move(inner)), scene_(scene), settings_(settings) {
    CheckGatherRays(settings.emitterRays, "the first shot");
    CheckGatherRays(settings.gatherRays, "the final gather");
    rays_ = std::make_unique<RayScene>(scene_, inner_->GetSurfels());
    Place();
    Shoot();
    const Surfels& s = inner_->GetSurfels();
    if (settings_.gatherRays > 0) {
        if (settings_.allSurfels) {
            for (uint32_t i = 0; i < s.size(); ++i) targets_.push_back(i);
        } else {
            for (size_t p = 0; p < scene_.primitives.size(); ++p)
                for (uint32_t i = 0; i < scene_.primitives[p].positions.size(); ++i)
                    targets_.push_back(s.firstSurfel[p] + i);
        }
        rotation_.resize(targets_.size());
        for (size_t t = 0; t < targets_.size(); ++t) {
            Pcg32 rng(settings_.seed, kGatherStream + targets_[t]);
            rotation_[t].x = rng.Uniform();
            rotation_[t].y = rng.Uniform();
        }
        Trace();
        Sky();
    }
}

void GatherStage::Shoot() {
    if (settings_.emitterRays <= 0) return;
    auto start = std::chrono::steady_clock::now();
    const Surfels& s = inner_->GetSurfels();
    EmitterDirectSettings es;
    es.rays = settings_.emitterRays;
    es.seed = settings_.seed;
    shot_ = EmitterIrradiance(*rays_, points_, s.normals, es);
    inner_->SetEmitterDirect(shot_);
    fresh_ = false;
    msShot_ = Ms(start);
}

void GatherStage::Place() {
    const Surfels& s = inner_->GetSurfels();
    points_ = s.positions;
    const auto inset = VertexEstimatePoints(scene_);
    for (size_t p = 0; p < inset.size(); ++p)
        std::copy(inset[p].begin(), inset[p].end(), points_.begin() + s.firstSurfel[p]);
}

glm::vec3 GatherStage::Direction(size_t target, int ray) const {
    const float u1 = static_cast<float>(std::fmod(rotation_[target].x + ray * kR2a, 1.0));
    const float u2 = static_cast<float>(std::fmod(rotation_[target].y + ray * kR2b, 1.0));
    return CosineDirection(inner_->GetSurfels().normals[targets_[target]], u1, u2);
}

void GatherStage::Trace() {
    auto start = std::chrono::steady_clock::now();
    const int n = settings_.gatherRays;
    hits_.assign(targets_.size() * n, Hit{kEscaped, 0, 0});
    const auto& tris = rays_->Triangles();
    tbb::parallel_for(tbb::blocked_range<size_t>(0, targets_.size(), 16), [&](const auto& range) {
        for (size_t t = range.begin(); t != range.end(); ++t) {
            const uint32_t i = targets_[t];
            const glm::vec3 o = points_[i] + rays_->Epsilon() * inner_->GetSurfels().normals[i];
            for (int r = 0; r < n; ++r) {
                const glm::vec3 d = Direction(t, r);
                const RayHit h = rays_->Intersect(o, d, std::numeric_limits<float>::infinity());
                Hit& out = hits_[t * n + r];
                if (!h.hit) continue;
                if (glm::dot(tris[h.triangle].normal, d) >= 0.0f) {
                    out.triangle = kBlack;
                    continue;
                }
                out.triangle = h.triangle;
                out.u = static_cast<uint16_t>(std::lround(std::clamp(h.u, 0.0f, 1.0f) * 65535.0f));
                out.v = static_cast<uint16_t>(std::lround(std::clamp(h.v, 0.0f, 1.0f) * 65535.0f));
            }
        }
    });
    fresh_ = false;
    msTrace_ = Ms(start);
}

void GatherStage::Sky() {
    const int n = settings_.gatherRays;
    sky_.assign(targets_.size(), glm::vec3(0.0f));
    if (!scene_.environment.Active()) return;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, targets_.size(), 64), [&](const auto& range) {
        for (size_t t = range.begin(); t != range.end(); ++t) {
            glm::vec3 sum(0.0f);
            for (int r = 0; r < n; ++r)
                if (hits_[t * n + r].triangle == kEscaped)
                    sum += scene_.environment.Radiance(Direction(t, r));
            sky_[t] = sum * (kPi / n);
        }
    });
    fresh_ = false;
}

void GatherStage::Evaluate() {
    auto start = std::chrono::steady_clock::now();
    indirect_ = inner_->SurfelIrradiance(Channel::kIndirect);
    direct_ = inner_->SurfelIrradiance(Channel::kDirect);
    const Surfels& s = inner_->GetSurfels();
    // The radiance each surfel reflects (and emits, where the solver carries the emission):
    // L = ρ/π · E over the surfel's whole irradiance.
    std::vector<glm::vec3> radiance(s.size());
    size_t p = 0;
    for (uint32_t i = 0; i < s.size(); ++i) {
        while (p + 1 < s.firstSurfel.size() && i >= s.firstSurfel[p + 1]) ++p;
        const Material& m = scene_.materials[scene_.primitives[p].material];
        radiance[i] = m.albedo / kPi * (indirect_[i] + direct_[i]);
        if (shot_.empty()) radiance[i] += m.emission;
    }
    const int n = settings_.gatherRays;
    std::vector<glm::vec3> gathered(targets_.size());
    tbb::parallel_for(tbb::blocked_range<size_t>(0, targets_.size(), 64), [&](const auto& range) {
        for (size_t t = range.begin(); t != range.end(); ++t) {
            glm::vec3 sum(0.0f);
            for (int r = 0; r < n; ++r) {
                const Hit& h = hits_[t * n + r];
                if (h.triangle >= kBlack) continue;
                const glm::uvec3& c = rays_->Corners(h.triangle);
                const float u = h.u * (1.0f / 65535.0f), v = h.v * (1.0f / 65535.0f);
                sum += (1.0f - u - v) * radiance[c.x] + u * radiance[c.y] + v * radiance[c.z];
            }
            gathered[t] = sum * (kPi / n) + sky_[t];
        }
    });
    for (size_t t = 0; t < targets_.size(); ++t) {
        const uint32_t i = targets_[t];
        indirect_[i] = (shot_.empty() ? glm::vec3(0.0f) : shot_[i]) + gathered[t];
    }
    fresh_ = true;
    msEvaluate_ = Ms(start);
}

void GatherStage::Iterate(int n) {
    inner_->Iterate(n);
    fresh_ = false;
}

std::vector<glm::vec3> GatherStage::SurfelIrradiance(Channel channel) {
    if (targets_.empty()) return inner_->SurfelIrradiance(channel);
    if (!fresh_) Evaluate();
    if (channel == Channel::kIndirect) return indirect_;
    if (channel == Channel::kDirect) return direct_;
    std::vector<glm::vec3> total(indirect_.size());
    for (size_t i = 0; i < total.size(); ++i) total[i] = indirect_[i] + direct_[i];
    return total;
}

void GatherStage::UpdateMaterials(const Scene& scene) {
    bool emissionChanged = scene.materials.size() != scene_.materials.size();
    for (size_t m = 0; !emissionChanged && m < scene.materials.size(); ++m)
        emissionChanged = scene.materials[m].emission != scene_.materials[m].emission;
    bool assignments = false;
    for (size_t p = 0; p < scene.primitives.size() && p < scene_.primitives.size(); ++p)
        assignments = assignments || scene.primitives[p].material != scene_.primitives[p].material;
    // Only what a material edit changes (no vertex arrays copied on an edit).
    scene_.materials = scene.materials;
    for (size_t p = 0; p < scene.primitives.size() && p < scene_.primitives.size(); ++p)
        scene_.primitives[p].material = scene.primitives[p].material;
    inner_->UpdateMaterials(scene);
    // The ray scene keeps each triangle's material and the emitters' power: rebuilt when
    // either changed (the same triangles, so the cached hits stay valid).
    if (emissionChanged || assignments)
        rays_ = std::make_unique<RayScene>(scene_, inner_->GetSurfels());
    if (emissionChanged) Shoot();
    fresh_ = false;
}

void GatherStage::UpdateLights(const Scene& scene) {
    const bool sky = !SameEnvironment(scene.environment, scene_.environment);
    scene_.lights = scene.lights;
    scene_.environment = scene.environment;
    inner_->UpdateLights(scene);
    if (sky && !targets_.empty()) Sky();
    fresh_ = false;
}

void GatherStage::UpdateGeometry(const Scene& scene) {
    inner_->UpdateGeometry(scene);
    scene_ = scene;
    rays_ = std::make_unique<RayScene>(scene_, inner_->GetSurfels());
    Place();
    Shoot();
    if (!targets_.empty()) {
        Trace();
        Sky();
    }
    fresh_ = false;
}

void GatherStage::WarmStart(const std::vector<float>& rows, const std::vector<uint8_t>& keep) {
    inner_->WarmStart(rows, keep);
    fresh_ = false;
}

SolverStats GatherStage::Stats() const {
    SolverStats s = inner_->Stats();
    s.emitterRays = shot_.empty() ? 0 : settings_.emitterRays;
    s.msEmitterDirect = msShot_;
    s.gatherRays = targets_.empty() ? 0 : settings_.gatherRays;
    s.gatherTargets = targets_.size();
    s.msGatherTrace = msTrace_;
    s.msGatherEvaluate = msEvaluate_;
    return s;
}

std::unique_ptr<Solver> WithGather(std::unique_ptr<Solver> solver, const Scene& scene,
                                   const GatherSettings& settings,
                                   std::vector<std::string>* notes) {
    CheckGatherRays(settings.emitterRays, "the first shot (emitter direct light)");
    CheckGatherRays(settings.gatherRays, "the final gather");
    const bool glossy = std::any_of(scene.materials.begin(), scene.materials.end(),
                                    [](const Material& m) { return m.Glossy(); });
    const bool emitters = std::any_of(
        scene.materials.begin(), scene.materials.end(),
        [](const Material& m) { return glm::any(glm::greaterThan(m.emission, glm::vec3(0.0f))); });
    GatherSettings s = settings;
    auto note = [&](const std::string& line) {
        if (notes) notes->push_back(line);
    };
    if (s.emitterRays > 0 && !emitters) {
        s.emitterRays = 0;
        note("no first shot: the scene has no emitting surfaces");
    } else if (s.emitterRays > 0 && glossy) {
        s.emitterRays = 0;
        note(
            "no first shot: not yet for scenes with glossy materials (their lobes would miss "
            "it); the solver carries the emission");
    }
    if (s.gatherRays > 0 && glossy) {
        s.gatherRays = 0;
        note(
            "no final gather: not yet for scenes with glossy materials (a glossy surface's "
            "light depends on the direction it is seen from); the solver's own answer");
    }
    if (s.emitterRays == 0 && s.gatherRays == 0) return solver;
    return std::make_unique<GatherStage>(std::move(solver), scene, s);
}

}  // namespace penumbra
