// The light-field solver's batches and bounces (lightfield_solver.h).
#include "solvers/lightfield/lightfield_solver.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <numbers>
#include <numeric>
#include <tuple>

#include "base/check.h"
#include "base/numeric.h"
#include "gpu/context.h"

namespace penumbra {
namespace {

using Clock = std::chrono::steady_clock;

// The ball the lines cover: around the refined mesh's bounding box.
LineGrid MakeGrid(const Surfels& surfels, float elementSize, int cells) {
    Bounds box;
    for (const glm::vec3& p : surfels.positions) box.Add(p);
    LineGrid g;
    if (box.Empty()) return g;
    g.centre = 0.5f * (box.lo + box.hi);
    g.radius = std::max(0.5f * glm::length(box.hi - box.lo) * 1.001f, 1e-4f);
    // Cells half an element wide: a surfel (about an element across) meets a few lines of
    // every direction it faces.
    g.cells = cells > 0
                  ? cells
                  : std::clamp(int(std::ceil(2.0f * g.radius / (0.5f * elementSize))), 16, 1024);
    return g;
}

}  // namespace

LightfieldSolver::LightfieldSolver(const Scene& scene, const SolverSettings& settings,
                                   const LightfieldSettings& own, const ProgressFn& progress)
    : own_(own), progress_(progress), scene_(scene) {
    const auto start = Clock::now();
    ValidateEnvironment(scene.environment);
    const float h = ElementSize(scene, settings);
    elementSize_ = h;
    if (progress) progress("refining", 0.0);
    surfels_ = RefineScene(scene_, h);
    rays_ = std::make_unique<RayScene>(scene_, surfels_);
    facets_ = std::make_unique<SurfelFacets>(*rays_, surfels_.size());
    grid_ = MakeGrid(surfels_, h, own.cells);
    MakeSmoothing();
    if (settings.device == DeviceChoice::kGpu || settings.device == DeviceChoice::kLavapipe) {
        // A rasteriser samples pixel centres: one jitter a direction (the CPU's re-traces
        // after a move use the same grid).
        grid_.jitter = LineJitter::kPerDirection;
        device_ = std::make_unique<gpu::Context>(settings.device == DeviceChoice::kLavapipe
                                                     ? gpu::DeviceKind::kLavapipe
                                                     : gpu::DeviceKind::kRealGpu,
                                                 settings.validation);
        vulkanLines_ = std::make_unique<VulkanLines>(*device_, *rays_, grid_, own.layers);
        // The device's walk knows no surface that passes light (glass): the CPU walks those.
        if (device_->FloatAtomics() && !rays_->Passing()) {
            vulkanWalk_ = std::make_unique<VulkanWalk>(*device_, *rays_, surfels_.size());
            vulkanWalk_->SetFacets(*facets_);
        }
    }
    base_ = HemisphereDirections(own.directions);
    sky_.Binned(scene.environment);
    const size_t n = surfels_.size();
    std::vector<uint32_t> order(n);
    std::iota(order.begin(), order.end(), 0u);
    light_.Reset(std::move(order));
    if (!scene.lights.empty()) {
        if (progress) progress("shadow maps", 0.0);
        mapSize_ = direct::MapSize(settings.shadowMapSize, scene.Diameter(), h);
        lights_ = static_cast<int>(scene.lights.size());
        directStage_ = direct::MakeDirectStage(scene_, Receivers(), mapSize_);
        CopyDirect();
    }
    Rematerial();
    setupSeconds_ = std::chrono::duration<double>(Clock::now() - start).count();
}

LightfieldSolver::~LightfieldSolver() = default;

void LightfieldSolver::MakeSmoothing() {
    const int passes =
        own_.smoothing >= 0
            ? own_.smoothing
            : SmoothingPasses(2.0f * grid_.radius / float(grid_.cells), elementSize_);
    smoothing_ = SurfelSmoothing(*rays_, surfels_.positions, surfels_.normals, passes);
}

std::vector<direct::GpuReceiver> LightfieldSolver::Receivers() const {
    return direct::MakeReceivers(surfels_, light_.surfel);
}

void LightfieldSolver::CopyDirect() {
    light_.CopyDirect(directStage_->Irradiance());
    perLight_ = directStage_->PerLight();
    for (size_t b = 0; b < batches_.size(); ++b) {
        PreparePunctual(b);
        Reflect(b);
    }
}

void LightfieldSolver::PreparePunctual(size_t b) {
    punctual_.resize(batches_.size());
    punctual_[b].clear();
    if (glossy_.empty() || perLight_.empty()) return;
    const std::vector<glm::vec3>& dirs = batches_[b].directions;
    const size_t columns = 2 * dirs.size(), surfels = surfels_.size();
    const float dOmega = 2.0f * std::numbers::pi_v<float> / float(dirs.size());
    punctual_[b].assign(glossy_.size() * columns, glm::vec3(0.0f));
    tbb::parallel_for(size_t(0), glossy_.size(), [&](size_t g) {
        const uint32_t s = glossy_[g];
        const glm::vec3 p = surfels_.positions[s], n = surfels_.normals[s];
        glm::vec3* row = punctual_[b].data() + g * columns;
        std::vector<float> scratch;
        std::vector<std::pair<uint32_t, float>> weights;
        for (size_t k = 0; k < scene_.lights.size(); ++k) {
            const float* e = perLight_.data() + (k * surfels + s) * 4;
            if (e[0] <= 0.0f && e[1] <= 0.0f && e[2] <= 0.0f) continue;
            const PunctualLight& light = scene_.lights[k];
            const glm::vec3 travel = light.type == LightType::kDirectional
                                         ? light.direction
                                         : glm::normalize(p - light.position);
            // E = L cos θ Δω of a light too small to sample with lines: exitant_j = B_j E / Δω.
            LobeWeights(dirs, n, exponents_[g], travel, scratch, weights);
            const glm::vec3 scaled = glm::vec3(e[0], e[1], e[2]) / dOmega;
            for (const auto& [j, w] : weights) row[j] += w * scaled;
        }
    });
}

void LightfieldSolver::Reflect(size_t b) {
    if (glossy_.empty()) return;
    const size_t columns = 2 * batches_[b].directions.size();
    const bool lit = !punctual_[b].empty();
    tbb::parallel_for(size_t(0), glossy_.size(), [&](size_t g) {
        const glm::vec3 f0 = scene_.materials[surfels_.materials[glossy_[g]]].specular;
        glm::vec3* out = exitant_[b].data() + g * columns;
        lobes_[b][lobeOf_[b][g]].Reflect(f0, incoming_[b].data() + g * columns, out);
        if (lit)
            for (size_t j = 0; j < columns; ++j) out[j] += f0 * punctual_[b][g * columns + j];
    });
}

void LightfieldSolver::ReadGlossy() {
    std::vector<int32_t> slot(surfels_.size(), -1);
    std::vector<uint32_t> glossy;
    std::vector<float> exponents;
    for (uint32_t s = 0; s < surfels_.size(); ++s)
        if (const Material& m = scene_.materials[surfels_.materials[s]]; m.Glossy()) {
            slot[s] = static_cast<int32_t>(glossy.size());
            glossy.push_back(s);
            exponents.push_back(m.phongExponent);
        }
    if (glossy != glossy_) {
        slot_ = std::move(slot);
        glossy_ = std::move(glossy);
        incoming_.assign(batches_.size(), {});
        exitant_.assign(batches_.size(), {});
        for (size_t b = 0; b < batches_.size(); ++b) {
            const size_t cells = glossy_.size() * 2 * batches_[b].directions.size();
            incoming_[b].assign(cells, glm::vec3(0.0f));
            exitant_[b].assign(cells, glm::vec3(0.0f));
        }
    } else if (exponents == exponents_) {
        return;  // the same lobes (an edit of colours or emission)
    }
    exponents_ = std::move(exponents);
    for (size_t b = 0; b < batches_.size(); ++b) {
        PrepareLobes(b);
        PreparePunctual(b);
    }
}

void LightfieldSolver::PrepareLobes(size_t b) {
    lobes_.resize(batches_.size());
    lobeOf_.resize(batches_.size());
    lobes_[b].clear();
    lobeOf_[b].assign(glossy_.size(), 0);
    if (glossy_.empty()) return;
    // One table per distinct (normal, exponent): a flat face's surfels share theirs.
    std::map<std::tuple<float, float, float, float>, uint32_t> tables;
    std::vector<std::pair<glm::vec3, float>> keys;
    for (size_t g = 0; g < glossy_.size(); ++g) {
        const glm::vec3 n = surfels_.normals[glossy_[g]];
        const float e = exponents_[g];
        auto [it, added] = tables.emplace(std::make_tuple(n.x, n.y, n.z, e), uint32_t(keys.size()));
        if (added) keys.emplace_back(n, e);
        lobeOf_[b][g] = it->second;
    }
    std::vector<std::unique_ptr<LobeTable>> made(keys.size());
    tbb::parallel_for(size_t(0), keys.size(), [&](size_t k) {
        made[k] =
            std::make_unique<LobeTable>(batches_[b].directions, keys[k].first, keys[k].second);
    });
    for (auto& t : made) lobes_[b].push_back(std::move(*t));
}

void LightfieldSolver::Rematerial() {
    ReadGlossy();
    light_.Rematerial(surfels_, scene_.materials);
    stale_ = true;
}

void LightfieldSolver::Reradiate() {
    stale_ = true;  // the next iteration walks every kept batch
    light_.Reradiate();
}

void LightfieldSolver::Bounce(bool newestOnly) {
    const auto t = Clock::now();
    const Environment& env = sky_.Last();
    const Environment* sky = env.Active() ? &env : nullptr;
    if (!newestOnly) {
        weighted_.assign(surfels_.size(), glm::vec3(0.0f));
        sampled_.assign(surfels_.size(), 0.0f);
    }
    for (size_t b = newestOnly ? batches_.size() - 1 : 0; b < batches_.size(); ++b) {
        if (glossy_.empty()) {
            Walk(b, sky, nullptr);
            continue;
        }
        // The glossy surfels send what they reflected in the walk before (a Jacobi bounce),
        // then reflect what arrived in this one.
        GlossyLines lines{&slot_, glossy_.size(), exitant_[b].data(), incoming_[b].data()};
        Walk(b, sky, &lines);
        Reflect(b);
    }
    // E_s = π Σ_ω P L̄ / Σ_ω P over the directions sampled, each sum as the lines gave it
    // (lines.h), both pooled over the neighbours where the cells are wider than the surfels
    // (SurfelSmoothing).
    const float pi = std::numbers::pi_v<float>;
    pooled_.resize(weighted_.size());
    for (size_t s = 0; s < weighted_.size(); ++s) pooled_[s] = glm::vec4(weighted_[s], sampled_[s]);
    smoothing_.Apply(pooled_, pooledScratch_);  // nothing at 0 passes
    for (size_t s = 0; s < pooled_.size(); ++s)
        light_.gathered[s] =
            pooled_[s].w > 0.0f ? (pi / pooled_[s].w) * glm::vec3(pooled_[s]) : glm::vec3(0.0f);
    Reradiate();
    msLastWalk_ = MsSince(t);
    msWalk_ += msLastWalk_;
    for (const glm::vec3& l : light_.radiance)
        if (divergence_.empty() && !Finite(l))
            divergence_ = "diverged at iteration " + std::to_string(iterations_ + 1) +
                          ": a surfel's light is not finite";
}

void LightfieldSolver::Walk(size_t b, const Environment* sky, const GlossyLines* glossy) {
    if (vulkanWalk_)
        vulkanWalk_->Walk(b, batches_[b], grid_.CellArea(), light_.radiance, sky, weighted_,
                          sampled_, glossy);
    else
        WalkBatch(batches_[b], *rays_, *facets_, grid_.CellArea(), light_.radiance, sky, weighted_,
                  sampled_, glossy);
}

void LightfieldSolver::Iterate(int n) {
    if (n < 0) throw Error("iteration count must not be negative");
    const auto start = Clock::now();
    for (int i = 0; i < n && divergence_.empty(); ++i) {
        bool newestOnly = false;
        if (batches_.size() < size_t(own_.batches)) {
            const auto t = Clock::now();
            const uint32_t next = static_cast<uint32_t>(batches_.size());
            batches_.push_back(vulkanLines_ ? vulkanLines_->TraceBatch(base_, own_.seed, next)
                                            : TraceBatch(*rays_, grid_, base_, own_.seed, next));
            const size_t cells = glossy_.size() * 2 * batches_.back().directions.size();
            incoming_.emplace_back(cells, glm::vec3(0.0f));
            exitant_.emplace_back(cells, glm::vec3(0.0f));
            PrepareLobes(batches_.size() - 1);
            PreparePunctual(batches_.size() - 1);
            Reflect(batches_.size() - 1);  // the lights' glossy reflections go out at once
            msTrace_ += MsSince(t);
            // While batches land, each is walked once with the light of its time (the
            // earlier ones carry a bounce or more fewer); an edit since, or the last batch,
            // walks all of them with today's light.
            newestOnly = !stale_ && batches_.size() > 1 && batches_.size() < size_t(own_.batches);
        }
        Bounce(newestOnly);
        stale_ = false;
        if (divergence_.empty()) ++iterations_;
        if (progress_) progress_("iterating", static_cast<double>(i + 1) / n);
    }
    msTotal_ += MsSince(start);
}

std::vector<glm::vec3> LightfieldSolver::SurfelIrradiance(Channel channel) {
    return light_.SurfelIrradiance(channel, surfels_.size());
}

void LightfieldSolver::UpdateMaterials(const Scene& scene) {
    PENUMBRA_CHECK_EQ(scene.primitives.size(), surfels_.firstSurfel.size());
    scene_.materials = scene.materials;
    for (size_t p = 0; p < scene.primitives.size(); ++p)
        scene_.primitives[p].material = scene.primitives[p].material;
    AssignSurfelMaterials(scene, surfels_);
    Rematerial();
}

void LightfieldSolver::UpdateLights(const Scene& scene) {
    ValidateEnvironment(scene.environment);
    sky_.Binned(scene.environment);  // the walks read it: nothing to re-bin
    stale_ = true;
    scene_.lights = scene.lights;  // where the glossy surfels see them
    if (!direct::UpdateDirectStage(directStage_.get(), lights_, scene)) return;
    CopyDirect();
    Reradiate();
}

std::string LightfieldSolver::Mismatch(const Scene& scene, Surfels& now) const {
    if (std::string why = RefinementMismatch(scene, lights_, surfels_, elementSize_, now);
        !why.empty())
        return why;
    // The lines cover the ball they were made for; a surface moved out of it would be missed.
    for (size_t s = 0; s < now.size(); ++s)
        if (now.positions[s] != surfels_.positions[s] &&
            glm::length(now.positions[s] - grid_.centre) > grid_.radius)
            return "a surface moved outside the ball the light field's lines cover";
    return {};
}

std::string LightfieldSolver::GeometryMismatch(const Scene& scene) const {
    Surfels now;
    return Mismatch(scene, now);
}

std::string LightfieldSolver::UpdateGeometry(const Scene& scene) {
    const auto start = Clock::now();
    Surfels now;  // refined once: checked, then taken
    if (std::string why = Mismatch(scene, now); !why.empty()) throw Error(why);
    // Where the moved surfels were and are: every line that can meet them is traced again.
    Bounds box;
    size_t moved = 0;
    for (size_t s = 0; s < now.size(); ++s) {
        if (now.positions[s] == surfels_.positions[s] && now.normals[s] == surfels_.normals[s])
            continue;
        box.Add(surfels_.positions[s]), box.Add(now.positions[s]);
        ++moved;
    }
    surfels_.positions = std::move(now.positions);
    surfels_.normals = std::move(now.normals);
    surfels_.areas = std::move(now.areas);
    surfels_.centroids = std::move(now.centroids);
    size_t retraced = 0;
    stale_ = true;
    if (moved > 0) {
        rays_->Update(surfels_);
        if (vulkanLines_) vulkanLines_->Update(*rays_);  // for the batches still to come
        facets_ = std::make_unique<SurfelFacets>(*rays_, surfels_.size());
        for (size_t b = 0; b < batches_.size(); ++b) {
            retraced += RetraceBatch(*rays_, grid_, own_.seed, box, batches_[b]);
            if (vulkanWalk_) vulkanWalk_->Invalidate(b);
        }
        if (vulkanWalk_) vulkanWalk_->SetFacets(*facets_);
        for (size_t b = 0; b < batches_.size(); ++b) PrepareLobes(b);
        MakeSmoothing();  // a deformation can open or close a crease
    }
    scene_.lights = scene.lights;
    if (directStage_) {
        directStage_->Move(scene, Receivers());
        CopyDirect();
        Reradiate();
    }
    ++geometryUpdates_;
    linesRetraced_ += retraced;
    msGeometry_ = MsSince(start);
    return "lines traced again in place (" + std::to_string(retraced) + " lines, " +
           std::to_string(int(msGeometry_ + 0.5)) + " ms)";
}

void LightfieldSolver::SetEmitterDirect(const std::vector<glm::vec3>& perSurfel) {
    light_.SetEmitterDirect(perSurfel, surfels_.size());
    Rematerial();
}

std::string LightfieldSolver::WarmStart(Solver& previous, const SurfelCarry& carry) {
    auto* before = dynamic_cast<LightfieldSolver*>(&previous);
    if (!before) return "cold start (the solver before was not a light-field solver)";
    if (carry.from.size() != surfels_.size() || !carry.kept) return "cold start";
    size_t kept = 0;
    for (size_t s = 0; s < surfels_.size(); ++s) {
        if (carry.from[s] == SurfelCarry::kNone) continue;
        light_.gathered[s] = before->light_.gathered[size_t(carry.from[s])];
        ++kept;
    }
    Reradiate();
    return "warm start for " + std::to_string(kept) + " of " + std::to_string(surfels_.size()) +
           " surfels";
}

std::vector<std::string> LightfieldSolver::ValidationMessages() const {
    return device_ ? device_->ValidationMessages() : std::vector<std::string>{};
}

SolverStats LightfieldSolver::Stats() const {
    SolverStats s;
    s.solver = "lightfield";
    s.device = device_ ? "vulkan:" + device_->DeviceName() : "cpu";
    s.elements = surfels_.size();
    s.nodes = surfels_.size();
    size_t lines = 0, hits = 0, bytes = 0;
    for (const LineBatch& b : batches_)
        lines += b.Lines(), hits += b.hits.size(), bytes += b.Bytes();
    s.links = hits;  // a line's hits are what carries light
    s.iterations = iterations_;
    s.gathers = iterations_;
    s.bounces = iterations_;
    s.elementSize = elementSize_;
    s.linkBuildSeconds = msTrace_ / 1000.0;
    s.setupSeconds = setupSeconds_;
    s.msTotal = msTotal_;
    s.passes = {{"trace", msTrace_}, {"walk", msWalk_}};
    // Per surfel six RGB arrays and the coverage; per glossy slot and batch three RGB rows; the
    // lights' E_d per surfel.
    size_t glossyBytes = 0;
    for (size_t b = 0; b < incoming_.size(); ++b)
        glossyBytes += (incoming_[b].size() + exitant_[b].size()) * sizeof(glm::vec3);
    for (const std::vector<glm::vec3>& rows : punctual_)
        glossyBytes += rows.size() * sizeof(glm::vec3);
    glossyBytes += perLight_.size() * sizeof(float);
    s.tableBytes = surfels_.size() * (6 * sizeof(glm::vec3) + sizeof(float)) + glossyBytes;
    s.linkBytes = bytes;
    s.lights = lights_;
    s.lighting = direct::DescribeLighting(directStage_.get(), mapSize_, sky_);
    s.motion.moves = geometryUpdates_;
    s.motion.msLastMove = msGeometry_;
    s.divergence = divergence_;
    // No furnace bound is computed; only that the light stays finite is checked.
    s.irradianceBound = std::numeric_limits<float>::infinity();
    s.SetDetail("directions_per_batch", double(own_.directions));
    s.SetDetail("batches", double(batches_.size()));
    s.SetDetail("batches_kept_at_most", double(own_.batches));
    s.SetDetail("cells", double(grid_.cells));
    s.SetDetail("smoothing_passes", double(smoothing_.Passes()));
    s.SetDetail("lines", double(lines));
    s.SetDetail("line_hits", double(hits));
    s.SetDetail("lines_retraced", double(linesRetraced_));
    s.SetDetail("last_walk_ms", msLastWalk_);
    if (vulkanLines_) {
        // The lines rasterised on the device; the walk there too where it has float atomics.
        s.SetDetail("device_trace_ms", vulkanLines_->msDevice);
        s.SetDetail("most_layers", double(vulkanLines_->MostLayers()));
        s.SetDetail("walk_device", vulkanWalk_ ? device_->DeviceName() : std::string("cpu"));
        if (vulkanWalk_) s.SetDetail("device_walk_ms", vulkanWalk_->msDevice);
    }
    return s;
}

}  // namespace penumbra
