// The gather stage as a Solver: construction, evaluation, edits, stats and the factory
// (gather_stage.h; its rays in gather_trace.cpp, its glossy paths in gather_glossy.cpp).
#include "gather/gather_stage.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>

#include "base/check.h"
#include "base/image.h"
#include "base/pcg.h"
#include "gather/gather_detail.h"
#include "gpu/context.h"
#include "gpu/ray_tracer.h"
#include "rays/sampling.h"

namespace penumbra {

using namespace gather_detail;

namespace {

// The same sky but perhaps for its intensity.
bool SameShape(const Environment& a, const Environment& b) {
    return a.source == b.source && a.image == b.image && a.constant == b.constant &&
           a.rotation == b.rotation;
}

bool SameEnvironment(const Environment& a, const Environment& b) {
    return SameShape(a, b) && a.intensity == b.intensity;
}

bool AnyEmitter(const std::vector<Material>& materials) {
    return std::any_of(materials.begin(), materials.end(), [](const Material& m) {
        return glm::any(glm::greaterThan(m.emission, glm::vec3(0.0f)));
    });
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
    glossy_ = AnyGlossy(scene_.materials);
    emitters_ = AnyEmitter(scene_.materials);
    skyParts_ = Parts(scene_.environment);
    diameter_ = scene_.Diameter();
    Place();
    SplitShot();
    const Surfels& s = inner_->GetSurfels();
    if (settings_.gatherRays > 0) {
        StartTracer();
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
        TraceAll();
    }
    Shoot();
    HandSky(false);
}

void GatherStage::TraceAll(const Moved* moved) {
    Trace(moved);
    TraceLobes(moved);
    PlaceGlints();
    TraceGlints(moved);
    Sky();
}

GatherStage::~GatherStage() = default;

std::vector<std::string> GatherStage::ValidationMessages() const {
    std::vector<std::string> all = inner_->ValidationMessages();
    if (tracer_)
        for (std::string& m : tracer_->ValidationMessages()) all.push_back(std::move(m));
    return all;
}

void GatherStage::StartTracer() {
    gpu::DeviceKind kind;
    switch (settings_.device) {
        case DeviceChoice::kCpu:
            return;
        case DeviceChoice::kLavapipe:
            kind = gpu::DeviceKind::kLavapipe;
            break;
        case DeviceChoice::kAuto:
            if (!gpu::FindRealGpu(nullptr)) return;
            kind = gpu::DeviceKind::kRealGpu;
            break;
        default:
            kind = gpu::DeviceKind::kRealGpu;
    }
    try {
        tracer_ = std::make_unique<gpu::RayTracer>(kind, settings_.validation);
    } catch (const Error& e) {
        tracerNote_ = e.what();
    }
}

SkyParts GatherStage::Parts(const Environment& sky) const {
    if (settings_.emitterRays > 0) return SplitSky(sky);
    SkyParts whole;
    whole.rest = sky;
    return whole;
}

void GatherStage::HandSky(bool always) {
    const bool rest = SunHanded();
    if (rest == innerRest_ && !always) return;
    innerRest_ = rest;
    ToInner([&](const Scene& scene) { inner_->UpdateLights(scene); });
}

template <typename F>
void GatherStage::ToInner(F&& call) {
    if (!innerRest_) {
        call(scene_);
        return;
    }
    // scene_ with the sky the solver is to see, for the call.
    Environment whole = std::move(scene_.environment);
    scene_.environment = skyParts_.rest;
    call(scene_);
    scene_.environment = std::move(whole);
}

void GatherStage::Evaluate() {
    auto start = std::chrono::steady_clock::now();
    indirect_ = inner_->SurfelIrradiance(Channel::kIndirect);
    direct_ = inner_->SurfelIrradiance(Channel::kDirect);
    const Surfels& s = inner_->GetSurfels();
    // The radiance each surfel reflects (and emits, where the solver carries the emission):
    // L = ρ/π · E over the surfel's whole irradiance.
    // Albedo and emission per surfel (their colour maps' tints in them), interpolated at hits.
    std::vector<glm::vec3> radiance(s.size()), albedo(s.size()), emission(s.size());
    for (uint32_t i = 0; i < s.size(); ++i) {
        const Material& m = scene_.materials[scene_.primitives[surfelPrimitive_[i]].material];
        albedo[i] = s.Albedo(m, i), emission[i] = s.Emission(m, i);
        radiance[i] = albedo[i] / kPi * (indirect_[i] + direct_[i]);
        if (shot_.empty()) radiance[i] += emission[i];
    }
    // Values per surfel interpolated at a hit.
    auto at = [&](const std::vector<glm::vec3>& f, const Hit& h) {
        const glm::uvec3& c = rays_->Corners(h.triangle & kIndex);
        const float u = h.u * (1.0f / 65535.0f), v = h.v * (1.0f / 65535.0f);
        return (1.0f - u - v) * f[c.x] + u * f[c.y] + v * f[c.z];
    };
    const int n = settings_.gatherRays, m = SecondRays();
    // What a lobe ray meets sends towards it: emission (no first shot weighs these) and
    // (ρ + F0)/π · E, a glossy surface's lobe taken as if it spread its light evenly (one
    // glossy bounce is followed, not two).
    std::vector<glm::vec3> lobeRadiance;
    if (glossy_) {
        lobeRadiance.resize(s.size());
        for (uint32_t i = 0; i < s.size(); ++i) {
            const Material& m = scene_.materials[scene_.primitives[surfelPrimitive_[i]].material];
            const glm::vec3 rho = albedo[i] + (m.Glossy() ? m.specular : glm::vec3(0.0f));
            lobeRadiance[i] = rho / kPi * (indirect_[i] + direct_[i]) + emission[i];
        }
    }
    if (!lightsFresh_ || lobeLight_.size() != targets_.size()) LobeLights();
    std::vector<glm::vec3> gathered(targets_.size());
    tbb::parallel_for(tbb::blocked_range<size_t>(0, targets_.size(), 64), [&](const auto& range) {
        for (size_t t = range.begin(); t != range.end(); ++t) {
            glm::vec3 sum(0.0f);
            size_t k = 0;  // this target's short hits so far
            for (int r = 0; r < n; ++r) {
                const Hit& h = hits_[t * n + r];
                if (!Front(h)) continue;
                if (!(h.triangle & kShort)) {
                    sum += Through(t, r) * at(radiance, h);
                    continue;
                }
                // A short hit: its irradiance gathered again, E = first shot (interpolated) +
                // the punctual lights it sees + π/M Σ L over its secondary rays.
                glm::vec3 e = ShortDirect(t, k, h) + secondSky_[secondStart_[t] + k];
                if (!shot_.empty()) e += at(shot_, h);
                glm::vec3 second(0.0f);
                for (int j = 0; j < m; ++j) {
                    const Hit& h2 = second_[t][k * m + j];
                    if (Front(h2)) second += at(radiance, h2);
                }
                e += second * (kPi / m);
                sum += Through(t, r) * (at(albedo, h) / kPi * e +
                                        (shot_.empty() ? at(emission, h) : glm::vec3(0.0f)));
                ++k;
            }
            // Glossy hits: what their lobes reflect towards the target, F0 times the lobe
            // ray's estimate (the radiance where it lands, the sky where it escapes); the
            // punctual lights seen through the lobes are in lobeLight_ (LobeLights).
            for (const LobeHit& e : lobes_[t]) {
                const Material& mat = rays_->MaterialOf(hits_[t * n + e.ray].triangle & kIndex);
                sum += mat.specular * (Front(e.hit) ? at(lobeRadiance, e.hit) : e.sky) * e.weight;
            }
            gathered[t] = sum * (kPi / n) + sky_[t] + lobeLight_[t];
        }
    });
    for (size_t t = 0; t < targets_.size(); ++t) {
        const uint32_t i = targets_[t];
        indirect_[i] = (shot_.empty() ? glm::vec3(0.0f) : shot_[i]) + gathered[t];
    }
    fresh_ = true;
    msEvaluate_ = MsSince(start);
}

void GatherStage::Iterate(int n) {
    ShotPart();  // a moved emitter's shot, its next part (none left: nothing)
    inner_->Iterate(n);
    fresh_ = false;
}

std::vector<glm::vec3> GatherStage::SurfelIrradiance(Channel channel) {
    if (targets_.empty()) return inner_->SurfelIrradiance(channel);
    if (!fresh_) Evaluate();
    if (channel == Channel::kIndirect) return indirect_;
    if (pointDirect_.size() != targets_.size()) PointDirect();
    std::vector<glm::vec3> out = direct_;
    for (size_t t = 0; t < targets_.size(); ++t) out[targets_[t]] = pointDirect_[t];
    if (channel == Channel::kTotal)
        for (size_t i = 0; i < out.size(); ++i) out[i] += indirect_[i];
    return out;
}

void GatherStage::PointDirect() {
    const Surfels& s = inner_->GetSurfels();
    const float diameter = scene_.Diameter();
    pointDirect_.assign(targets_.size(), glm::vec3(0.0f));
    if (scene_.lights.empty()) return;
    tbb::parallel_for(size_t(0), targets_.size(), [&](size_t t) {
        const uint32_t i = targets_[t];
        pointDirect_[t] =
            VertexLightDirect(*rays_, scene_.lights, points_[i], s.normals[i], diameter);
    });
}

void GatherStage::UpdateMaterials(const Scene& scene) {
    // Per primitive: whether its emission changed, and whether it emits where it did not
    // when the rays were traced (the emitters' sampling does not know it: trace again).
    bool emissionChanged = false, newEmitter = false;
    for (size_t p = 0; p < scene.primitives.size() && p < scene_.primitives.size(); ++p) {
        const glm::vec3& was = scene_.materials[scene_.primitives[p].material].emission;
        const glm::vec3& now = scene.materials[scene.primitives[p].material].emission;
        emissionChanged = emissionChanged || was != now;
        newEmitter = newEmitter || (glm::any(glm::greaterThan(now, glm::vec3(0.0f))) &&
                                    rays_->EmitterSlot(static_cast<uint32_t>(p)) < 0);
    }
    // Whether a lobe changed its shape (exponent), or a material turned glossy or diffuse:
    // the lobe rays go elsewhere.
    bool lobesChanged = scene.materials.size() != scene_.materials.size();
    // Whether the glints' density changed (a glossy material's F0, or which are glossy).
    bool glintsChanged = lobesChanged;
    for (size_t p = 0; p < scene.primitives.size() && p < scene_.primitives.size(); ++p) {
        const Material& a = scene.materials[scene.primitives[p].material];
        const Material& b = scene_.materials[scene_.primitives[p].material];
        lobesChanged = lobesChanged || a.phongExponent != b.phongExponent;
        glintsChanged =
            glintsChanged || a.Glossy() != b.Glossy() || (a.Glossy() && a.specular != b.specular);
    }
    // Only what a material edit changes (no vertex arrays copied on an edit). The ray scene
    // reads materials through the primitives (RayScene::MaterialOf), so it stays valid.
    scene_.materials = scene.materials;
    for (size_t p = 0; p < scene.primitives.size() && p < scene_.primitives.size(); ++p)
        scene_.primitives[p].material = scene.primitives[p].material;
    inner_->UpdateMaterials(scene);
    fresh_ = false;
    lightsFresh_ = false;
    pointDirect_.clear();
    // A scene that turned glossy takes the first shot back from the solver (its lobes would
    // miss it), one that turned diffuse hands it over.
    const bool handed = HandsOver();
    glossy_ = AnyGlossy(scene_.materials);
    emitters_ = AnyEmitter(scene_.materials);
    if (HandsOver() != handed && !shot_.empty()) {
        inner_->SetEmitterDirect(HandsOver() ? shot_ : std::vector<glm::vec3>());
        HandSky(false);  // the sun goes with the shot
    }
    if (lobesChanged && !targets_.empty()) {
        TraceLobes();
        Sky();
    }
    if ((lobesChanged || glintsChanged) && !targets_.empty()) {
        PlaceGlints();
        TraceGlints();
    }
    if (!emissionChanged || settings_.emitterRays <= 0 || shot_.empty()) return;
    // The first shot and the gather's emitter hits are linear in each emitting primitive's
    // emission: re-weighted from their coefficients, unless an emitter is new.
    auto start = std::chrono::steady_clock::now();
    const size_t slots = rays_->EmitterPrimitives().size();
    // (Not while a moved emitter's shot is traced in parts: the points not yet traced have no
    // coefficients; it is traced whole below.)
    if (!newEmitter && shooter_ && !ShotPending() && shooter_->Reevaluate(*rays_, emitterShot_) &&
        (targets_.empty() || emitterCoef_.size() == targets_.size() * slots)) {
        std::vector<glm::vec3> le(slots);
        for (size_t k = 0; k < slots; ++k)
            le[k] = scene_.materials[scene_.primitives[rays_->EmitterPrimitives()[k]].material]
                        .emission;
        for (size_t t = 0; t < targets_.size(); ++t) {
            emitterHits_[t] = glm::vec3(0.0f);
            for (size_t k = 0; k < slots; ++k)
                emitterHits_[t] += le[k] * emitterCoef_[t * slots + k];
            emitterShot_[targets_[t]] += emitterHits_[t];
        }
        Combine();
        msShot_ = MsSince(start);
        return;
    }
    rays_ = std::make_unique<RayScene>(scene_, inner_->GetSurfels());
    SplitShot();  // a new emitter: split for the emitters there are now
    if (!targets_.empty()) TraceAll();
    Shoot();
}

void GatherStage::UpdateLights(const Scene& scene) {
    const bool sky = !SameEnvironment(scene.environment, scene_.environment);
    const bool reshaped = !SameShape(scene.environment, scene_.environment);
    const std::vector<PunctualLight> before = scene_.lights;
    scene_.lights = scene.lights;
    scene_.environment = scene.environment;
    if (sky && settings_.emitterRays > 0) {
        auto start = std::chrono::steady_clock::now();
        if (!reshaped) {
            // Only its intensity: the sun's rays keep their directions and what they met.
            skyParts_.sun.intensity = skyParts_.rest.intensity = scene.environment.intensity;
            if (sun_ && skyParts_.Split())
                sunShot_ = sun_->Reevaluate(skyParts_, inner_->GetSurfels().normals);
        } else {
            skyParts_ = Parts(scene_.environment);
            ++traces_;
            if (skyParts_.Split()) {
                sun_ = std::make_unique<SunDirect>(SunRays(), settings_.seed);
                sunShot_ = sun_->Trace(*rays_, skyParts_, points_, inner_->GetSurfels().normals,
                                       2.0f * diameter_);
            } else {
                sun_.reset();
                sunShot_.clear();
            }
        }
        Combine();
        msShot_ = MsSince(start);
    }
    HandSky(true);
    Relit(before);
    if (sky && !targets_.empty()) Sky();
    fresh_ = false;
    lightsFresh_ = false;
    pointDirect_.clear();
}

std::string GatherStage::UpdateGeometry(const Scene& scene) {
    const std::vector<glm::vec3> before = inner_->GetSurfels().positions;
    const std::vector<glm::vec3> normalsBefore = inner_->GetSurfels().normals;
    const std::vector<PunctualLight> lightsBefore = scene_.lights;
    scene_ = scene;
    std::string done;
    ToInner([&](const Scene& forInner) { done = inner_->UpdateGeometry(forInner); });
    const Surfels& s = inner_->GetSurfels();
    // What moved, and where it was and is: only the rays near it are traced again.
    Moved moved;
    moved.surfels.assign(s.size(), 0);
    Bounds was, is;
    bool emitterMoved = false;
    for (size_t i = 0; i < s.size(); ++i) {
        if (before[i] == s.positions[i] && normalsBefore[i] == s.normals[i]) continue;
        moved.surfels[i] = 1;
        was.Add(before[i]);
        is.Add(s.positions[i]);
        const uint32_t m = scene_.primitives[surfelPrimitive_[i]].material;
        emitterMoved = emitterMoved ||
                       glm::any(glm::greaterThan(scene_.materials[m].emission, glm::vec3(0.0f)));
    }
    // Rays that graze a moved surface's old place still count: the boxes are padded.
    const glm::vec3 pad(4.0f * rays_->Epsilon());
    for (Bounds* b : {&was, &is})
        if (!b->Empty()) moved.boxes.push_back({b->lo - pad, b->hi + pad});
    rays_->Update(s);
    diameter_ = scene_.Diameter();
    Place();
    raysRetraced_ = 0;
    // The gather's rays, lobes and glints: those that pass near what moved are traced again,
    // a moved emitter too (what a ray meets emits what its material does, wherever it is). A
    // moved emitter moves the points the first shot's shadow rays aim at: the shot is traced
    // again whole.
    if (!targets_.empty()) {
        TraceAll(&moved);
        Relit(lightsBefore);  // lights placed by a moved node
    }
    // A moved emitter's shot in parts (any move while one is under way starts it again: its
    // surfels traced so far saw the scene before this move); the sun's part as after any
    // move.
    if ((emitterMoved || ShotPending()) && settings_.shotPartMs > 0.0 && emitters_ &&
        settings_.emitterRays > 0) {
        Shoot(&moved, false);
        const double sunMs = msShot_;
        StartShotParts();
        msShot_ += sunMs;
    } else {
        Shoot(emitterMoved ? nullptr : &moved);
    }
    fresh_ = false;
    lightsFresh_ = false;
    pointDirect_.clear();
    return done;
}

std::string GatherStage::WarmStart(Solver& previous, const SurfelCarry& carry) {
    auto* before = dynamic_cast<GatherStage*>(&previous);
    std::string note = inner_->WarmStart(before ? *before->inner_ : previous, carry);
    fresh_ = false;
    return note;
}

SolverStats GatherStage::Stats() const {
    SolverStats s = inner_->Stats();
    GatherFigures& g = s.gather;
    g.emitterRays = shot_.empty() ? 0 : settings_.emitterRays;
    g.sunRays = sun_ ? sun_->Rays() : 0;
    g.msFirstShot = msShot_;
    g.rays = targets_.empty() ? 0 : settings_.gatherRays;
    g.targets = targets_.size();
    g.msTrace = msTrace_;
    g.msEvaluate = msEvaluate_;
    g.raysRetraced = raysRetraced_;
    g.traces = traces_;
    g.device =
        tracer_ ? "vulkan:" + tracer_->DeviceName() + " (ray tracing pipeline)" : "cpu (Embree)";
    if (!tracer_ && !tracerNote_.empty()) g.device += "; no GPU ray tracing: " + tracerNote_;
    // Every target has GlintCount() glints where there are glossy triangles to draw them on
    // (TraceGlints).
    if (!glossyTriangles_.empty())
        s.SetDetail("gather_glints", static_cast<double>(targets_.size() * GlintCount()));
    // Each short hit traces a shadow ray a punctual light (SeeShort).
    if (!secondStart_.empty())
        s.SetDetail("gather_short_hits", static_cast<double>(secondStart_.back()));
    if (ShotPending()) {
        char line[160];
        std::snprintf(line, sizeof line,
                      "the first shot traced again after an emitter moved: %.0f%% of the "
                      "surfels (the others keep its old place's light)",
                      100.0 * double(shotNext_) / double(points_.size()));
        s.catchingUp = line;
    }
    return s;
}

GatherSettings GatherParts(const Scene& scene, const GatherSettings& settings,
                           std::vector<std::string>* notes) {
    CheckGatherRays(settings.emitterRays, "the first shot (emitter direct light)");
    CheckGatherRays(settings.gatherRays, "the final gather");
    const bool glossy = AnyGlossy(scene.materials);
    const bool emitters = AnyEmitter(scene.materials);
    GatherSettings s = settings;
    auto note = [&](const std::string& line) {
        if (notes) notes->push_back(line);
    };
    if (s.emitterRays > 0 && !emitters && !HasSun(scene.environment)) {
        s.emitterRays = 0;
        note("no first shot: the scene has no emitting surfaces and no sun in its sky");
    } else if (s.emitterRays > 0 && glossy) {
        note(
            "the first shot serves the output vertices and the gather, not the solver: with "
            "glossy materials the solver carries the emission (its lobes reflect it)");
    }
    return s;
}

namespace {

// `solver` behind a gather stage with `parts` (GatherParts has checked them).
std::unique_ptr<Solver> Behind(std::unique_ptr<Solver> solver, const Scene& scene,
                               const GatherSettings& parts, std::vector<std::string>* notes) {
    if (parts.emitterRays == 0 && parts.gatherRays == 0) return solver;
    if (notes && parts.emitterRays > 0 && !AnyGlossy(scene.materials) &&
        !solver->TakesEmitterDirect())
        notes->push_back(
            "the first shot serves the output vertices and the gather, not the "
            "solver: solver '" +
            solver->Stats().solver + "' carries the emission itself");
    return std::make_unique<GatherStage>(std::move(solver), scene, parts);
}

}  // namespace

std::unique_ptr<Solver> WithGather(std::unique_ptr<Solver> solver, const Scene& scene,
                                   const GatherSettings& settings,
                                   std::vector<std::string>* notes) {
    return Behind(std::move(solver), scene, GatherParts(scene, settings, notes), notes);
}

std::unique_ptr<Solver> CreateGatheredSolver(const Scene& scene, SolverSettings settings,
                                             const GatherSettings& gather,
                                             const ProgressFn& progress,
                                             std::vector<std::string>* notes) {
    GatherSettings parts = GatherParts(scene, gather, notes);
    parts.device = settings.device;
    parts.validation = settings.validation;
    settings.behindGather = parts.gatherRays > 0 && !AnyGlossy(scene.materials);
    std::unique_ptr<Solver> solver = CreateSolver(scene, settings, progress);
    if (progress && (parts.emitterRays > 0 || parts.gatherRays > 0))
        progress("gather: tracing", 0.0);
    return Behind(std::move(solver), scene, parts, notes);
}

}  // namespace penumbra
