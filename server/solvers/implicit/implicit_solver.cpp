// The implicit-visibility solver's frame: refit, relink, bounce (implicit_solver.h).
#include "solvers/implicit/implicit_solver.h"

#include <tbb/parallel_for.h>

#include <chrono>
#include <cmath>
#include <limits>
#include <numbers>

#include "base/check.h"
#include "base/numeric.h"
#include "gpu/context.h"
#include "scene/solids.h"
#include "solvers/implicit/vulkan_bounce.h"
#include "solvers/implicit/vulkan_composite.h"
#include "solvers/implicit/vulkan_links.h"

namespace penumbra {
namespace {

using Clock = std::chrono::steady_clock;

// Sums each node's two children's rows into its own, deepest clusters first (the pull).
template <typename T>
void PullRows(const Hierarchy& h, size_t width, std::vector<T>& rows) {
    for (size_t depth = h.byDepth.size(); depth-- > 0;) {
        const std::vector<uint32_t>& level = h.byDepth[depth];
        tbb::parallel_for(tbb::blocked_range<size_t>(0, level.size(), 32), [&](const auto& range) {
            for (size_t k = range.begin(); k != range.end(); ++k) {
                const uint32_t n = level[k];
                if (h.nodes[n].IsLeaf()) continue;
                T* row = rows.data() + size_t(n) * width;
                const T* a = rows.data() + size_t(n + 1) * width;
                const T* b = rows.data() + size_t(h.nodes[n + 1].end) * width;
                for (size_t j = 0; j < width; ++j) row[j] = a[j] + b[j];
            }
        });
    }
}

}  // namespace

ImplicitSolver::ImplicitSolver(const Scene& scene, const SolverSettings& settings,
                               const ImplicitSettings& own, const ProgressFn& progress)
    : settings_(settings),
      own_(own),
      progress_(progress),
      dirs_(own.bins),
      linker_(dirs_, own.linkThreshold, own.closest) {
    const auto start = Clock::now();
    if (settings.device == DeviceChoice::kGpu || settings.device == DeviceChoice::kLavapipe) {
        // The links are created on the device (vulkan_links.h); the rest of the frame runs here.
        device_ = std::make_unique<gpu::Context>(settings.device == DeviceChoice::kLavapipe
                                                     ? gpu::DeviceKind::kLavapipe
                                                     : gpu::DeviceKind::kRealGpu,
                                                 settings.validation);
        // The closest-link rule keeps each slot's closest link there by 64-bit atomicMin, where
        // the device has it (else its links are made here); it composites nothing.
        if (!own.closest) {
            vulkanLinks_ = std::make_unique<VulkanLinkCreation>(*device_, dirs_, own.linkThreshold);
            linker_.UseDevice(vulkanLinks_.get());
            vulkanComposite_ =
                std::make_unique<VulkanCompositing>(*device_, dirs_, linker_.BinRadius());
            linker_.UseDeviceCompositing(vulkanComposite_.get());
        } else {
            closestOnHost_ = VulkanLinkCreation::ClosestUnsupported(*device_);
            if (closestOnHost_.empty()) {
                vulkanLinks_ = std::make_unique<VulkanLinkCreation>(*device_, dirs_,
                                                                    own.linkThreshold, 0, true);
                linker_.UseDevice(vulkanLinks_.get());
            }
        }
    }
    ValidateEnvironment(scene.environment);
    const float h = ElementSize(scene, settings);
    elementSize_ = h;
    if (progress) progress("refining", 0.0);
    surfels_ = RefineScene(scene, h);
    if (progress) progress("clustering", 0.0);
    hierarchy_ = BuildHierarchy(surfels_);
    if (device_) vulkanBounce_ = std::make_unique<VulkanBounce>(*device_, dirs_, hierarchy_);
    FindSolids(scene);
    sky_.Update(scene.environment, dirs_, environment_);
    std::vector<uint32_t> order;
    for (uint32_t node : hierarchy_.leaves) order.push_back(hierarchy_.nodes[node].surfel);
    light_.Reset(std::move(order));
    ReadMaterials(scene);
    if (!scene.lights.empty()) {
        if (progress) progress("shadow maps", 0.0);
        mapSize_ = direct::MapSize(settings.shadowMapSize, scene.Diameter(), h);
        lights_ = static_cast<int>(scene.lights.size());
        directStage_ = direct::MakeDirectStage(scene, LeafReceivers(), mapSize_);
        CopyDirect(scene);
    }
    if (progress) progress("linking", 0.0);
    Relink();
    light_.Reradiate();
    setupSeconds_ = std::chrono::duration<double>(Clock::now() - start).count();
}

ImplicitSolver::~ImplicitSolver() = default;

std::vector<direct::GpuReceiver> ImplicitSolver::LeafReceivers() const {
    return direct::MakeReceivers(surfels_, light_.surfel);
}

void ImplicitSolver::CopyDirect(const Scene& scene) {
    light_.CopyDirect(directStage_->Irradiance());
    lightPlaces_ = scene.lights;
    GlossyDirectRows();
}

void ImplicitSolver::FindSolids(const Scene& scene) {
    // Per surfel the closed node it lies on (kOpen: a surface that bounds no solid), then per
    // node the one all its members on solids share: a cluster of a solid's face and an open
    // surface just before it (a lamp quad 2 mm before its housing) is the solid's, since
    // whatever of the open surface lies in the solid's shadow shows no more than the solid.
    constexpr uint32_t kOpen = kNoSolid - 1;
    const std::vector<int> solids = NodeSolids(scene);
    std::vector<uint32_t> ofSurfel(surfels_.size(), kOpen);
    bool any = false;
    for (size_t p = 0; p < scene.primitives.size(); ++p) {
        const int node = scene.primitives[p].nodeIndex;
        if (node < 0 || solids[size_t(node)] < 0) continue;
        any = true;
        for (size_t i = surfels_.firstSurfel[p]; i < surfels_.End(p); ++i)
            ofSurfel[i] = uint32_t(solids[size_t(node)]);
    }
    solid_.clear();
    if (!any) return;
    solid_.assign(hierarchy_.size(), kNoSolid);
    for (size_t n = hierarchy_.size(); n-- > 0;) {  // preorder: children after their parent
        const HierarchyNode& node = hierarchy_.nodes[n];
        if (node.IsLeaf()) {
            solid_[n] = ofSurfel[node.surfel];
        } else {
            const uint32_t a = solid_[n + 1], b = solid_[hierarchy_.nodes[n + 1].end];
            solid_[n] = a == b ? a : a == kOpen ? b : b == kOpen ? a : kNoSolid;
        }
    }
    for (uint32_t& s : solid_)
        if (s == kOpen) s = kNoSolid;
}

void ImplicitSolver::ReadMaterials(const Scene& scene) {
    materials_ = scene.materials;
    AssignSurfelMaterials(scene, surfels_);
    light_.Rematerial(surfels_, materials_);
    ReadGlossy();
}

void ImplicitSolver::Relink(const std::vector<uint8_t>* moved) {
    auto start = Clock::now();
    RefitHierarchy(hierarchy_, surfels_);
    MirrorRows();  // the glossy leaves' normals as they are now
    // The nodes with a moved element below them (children follow their parent in preorder:
    // walk backwards). Within the set of an earlier move, that set again: the links of the
    // other pairs were kept for it, and nothing outside it has moved since.
    const std::vector<uint8_t>* moving = nullptr;
    if (moved) {
        std::vector<uint8_t> now(hierarchy_.size(), 0);
        for (size_t k = hierarchy_.size(); k-- > 0;) {
            const HierarchyNode& n = hierarchy_.nodes[k];
            now[k] = n.IsLeaf() ? (*moved)[n.surfel]
                                : uint8_t(now[k + 1] | now[hierarchy_.nodes[k + 1].end]);
        }
        bool within = !moving_.empty();
        for (size_t k = 0; within && k < now.size(); ++k) within = !now[k] || moving_[k];
        if (!within) moving_ = std::move(now);
        moving = &moving_;
    }
    // Front-facing projected areas per node and bin, Σ A cos⁺(n, ω_b): the leaves', summed
    // up the tree.
    const size_t bins = dirs_.Count();
    projected_.assign(hierarchy_.size() * bins, 0.0f);
    tbb::parallel_for(size_t(0), hierarchy_.leaves.size(), [&](size_t i) {
        const HierarchyNode& n = hierarchy_.nodes[hierarchy_.leaves[i]];
        float* row = projected_.data() + size_t(hierarchy_.leaves[i]) * bins;
        for (size_t b = 0; b < bins; ++b)
            row[b] = n.area * std::max(0.0f, glm::dot(n.normal, dirs_.Direction(uint32_t(b))));
    });
    PullRows(hierarchy_, bins, projected_);
    msUpdate_ += MsSince(start);
    linker_.Build(hierarchy_, projected_, solid_, elementSize_, links_, moving);
    msCreate_ += links_.msCreate;
    msPush_ += links_.msPush;
    // Per share, where Bounce reads its light in intensity_ and the factor on it (the
    // geometry's part, fixed until the next relink): a sender node seen through a bin shows
    // I / P, P the larger of its front- and back-facing projected areas there, so its factor
    // is weight / P (0 where it shows none, and for a flat sender turned away: a dark
    // blocker); a facing flat sender its mean radiance Σ A L / Σ A, so weight / Σ A on its
    // Σ A L; the environment's radiance the weight itself. One read and one product a share,
    // whatever it sees.
    start = Clock::now();
    const ShareTable table{hierarchy_.size(), bins};
    const size_t shares = links_.sender.size(), sumsAt = table.SumsAt(),
                 environmentAt = table.EnvironmentAt();
    PENUMBRA_CHECK(table.Entries() <= 0xffffffffu);  // gatherAt_ holds 32 bits
    gatherAt_.resize(shares);
    gatherFactor_.resize(shares);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, shares, 4096), [&](const auto& range) {
        for (size_t k = range.begin(); k != range.end(); ++k) {
            const uint32_t s = links_.sender[k], travel = links_.travel[k];
            float f = links_.weight[k];
            size_t at = 0;
            if (s == kNoSender) {
                at = environmentAt + travel;
            } else if (travel == kFacing) {
                at = sumsAt + s;
                const float area = hierarchy_.nodes[s].area;
                f = area > 0.0f ? f / area : 0.0f;
            } else if (travel == kAway) {
                f = 0.0f;
            } else {
                at = size_t(s) * bins + travel;
                const float p =
                    std::max(projected_[at], projected_[size_t(s) * bins + dirs_.Opposite(travel)]);
                f = p > 0.0f ? f / p : 0.0f;
            }
            gatherAt_[k] = uint32_t(at);
            gatherFactor_[k] = f;
        }
    });
    // The same shares on the device, when it bounces there (vulkan_bounce.h).
    if (vulkanBounce_) {
        bounceUnfit_ = vulkanBounce_->Unfit(shares);
        if (bounceUnfit_.empty())
            vulkanBounce_->SetShares(hierarchy_, links_.offsets, gatherAt_, gatherFactor_);
    }
    msPush_ += MsSince(start);
    ++relinks_;
    if (linker_.Incremental()) ++incrementalRelinks_;
}

void ImplicitSolver::ExitantTables() {
    const size_t bins = dirs_.Count();
    // Every row is written below (the leaves', then the clusters' by the pull), then the
    // tail: the nodes' Σ A L and the environment (Relink's gatherAt_).
    const ShareTable table{hierarchy_.size(), bins};
    intensity_.resize(table.Entries());
    tbb::parallel_for(size_t(0), hierarchy_.leaves.size(), [&](size_t i) {
        const HierarchyNode& n = hierarchy_.nodes[hierarchy_.leaves[i]];
        glm::vec3* row = intensity_.data() + size_t(hierarchy_.leaves[i]) * bins;
        const glm::vec3 sent = n.area * light_.radiance[i];
        for (size_t b = 0; b < bins; ++b)
            row[b] = std::max(0.0f, glm::dot(n.normal, dirs_.Direction(uint32_t(b)))) * sent;
    });
    PullRows(hierarchy_, bins, intensity_);
    if (!glossy_.empty()) {
        glossyIntensity_.assign(hierarchy_.size() * bins, glm::vec3(0.0f));
        tbb::parallel_for(size_t(0), glossy_.size(), [&](size_t g) {
            const uint32_t node = hierarchy_.leaves[glossy_[g].leaf];
            const HierarchyNode& n = hierarchy_.nodes[node];
            glm::vec3* row = glossyIntensity_.data() + size_t(node) * bins;
            const glm::vec3* leaving = glossyLeaving_.data() + g * bins;
            for (size_t b = 0; b < bins; ++b)
                row[b] = n.area * std::max(0.0f, glm::dot(n.normal, dirs_.Direction(uint32_t(b)))) *
                         leaving[b];
        });
        PullRows(hierarchy_, bins, glossyIntensity_);
    } else {
        glossyIntensity_.clear();
    }
    // Σ A L per node: the leaves', summed up the tree (a facing flat sender's mean radiance
    // is this over Σ A, folded into its shares' factors).
    sums_.assign(hierarchy_.size(), glm::vec3(0.0f));
    for (size_t i = 0; i < hierarchy_.leaves.size(); ++i)
        sums_[hierarchy_.leaves[i]] =
            hierarchy_.nodes[hierarchy_.leaves[i]].area * light_.radiance[i];
    PullRows(hierarchy_, 1, sums_);
    std::copy(sums_.begin(), sums_.end(), intensity_.begin() + table.SumsAt());
    std::copy(environment_.begin(), environment_.end(), intensity_.begin() + table.EnvironmentAt());
}

bool ImplicitSolver::BouncesOnDevice() const {
    return vulkanBounce_ && bounceUnfit_.empty() && glossy_.empty();
}

void ImplicitSolver::Bounce() {
    if (BouncesOnDevice()) {
        light_.gathered = vulkanBounce_->Gather(light_.radiance, environment_);
        ++deviceBounces_;
        Reradiate();
        return;
    }
    ExitantTables();
    const size_t bins = dirs_.Count();
    const bool glossy = !glossy_.empty();
    tbb::parallel_for(
        tbb::blocked_range<size_t>(0, hierarchy_.leaves.size(), 64), [&](const auto& range) {
            for (size_t i = range.begin(); i != range.end(); ++i) {
                const HierarchyNode& receiver = hierarchy_.nodes[hierarchy_.leaves[i]];
                const uint32_t g = glossy ? glossyOf_[i] : kNotGlossy;
                const uint32_t* mirror =
                    g != kNotGlossy ? mirror_.data() + size_t(g) * bins : nullptr;
                glm::vec3* arrived = mirror ? glossyArrived_.data() + size_t(g) * bins : nullptr;
                if (mirror) std::fill(arrived, arrived + bins, glm::vec3(0.0f));
                glm::vec3 e(0.0f);
                for (uint32_t k = links_.offsets[i]; k < links_.offsets[i + 1]; ++k) {
                    // weight · L, the light arriving through this share (Relink's gatherAt_).
                    glm::vec3 got = gatherFactor_[k] * intensity_[gatherAt_[k]];
                    const uint32_t s = links_.sender[k];
                    if (glossy && s != kNoSender && glossyNode_[s]) {
                        // A glossy sender's light towards this leaf, over the larger of its
                        // front- and back-facing projected areas: through the link's bin, or
                        // for a flat sender facing the leaf the bin of the direction from it
                        // (the diffuse part is in `got`; one turned away sends nothing).
                        uint32_t t = links_.travel[k];
                        if (t == kFacing) {
                            const glm::vec3 d = receiver.center - hierarchy_.nodes[s].center;
                            const float len = glm::length(d);
                            t = len > 0.0f ? dirs_.Lookup(d / len) : kAway;
                        }
                        if (t != kAway) {
                            const size_t row = size_t(s) * bins;
                            got += links_.weight[k] *
                                   GlossySent(s, t,
                                              std::max(projected_[row + t],
                                                       projected_[row + dirs_.Opposite(t)]));
                        }
                    }
                    e += got;
                    // cos θ · Ω · L arriving from the link's bin, where its mirror image leaves.
                    if (mirror) arrived[mirror[links_.bin[k]]] += got;
                }
                light_.gathered[i] = e;
                if (mirror) ReflectGlossy(g);
            }
        });
    Reradiate();
}

void ImplicitSolver::Reradiate() {
    light_.Reradiate();
    for (const glm::vec3& l : light_.radiance)
        if (divergence_.empty() && !Finite(l))
            divergence_ = "diverged at iteration " + std::to_string(iterations_ + 1) +
                          ": a leaf's light is not finite";
}

void ImplicitSolver::Iterate(int n) {
    if (n < 0) throw Error("iteration count must not be negative");
    const auto start = Clock::now();
    for (int i = 0; i < n && divergence_.empty(); ++i) {
        const auto t = Clock::now();
        Bounce();
        msIllumination_ += MsSince(t);
        if (divergence_.empty()) ++iterations_;
        if (progress_) progress_("iterating", static_cast<double>(i + 1) / n);
    }
    msTotal_ += MsSince(start);
}

std::vector<glm::vec3> ImplicitSolver::SurfelIrradiance(Channel channel) {
    return light_.SurfelIrradiance(channel, surfels_.size());
}

void ImplicitSolver::UpdateMaterials(const Scene& scene) { ReadMaterials(scene); }

void ImplicitSolver::UpdateLights(const Scene& scene) {
    sky_.Update(scene.environment, dirs_, environment_);
    if (!direct::UpdateDirectStage(directStage_.get(), lights_, scene)) return;
    CopyDirect(scene);
    light_.Reradiate();  // the radiance leaving, with the new direct light
}

bool ImplicitSolver::Checked::Same(const Scene& scene) const {
    if (!valid || positions.size() != scene.primitives.size()) return false;
    for (size_t p = 0; p < positions.size(); ++p)
        if (scene.primitives[p].positions != positions[p] ||
            scene.primitives[p].normals != normals[p])
            return false;
    return true;
}

std::string ImplicitSolver::GeometryMismatch(const Scene& scene) const {
    if (scene.lights.size() == size_t(lights_) && checked_.Same(scene)) return {};
    ++refinements_;
    std::string why = RefinementMismatch(scene, lights_, surfels_, elementSize_, checked_.surfels);
    checked_.valid = why.empty();
    if (checked_.valid) {
        checked_.positions.resize(scene.primitives.size());
        checked_.normals.resize(scene.primitives.size());
        for (size_t p = 0; p < scene.primitives.size(); ++p) {
            checked_.positions[p] = scene.primitives[p].positions;
            checked_.normals[p] = scene.primitives[p].normals;
        }
    }
    return why;
}

std::string ImplicitSolver::UpdateGeometry(const Scene& scene) {
    const auto start = Clock::now();
    // Refined once: checked (GeometryMismatch keeps it), then taken.
    if (std::string why = GeometryMismatch(scene); !why.empty()) throw Error(why);
    Surfels now = std::move(checked_.surfels);
    checked_.valid = false;
    // What moved: the elements whose centroid, normal or area (what the hierarchy is
    // refitted from) changed.
    std::vector<uint8_t> moved(surfels_.size(), 0);
    for (size_t i = 0; i < moved.size(); ++i)
        moved[i] = surfels_.centroids[i] != now.centroids[i] ||
                   surfels_.normals[i] != now.normals[i] || surfels_.areas[i] != now.areas[i];
    surfels_.positions = std::move(now.positions);
    surfels_.normals = std::move(now.normals);
    surfels_.areas = std::move(now.areas);
    surfels_.centroids = std::move(now.centroids);
    if (directStage_) {
        directStage_->Move(scene, LeafReceivers());
        CopyDirect(scene);
        light_.Reradiate();
    }
    Relink(&moved);
    ++geometryUpdates_;
    msGeometry_ = MsSince(start);
    return "links rebuilt in place (" + std::to_string(links_.Count()) + " links, " +
           std::to_string(int(msGeometry_ + 0.5)) + " ms)";
}

void ImplicitSolver::SetEmitterDirect(const std::vector<glm::vec3>& perSurfel) {
    light_.SetEmitterDirect(perSurfel, surfels_.size());
    light_.Rematerial(surfels_, materials_);
}

std::string ImplicitSolver::WarmStart(Solver& previous, const SurfelCarry& carry) {
    auto* before = dynamic_cast<ImplicitSolver*>(&previous);
    if (!before) return "cold start (the solver before was not an implicit-visibility solver)";
    if (carry.from.size() != surfels_.size() || !carry.kept) return "cold start";
    size_t kept = 0;
    for (size_t i = 0; i < hierarchy_.leaves.size(); ++i) {
        const uint32_t s = hierarchy_.nodes[hierarchy_.leaves[i]].surfel;
        if (carry.from[s] == SurfelCarry::kNone) continue;
        const uint32_t old = before->hierarchy_.leafOfSurfel[size_t(carry.from[s])];
        if (old == kNoParent) continue;
        // Leaves are numbered in preorder; find the old leaf's index among the leaves.
        const auto it = std::lower_bound(before->hierarchy_.leaves.begin(),
                                         before->hierarchy_.leaves.end(), old);
        const size_t j = size_t(it - before->hierarchy_.leaves.begin());
        light_.gathered[i] = before->light_.gathered[j];
        light_.radiance[i] = before->light_.radiance[j];
        ++kept;
    }
    return "warm start for " + std::to_string(kept) + " of " + std::to_string(surfels_.size()) +
           " surfels";
}

SolverStats ImplicitSolver::Stats() const {
    SolverStats s;
    s.solver = "implicit";
    s.device = device_ ? "vulkan:" + device_->DeviceName() : "cpu";
    s.elements = hierarchy_.leaves.size();
    s.nodes = hierarchy_.size();
    s.links = links_.Count();
    s.bins = dirs_.Count();
    s.iterations = iterations_;
    s.gathers = iterations_;
    s.bounces = iterations_;
    s.elementSize = elementSize_;
    s.linkBuildSeconds = (links_.msCreate + links_.msPush) / 1000.0;
    s.setupSeconds = setupSeconds_;
    s.msTotal = msTotal_;
    s.passes = {{"update", msUpdate_},
                {"create", msCreate_},
                {"refine_push", msPush_},
                {"illumination", msIllumination_}};
    s.tableBytes = intensity_.size() * sizeof(glm::vec3) + projected_.size() * sizeof(float);
    // Per share: bin, sender, weight and travel, and the bounce's index and factor.
    s.linkBytes = links_.sender.size() * (4 * sizeof(uint32_t) + 2 * sizeof(float));
    s.lights = lights_;
    s.lighting = direct::DescribeLighting(directStage_.get(), mapSize_, sky_);
    s.motion.moves = geometryUpdates_;
    s.motion.msLastMove = msGeometry_;
    s.divergence = divergence_;
    // No furnace bound is computed (a Jacobi bounce with albedos below 1 cannot grow without
    // bound); infinite: none is checked, only that the light stays finite.
    s.irradianceBound = std::numeric_limits<float>::infinity();
    s.SetDetail("link_threshold", own_.linkThreshold);
    s.SetDetail("bin_cover", std::string(own_.closest ? "closest" : "layer"));
    s.SetDetail("candidate_pairs", double(links_.pairs));
    s.SetDetail("empty_bins", double(links_.empty));
    s.SetDetail("relinks", double(relinks_));
    s.SetDetail("relinks_kept", double(incrementalRelinks_));
    s.SetDetail("refinements", double(refinements_));
    // Where the links are created: the device's rounds (uploads, dispatches, readbacks).
    const std::string& linkedOnHost =
        !closestOnHost_.empty() ? closestOnHost_ : linker_.LinkedOnHostBecause();
    s.SetDetail("link_device",
                vulkanLinks_ && linkedOnHost.empty() ? device_->DeviceName() : std::string("cpu"));
    if (device_ && !linkedOnHost.empty()) s.SetDetail("link_on_host", linkedOnHost);
    if (vulkanLinks_) {
        s.SetDetail("device_create_ms", vulkanLinks_->msDevice);
        s.SetDetail("device_create_busy_ms", vulkanLinks_->msBusy);
        s.SetDetail("device_rounds", double(vulkanLinks_->rounds));
    }
    // Where the leaves' bins are composited, and why on the host where a device was asked for.
    s.SetDetail("composite_device",
                linker_.CompositedOnDevice() ? device_->DeviceName() : std::string("cpu"));
    if (vulkanComposite_) {
        if (!linker_.CompositedOnDevice())
            s.SetDetail("composite_on_host", linker_.CompositedOnHostBecause());
        s.SetDetail("device_composites", double(vulkanComposite_->runs));
        s.SetDetail("device_composite_ms", vulkanComposite_->msDevice);
        s.SetDetail("device_composite_busy_ms", vulkanComposite_->msBusy);
    } else if (device_) {
        s.SetDetail("composite_on_host",
                    std::string("bin-cover closest: no layer to composite, the push-down and the "
                                "shares on the CPU"));
    }
    // Where the bounces run, and why on the host where a device was asked for.
    s.SetDetail("bounce_device", BouncesOnDevice() ? device_->DeviceName() : std::string("cpu"));
    if (vulkanBounce_ && !BouncesOnDevice())
        s.SetDetail("bounce_on_host",
                    !bounceUnfit_.empty() ? bounceUnfit_ : std::string("glossy leaves"));
    if (vulkanBounce_) {
        s.SetDetail("device_bounces", double(deviceBounces_));
        s.SetDetail("device_bounce_ms", vulkanBounce_->msDevice);
        s.SetDetail("device_bounce_busy_ms", vulkanBounce_->msBusy);
    }
    return s;
}

std::vector<std::string> ImplicitSolver::ValidationMessages() const {
    return device_ ? device_->ValidationMessages() : std::vector<std::string>{};
}

}  // namespace penumbra
