// The light field's parallel subfields (Mortensen, Khanna, Slater 2008, Sec. 2.1): per
// direction a grid of parallel lines over the plane orthogonal to it, covering the scene's
// bounding sphere, and every surface each line meets in order along it. The paper sorts faces
// along each direction (Sec. 3.2) and rasterises; here Embree collects a line's hits in one
// traversal (RayScene::AllHits) on the refined mesh, so a hit names the three surfels around
// it. Batches of directions are new random rotations of one near-uniform set (global ray
// bundles, Szirmay-Kalos 1998), so that the fixed directions' artefacts turn into noise that
// averages out.
#pragma once

#include <algorithm>
#include <cstdint>
#include <glm/glm.hpp>
#include <utility>
#include <vector>

#include "rays/ray_scene.h"
#include "scene/environment.h"

namespace penumbra {

// One surface a line meets: 8 bytes.
struct LineHit {
    uint32_t triangle;  // RayScene triangle; the top bit: its front faces along the line
    uint16_t u, v;      // barycentrics × 65535 (the hat weights of Corners' y and z)
};
inline constexpr uint32_t kFacesAlong = 0x80000000u;

// The lines of one batch of directions: per direction its lines that meet something, per
// line its hits nearest first (along +direction).
struct LineBatch {
    uint32_t batch = 0;                    // its number: its rotation's and jitter's streams
    std::vector<glm::vec3> directions;     // unit
    std::vector<uint32_t> directionLines;  // per direction its first line; directions + 1
    std::vector<uint32_t> lineHits;        // per line its first hit; lines + 1
    std::vector<uint32_t> lineCells;       // per line its cell (j · cells + i), ascending
    std::vector<LineHit> hits;
    size_t Lines() const { return lineHits.empty() ? 0 : lineHits.size() - 1; }
    size_t Bytes() const {
        return hits.size() * sizeof(LineHit) + (lineHits.size() + lineCells.size()) * 4 +
               directionLines.size() * 4 + directions.size() * sizeof(glm::vec3);
    }
};

// `count` line directions spread evenly over a hemisphere (a spherical Fibonacci set in
// cos θ), so that they and their opposites cover the sphere evenly.
std::vector<glm::vec3> HemisphereDirections(int count);

// A uniformly random rotation (Shoemake's unit quaternion from three uniforms).
glm::mat3 RandomRotation(uint32_t seed, uint64_t stream);

// How a direction's lines sit in their cells: each jittered on its own (the CPU back end's:
// stratified), or the whole grid shifted by one jitter (a rasteriser's pixel centres: the
// Vulkan back end's, vulkan_lines.h).
enum class LineJitter { kPerCell, kPerDirection };

// The grid of lines every direction uses: `cells` a side over the square around the ball
// (centre, radius), a line jittered in each cell.
struct LineGrid {
    glm::vec3 centre{0.0f};
    float radius = 1.0f;
    int cells = 64;
    LineJitter jitter = LineJitter::kPerCell;
    float CellArea() const {
        const float side = 2.0f * radius / float(cells);
        return side * side;
    }
};

// One direction's grid: cell (i, j)'s line starts at corner + (i + a)·side·t + (j + b)·side·s
// and runs `length` along d, (a, b) its jitter (Jitter).
struct DirectionGrid {
    glm::vec3 d, t, s, corner;
    float side, length;
    int n;
    DirectionGrid(const LineGrid& grid, const glm::vec3& direction);
    // Whether cell (i, j) lies wholly outside the ball's disc (its lines meet nothing).
    bool Outside(int i, int j) const;
    // The jitter (a, b) in [0, 1)² of cell `cell` of direction `direction` of batch `batch`:
    // its own stream, so that a re-trace draws the same line (per cell), or one for the
    // whole direction.
    static glm::vec2 Jitter(LineJitter mode, uint32_t seed, uint32_t batch, size_t direction,
                            uint32_t cell);
};

// Batch `batch`'s directions: `base` rotated by RandomRotation(seed, batch's stream).
std::vector<glm::vec3> RotatedDirections(const std::vector<glm::vec3>& base, uint32_t seed,
                                         uint32_t batch);

// Traces batch `batch` of the field: `base` rotated by RandomRotation(seed, batch), every
// line of every direction through `rays` (built over the refined mesh). Deterministic for a
// (seed, batch) whatever the thread count.
LineBatch TraceBatch(const RayScene& rays, const LineGrid& grid, const std::vector<glm::vec3>& base,
                     uint32_t seed, uint32_t batch);

// Traces again the lines of batch `b` (traced by TraceBatch with `seed` and `grid`) whose
// cells the box's shadow covers along each direction: after surfaces inside `box` moved (the
// box holding where they were and where they are), `rays` updated. Returns the lines traced.
size_t RetraceBatch(const RayScene& rays, const LineGrid& grid, uint32_t seed, const Bounds& box,
                    LineBatch& b);

// Each surfel's share of its triangles, for the projected area of its hat function towards a
// direction: facets[offsets[s] … offsets[s + 1]) are normal × area / 3 of the refined
// triangles around surfel s (RayScene's, built over the refined mesh), those with one normal
// summed into one; most[s] = Σ |f| bounds P_s over every direction.
struct SurfelFacets {
    std::vector<uint32_t> offsets;
    std::vector<glm::vec3> facets;
    std::vector<float> most;
    explicit SurfelFacets(const RayScene& rays, size_t surfels);
    // ∫ φ_s cos⁺ dA towards light arriving along `travel`: Σ max(0, −f · travel).
    float Projected(uint32_t s, const glm::vec3& travel) const {
        float p = 0.0f;
        for (uint32_t k = offsets[s]; k < offsets[s + 1]; ++k)
            p += std::max(0.0f, -glm::dot(facets[k], travel));
        return p;
    }
};

// The estimate read at the interface's resolution where the cells are wider than the surfels.
// Sec. 3.3 maps the interface onto each face's texels by texture lookup, so every texel reads
// every direction's interface, blurred at the cell's scale; the global-lines estimator
// instead feeds a surfel only from the lines that meet its hat, and a hat much smaller than a
// cell meets few lines (a 1.5 cm surfel under 6 cm cells: ~14 lines over 512 two-way
// directions), so its E_s is mostly noise. Smoothing both sums with one kernel before
// dividing them pools the neighbours' lines: E_s = π Σ_j W_sj (Σ_ω P L̄)_j / Σ_j W_sj (Σ_ω P)_j,
// the same mean where the light is smooth over the kernel, at the cells' resolution where it
// is not (as the paper's lookup). The kernel: `passes` averages of each surfel with its
// neighbours on the refined mesh (a surfel and the surfels it shares a triangle with), along
// edges whose normals agree (cos ≥ kSmoothCrease) and that nothing stands on (the segment
// between the two, lifted off the surface by kSmoothLift of its length, meets no surface), so
// that light does not cross a crease, a gap between surfaces, or a wall standing across one
// (as along a ceiling that runs over a wall from a lit room into a dark one).
inline constexpr float kSmoothCrease = 0.9f;
inline constexpr float kSmoothLift = 0.02f;
class SurfelSmoothing {
  public:
    SurfelSmoothing() = default;
    SurfelSmoothing(const RayScene& rays, const std::vector<glm::vec3>& positions,
                    const std::vector<glm::vec3>& normals, int passes);
    int Passes() const { return passes_; }
    // Smooths each surfel's (Σ P L̄ as RGB, Σ P as w) in place (`scratch`: any vector).
    void Apply(std::vector<glm::vec4>& values, std::vector<glm::vec4>& scratch) const;

  private:
    int passes_ = 0;
    std::vector<uint32_t> offsets_, neighbours_;
};
// Smoothing passes for lines `side` apart over surfels `elementSize` wide: none where a
// surfel meets a line of each direction it faces (side ≤ elementSize); else enough that the
// kernel's radius (about √(0.43 · passes) elements: a random walk's spread over the mesh)
// reaches half a cell.
int SmoothingPasses(float side, float elementSize);

// The radiance interface's walk (Sec. 3.2, Fig. 5) along every line of `b`, both ways: the
// interface starts as the sky's radiance along the line (black without one: Sec. 3.3's reset);
// a surface whose front faces the light arriving receives the interface and hides what lies
// behind it (back sides are black); a surface whose front faces along the travel replaces the
// interface with its own exitant radiance, interpolated from its three surfels'.
// What a front receives goes to its surfels by their hat weights φ_s at the hit. The
// global-lines estimator adds Σ φ_s L_I · A_cell per direction of travel ω: its mean is
// P_s(ω) L̄_s(ω), with P_s(ω) = ∫ φ_s cos⁺ dA the hat's projected area towards ω and L̄_s(ω)
// the mean radiance arriving over it; beside it goes its weight Σ φ_s · A_cell, whose mean
// is P_s(ω). E_s = π Σ_ω (the first) / Σ_ω (the second) (`weighted` / `sampled`): the ratio
// of the two sums, so that how many lines happened to meet a small hat cancels (a constant
// radiance comes out exact; dividing by Σ_ω P_s instead, the exact mean of the weights, left
// that count's noise in: 4.3% relative RMS over the vertices of a white furnace at the
// default cells). Where the hat's footprint spans a few cells (P_s ≥ kRatioCells · A_cell)
// the walk adds P_s · Σ φ L_I / Σ φ with the weight P_s itself: the same mean, and the
// weight is exact. Adds to `weighted` (per surfel, RGB) and `sampled` (per surfel).
//
// Glossy surfels (`glossy`, null: none) have radiance per direction of travel as well (the
// paper's non-diffuse tiles, Sec. 3.4): a sender adds its surfels' `glossy->exitant` towards
// the travel to the diffuse radiance, and a receiver records per direction of travel the
// mean radiance arriving over the hat (`glossy->incoming`; 0 where no line met it: the
// global-lines form keeps the mean there too) for Reflect.
inline constexpr float kRatioCells = 2.0f;
struct GlossyLines {
    const std::vector<int32_t>* slot = nullptr;  // per surfel: its glossy slot, or −1
    size_t slots = 0;
    // Per slot, per direction of travel of the batch (direction k along +d_k is k, along −d_k
    // is directions + k): RGB.
    const glm::vec3* exitant = nullptr;
    glm::vec3* incoming = nullptr;
};
void WalkBatch(const LineBatch& b, const RayScene& rays, const SurfelFacets& facets, float cellArea,
               const std::vector<glm::vec3>& radiance, const Environment* sky,
               std::vector<glm::vec3>& weighted, std::vector<float>& sampled,
               const GlossyLines* glossy = nullptr);

// The glossy lobe of Sec. 3.4 over one batch's directions of travel: for each direction the
// light arrived along (travel t_k, cos θ_k = −n·t_k > 0, Δω = 2π / directions), its mirror
// image r_k, the normalised Phong lobe F0 (n + 2)/(2π) cosⁿ(r_k · t_j) (docs/MATERIALS.md)
// sampled at the batch's own directions t_j and normalised over them (Σ_j p̃ Δω = 1, so a lobe
// narrower than the directions' spacing goes to its nearest ones, the paper's "three
// nearest PSFs", with its energy kept): exitant_j = F0 Σ_k (n + 2)/(n + 1) p̃(k → j) L_k
// cos θ_k Δω, towards the front only (n·t_j > 0). One table of weights serves every surfel
// with the same normal and exponent (a flat face's).
//
// LobeWeights gives one incoming direction's row: for light arriving along `travel` (cos θ =
// −n·travel > 0), per direction of travel j towards the front the weight B_j = (n + 2)/(n + 1)
// p̃(travel → j) Δω, so that exitant_j = F0 B_j E / Δω for the irradiance E it brings (a
// punctual light's; Δω = 2π / directions) and F0 B_j cos θ L for a radiance L. Empty when
// the light arrives from behind.
void LobeWeights(const std::vector<glm::vec3>& directions, const glm::vec3& normal, float exponent,
                 const glm::vec3& travel, std::vector<float>& scratch,
                 std::vector<std::pair<uint32_t, float>>& out);
class LobeTable {
  public:
    LobeTable(const std::vector<glm::vec3>& directions, const glm::vec3& normal, float exponent);
    // exitant (2 × directions) = F0 × the lobe over incoming (2 × directions).
    void Reflect(const glm::vec3& f0, const glm::vec3* incoming, glm::vec3* exitant) const;

  private:
    struct Entry {
        uint32_t from, to;
        float weight;
    };
    std::vector<Entry> entries_;
    size_t columns_ = 0;
};

}  // namespace penumbra
