// The one small interface every GI solver implements (docs/ARCHITECTURE.md): build from a scene and
// settings, iterate, read per-surfel irradiance, report stats.
#pragma once

#include <atomic>
#include <functional>
#include <glm/glm.hpp>
#include <memory>
#include <string>
#include <utility>
#include <variant>
#include <vector>

#include "base/check.h"
#include "scene/motion.h"
#include "scene/scene.h"
#include "scene/surfels.h"
#include "solver/options.h"
#include "solver/stage_figures.h"

namespace penumbra {

// What a solver reports (protocol/SPEC.md, Channels): `direct` is the shadowed direct light of
// punctual lights, `indirect` everything else (emitters, environment, every bounce),
// `total` their sum.
enum class Channel { kIndirect, kDirect, kTotal };
enum class DeviceChoice { kAuto, kGpu, kLavapipe, kCpu };
// What every solver takes (each solver's own options travel in `options`, declared in its
// registry entry: solvers/registry.h).
// The solver a bake, a render or a LoadScene gets when it names none: the light-field solver
// (docs/SOLVER.md "The default solver": chosen by measurement on the clutter suite, the
// bundled scenes and real models; its iteration carries only light that is there, so it
// cannot diverge).
inline constexpr const char* kDefaultSolver = "lightfield";

struct SolverSettings {
    std::string solver = kDefaultSolver;  // a name in the registry (Solvers())
    float elementSize = 0.0f;  // metres; 0 picks a fraction of the scene's diameter (below)
    DeviceChoice device = DeviceChoice::kAuto;
    int threads = 0;          // CPU threads; 0 = all cores
    bool validation = false;  // Vulkan validation layers (tests turn them on)
    int shadowMapSize = 0;    // texels per side of each shadow map; 0: from the element size
    BackOcclusion backOcclusion = BackOcclusion::kAuto;  // scene/surfels.h
    // Prepare the dynamic nodes (extras.penumbra.dynamic) to move inside their motion bounds
    // without a rebuild (Solver::UpdateGeometry; what that takes is the solver's own, see
    // docs/SOLVER.md). The service turns it on; a one-off bake has no use for it.
    bool prepareMoves = false;
    // A final gather reads this solver's answer (gather/gather_stage.h): the solver may pick
    // cheaper defaults for the options not given (docs/SOLVER.md "Settings behind the gather").
    bool behindGather = false;
    SolverOptions options;  // the solver's own, by name, as text (solver/options.h)
};

inline constexpr float kDefaultElementFraction = 1.0f / 40.0f;
// Behind a final gather (behindGather) the solver's answer is read a bounce away through the
// gather's hits, so coarser elements cost little there (docs/SOLVER.md, "Settings behind the
// gather"; measured in bench/results/FINDINGS.md, "Settings behind the gather").
inline constexpr float kGatherElementFraction = 1.0f / 24.0f;

// The element size a solver refines `scene` at: settings.elementSize, or when 0 the scene's
// diameter times kGatherElementFraction behind a final gather, kDefaultElementFraction
// otherwise. Throws penumbra::Error when that is not a positive number of metres.
float ElementSize(const Scene& scene, const SolverSettings& settings);
// For a solver that takes any move keeping its refinement: why `scene` (edited) cannot be
// taken by one built with `lights` punctual lights over `surfels` refined at `elementSize`
// (the light count changed, other primitives, surfaces refining into other elements), or
// empty; `now` gets the surfels refined from `scene` when it gets that far.
std::string RefinementMismatch(const Scene& scene, int lights, const Surfels& surfels,
                               float elementSize, Surfels& now);

struct PassTiming {
    std::string name;
    double msTotal = 0.0;
};

struct SolverStats {
    std::string solver;
    std::string device;
    size_t elements = 0;  // surfels (hierarchy leaves)
    size_t nodes = 0;     // hierarchy nodes, leaves and clusters
    size_t links = 0;     // links between elements (0: a solver without them)
    int bins = 0;         // direction bins it resolves (0: none)
    int iterations = 0;   // done so far (Solver::Iterate)
    int gathers = 0;      // passes they took (the solver's own kind of pass: `passes`)
    float elementSize = 0.0f;
    double linkBuildSeconds = 0.0;
    double setupSeconds = 0.0;  // scene → device-resident tables, links included
    double msTotal = 0.0;       // wall time of all iterations
    std::vector<PassTiming> passes;
    size_t tableBytes = 0;  // the radiance it keeps
    size_t linkBytes = 0;
    int lights = 0;  // punctual lights
    LightingFigures lighting;
    size_t twoSidedElements = 0;  // elements that occlude from both sides
    size_t glossyElements = 0;    // elements with a glossy lobe (Material::Glossy)
    MotionFigures motion;
    // Work an edit left for the iterations that follow (a moved emitter's first shot traced
    // in parts: GatherSettings::shotPartMs): what and how far; empty when none. The answer
    // is not settled while it is not empty.
    std::string catchingUp;
    int bounces = 0;  // bounces of light carried so far
    // No surface can receive more than `irradianceBound` lux (the furnace bound of the
    // scene's emitters, lights, sky and albedos; infinite when an albedo reaches 1). A solution
    // past kDivergenceMargin × it, or not finite, has diverged: `divergence` says where, and
    // the solver stops iterating (Iterate does nothing more).
    float irradianceBound = 0.0f;
    std::string divergence;
    GatherFigures gather;  // empty without a gather stage
    // The solver's own figures by name (docs/SOLVER.md lists each solver's): a number or a
    // word. StatsToJson writes them beside the fields above.
    std::vector<std::pair<std::string, std::variant<double, std::string>>> details;

    double MsPerIteration() const { return iterations ? msTotal / iterations : 0.0; }
    void SetDetail(const std::string& name, double value);
    void SetDetail(const std::string& name, const std::string& value);
    double Number(const std::string& name) const;     // 0 when absent or a word
    std::string Text(const std::string& name) const;  // "" when absent or a number
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
    // solution moves towards the new one from the next iteration on (the iteration continues
    // from the current solution).
    virtual void UpdateMaterials(const Scene& scene) = 0;
    // Re-reads the punctual lights and the environment of `scene` (same geometry; lights
    // moved, recoloured, dimmed; the sky changed, turned or scaled): one shadow pass and a
    // new direct light, the environment re-binned; the iteration continues.
    virtual void UpdateLights(const Scene& scene) = 0;
    virtual SolverStats Stats() const = 0;
    // Moving objects: why `scene` (the scene this solver was built from, dynamic nodes moved)
    // cannot be taken by UpdateGeometry, or empty when it can: the solver was built with
    // prepareMoves, every moved node moved rigidly and stays inside its bounds
    // (MotionMismatch, scene/motion.h).
    virtual std::string GeometryMismatch(const Scene& scene) const {
        (void)scene;
        return "this solver has no motion links";
    }
    // Moves the surfaces of the moved dynamic nodes to their places in `scene` and updates
    // what depends on them (a solver with links: the links touching them); the iteration
    // continues from the current solution. Returns what the move did, for a frame's note
    // ("links updated in place on the host (…)"). Call only when GeometryMismatch is empty
    // (throws penumbra::Error otherwise).
    virtual std::string UpdateGeometry(const Scene& scene) { throw Error(GeometryMismatch(scene)); }
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
    // Whether SetEmitterDirect can take a first shot in a scene without glossy materials
    // (else the gather stage keeps the shot for its own targets and the solver carries the
    // emission itself).
    virtual bool TakesEmitterDirect() const { return false; }
    // Carrying a solution over a rebuild (a move that rebuilds): this solver, just
    // built from the scene after an edit, starts from `previous` (the solver of the scene
    // before, built with the same settings) for the surfels `carry` maps (CarrySurfels,
    // scene/motion.h), their light turned with the moved ones; the others start from their
    // emission. Returns what it did, for the frame's note ("warm start for N of M surfels",
    // "cold start (why)").
    virtual std::string WarmStart(Solver& previous, const SurfelCarry& carry) {
        (void)previous, (void)carry;
        return "cold start (this solver carries no state over)";
    }
    // While `flag` (null: none) reads true, Iterate returns after the pass under way instead
    // of finishing its iteration; the next Iterate takes the iteration up where it stopped
    // (an edit applied in between reaches the passes still to come). SurfelIrradiance keeps
    // reporting the last finished iteration. The service points it at "an edit is waiting",
    // so that an edit need not wait for a whole bounce. A solver whose iterations cannot be
    // cut ignores it.
    virtual void SetInterrupt(const std::atomic<bool>* flag) { (void)flag; }
    // Vulkan validation-layer messages (warnings and errors) seen so far, where the solver
    // or a stage around it runs on a Vulkan device with SolverSettings::validation.
    virtual std::vector<std::string> ValidationMessages() const { return {}; }
};

using ProgressFn = std::function<void(const std::string& stage, double fraction)>;

// Builds the named solver (its registry entry, solvers/registry.h). Throws penumbra::Error
// for an unknown solver, bad options or an unusable device.
std::unique_ptr<Solver> CreateSolver(const Scene& scene, const SolverSettings& settings,
                                     const ProgressFn& progress = {});

// Parse the common settings' words; throw penumbra::Error naming the choices.
DeviceChoice ParseDevice(const std::string& name);          // "auto" | "gpu" | "lavapipe" | "cpu"
Channel ParseChannel(const std::string& name);              // "indirect" | "direct" | "total"
BackOcclusion ParseBackOcclusion(const std::string& name);  // "auto" | "on" | "off"
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
