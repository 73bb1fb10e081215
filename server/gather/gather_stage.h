// The gather stage (issue 19, docs/SOLVER.md): solver-neutral, between any solver and the output.
//
// 1. The first shot: the emitters' direct light with explicit visibility (emitter_direct.h)
//    and an environment map's sun (sun_direct.h: the part of the map above its mean, drawn by
//    its brightness) at the solver's surfels, handed to it (Solver::SetEmitterDirect), so the
//    solver carries only bounces and the rest of the sky (not in a scene with glossy
//    materials, whose lobes would miss it).
// 2. The final gather: at each output surfel, cosine-distributed rays (a fixed pattern per
//    surfel, so frames do not flicker); each ray that meets a surface reads the light that
//    surface reflects, L = ρ/π · E with E the solver's irradiance interpolated on the refined
//    mesh (first shot and punctual lights included); each ray that escapes reads the
//    environment. E(x) = π/N Σ L over the N rays, plus the first shot at x. The solver's
//    bin-scale blur and its leaks are integrated over the hemisphere instead of read
//    directly (two-pass radiosity's final gather). A glossy surface met also reflects
//    through its lobe: a lobe ray, and the punctual lights it sees (with glints, MIS).
//
// A Solver wrapping another: edits pass through; the rays are traced once and their outcomes
// cached, so a light, material or sky edit re-reads them, an emissive edit re-weights them,
// and a move traces again only the rays that pass near what moved.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>

#include "gather/emitter_direct.h"
#include "gather/sun_direct.h"
#include "rays/ray_scene.h"
#include "solver/solver.h"

namespace penumbra {

namespace gpu {
class RayTracer;
}

struct GatherSettings {
    // First shot: rays a surfel to the emitters (half of them to a sky map's sun); 0: the
    // solver carries the emission and the whole sky.
    int emitterRays = 256;
    int gatherRays = 256;  // final gather: rays an output surfel; 0: the solver's own answer
    // Gather at every surfel (a render of the refined mesh) or only at the input vertices
    // (what bake and the service write).
    bool allSurfels = false;
    uint64_t seed = 1;
    // Where the final gather's rays are traced when all of them are (at the start, after an
    // emitter moved). kCpu: Embree. kGpu, and kAuto where a GPU is found: the GPU's hardware
    // ray tracing (gpu/ray_tracer.h), Embree where it has none, with why in the stats
    // (SolverStats::gatherDevice). kLavapipe: tried there (Mesa 22.3 has none). The first
    // shot, the secondary gathers and the rays a move traces again stay on Embree.
    // CreateGatheredSolver takes both from the solver's settings.
    DeviceChoice device = DeviceChoice::kCpu;
    bool validation = false;  // Vulkan validation layers on the ray tracer's device
    // A moved emitter's first shot (every surfel's shadow rays aim at it): 0, traced again
    // whole by UpdateGeometry; > 0, in parts of about this many milliseconds, the first by
    // UpdateGeometry and one before each Iterate, so that frames go out while it is under
    // way (the surfels not yet traced again keep the light of the emitter's old place;
    // SolverStats::catchingUp says how far it is). The service's frames take parts.
    double shotPartMs = 0.0;
};

// The most rays a surfel either part takes; CheckGatherRays throws penumbra::Error for a
// count outside 0 (off) … kMaxGatherRays, naming `what` (the option).
inline constexpr int kMaxGatherRays = 65536;
void CheckGatherRays(int rays, const std::string& what);

class GatherStage : public Solver {
  public:
    // Traces the first shot and the gather's hits for `inner`, built from `scene`. Throws
    // penumbra::Error when the inner solver cannot take the shot (Solver::SetEmitterDirect).
    GatherStage(std::unique_ptr<Solver> inner, const Scene& scene, const GatherSettings& settings);
    ~GatherStage() override;
    // The inner solver's, then the ray tracer's.
    std::vector<std::string> ValidationMessages() const override;

    void Iterate(int n) override;
    // With the final gather: `indirect` = first shot + gathered light at the output surfels,
    // `direct` = the solver's (punctual lights); the other surfels keep the solver's values.
    std::vector<glm::vec3> SurfelIrradiance(Channel channel) override;
    const Surfels& GetSurfels() const override { return inner_->GetSurfels(); }
    void UpdateMaterials(const Scene& scene) override;
    void UpdateLights(const Scene& scene) override;
    SolverStats Stats() const override;
    std::string GeometryMismatch(const Scene& scene) const override {
        return inner_->GeometryMismatch(scene);
    }
    std::string UpdateGeometry(const Scene& scene) override;
    std::string WarmStart(Solver& previous, const SurfelCarry& carry) override;
    void SetInterrupt(const std::atomic<bool>* flag) override { inner_->SetInterrupt(flag); }
    Solver& Inner() { return *inner_; }

  private:
    // A gather ray's first hit: refined triangle (low 30 bits) and barycentrics (u, v in
    // 1/65535), or kEscaped.
    struct Hit {
        uint32_t triangle;
        uint16_t u, v;
    };
    static constexpr uint32_t kEscaped = 0xffffffffu;  // read the environment
    // Set on a hit on a back side: opaque and black (as in the reference).
    static constexpr uint32_t kBack = 0x40000000u;
    // Set on a hit closer than half the solver's element size: its light is gathered again
    // there (a secondary gather), the solver's answer being least trustworthy across its own
    // elements near a junction or a contact.
    static constexpr uint32_t kShort = 0x80000000u;
    static constexpr uint32_t kIndex = 0x3fffffffu;
    static bool Front(const Hit& h) { return h.triangle != kEscaped && !(h.triangle & kBack); }
    static bool Same(const Hit& a, const Hit& b) {
        return a.triangle == b.triangle && a.u == b.u && a.v == b.v;
    }
    // A lobe ray below its surface: it carries nothing (not a triangle, not the sky).
    static constexpr uint32_t kNone = 0xfffffffeu;
    // Glossy hits: a front hit y on a glossy surface also reflects, through its Phong lobe
    // (the reference's BRDF, F0 (n + 2)/(2π) cosⁿθ_r), the light arriving at y from around
    // the mirror image of the ray. Per such hit, one ray from y drawn from the lobe (a fixed
    // direction per target and ray) and the punctual lights y sees.
    struct LobeHit {
        uint16_t ray;   // the gather ray whose hit y this continues
        Hit from;       // that hit when the lobe ray was traced
        Hit hit;        // the lobe ray's first hit (kEscaped: the sky; kNone: below y)
        float weight;   // (n + 2)/(n + 1) · cosθ_i: the estimator's weight over F0
        glm::vec3 sky;  // the sky's radiance along it, where it escaped
    };

    // What a move changed, for the rays cached before it (UpdateGeometry).
    struct Moved {
        std::vector<uint8_t> surfels;  // per surfel: it moved (or turned)
        std::vector<Bounds> boxes;     // where the moved surfaces were and are
        // Whether o + s·span, s in [0, tMax], meets a box.
        bool Meets(const glm::vec3& o, const glm::vec3& span, float tMax) const {
            for (const Bounds& b : boxes)
                if (b.Meets(o, span, tMax)) return true;
            return false;
        }
        // Whether a corner of refined triangle `tri` of `rays` moved.
        bool Touches(const RayScene& rays, uint32_t tri) const {
            const glm::uvec3& c = rays.Corners(tri);
            return surfels[c.x] || surfels[c.y] || surfels[c.z];
        }
    };
    // A barycentric coordinate in 1/65535.
    static uint16_t Quantise(float x) {
        return static_cast<uint16_t>(std::lround(std::clamp(x, 0.0f, 1.0f) * 65535.0f));
    }
    // The first hit of the ray o + t·d (kBack set on a back side, kEscaped where there is
    // none), and at `t` (when given) how far along it lies (∞ when it escaped).
    Hit Cast(const glm::vec3& o, const glm::vec3& d, float* t = nullptr) const;
    // The cached form of Embree's answer `h` for a ray along d (kEscaped where it met nothing).
    Hit Cached(const RayHit& h, const glm::vec3& d) const;
    // The cached form of a ray along d meeting triangle `tri` at (u, v), whichever tracer
    // found it.
    Hit Found(uint32_t tri, float u, float v, const glm::vec3& d) const;

    // points_: the input vertices' estimate points, the others just inside their surface.
    void Place();
    // The emitters' and the sun's light at the surfels (all of it, or after a move the rays
    // it can have changed), then Combine.
    // `emitterPart` false: the sun's part only (the emitters' is traced in parts).
    void Shoot(const Moved* moved = nullptr, bool emitterPart = true);
    // shot_ = emitterShot_ + sunShot_, handed to the solver where it takes it.
    void Combine();
    // A moved emitter's shot in parts (GatherSettings::shotPartMs): StartShotParts forgets
    // the shooter's outcomes and traces the first part, ShotPart the next (about shotPartMs
    // each); shotNext_ < the surfel count while parts are left.
    void StartShotParts();
    void ShotPart();
    EmitterDirectSettings ShotSettings() const;  // the first shot's rays and seed
    EmitterDirect& NewShooter();                 // shooter_ made afresh for the settings
    void SplitShot();                            // shotSplit_ for the surfels and emitters now
    std::vector<int> CosineAtTargets() const;    // per surfel: the gather's rays (targets), or 0
    bool ShotPending() const { return shooter_ && shotNext_ < points_.size(); }
    // The sky the solver is given: without its sun where the solver takes the sun's shot
    // (SunHanded), the whole sky otherwise. Calls inner_->UpdateLights when that changed or
    // `always`.
    void HandSky(bool always);
    // Calls `call` with scene_ as the solver is to see it (its sky without the sun where
    // innerRest_).
    template <typename F>
    void ToInner(F&& call);
    bool SunHanded() const { return skyParts_.Split() && HandsOver(); }
    // The sky the gather's cosine rays read where they escape: without its sun where the
    // first shot carries it.
    const Environment& CosineSky() const {
        return skyParts_.Split() ? skyParts_.rest : scene_.environment;
    }
    // scene_'s environment split for the first shot (not split without one).
    SkyParts Parts(const Environment& sky) const;
    // Rays a surfel to the sun: half the first shot's.
    int SunRays() const { return std::max(1, settings_.emitterRays / 2); }
    // The gather rays' hits at the targets: all of them, or after a move those that it can
    // have changed; then emitterHits_ (Shoot reads them).
    void Trace(const Moved* moved = nullptr);
    struct TargetTracer;  // one thread's tracing of its targets (Trace)
    // Every ray the gather keeps (all of them, or after a move those it can have changed):
    // Trace, the glossy hits' lobes, the glints, then the sky the escaped rays read.
    void TraceAll(const Moved* moved = nullptr);
    // emitterHits_ and emitterCoef_ from the gather rays' emitting hits: at every target, or
    // `afterMove` at those `touched` (a ray traced again).
    void WeighEmitterHits(bool afterMove, const std::vector<uint8_t>& touched);
    void Sky();  // the environment light of the escaped rays
    // The lobe rays of the targets' glossy hits: all of them, or after a move those that it
    // can have changed (every cached one is checked against the moved boxes).
    void TraceLobes(const Moved* moved = nullptr);
    // Which punctual lights the lobe hits see, again for the lights marked in `which` (empty:
    // every light, after their count changed).
    void SeeLights(const std::vector<uint8_t>& which);
    // The punctual lights a point y (lifted off its surface, normal n) sees, as LightWords()
    // words of bits at `bits`: each light traced again where `old` is null, where `which`
    // marks it or where `moved` can have cut its segment; the others keep their bit from
    // `old` (which may be `bits` itself). Returns the shadow rays traced.
    size_t See(const glm::vec3& y, const glm::vec3& n, uint32_t* bits, const uint32_t* old,
               const Moved* moved, const std::vector<uint8_t>* which = nullptr) const;
    // SeeLights for the punctual lights placed otherwise than in `before` (scene_'s now).
    void Relit(const std::vector<PunctualLight>& before);
    // The lobe ray of target t's ray r, which met glossy `h`, and its cosine at h's surface.
    glm::vec3 LobeDirection(size_t target, int ray, const Hit& h, float& cosine) const;
    int LightWords() const { return (static_cast<int>(scene_.lights.size()) + 31) / 32; }
    // Glints: points on the glossy triangles drawn from each target by area × F0 (one
    // light-independent density for all targets), each with whether the target sees its front
    // and which punctual lights it sees. They estimate the punctual lights seen through glossy
    // lobes a second way, combined with the gather rays' glossy hits by multiple importance
    // sampling (power heuristic): a gather ray meets a small glossy object rarely, and its
    // lobe's highlight more rarely still.
    struct Glint {
        uint32_t triangle;  // refined triangle
        uint16_t u, v;      // barycentrics in 1/65535
        uint32_t seen;      // 1: the target sees its front, unoccluded
    };
    // Four times the gather's rays: on the glossy box more glints stopped paying past that
    // (bench/results/FINDINGS.md, "Gather: glossy hits").
    int GlintCount() const { return 4 * settings_.gatherRays; }
    // The punctual lights a glossy point y (on refined `triangle`, lifted off it) reflects
    // towards wo through its lobe, without F0: Σ (n + 2)/(2π) cosⁿθ_r · E_l(y) over the lights
    // set in `seen` (LightWords() words from entry · LightWords()).
    glm::vec3 LobeLight(size_t entry, uint32_t triangle, const glm::vec3& wo, const glm::vec3& y,
                        const std::vector<uint32_t>& seen) const;
    // The glossy triangles and their cumulative weights (area × luminance of F0); none in a
    // scene without glossy materials or without punctual lights.
    void PlaceGlints();
    // The glints' visibility: all of them anew, or after a move those it can have changed.
    void TraceGlints(const Moved* moved = nullptr);
    // The glints' area density at a point of glossy triangle `tri` (0 for any other).
    float GlintDensity(uint32_t tri) const;
    // lobeLight_: per target, the punctual lights seen through glossy lobes, from the gather
    // rays' glossy hits and the glints (MIS). It depends on the lights, materials and
    // geometry but not on the solver's answer, so it is kept between evaluations.
    void LobeLights();
    glm::vec3 Direction(size_t target, int ray) const;
    // Secondary ray j from the short hit of target t's ray r, on triangle `tri`: point j of
    // the R2 sequence rotated by SecondRotation(t, r), cosine-distributed.
    glm::vec2 SecondRotation(size_t target, int ray) const;
    glm::vec3 SecondDirection(size_t target, int ray, uint32_t tri, int j) const;
    // Rays a secondary gather: 4 at 256. A vertex has many short hits (about a quarter of its
    // rays on the office), whose secondaries' noise averages out over them: 16, 8 and 4 gave
    // the same answers, 2 began to lose (bench/results/FINDINGS.md, "Constants in the code").
    int SecondRays() const { return std::max(4, settings_.gatherRays / 64); }
    // A cached hit's point (front or back side; not for kEscaped), and how far along its ray
    // it lies (∞ when it escaped).
    glm::vec3 HitPoint(const Hit& h) const;
    float Distance(const glm::vec3& origin, const Hit& h) const;
    void Evaluate();  // indirect_, direct_ from the inner solver's answer and the cached hits

    std::unique_ptr<Solver> inner_;
    Scene scene_;  // as last edited: the ray scene's materials and environment
    GatherSettings settings_;
    std::unique_ptr<RayScene> rays_;
    // Per surfel, where its light is estimated: an input vertex at its estimate point
    // (VertexEstimatePoints, where the reference estimates it too), others where they are.
    std::vector<glm::vec3> points_;
    std::vector<uint32_t> surfelPrimitive_;   // per surfel: its primitive
    std::unique_ptr<EmitterDirect> shooter_;  // the first shot's rays (null: no emitters)
    // Per surfel: its first shot's cosine rays of emitterRays (EmitterCosineRays), the rest
    // light rays; kept through moves (a stale split is still unbiased), so that the gather's
    // emitter hits at a target are weighted as the shot there was. Empty: no emitters.
    std::vector<uint16_t> shotSplit_;
    // The next surfel of a shot in parts (past the surfels, SIZE_MAX when none is under way).
    size_t shotNext_ = SIZE_MAX;
    std::vector<int32_t> targetOf_;       // per surfel: its target, or −1
    std::vector<glm::vec3> shot_;         // first shot per surfel (empty: off)
    std::vector<glm::vec3> emitterShot_;  // its emitters' part (empty: none)
    bool emitters_ = false;               // the scene has emitting materials
    SkyParts skyParts_;                   // the sky, its sun split off for the first shot
    std::unique_ptr<SunDirect> sun_;      // the sun's rays (null: no sun)
    std::vector<glm::vec3> sunShot_;      // the first shot's sun part (empty: none)
    bool innerRest_ = false;              // the solver has skyParts_.rest as its sky
    // Per target: the emitters its gather rays meet, weighted against the first shot's
    // shadow rays (EmitterHitWeight), which at the targets counts the gather rays in.
    std::vector<glm::vec3> emitterHits_;
    // The same as a coefficient per target and emitting primitive (RayScene::EmitterSlot),
    // so that an emissive edit re-weights them without tracing (empty: not kept).
    std::vector<glm::vec3> emitterCoef_;
    // Per target: the punctual lights' direct light at its point (points_, VertexLightDirect),
    // for the output's direct channel: a vertex's own value, as the reference has it, where
    // the solver's E_d is a mean over the surfel's footprint (what it reflects). Empty: to be
    // traced again (a light, a move).
    std::vector<glm::vec3> pointDirect_;
    void PointDirect();
    std::vector<uint32_t> targets_;    // surfels gathered at
    std::vector<glm::vec2> rotation_;  // per target: its rotation of the ray pattern
    std::vector<Hit> hits_;            // targets × gatherRays
    // Per gather ray, the transmittance of the surfaces it looked through (glass: the ray
    // scene's Passing); empty when nothing passes light. Through(t, r): 1 then.
    std::vector<glm::vec3> through_;
    glm::vec3 Through(size_t t, int r) const {
        return through_.empty() ? glm::vec3(1.0f) : through_[t * settings_.gatherRays + r];
    }
    std::vector<glm::vec3> sky_;  // per target: π/N Σ over escaped rays of L_env
    // Secondary gathers: per target SecondRays() hits per short hit in ray order; per short
    // hit π/M Σ over its escaped rays of L_env (target t's from secondStart_[t]).
    std::vector<std::vector<LobeHit>> lobes_;  // per target, in ray order
    // Per target, LightWords() words a lobe hit: bit l where punctual light l reaches its y
    // unoccluded (where it is turned towards y's surface).
    std::vector<std::vector<uint32_t>> seen_;
    // The scene has glossy materials: the first shot serves the targets and the gather but is
    // not handed to the solver, whose lobes reflect the emission it carries itself.
    bool glossy_ = false;
    // Whether the solver takes the first shot (then it carries only bounces): in a scene
    // without glossy materials, from a solver that can (Solver::TakesEmitterDirect).
    bool HandsOver() const { return !glossy_ && inner_->TakesEmitterDirect(); }
    std::vector<uint32_t> glossyTriangles_;   // refined triangles of glossy materials
    std::vector<double> glossyCdf_;           // their weights, cumulative (glossyCdf_.back(): all)
    std::vector<float> glintDensity_;         // per refined triangle: lum(F0) / all (or 0)
    std::vector<std::vector<Glint>> glints_;  // per target
    std::vector<std::vector<uint32_t>> glintSeen_;  // per target, LightWords() words a glint
    float diameter_ = 0.0f;             // the scene's: where directional lights' shadow rays end
    std::vector<glm::vec3> lobeLight_;  // per target (LobeLights)
    bool lightsFresh_ = false;          // lobeLight_ holds the current lights and geometry
    std::vector<std::vector<Hit>> second_;
    std::vector<uint32_t> secondStart_;
    std::vector<glm::vec3> secondSky_;
    // Per target, LightWords() words a short hit (in ray order): bit l where punctual light l
    // reaches the hit's point y unoccluded. A short hit's direct light is then y's own, as
    // the reference has it, where the solver's, interpolated over a refined triangle, reaches
    // across a wall that stands on the triangle (the lit side's light read behind the wall).
    std::vector<std::vector<uint32_t>> shortSeen_;
    // shortSeen_ after Trace: every short hit of a target whose rays were traced again
    // (`touched`; all of them without `moved`), and the others' lights whose segments the
    // move can have cut. Returns the shadow rays traced.
    size_t SeeShort(const Moved* moved, const std::vector<uint8_t>& touched);
    // Target t's part of it: every short hit's lights traced (`fresh`, its words laid out
    // anew), or each light again where `which` marks it or `moved` can have cut its segment.
    size_t SeeShortOf(size_t t, bool fresh, const Moved* moved, const std::vector<uint8_t>* which);
    // The punctual lights' irradiance at target t's k-th short hit h (shortSeen_).
    glm::vec3 ShortDirect(size_t t, size_t k, const Hit& h) const;
    bool fresh_ = false;                        // indirect_, direct_ hold the current answer
    std::vector<glm::vec3> indirect_, direct_;  // per surfel, after Evaluate
    // The GPU that traces full gathers (null: Embree), or why there is none (empty: not asked).
    std::unique_ptr<gpu::RayTracer> tracer_;
    std::string tracerNote_;
    void StartTracer();
    // The gather rays of every target traced on tracer_ (its acceleration structures built
    // over the refined mesh as it is now): hits_ and the distances along the rays.
    bool TraceOnGpu(std::vector<float>& distances);
    double msShot_ = 0.0, msTrace_ = 0.0, msEvaluate_ = 0.0;
    size_t raysRetraced_ = 0;  // by the last move, both parts
    size_t traces_ = 0;        // tracings of either part, whole or after a move
};

// The parts of `settings` that can serve `scene`: the first shot is declined (0 rays) for a
// scene without emitters. In a scene with glossy materials it is kept but not handed to the
// solver (GatherStage::glossy_), which a note says. `notes` (when given) gets a line for
// each part declined or changed. Throws penumbra::Error for ray counts out of range.
GatherSettings GatherParts(const Scene& scene, const GatherSettings& settings,
                           std::vector<std::string>* notes = nullptr);

// `solver` behind the gather stage, with the parts GatherParts leaves (both declined:
// `solver` as it is).
std::unique_ptr<Solver> WithGather(std::unique_ptr<Solver> solver, const Scene& scene,
                                   const GatherSettings& settings,
                                   std::vector<std::string>* notes = nullptr);

// The solver `settings` names, built for what it will feed, then behind the gather stage
// (WithGather). When GatherParts keeps the final gather in a scene without glossy materials,
// the solver's answer is read only through the gather's hits, a bounce later and averaged
// over the hemisphere, so its resolution matters less: SolverSettings::behindGather is set
// and the solver picks cheaper defaults (docs/SOLVER.md, "Settings behind the gather").
std::unique_ptr<Solver> CreateGatheredSolver(const Scene& scene, SolverSettings settings,
                                             const GatherSettings& gather,
                                             const ProgressFn& progress = {},
                                             std::vector<std::string>* notes = nullptr);

}  // namespace penumbra
