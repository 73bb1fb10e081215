// The light-field solver (Mortensen, Khanna, Slater 2008: virtual light field propagation)
// behind the Solver interface; lines traced by Embree on the CPU, or rasterised on a Vulkan
// device (vulkan_lines.h), walked on the CPU. Light travels along batches of parallel lines
// (lines.h): each line's surfaces in order, walked with a radiance interface both ways, so
// visibility is exact along every line (no leak through a wall of any thickness). Surfels
// stand for the paper's diffuse texels: each keeps one radiance, and a line's hit reads and
// feeds its three surfels by their hat weights.
//
// An iteration traces one more batch while fewer than `batches` are kept and walks it with the
// radiance of the iteration before (one bounce, Jacobi: the paper's propagation iterations,
// Sec. 3), adding to what the earlier batches gave (E_s from every kept batch's lines,
// WalkBatch); the last batch, and any iteration after an edit, walks every kept batch. Once every
// batch is kept, iterations only bounce: edits of lights, materials and the sky walk the same lines
// again with no new rays.
#pragma once

#include <memory>

#include "direct/direct_stage.h"
#include "rays/ray_scene.h"
#include "solver/solver.h"
#include "solvers/lightfield/lines.h"
#include "solvers/lightfield/settings.h"
#include "solvers/lightfield/vulkan_lines.h"
#include "solvers/lightfield/vulkan_walk.h"
#include "solvers/receiver_light.h"

namespace penumbra {

class LightfieldSolver : public Solver {
  public:
    LightfieldSolver(const Scene& scene, const SolverSettings& settings,
                     const LightfieldSettings& own, const ProgressFn& progress);
    ~LightfieldSolver() override;

    void Iterate(int n) override;
    std::vector<glm::vec3> SurfelIrradiance(Channel channel = Channel::kIndirect) override;
    const Surfels& GetSurfels() const override { return surfels_; }
    void UpdateMaterials(const Scene& scene) override;
    void UpdateLights(const Scene& scene) override;
    SolverStats Stats() const override;
    // Any move or deformation that keeps the primitives, their refinement and the number of
    // punctual lights (no motion bounds needed): UpdateGeometry traces again the lines that
    // can meet the moved surfaces, where they were or are now.
    std::string GeometryMismatch(const Scene& scene) const override;
    std::string UpdateGeometry(const Scene& scene) override;
    void SetEmitterDirect(const std::vector<glm::vec3>& perSurfel) override;
    bool TakesEmitterDirect() const override { return true; }
    std::string WarmStart(Solver& previous, const SurfelCarry& carry) override;
    std::vector<std::string> ValidationMessages() const override;

    const std::vector<LineBatch>& Batches() const { return batches_; }
    const LineGrid& Grid() const { return grid_; }

  private:
    // GeometryMismatch's reasons, with `now` the surfels refined from `scene` when it gets
    // that far (UpdateGeometry takes them instead of refining again).
    std::string Mismatch(const Scene& scene, Surfels& now) const;
    // A walk of every kept batch (or of the newest only, added to the others' sums), then
    // Reradiate.
    void Bounce(bool newestOnly);
    void Rematerial();  // albedo and emission per surfel, the glossy slots, then Reradiate
    // The glossy surfels' slots and, for every kept batch, their tables (zeroed where the
    // slots changed) and lobes.
    void ReadGlossy();
    void PrepareLobes(size_t batch);  // batch's lobe tables for the glossy slots
    // Batch's punctual_ rows from the lights' direct light at the glossy surfels (perLight_).
    void PreparePunctual(size_t batch);
    // Batch's exitant rows: F0 × (the lobes over the light that arrived + punctual_).
    void Reflect(size_t batch);
    void Reradiate();   // the light leaving each surfel from the light arriving there now
    void CopyDirect();  // E_d per surfel from the direct stage
    std::vector<direct::GpuReceiver> Receivers() const;  // the surfels, in their order

    LightfieldSettings own_;
    ProgressFn progress_;
    Scene scene_;  // the ray scene reads its materials (a move updates surfels, not this)
    float elementSize_ = 0.0f;
    Surfels surfels_;
    std::unique_ptr<RayScene> rays_;
    // With --device gpu or lavapipe: the device, the lines rasterised on it (a batch's trace;
    // moves re-trace their few lines on Embree) and the walk there (null on a device without
    // float atomics: the walk runs on the CPU).
    std::unique_ptr<gpu::Context> device_;
    std::unique_ptr<VulkanLines> vulkanLines_;
    std::unique_ptr<VulkanWalk> vulkanWalk_;
    // The walk of kept batch b (on the device or the CPU).
    void Walk(size_t b, const Environment* sky, const GlossyLines* glossy);
    std::unique_ptr<SurfelFacets> facets_;
    LineGrid grid_;
    // The estimate pooled over neighbouring surfels where the cells are wider than they are.
    SurfelSmoothing smoothing_;
    void MakeSmoothing();
    std::vector<glm::vec4> pooled_, pooledScratch_;
    std::vector<glm::vec3> base_;  // the batches' direction set before its rotation
    std::vector<LineBatch> batches_;
    // Per surfel, over the last walks (WalkBatch): Σ P L̄ and Σ P as the lines gave them.
    std::vector<glm::vec3> weighted_;
    std::vector<float> sampled_;
    // Glossy surfels (Sec. 3.4): per surfel its slot or −1, per slot its surfel; per kept
    // batch, per slot and direction of travel, the light arriving and leaving (GlossyLines),
    // and the lobe tables (one per normal and exponent) with each slot's.
    std::vector<int32_t> slot_;
    std::vector<uint32_t> glossy_;
    std::vector<float> exponents_;  // per slot: its Phong exponent when the lobes were made
    std::vector<std::vector<glm::vec3>> incoming_, exitant_;
    // Per kept batch, per slot and direction of travel: the punctual lights' light the lobe
    // sends that way before F0 (the direct stage gives irradiance; a glossy surfel reflects
    // each light along its mirror direction). Empty: no light or no glossy surfel.
    std::vector<std::vector<glm::vec3>> punctual_;
    std::vector<float> perLight_;  // the direct stage's E_d per light and surfel (stride 4)
    std::vector<std::vector<LobeTable>> lobes_;
    std::vector<std::vector<uint32_t>> lobeOf_;
    bool stale_ = true;    // the light changed since the last walk of every batch
    ReceiverLight light_;  // per surfel, in surfel order
    std::unique_ptr<direct::DirectStage> directStage_;
    direct::SkyBins sky_;  // the sky the walks read (only its Last() is used)
    int lights_ = 0, mapSize_ = 0;
    int iterations_ = 0;
    double setupSeconds_ = 0.0, msTotal_ = 0.0, msTrace_ = 0.0, msWalk_ = 0.0;
    double msGeometry_ = 0.0, msLastWalk_ = 0.0;
    size_t geometryUpdates_ = 0, linesRetraced_ = 0;
    std::string divergence_;
};

}  // namespace penumbra
