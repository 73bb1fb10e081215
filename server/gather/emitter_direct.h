// The gather stage's emitter direct light (issue 19, part 1): the irradiance that emitting
// surfaces send straight to a set of points, with explicit visibility (shadow rays through
// RayScene), instead of through the solver's bins. Solver-neutral: it sees the input
// geometry and materials only.
#pragma once

#include <glm/glm.hpp>
#include <vector>

#include "rays/ray_scene.h"

namespace penumbra {

struct EmitterDirectSettings {
    // Rays per point: shadow rays to the emitters and cosine rays, split per point by the
    // two techniques' variance (an eighth to seven eighths cosine rays; EmitterCosineRays).
    int rays = 256;
    uint64_t seed = 1;  // the same seed gives the same answer (no flicker between frames)
    // Cosine-distributed rays per point traced elsewhere (the final gather's) whose emitter
    // hits the caller adds with EmitterHitWeight: the weights here count them in.
    int extraCosineRays = 0;
};

// E(x) = ∫ L_e(y) cosθ_x cosθ_y / |x − y|² V(x, y) dA_y over every emitting triangle's front,
// per point x with unit normal n, by multiple importance sampling (Veach 1997, the power
// heuristic) of two kinds of rays: an emitting triangle chosen by power and a point on it
// (RayScene::PickEmitter, AreaPdf: jittered strata for the choice, a rotated R2 sequence for
// the point), and cosine-distributed directions (a rotated R2 sequence), each kind with a
// random stream of its own per point, so the answer depends neither on the thread count nor
// on the frame. How many of each a point takes follows from pilots of its own
// (EmitterCosineRays: more cosine rays where emitters surround the point). Light sampling
// alone is unbounded where an emitter lies close to the point (the 1/d² of the area measure);
// cosine sampling alone misses small emitters. Points with no emitter in front get 0. Throws
// penumbra::Error for rays < 1 or mismatched arrays.
std::vector<glm::vec3> EmitterIrradiance(const RayScene& rays, const std::vector<glm::vec3>& points,
                                         const std::vector<glm::vec3>& normals,
                                         const EmitterDirectSettings& settings = {});

// Per point, how many of `settings.rays` EmitterIrradiance's estimate makes cosine rays (the
// rest are light rays): from two pilots that are not part of the estimate, points drawn on
// the emitters (nothing traced) and a few traced cosine rays (more cosine rays where emitters
// surround the point, more light rays where they are small or far). A split that stays fixed while
// the scene changes keeps the estimate unbiased, only less efficient. Empty when the scene has no
// emitters.
std::vector<uint16_t> EmitterCosineRays(const RayScene& rays, const std::vector<glm::vec3>& points,
                                        const std::vector<glm::vec3>& normals,
                                        const EmitterDirectSettings& settings);

// EmitterIrradiance at a fixed set of points with every ray's outcome kept (a bit per shadow
// ray, the first hit of each cosine ray: 8 bytes a cosine ray), so that after a move only the
// rays that pass near what moved are traced again.
class EmitterDirect {
  public:
    explicit EmitterDirect(const EmitterDirectSettings& settings);
    // Traces every point. `extraCosine` (empty: none) gives per point the cosine rays traced
    // elsewhere whose emitter hits the caller adds (EmitterDirectSettings::extraCosineRays);
    // `split` (empty: EmitterCosineRays's) per point its cosine rays of the settings' rays.
    std::vector<glm::vec3> Trace(const RayScene& rays, const std::vector<glm::vec3>& points,
                                 const std::vector<glm::vec3>& normals,
                                 const std::vector<int>& extraCosine = {},
                                 const std::vector<uint16_t>& split = {});
    // Trace in parts (the same answer): Start forgets every point's outcomes, TracePart
    // traces points [first, last) into out[first, last) (`out` sized as `points`). Retrace
    // and Reevaluate need every point traced since the last Start.
    void Start(const RayScene& rays, const std::vector<glm::vec3>& points,
               const std::vector<glm::vec3>& normals, const std::vector<int>& extraCosine = {},
               const std::vector<uint16_t>& split = {});
    void TracePart(const RayScene& rays, const std::vector<glm::vec3>& points,
                   const std::vector<glm::vec3>& normals, size_t first, size_t last,
                   std::vector<glm::vec3>& out);
    // After a move (`rays` built on the moved scene, the points and normals as in Trace, the
    // moved ones at their new places): the points marked in `moved` are traced again; of the
    // others, each ray whose segment meets one of `boxes` (where the moved surfaces were and
    // are). The emitters must not have moved (trace them all again then). Returns E; `traced`
    // (when given) gets the number of rays traced.
    std::vector<glm::vec3> Retrace(const RayScene& rays, const std::vector<glm::vec3>& points,
                                   const std::vector<glm::vec3>& normals,
                                   const std::vector<uint8_t>& moved,
                                   const std::vector<Bounds>& boxes, size_t* traced = nullptr);

    // E again with the emission the scene has now, from the kept coefficients (a colour per
    // point and emitting primitive, RayScene::EmitterSlot: the emission maps' tints are in
    // them), without tracing: valid while the
    // emitting primitives are those `rays` was built with. False when none are kept (more
    // than kMaxSlots emitting primitives).
    static constexpr size_t kMaxSlots = 64;
    bool Reevaluate(const RayScene& rays, std::vector<glm::vec3>& out) const;

  private:
    // A light ray: the segment from the point (lifted off its surface) to the point on the
    // emitting triangle, its squared length and the cosines at both ends.
    struct Sample {
        glm::vec3 span;
        float dist2, cx, cy;
        glm::vec2 uv;  // the point on the triangle
    };
    // Light ray r of a point x with normal nx (rotation `sl` of its R2 sequence) to emitting
    // triangle `ti`; false where it adds nothing (either side faces away).
    bool LightRay(const RayScene& rays, uint32_t ti, int r, const glm::vec2& sl, const glm::vec3& x,
                  const glm::vec3& nx, Sample& out) const;
    // Point i's E, its rays traced where `boxes` is null or they meet one of them, their
    // kept outcomes read otherwise.
    glm::vec3 Shoot(const RayScene& rays, size_t i, const glm::vec3& x, const glm::vec3& n,
                    const std::vector<Bounds>* boxes, size_t& traced);
    // Traces again point i's rays that meet one of `boxes` (`cones`: a BallCone around each
    // from the point): its light rays to the emitting primitives whose slots are set in
    // `slots`, its cosine rays if `cosine` (those whose outcome can change what the point
    // receives: a first hit on an emitter, or on a surface that moved: `moved` per surfel);
    // keeps the new outcomes. True when one of them changed what the point receives.
    bool Recheck(const RayScene& rays, size_t i, const glm::vec3& x, const glm::vec3& n,
                 const std::vector<Bounds>& boxes, const std::vector<BallCone>& cones,
                 uint64_t slots, bool cosine, const std::vector<uint8_t>& moved, size_t& traced);

    EmitterDirectSettings settings_;
    int words_ = 0;
    std::vector<int> extra_;
    std::vector<uint64_t> blocked_;    // points × words_: bit r, light ray r was blocked
    std::vector<uint16_t> cosine_;     // per point: its cosine rays (the rest are light rays)
    std::vector<size_t> cosineFirst_;  // per point: its first cosine ray's outcome below
    std::vector<float> cosineT_;       // per cosine ray: the first hit's distance (∞: none)
    std::vector<uint32_t> cosineTri_;  // and its triangle
    size_t slots_ = 0;                 // emitting primitives kept (0: none kept)
    std::vector<glm::vec3> coef_;      // points × slots_
};

// The share of E that a cosine-distributed ray from a point with normal n, meeting emitting
// triangle `triangle`'s front at distance t in direction w, adds to the point's emitter
// direct light, when the point takes `lightRays` light rays and `cosineRays` cosine rays in
// all (this ray's kind, traced elsewhere, counted in): weight × L_e, zero for a triangle that
// does not emit or is met from behind.
float EmitterHitWeight(const RayScene& rays, int lightRays, int cosineRays, const glm::vec3& n,
                       const glm::vec3& w, uint32_t triangle, float t);

}  // namespace penumbra
