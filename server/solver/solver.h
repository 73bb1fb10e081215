// The one small interface every GI solver implements (DESIGN.md): build from a scene and
// settings, iterate, read per-surfel irradiance, report stats.
#pragma once

#include <atomic>
#include <functional>
#include <glm/glm.hpp>
#include <memory>
#include <string>
#include <vector>

#include "base/check.h"
#include "links/oracle.h"
#include "scene/scene.h"
#include "scene/surfels.h"

namespace penumbra {

// How the local pass's two operators are scheduled (Sec. 2.2, docs/SOLVER.md "Stability").
// kSymmetric: K and J in every pass (the paper's default; diverges on stacks of occluders).
// kAsymmetric: one radiance step (K), then `antiradianceSteps` antiradiance steps (J).
// kAdaptive: one radiance step, then antiradiance steps until the antiradiance has
// converged for that radiance (at most `maxAntiradianceSteps`).
enum class Scheme { kSymmetric, kAsymmetric, kAdaptive };
// What a solver reports (DESIGN.md, Channels): `direct` is the shadowed direct light of
// punctual lights, `indirect` everything else (emitters, environment, every bounce),
// `total` their sum.
enum class Channel { kIndirect, kDirect, kTotal };
enum class DeviceChoice { kAuto, kGpu, kLavapipe, kCpu };
// Whether surfaces that do not close a solid occlude light arriving at their backs
// (Surfels::twoSided). `auto`: on when the scene has an environment, whose light reaches
// every back side; without one, light reaches a back only from inside the scene, which the
// paper's front-side rule (Fig. 7) ignores at the cost of leaks through thin walls.
enum class BackOcclusion { kAuto, kOn, kOff };
// How the CPU back end stores its I_ex tables (cpu_passes.h): fp32, or fp16 over each
// node's area (half the memory traffic, about 5·10⁻⁴ relative). kAuto: fp16 where the CPU
// has F16C. The Vulkan passes use fp32.
enum class TablePrecision { kAuto, kFp32, kFp16 };

inline constexpr int kDefaultBins = 128;

struct SolverSettings {
    std::string solver = "antiradiance";
    // Direction bins, 32…1024, a multiple of 4; 0: the default, kDefaultBins (the gather
    // stage's CreateGatheredSolver picks kGatherBins behind a final gather). Read Bins().
    int bins = 0;
    int Bins() const { return bins > 0 ? bins : kDefaultBins; }
    float elementSize = 0.0f;  // metres; 0 picks kDefaultElementFraction × scene diameter
    // Adaptive by default: the paper's symmetric scheme diverges on rows and stacks of
    // occluders (docs/SOLVER.md "Stability"); where it converges, both reach one fixed point.
    Scheme scheme = Scheme::kAdaptive;
    int antiradianceSteps = 3;  // asymmetric: antiradiance steps after each radiance step
    // Adaptive: antiradiance steps end when no leaf's irradiance moved by more than
    // `antiradianceTolerance` × the largest leaf irradiance in the last step, or after
    // `maxAntiradianceSteps` (SolverStats::antiradianceCapHits counts those).
    float antiradianceTolerance = 1e-4f;
    int maxAntiradianceSteps = 64;
    DeviceChoice device = DeviceChoice::kAuto;
    float oracle = 1.0f;  // link refinement threshold in units of ω_bin
    // Receiver threshold relative to `oracle` (conservative and area oracles). 0.5: a
    // receiver cluster's error is of the first order in its size (docs/SOLVER.md, "Receiver
    // size"); against 1, at 128 bins and 0.1 m, the blocker goes from 16.2 to 12.5% RMSE, the
    // Cornell box from 9.9 to 8.7%, the maze from 13.6 to 12.8%, for 1.4–1.7× the links.
    float receiverOracle = 0.5f;
    LinkOracle linkOracle = LinkOracle::kConservative;  // links/oracle.h
    int threads = 0;                                    // CPU threads; 0 = all cores
    bool validation = false;  // Vulkan validation layers (tests turn them on)
    int shadowMapSize = 0;    // texels per side of each shadow map; 0: from the element size
    BackOcclusion backOcclusion = BackOcclusion::kAuto;
    TablePrecision tables = TablePrecision::kAuto;
    // Sec. 3.3: build the links of dynamic nodes (extras.penumbra.dynamic) for the worst case
    // over their motion bounds, so that a move recomputes only the form factors and bins of
    // their links (Solver::UpdateGeometry) instead of rebuilding every link. Costs more links
    // (every pair the bounds let come close is linked at the finest level); the service
    // turns it on, a one-off bake has no use for it.
    bool motionLinks = false;
    // With motionLinks: when the links touching dynamic nodes would outnumber the others by
    // more than this factor, the usual links are built instead and moves rebuild them
    // (Stats().motionDeclined says so). 0: no limit.
    float motionLinkBudget = 0.0f;
    // Where a move inside the bounds recomputes its links on a Vulkan back end: on the device
    // (shaders/links.comp), or on the host with the links uploaded after. Default: the
    // device, except lavapipe, whose "device" is the host's own cores and runs the pass
    // slower than the host code does (office chair: 17 against 22 ms a move).
    enum class LinkUpdate { kAuto, kDevice, kHost };
    LinkUpdate linkUpdate = LinkUpdate::kAuto;
};

inline constexpr float kDefaultElementFraction = 1.0f / 40.0f;

struct PassTiming {
    std::string name;
    double msTotal = 0.0;
};

struct SolverStats {
    std::string solver;
    std::string device;
    size_t elements = 0;  // surfels (hierarchy leaves)
    size_t nodes = 0;     // hierarchy nodes, leaves and clusters
    size_t links = 0;
    int bins = 0;
    int iterations = 0;  // done so far (Solver::Iterate)
    int gathers = 0;     // global + local passes they took (docs/SOLVER.md "Stability")
    float elementSize = 0.0f;
    double linkBuildSeconds = 0.0;
    double setupSeconds = 0.0;  // scene → device-resident tables, links included
    double msTotal = 0.0;       // wall time of all iterations
    std::vector<PassTiming> passes;
    size_t tableBytes = 0;
    std::string tables;  // "fp32" or "fp16": how I_ex is stored
    size_t linkBytes = 0;
    int lights = 0;           // punctual lights
    int shadowViews = 0;      // shadow maps rendered per light update (cube faces count 6)
    int shadowMapSize = 0;    // texels per side
    double msShadow = 0.0;    // last shadow pass
    double msDirect = 0.0;    // last direct-light initialisation
    std::string environment;  // its source (file or "constant"); empty: none
    float environmentIntensity = 0.0f;
    float environmentRotation = 0.0f;  // radians
    size_t twoSidedElements = 0;       // elements that occlude from both sides
    size_t glossyElements = 0;         // elements with a glossy lobe (Material::Glossy)
    size_t glossyLobes = 0;            // distinct discretised lobes
    size_t motionGroups = 0;           // dynamic nodes linked for their motion bounds (Sec. 3.3)
    size_t motionLinks = 0;            // links touching them, recomputed when they move
    size_t geometryUpdates = 0;        // moves taken by UpdateGeometry
    size_t linksUpdated = 0;           // links recomputed by those moves, in all
    double msGeometry = 0.0;           // the last move: links, leaves, uploads, shadow maps
    std::string linkUpdate;            // where moves recompute links: "device" or "host"
    double msLinkUpdateDevice = 0.0;   // the last move's link update pass, device time
    std::string motionDeclined;        // why motion links were asked for and not built
    // Convergence (docs/SOLVER.md "Stability"). The adaptive scheme: radiance steps done,
    // the antiradiance steps the last finished bounce took, bounces that hit the cap.
    int bounces = 0;
    int lastAntiradianceSteps = 0;
    size_t antiradianceCapHits = 0;
    // No surface can receive more than `irradianceBound` lux (the furnace bound of the
    // scene's emitters, lights, sky and albedos; infinite when an albedo reaches 1). A solution
    // past kDivergenceMargin × it, or not finite, has diverged: `divergence` says where, and
    // the solver stops iterating (Iterate does nothing more).
    float irradianceBound = 0.0f;
    std::string divergence;
    // The gather stage's first shot (gather/gather_stage.h): shadow rays a surfel for the
    // emitters' direct light (0: the solver carries the emission itself), and the last
    // computation's milliseconds.
    int emitterRays = 0;
    double msEmitterDirect = 0.0;
    // Its final gather (0 rays: none): rays a surfel, the surfels gathered at, the last
    // tracing of their hits and the last evaluation of those hits, in milliseconds.
    int gatherRays = 0;
    size_t gatherTargets = 0;
    double msGatherTrace = 0.0;
    double msGatherEvaluate = 0.0;
    size_t gatherRaysRetraced = 0;  // rays the last move traced again (both parts)
    size_t gatherTraces = 0;        // tracings of either part so far (edits that traced)
    // Where the gather stage traces: the CPU (Embree) on every solver device for now (no
    // Vulkan ray-query path yet); empty without a gather stage.
    std::string gatherDevice;

    double MsPerIteration() const { return iterations ? msTotal / iterations : 0.0; }
};

// How far past SolverStats::irradianceBound a leaf may go before the solver calls the
// solution diverged: the discretisation (calibrated form factors, bin spread) may overshoot
// the bound a little near contacts; a diverging iteration passes any margin within passes.
inline constexpr float kDivergenceMargin = 2.0f;

class Solver {
  public:
    virtual ~Solver() = default;
    // Runs `n` more iterations: n more bounces of light, each ending in a solution that
    // SurfelIrradiance reports (how many passes an iteration takes is the solver's own:
    // Stats().gathers). Does nothing once the solution has diverged (Stats().divergence).
    virtual void Iterate(int n) = 0;
    // Irradiance per surfel in lux: `indirect` (all light arriving from surfaces),
    // `direct` (punctual lights, shadowed) or `total`.
    virtual std::vector<glm::vec3> SurfelIrradiance(Channel channel = Channel::kIndirect) = 0;
    virtual const Surfels& GetSurfels() const = 0;
    // Re-reads every surfel's albedo and emission from `scene` (the scene it was built from,
    // with materials or primitive material assignments changed, geometry unchanged). The
    // solution moves towards the new one from the next iteration on (Sec. 3.3: the
    // iteration continues from the current radiance).
    virtual void UpdateMaterials(const Scene& scene) = 0;
    // Re-reads the punctual lights and the environment of `scene` (same geometry; lights
    // moved, recoloured, dimmed; the sky changed, turned or scaled): one shadow pass and a
    // new direct light, the environment re-binned; the iteration continues.
    virtual void UpdateLights(const Scene& scene) = 0;
    virtual SolverStats Stats() const = 0;
    // Sec. 3.3, moving objects: why `scene` (the scene this solver was built from, dynamic
    // nodes moved) cannot be taken by UpdateGeometry, or empty when it can: the solver was
    // built with motionLinks, every moved node moved rigidly and stays inside its bounds.
    virtual std::string GeometryMismatch(const Scene& scene) const {
        (void)scene;
        return "this solver has no motion links";
    }
    // Moves the surfaces of the moved dynamic nodes to their places in `scene` and recomputes
    // the links touching them; the iteration continues from the current solution. Call only
    // when GeometryMismatch is empty (throws penumbra::Error otherwise).
    virtual void UpdateGeometry(const Scene& scene) { throw Error(GeometryMismatch(scene)); }
    // Carrying a solution over a rebuild (a move rebuilds the links, Sec. 3.3): each surfel's
    // exitant intensity, `Bins()` RGB rows after one another per surfel (empty when the
    // solver has no such state), and a start from such rows for the surfels marked in `keep`
    // (the others start from their emission). Rows from a solver with other bins or another
    // surfel count are refused with penumbra::Error.
    virtual std::vector<float> SurfelExitant() { return {}; }
    // The first shot from outside (the gather stage, gather/gather_stage.h): per surfel, the
    // irradiance arriving straight from emitting surfaces, computed with explicit visibility.
    // The solver reflects it like the punctual lights' direct light, reports it in the
    // `indirect` channel, and stops carrying its emitters' own emission, so it carries only
    // bounces. Empty: back to carrying the emission itself. Throws penumbra::Error when the
    // solver cannot take it.
    virtual void SetEmitterDirect(const std::vector<glm::vec3>& perSurfel) {
        (void)perSurfel;
        throw Error("this solver takes no emitter direct light from outside");
    }
    virtual void WarmStart(const std::vector<float>& rows, const std::vector<uint8_t>& keep) {
        (void)rows, (void)keep;
    }
    // While `flag` (null: none) reads true, Iterate returns after the pass under way instead
    // of finishing its iteration; the next Iterate takes the iteration up where it stopped
    // (an edit applied in between reaches the passes still to come). SurfelIrradiance keeps
    // reporting the last finished iteration. The service points it at "an edit is waiting",
    // so that an edit need not wait for a whole bounce. A solver whose iterations cannot be
    // cut ignores it.
    virtual void SetInterrupt(const std::atomic<bool>* flag) { (void)flag; }
};

using ProgressFn = std::function<void(const std::string& stage, double fraction)>;

// Builds the named solver. Throws penumbra::Error for bad settings or an unusable device.
std::unique_ptr<Solver> CreateSolver(const Scene& scene, const SolverSettings& settings,
                                     const ProgressFn& progress = {});

// Parses "auto|gpu|lavapipe|cpu" and "adaptive|symmetric|asymmetric"; throws penumbra::Error.
DeviceChoice ParseDevice(const std::string& name);
LinkOracle ParseLinkOracle(const std::string& name);  // "conservative" | "paper" | "area"
const char* LinkOracleName(LinkOracle oracle);
Scheme ParseScheme(const std::string& name);
const char* SchemeName(Scheme scheme);
Channel ParseChannel(const std::string& name);                // "indirect" | "direct" | "total"
BackOcclusion ParseBackOcclusion(const std::string& name);    // "auto" | "on" | "off"
TablePrecision ParseTablePrecision(const std::string& name);  // "auto" | "fp32" | "fp16"
const char* ChannelName(Channel channel);

// How much a solution moved: Σ|now − before| / Σ|now| over surfels and channels; 1 when
// the two are not comparable (other sizes), 0 when `now` is all zeros.
double RelativeChange(const std::vector<glm::vec3>& now, const std::vector<glm::vec3>& before);

// Iterating until the answer stops moving (bake, render; the service decides per frame):
// iterations until two in a row change the surfels' irradiance (every channel) by less than
// `tolerance` each (RelativeChange), at most `maxIterations`, or until the solution diverged.
struct Convergence {
    int iterations = 0;
    double change = 1.0;     // of the last iteration
    bool converged = false;  // change < tolerance
};
Convergence IterateUntilConverged(Solver& solver, double tolerance, int maxIterations,
                                  const ProgressFn& progress = {});

// Per-vertex irradiance for primitive `p` in its input vertex order, clamped at zero.
std::vector<glm::vec3> PrimitiveIrradiance(const Surfels& surfels,
                                           const std::vector<glm::vec3>& surfelIrradiance,
                                           const Scene& scene, size_t p);

}  // namespace penumbra
