// The antiradiance solver (Dachsbacher et al. 2007) behind the Solver interface:
// builds the model once, then iterates on the chosen device back end.
#pragma once

#include <memory>

#include "direct/direct_stage.h"
#include "solver/solver.h"
#include "solvers/antiradiance/backend.h"
#include "solvers/antiradiance/model.h"
#include "solvers/antiradiance/schedule.h"
#include "solvers/antiradiance/settings.h"

namespace penumbra {

class AntiradianceSolver : public Solver {
  public:
    // `own`: the solver's options, read from settings.options (ReadAntiradianceSettings).
    AntiradianceSolver(const Scene& scene, const SolverSettings& settings,
                       const AntiradianceSettings& own, const ProgressFn& progress);
    // The same with `own` read from settings.options.
    AntiradianceSolver(const Scene& scene, const SolverSettings& settings,
                       const ProgressFn& progress)
        : AntiradianceSolver(scene, settings, ReadAntiradianceSettings(settings), progress) {}
    ~AntiradianceSolver() override;

    void Iterate(int n) override;
    std::vector<glm::vec3> SurfelIrradiance(Channel channel = Channel::kIndirect) override;
    const Surfels& GetSurfels() const override { return model_.surfels; }
    void UpdateMaterials(const Scene& scene) override;
    void UpdateLights(const Scene& scene) override;
    SolverStats Stats() const override;
    std::string GeometryMismatch(const Scene& scene) const override;
    std::string UpdateGeometry(const Scene& scene) override;
    void SetEmitterDirect(const std::vector<glm::vec3>& perSurfel) override;
    bool TakesEmitterDirect() const override { return true; }
    std::string WarmStart(Solver& previous, const SurfelCarry& carry) override;
    // The state WarmStart carries: each surfel's exitant intensity, Bins() RGB rows after one
    // another per surfel; and a start from such rows for the surfels marked in `keep` (the
    // others start from their emission). Rows for other bins or another surfel count are
    // refused with penumbra::Error.
    std::vector<float> ExitantRows();
    void StartFrom(const std::vector<float>& rows, const std::vector<uint8_t>& keep);
    // Checked after each pass of an unsettled bounce: the schedule keeps its place.
    void SetInterrupt(const std::atomic<bool>* flag) override { interrupt_ = flag; }

    const AntiradianceModel& Model() const { return model_; }
    // Vulkan validation messages so far (settings.validation; none on the CPU back end).
    std::vector<std::string> ValidationMessages() const override;

  private:
    // Whether moves recompute links on the Vulkan device (AntiradianceSettings::linkUpdate).
    bool DeviceLinkUpdate() const;
    SolverSettings settings_;
    AntiradianceSettings own_;
    ProgressFn progress_;
    AntiradianceModel model_;
    std::unique_ptr<AntiradianceBackend> backend_;  // the CPU walk or the Vulkan passes
    // Only when the scene has punctual lights; on the back end's device when it has one.
    std::unique_ptr<direct::DirectStage> direct_;
    int lights_ = 0;
    int mapSize_ = 0;
    direct::SkyBins sky_;  // the sky as last binned into model_.environment
    // Host copies of E_d (and each light's share), from the direct stage's last update.
    void CopyDirect(const Scene& scene);
    // The lights' direct light reflected by the glossy lobes (model_.glossyDirect); false
    // when there is nothing to reflect (no glossy leaves or no lights).
    bool ReflectDirect();
    std::vector<PunctualLight> lightPlaces_;
    std::vector<float> perLight_;
    int iterations_ = 0;
    PassSchedule schedule_;
    std::string divergence_;    // SolverStats::divergence
    float bound_ = 0.0f;        // IrradianceBound, redone where the solver's inputs change
    float reflectance_ = 0.0f;  // the largest reflectance (IrradianceBound)
    // After an edit, the old state's bound, times the reflectance per bounce since: what the
    // iteration may still carry over from before the edit (the guard allows bound_ + it).
    float carried_ = 0.0f;
    void Rebound();  // bound_ for the inputs as they are now, carried_ from the old one
    // SetEmitterDirect: per leaf, the emitters' light (in leafDirect too, which the local
    // pass reflects); empty while the solver carries the emission itself.
    std::vector<glm::vec3> emitterDirect_;
    std::vector<Material> materials_;  // the scene's, as last read (their emission)
    // The leaves' E as the last pass left it (RGB per leaf).
    std::vector<float> LeafIrradiance();
    // The leaves' E when the schedule last settled (PassSchedule::Finished): what
    // SurfelIrradiance reports. Zero until the first settles: the adaptive scheme's first
    // antiradiance steps have no answer to show yet, only transients.
    std::vector<float> settled_;
    double msTotal_ = 0.0;
    double setupSeconds_ = 0.0;
    const std::atomic<bool>* interrupt_ = nullptr;  // SetInterrupt
    // Moves taken by UpdateGeometry, their links recomputed in all, the last one's time.
    size_t geometryUpdates_ = 0, linksUpdated_ = 0;
    double msGeometry_ = 0.0;
    // The direct stage for the scene's lights and the model's surfels as they are now.
    void MakeDirect(const Scene& scene);
    // The direct stage's receivers: the leaves' surfels where they are now.
    std::vector<direct::GpuReceiver> LeafReceivers() const;
};

}  // namespace penumbra
