// The scene's triangles in an Embree BVH, for everything that traces rays against the input
// geometry: the reference path tracer (reference/path_tracer.cpp) and the gather stage's
// emitter direct light (gather/emitter_direct.h). Also the emitting triangles with a
// power-proportional choice, for light sampling.
#pragma once

#include <cmath>
#include <cstdint>
#include <glm/glm.hpp>
#include <limits>
#include <string>
#include <vector>

#include "scene/scene.h"
#include "scene/surfels.h"

struct RTCDeviceTy;
struct RTCSceneTy;

namespace penumbra {

struct RayTriangle {
    glm::vec3 p0, e1, e2;  // p0 + u·e1 + v·e2
    glm::vec3 normal;      // unit, on the side the vertex normals point to (its front)
    float area = 0.0f;
    uint32_t material = 0;   // the primitive's material when the BVH was built
    uint32_t primitive = 0;  // index into Scene::primitives
};

// An axis-aligned box, for asking which cached rays a move can have changed.
struct Bounds {
    glm::vec3 lo{std::numeric_limits<float>::infinity()};
    glm::vec3 hi{-std::numeric_limits<float>::infinity()};
    void Add(const glm::vec3& p) { lo = glm::min(lo, p), hi = glm::max(hi, p); }
    bool Empty() const { return lo.x > hi.x; }
    // Whether origin + t·dir meets the box for some t in [0, tmax] (slab test).
    bool Meets(const glm::vec3& origin, const glm::vec3& dir, float tmax) const;
};

// A ball around a box, for cheap tests of which rays a box can cut off.
struct Ball {
    glm::vec3 centre;
    float radius;
    explicit Ball(const Bounds& b)
        : centre(0.5f * (b.lo + b.hi)), radius(0.5f * glm::length(b.hi - b.lo)) {}
};

// Whether some segment from x to a point in ball `to` can pass through ball `by`: the cones
// from x around both balls overlap, and `by` does not lie wholly beyond `to`.
bool CanCut(const glm::vec3& x, const Ball& by, const Ball& to);

// The cone of directions from a point towards a ball: a segment from the point that leaves
// the cone, or ends before the ball begins, misses the ball. A few multiplications a
// segment, against the slab test's three divisions a box.
class BallCone {
  public:
    BallCone(const glm::vec3& origin, const Ball& ball);
    // Whether the segment origin → origin + span (a ray along span when `endless`) can meet
    // the ball.
    bool MayMeet(const glm::vec3& span, bool endless = false) const {
        if (inside_) return true;
        const float a = glm::dot(span, axis_), len2 = glm::dot(span, span);
        return a > 0.0f && a * a >= len2 * cos2_ && (endless || len2 >= near2_);
    }

    // The cone: whether the origin lies in the ball (then every direction), its unit axis and
    // the sine of its half-angle.
    bool Inside() const { return inside_; }
    const glm::vec3& Axis() const { return axis_; }
    float SinHalf() const { return std::sqrt(1.0f - cos2_); }

  private:
    bool inside_ = true;
    glm::vec3 axis_{0.0f};
    float cos2_ = 0.0f, near2_ = 0.0f;
};

struct RayHit {
    bool hit = false;
    uint32_t triangle = 0;  // index into RayScene::Triangles()
    float t = 0.0f, u = 0.0f, v = 0.0f;
};

class RayScene {
  public:
    // Builds the BVH over every triangle of `scene` (which must outlive this object).
    // Throws penumbra::Error on an Embree failure.
    explicit RayScene(const Scene& scene);
    // Over the refined mesh instead (Surfels::refinedTriangles, the same surfaces): a hit
    // names the three surfels around it (Corners), so that what a solver knows per surfel can
    // be interpolated there. Triangle materials are those of the primitives in `scene`.
    RayScene(const Scene& scene, const Surfels& surfels);
    // Built over a refined mesh: its surfels moved (the same refinement, `scene` as edited):
    // the triangles, emitters and BVH made again on the same Embree device. Throws
    // penumbra::Error for a RayScene not built over a refined mesh or another refinement.
    void Update(const Surfels& surfels);
    ~RayScene();
    RayScene(const RayScene&) = delete;
    RayScene& operator=(const RayScene&) = delete;

    // Whether an opaque surface lies on the segment from `from` to `from + span` (its last
    // 10⁻⁴ excluded, so that a ray aimed at a surface point is not stopped by that surface).
    // Surfaces that pass light (Material::Passes: glass, cutouts) do not stop it.
    bool Occluded(const glm::vec3& from, const glm::vec3& span) const;
    // What of the light along that segment gets through, per channel: 0 where an opaque
    // surface lies on it, else the product of the transmittances of the passing surfaces it
    // crosses (1 when none).
    glm::vec3 Transmittance(const glm::vec3& from, const glm::vec3& span) const;
    // The nearest opaque triangle along origin + t·dir, t in (0, tfar): passing surfaces are
    // looked through, and `through` (when given) gets the product of their transmittances
    // before the hit (all of them when nothing is hit).
    RayHit Intersect(const glm::vec3& origin, const glm::vec3& dir, float tfar,
                     glm::vec3* through = nullptr) const;
    // Occluded for `count` segments from one point, in Embree packets of 8 (rtcOccluded8):
    // per segment 1 where something lies on it, else 0, into out[0, count).
    void OccludedFrom(const glm::vec3& from, const glm::vec3* spans, size_t count,
                      uint8_t* out) const;
    // Intersect for `count` rays from one origin, in packets of 8 (rtcIntersect8): the same
    // hits as one at a time, for less where the rays start together; into out[0, count),
    // and each ray's `through` into through[0, count) when given.
    void IntersectFrom(const glm::vec3& origin, const glm::vec3* dirs, size_t count, float tfar,
                       RayHit* out, glm::vec3* through = nullptr) const;
    // Whether some material passes light (Material::Passes) when the BVH was built: the
    // queries above then look through those surfaces, one ray at a time.
    bool Passing() const { return passing_; }
    // Every triangle along origin + t·dir, t in (0, tfar), nearest first, in one traversal (a
    // filter that records each hit and lets the ray go on); a triangle Embree meets twice
    // (its spatial splits) counted once. For the light field's lines (solvers/lightfield/).
    // Clears `hits` first.
    void AllHits(const glm::vec3& origin, const glm::vec3& dir, float tfar,
                 std::vector<RayHit>& hits) const;

    const Scene& GetScene() const { return scene_; }
    const std::vector<RayTriangle>& Triangles() const { return tris_; }
    // Three a triangle, in Triangles()' order: p0, p0 + e1, p0 + e2 (for another tracer's
    // build, gpu/ray_tracer.h).
    std::vector<glm::vec3> Vertices() const;
    // Built over a refined mesh: the surfels at triangle t's p0, p0 + e1 and p0 + e2.
    const glm::uvec3& Corners(uint32_t t) const { return corners_[t]; }
    bool HasCorners() const { return !corners_.empty(); }  // built over the refined mesh
    // Emitting triangles (emission > 0), chosen in proportion to their power (area × summed
    // radiance): `emitters[k]` with the cumulative probability `cdf[k]`.
    const std::vector<uint32_t>& Emitters() const { return emitters_; }
    const std::vector<double>& EmitterCdf() const { return cdf_; }
    // The primitives with an emitting triangle when the BVH was built, each with a slot
    // 0 … EmitterPrimitives().size() − 1 (EmitterSlot: −1 for the others). Light sampled
    // from them is linear in their current emission, so that what depends on the emitters
    // can keep a coefficient per slot.
    const std::vector<uint32_t>& EmitterPrimitives() const { return emitterPrimitives_; }
    int EmitterSlot(uint32_t primitive) const { return emitterSlot_[primitive]; }
    // The emitter k a uniform number u in [0, 1) picks.
    size_t PickEmitter(float u) const;
    // Per triangle: P(chosen) / area, the area density of a point drawn by PickEmitter and
    // then uniformly on the triangle; 0 for triangles that do not emit.
    float AreaPdf(uint32_t triangle) const { return areaPdf_[triangle]; }
    // Triangle t's material and emission as the scene says now (a material edit may have
    // reassigned its primitive's material since the BVH was built).
    const Material& MaterialOf(uint32_t t) const {
        return scene_.materials[scene_.primitives[tris_[t].primitive].material];
    }
    // The tints of triangle t's material at its point p0 + u·e1 + v·e2: from its colour maps
    // at the point's texture coordinates over the input mesh; over the refined mesh, the
    // surfels' tints (Surfels::albedoTints, a hat-function average of the maps) interpolated.
    Tints TintsAt(uint32_t t, float u, float v) const;
    // The (u, v) at which the line origin + s·dir meets triangle t's plane.
    glm::vec2 Barycentrics(uint32_t t, const glm::vec3& origin, const glm::vec3& dir) const;
    // Whether any triangle's material has a colour map (else every tint is 1).
    bool Mapped() const { return mapped_; }
    // Offset that lifts ray origins off their surface: 10⁻⁴ × the scene's diameter.
    float Epsilon() const { return eps_; }

  private:
    void AddTriangle(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c,
                     const glm::vec3& normalSum, uint32_t primitive);
    // Triangle t's emission tint averaged over it, for its power.
    glm::vec3 MeanEmissionTint(uint32_t t) const;
    void Build();                        // Sample, then BuildBvh
    void Sample();                       // the emitters' choice from tris_
    void BuildBvh();                     // Embree's BVH over tris_
    void WriteVertices(float* v) const;  // tris_' corners, 9 floats a triangle
    void CheckError() const;
    RayHit IntersectThrough(const glm::vec3& origin, const glm::vec3& dir, float tfar,
                            glm::vec3& through) const;

    const Scene& scene_;
    bool passing_ = false;
    RTCDeviceTy* device_ = nullptr;
    RTCSceneTy* rtcScene_ = nullptr;
    std::string error_;
    float eps_ = 0.0f;
    std::vector<RayTriangle> tris_;
    std::vector<glm::uvec3> corners_;  // refined mesh only
    bool mapped_ = false;
    std::vector<glm::uvec3> vertices_;  // input mesh with maps: the primitive's vertices
    std::vector<glm::vec3> albedoTints_, emissionTints_;  // refined mesh with maps: per surfel
    std::vector<uint32_t> emitters_;
    std::vector<double> cdf_;
    std::vector<float> areaPdf_;
    std::vector<uint32_t> emitterPrimitives_;
    std::vector<int> emitterSlot_;
};

// Where per-vertex irradiance is estimated by everything that traces rays (the reference,
// the gather stage), per primitive in its input vertex order: each vertex moved
// kVertexInset × the scene's diameter into its own surface, towards the centroids of its
// triangles, in its tangent plane, but at most half way to the nearest of those centroids. A vertex
// on an edge where another wall meets it would otherwise see that wall's back side, and one where
// two objects touch would be inside both.
inline constexpr float kVertexInset = 1e-3f;
std::vector<std::vector<glm::vec3>> VertexEstimatePoints(const Scene& scene);

// The punctual lights' irradiance at a vertex's estimate point x (normal n, a directional
// light's shadow ray `diameter` × 4 long, as PunctualArrival), each light's visibility the
// mean over a disc of radius rays.Epsilon() about x in its tangent plane. A vertex on the
// edge of a shadow (a mesh edge the shadow follows, as a sun through a window lines up with
// its frame) reads the mean of the two sides, the limit of the light about it from every
// side; one shadow ray from x would read whichever side rounding puts it on. Elsewhere the
// disc is all lit or all dark: its centre and four points on its rim agree, and only where
// they do not are 16 more traced, spread over it. `count` (when given) adds the shadow rays.
// The reference and the gather stage's vertices both read their direct light so.
glm::vec3 VertexLightDirect(const RayScene& rays, const std::vector<PunctualLight>& lights,
                            const glm::vec3& x, const glm::vec3& n, float diameter,
                            uint64_t* count = nullptr);

}  // namespace penumbra
