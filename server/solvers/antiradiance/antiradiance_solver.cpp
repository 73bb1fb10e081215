// Device choice, iteration schedule and stats of the antiradiance solver.
#include "solvers/antiradiance/antiradiance_solver.h"

#include <chrono>
#include <limits>

#include "base/check.h"
#include "base/numeric.h"
#include "gpu/context.h"
#include "solvers/antiradiance/cpu_passes.h"
#include "solvers/antiradiance/vulkan_passes.h"

namespace penumbra {

AntiradianceSolver::AntiradianceSolver(const Scene& scene, const SolverSettings& settings,
                                       const AntiradianceSettings& own, const ProgressFn& progress)
    : settings_(settings), own_(own), progress_(progress), schedule_(own) {
    auto start = std::chrono::steady_clock::now();
    // Resolve the device before the (long) model build so a bad choice fails fast.
    DeviceChoice device = settings.device;
    std::string gpuName;
    if (device == DeviceChoice::kAuto) {
        // On a CPU-only machine the native back end beats Vulkan on lavapipe by ~5×
        // (bench/results/office.json), so `auto` takes a real GPU only.
        device = gpu::FindRealGpu(&gpuName) ? DeviceChoice::kGpu : DeviceChoice::kCpu;
    }
    if (own.tables == TablePrecision::kFp16 && device != DeviceChoice::kCpu)
        throw Error(
            "fp16 tables are a CPU back end option (--device cpu); the Vulkan passes "
            "keep fp32 tables");
    ValidateEnvironment(scene.environment);
    model_ = BuildAntiradianceModel(scene, settings, own, progress);
    sky_.Binned(scene.environment);  // the model binned it
    materials_ = scene.materials;
    if (device == DeviceChoice::kCpu) {
        // fp16 where the CPU converts in hardware, unless asked otherwise (kFp16 on a CPU
        // without F16C throws).
        const bool half = own.tables == TablePrecision::kFp16 ||
                          (own.tables == TablePrecision::kAuto && cpu::CpuBackend::HalfSupported());
        backend_ = std::make_unique<cpu::CpuBackend>(
            model_, half ? cpu::TableFormat::kHalf : cpu::TableFormat::kFloat);
    } else {
        backend_ = std::make_unique<VulkanAntiradiance>(model_, device == DeviceChoice::kLavapipe,
                                                        settings.validation);
    }
    if (!scene.lights.empty()) {
        if (progress) progress("shadow maps", 0.0);
        mapSize_ = direct::MapSize(settings.shadowMapSize, scene.Diameter(), model_.elementSize);
        lights_ = static_cast<int>(scene.lights.size());
        MakeDirect(scene);
    }
    bound_ = IrradianceBound(model_, &reflectance_);
    setupSeconds_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

AntiradianceSolver::~AntiradianceSolver() = default;

std::vector<direct::GpuReceiver> AntiradianceSolver::LeafReceivers() const {
    std::vector<uint32_t> order;
    for (const LeafAttributes& leaf : model_.leaves) order.push_back(leaf.surfel);
    return direct::MakeReceivers(model_.surfels, order);
}

void AntiradianceSolver::MakeDirect(const Scene& scene) {
    direct_.reset();
    direct_ = direct::MakeDirectStage(scene, LeafReceivers(), mapSize_, backend_->DirectDevice(),
                                      backend_->DirectOut());
    CopyDirect(scene);
}

std::string AntiradianceSolver::GeometryMismatch(const Scene& scene) const {
    if (scene.lights.size() != static_cast<size_t>(lights_))
        return "the number of punctual lights changed";
    // Back occlusion `auto` follows whether there is a sky, and is decided at the build.
    if (BackOcclusionOn(settings_.backOcclusion, scene.environment) ==
        model_.surfels.twoSided.empty())
        return "a sky appeared or went, which changes back occlusion";
    if (!model_.motionDeclined.empty())
        return "motion links were not built: " + model_.motionDeclined;
    return MotionMismatch(model_.motion, model_.surfels, scene);
}

bool AntiradianceSolver::DeviceLinkUpdate() const {
    if (!backend_->CanUpdateLinks() || own_.linkUpdate == LinkUpdate::kHost) return false;
    return own_.linkUpdate == LinkUpdate::kDevice || !backend_->OnCpu();
}

std::string AntiradianceSolver::UpdateGeometry(const Scene& scene) {
    if (std::string why = GeometryMismatch(scene); !why.empty()) throw Error(why);
    auto start = std::chrono::steady_clock::now();
    // Surfels, nodes and leaves re-placed on the host (cheap: per element); the links touching
    // the moved groups recomputed on the device when there is one (links.comp), else here.
    const std::vector<uint8_t> moved = PlaceGroups(model_, scene);
    const std::vector<uint32_t> touched = TouchedLinks(model_, moved);
    uint32_t changed = AntiradianceBackend::kLeaves;
    if (!model_.glossy.empty()) changed |= AntiradianceBackend::kGlossy;
    if (DeviceLinkUpdate()) {
        backend_->UpdateLinks(moved);
    } else {
        RedoLinks(model_, touched);
        changed |= AntiradianceBackend::kLinks;
    }
    backend_->InputsChanged(changed);
    linksUpdated_ += touched.size();
    ++geometryUpdates_;
    // Shadow casters and receivers follow the moved surfaces (the same buffers, new
    // places); the sky needs nothing.
    if (direct_) {
        direct_->Move(scene, LeafReceivers());
        CopyDirect(scene);
    }
    msGeometry_ = MsSince(start);
    return std::string("links updated in place on the ") +
           (DeviceLinkUpdate() ? "device" : "host") + " (" + std::to_string(linksUpdated_) +
           " so far, this move " + std::to_string(int(msGeometry_ + 0.5)) + " ms)";
}

std::vector<float> AntiradianceSolver::LeafIrradiance() { return backend_->LeafIrradiance(); }

void AntiradianceSolver::Iterate(int n) {
    if (n < 0) throw Error("iteration count must not be negative");
    auto start = std::chrono::steady_clock::now();
    bool cut = false;  // SetInterrupt's flag stopped the iteration under way
    for (int i = 0; i < n && divergence_.empty() && !cut; ++i) {
        // One iteration: passes until the schedule settles (one pass under the symmetric
        // scheme; a radiance step and its antiradiance steps under the others). The schedule
        // keeps its place across calls, so a cut iteration goes on where it stopped.
        for (bool settled = false; !settled && divergence_.empty();) {
            if (interrupt_ && interrupt_->load(std::memory_order_relaxed)) {
                cut = true;
                break;
            }
            const LocalMode mode = schedule_.Next();
            backend_->Iterate(mode);
            // Every pass's irradiance is read (on a Vulkan device 12 bytes a leaf after a
            // pass that was waited for anyway): the adaptive schedule goes by it, and the
            // guard. Settled solutions are held to the bound, the transients in between
            // only to being finite.
            std::vector<float> e = LeafIrradiance();
            settled = schedule_.Finished(e);
            const float bound =
                settled ? bound_ + carried_ : std::numeric_limits<float>::infinity();
            if (std::string why = Divergence(e, bound); !why.empty())
                divergence_ = "diverged at iteration " + std::to_string(iterations_ + 1) +
                              " (pass " + std::to_string(schedule_.passes) + "): " + why;
            else if (settled)
                settled_ = std::move(e), carried_ *= reflectance_;
        }
        if (cut) break;
        if (divergence_.empty()) ++iterations_;
        if (progress_) progress_("iterating", static_cast<double>(i + 1) / n);
    }
    msTotal_ += MsSince(start);
}

std::vector<glm::vec3> AntiradianceSolver::SurfelIrradiance(Channel channel) {
    std::vector<float> leaf;
    if (channel != Channel::kDirect)
        leaf = settled_.empty() ? std::vector<float>(model_.leaves.size() * 3, 0.0f) : settled_;
    std::vector<glm::vec3> out(model_.surfels.size(), glm::vec3(0.0f));
    for (size_t i = 0; i < model_.leaves.size(); ++i) {
        // leafDirect holds the punctual lights' E_d plus, with SetEmitterDirect, the
        // emitters' first shot, which belongs to `indirect`.
        const glm::vec3 emitter = emitterDirect_.empty() ? glm::vec3(0.0f) : emitterDirect_[i];
        glm::vec3 e(0.0f);
        if (channel != Channel::kDirect)
            e = glm::vec3(leaf[i * 3], leaf[i * 3 + 1], leaf[i * 3 + 2]) + emitter;
        if (channel != Channel::kIndirect) e += glm::vec3(model_.leafDirect[i]) - emitter;
        out[model_.leaves[i].surfel] = e;
    }
    return out;
}

void AntiradianceSolver::CopyDirect(const Scene& scene) {
    // On a device E_d is already where its local pass reads it; keep a host copy for the
    // `direct` channel (and the CPU back end, which reads model_.leafDirect).
    std::vector<float> e = direct_->Irradiance();
    for (size_t i = 0; i < model_.leafDirect.size(); ++i) {
        model_.leafDirect[i] = glm::vec4(e[i * 4], e[i * 4 + 1], e[i * 4 + 2], 0.0f);
        if (!emitterDirect_.empty()) model_.leafDirect[i] += glm::vec4(emitterDirect_[i], 0.0f);
    }
    uint32_t changed = emitterDirect_.empty() ? 0u : uint32_t(AntiradianceBackend::kDirect);
    // Glossy leaves reflect each light along its own mirror direction: per-light shares.
    lightPlaces_ = scene.lights;
    perLight_ = direct_->PerLight();
    if (ReflectDirect()) changed |= AntiradianceBackend::kGlossyDirect;
    backend_->InputsChanged(changed);
    Rebound();
}

void AntiradianceSolver::Rebound() {
    // The iteration continues from the state the edit found, which the old bound held (a
    // bounce cut mid-way included: Solver::SetInterrupt), its excess over the new answer
    // dying away by the largest reflectance each bounce (Iterate): a light dimmed or turned
    // off is not a divergence. Where the old bound was infinite (a reflectance of 1), the
    // largest settled E stands for it.
    float state = 0.0f;
    for (float e : settled_) state = std::max(state, std::abs(e));
    carried_ = std::max({carried_, state, std::isfinite(bound_) ? bound_ : 0.0f});
    bound_ = IrradianceBound(model_, &reflectance_);
}

bool AntiradianceSolver::ReflectDirect() {
    if (model_.glossy.empty() || lightPlaces_.empty()) return false;
    GlossyDirect(model_, lightPlaces_, perLight_);
    return true;
}

void AntiradianceSolver::UpdateLights(const Scene& scene) {
    if (sky_.Update(scene.environment, model_.dirs, model_.environment)) {
        backend_->InputsChanged(AntiradianceBackend::kEnvironment);
        Rebound();
    }
    if (!direct::UpdateDirectStage(direct_.get(), lights_, scene)) return;
    CopyDirect(scene);
}

void AntiradianceSolver::UpdateMaterials(const Scene& scene) {
    PENUMBRA_CHECK_EQ(scene.primitives.size(), model_.surfels.firstSurfel.size());
    materials_ = scene.materials;
    for (size_t p = 0; p < scene.primitives.size(); ++p) {
        for (size_t s = model_.surfels.firstSurfel[p]; s < model_.surfels.End(p); ++s)
            model_.surfels.materials[s] = scene.primitives[p].material;
    }
    for (LeafAttributes& leaf : model_.leaves) {
        const Material& mat = scene.materials[model_.surfels.materials[leaf.surfel]];
        leaf.albedo = model_.surfels.Albedo(mat, leaf.surfel);
        // With a first shot from outside the emitters' light is not carried here.
        leaf.emission =
            emitterDirect_.empty() ? model_.surfels.Emission(mat, leaf.surfel) : glm::vec3(0.0f);
    }
    // Which leaves are glossy, and their lobes, may have changed with the materials (most
    // edits, a dimmed emitter say, leave them as they are).
    uint32_t changed = AntiradianceBackend::kLeaves;
    if (!GlossyMatches(model_, scene)) {
        BuildGlossy(model_, scene);
        ReflectDirect();
        changed |= AntiradianceBackend::kGlossy;
    }
    backend_->InputsChanged(changed);
    Rebound();
}

std::vector<float> AntiradianceSolver::ExitantRows() {
    const std::vector<float> table = backend_->Iex();
    const size_t row = size_t(model_.Bins()) * 3;
    std::vector<float> rows(model_.surfels.size() * row, 0.0f);
    for (const LeafAttributes& leaf : model_.leaves)
        std::copy_n(table.begin() + leaf.node * row, row, rows.begin() + leaf.surfel * row);
    return rows;
}

void AntiradianceSolver::StartFrom(const std::vector<float>& rows,
                                   const std::vector<uint8_t>& keep) {
    const size_t row = size_t(model_.Bins()) * 3;
    if (rows.size() != model_.surfels.size() * row || keep.size() != model_.surfels.size())
        throw Error("warm start: the rows are for another surfel count or bin count");
    std::vector<float> table = backend_->Iex();
    for (const LeafAttributes& leaf : model_.leaves)
        if (keep[leaf.surfel])
            std::copy_n(rows.begin() + leaf.surfel * row, row, table.begin() + leaf.node * row);
    cpu::PullPass(model_, table.data());  // clusters = Σ children again
    backend_->SetIex(table);
}

std::string AntiradianceSolver::WarmStart(Solver& previous, const SurfelCarry& carry) {
    // Surfels that stayed put keep the old solution's exitant intensity. Those of a primitive
    // that moved rigidly keep it too, turned with them: the row leaving in bin b now is the
    // one that left in the bin of R⁻¹ ω_b (Sec. 3.3: a moved object takes its light along;
    // what arrives there has changed, and the next iterations correct it).
    auto* before = dynamic_cast<AntiradianceSolver*>(&previous);
    if (!before) return "cold start (the solver before was not an antiradiance solver)";
    if (before->model_.Bins() != model_.Bins()) return "cold start (the bins changed)";
    if (carry.from.size() != model_.surfels.size() || !carry.kept) return "cold start";
    const int bins = model_.Bins();
    const size_t row = size_t(bins) * 3;
    const std::vector<float> old = before->ExitantRows();
    // Per turn: the bin each of today's bins left in before.
    std::vector<std::vector<uint32_t>> binFrom(carry.turns.size());
    for (size_t t = 1; t < carry.turns.size(); ++t) {
        const glm::mat3 back = glm::transpose(carry.turns[t]);
        for (int b = 0; b < bins; ++b)
            binFrom[t].push_back(model_.dirs.Lookup(back * model_.dirs.Direction(b)));
    }
    std::vector<float> rows(model_.surfels.size() * row, 0.0f);
    std::vector<uint8_t> keep(model_.surfels.size(), 0);
    for (size_t s = 0; s < keep.size(); ++s) {
        if (carry.from[s] == SurfelCarry::kNone) continue;
        keep[s] = 1;
        const float* src = old.data() + size_t(carry.from[s]) * row;
        float* dst = rows.data() + s * row;
        if (!carry.turn[s]) {
            std::copy_n(src, row, dst);
            continue;
        }
        const std::vector<uint32_t>& from = binFrom[carry.turn[s]];
        for (int b = 0; b < bins; ++b) std::copy_n(src + from[b] * 3, 3, dst + b * 3);
    }
    try {
        StartFrom(rows, keep);
    } catch (const Error& e) {
        return std::string("cold start (") + e.what() + ")";
    }
    std::string note = "warm start for " + std::to_string(carry.kept) + " of " +
                       std::to_string(model_.surfels.size()) + " surfels";
    if (carry.turned)
        note += " (" + std::to_string(carry.turned) + " moved, their light turned with them)";
    return note;
}

std::vector<std::string> AntiradianceSolver::ValidationMessages() const {
    return backend_->ValidationMessages();
}

void AntiradianceSolver::SetEmitterDirect(const std::vector<glm::vec3>& perSurfel) {
    if (!perSurfel.empty() && perSurfel.size() != model_.surfels.size())
        throw Error("emitter direct light for " + std::to_string(perSurfel.size()) +
                    " surfels; the solver has " + std::to_string(model_.surfels.size()));
    if (!perSurfel.empty() && !model_.glossy.empty())
        throw Error(
            "emitter direct light from outside reaches glossy surfaces only through their "
            "diffuse part; not taken for a scene with glossy materials");
    // Take the old share out of leafDirect, the new one in.
    for (size_t i = 0; i < model_.leaves.size(); ++i) {
        glm::vec3 old = emitterDirect_.empty() ? glm::vec3(0.0f) : emitterDirect_[i];
        glm::vec3 now = perSurfel.empty() ? glm::vec3(0.0f) : perSurfel[model_.leaves[i].surfel];
        model_.leafDirect[i] += glm::vec4(now - old, 0.0f);
    }
    const bool wasOn = !emitterDirect_.empty();
    emitterDirect_.clear();
    if (!perSurfel.empty())
        for (const LeafAttributes& leaf : model_.leaves)
            emitterDirect_.push_back(perSurfel[leaf.surfel]);
    if (wasOn != !emitterDirect_.empty()) {
        // Emission off in the transport, or back on from the materials as last read.
        for (LeafAttributes& leaf : model_.leaves)
            leaf.emission =
                emitterDirect_.empty()
                    ? model_.surfels.Emission(materials_[model_.surfels.materials[leaf.surfel]],
                                              leaf.surfel)
                    : glm::vec3(0.0f);
    }
    backend_->InputsChanged(AntiradianceBackend::kLeaves | AntiradianceBackend::kDirect);
    Rebound();
}

SolverStats AntiradianceSolver::Stats() const {
    SolverStats s;
    s.solver = "antiradiance";
    s.device = backend_->DeviceName();
    s.elements = model_.leaves.size();
    s.nodes = model_.Nodes();
    s.links = model_.links.Count();
    s.bins = model_.Bins();
    s.iterations = iterations_;
    s.elementSize = model_.elementSize;
    s.linkBuildSeconds = model_.links.buildSeconds;
    s.setupSeconds = setupSeconds_;
    s.msTotal = msTotal_;
    s.linkBytes =
        model_.links.links.size() * sizeof(Link) + model_.links.offsets.size() * sizeof(uint32_t);
    s.lights = lights_;
    for (const LeafAttributes& leaf : model_.leaves)
        s.twoSidedElements += leaf.flags & kLeafTwoSided;
    s.glossyElements = model_.glossy.size();
    s.SetDetail("glossy_lobes", double(model_.lobes.size()));
    s.motion.groups = model_.motion.size();
    s.motion.links = model_.links.dynamic.size();
    s.motion.moves = geometryUpdates_;
    s.motion.linksUpdated = linksUpdated_;
    s.motion.msLastMove = msGeometry_;
    if (!model_.links.dynamic.empty()) {
        s.SetDetail("link_update", DeviceLinkUpdate() ? "device" : "host");
        s.SetDetail("last_link_update_device_ms", backend_->LinkUpdateMs());
    }
    s.motion.declined = model_.motionDeclined;
    s.gathers = schedule_.passes;
    s.bounces = schedule_.bounces;
    s.SetDetail("scheme", SchemeName(own_.scheme));
    s.SetDetail("last_antiradiance_steps", schedule_.lastSteps);
    s.SetDetail("antiradiance_cap_hits", double(schedule_.capHits));
    s.irradianceBound = bound_;
    s.divergence = divergence_;
    s.lighting = direct::DescribeLighting(direct_.get(), mapSize_, sky_);
    s.passes = backend_->PassTimings();
    s.tableBytes = backend_->TableBytes();
    s.SetDetail("tables", backend_->Tables());
    return s;
}

}  // namespace penumbra
