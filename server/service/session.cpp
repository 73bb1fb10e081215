// The shared scene session: edit validation, the frame loop, link rebuilds on moves.
#include "service/session.h"

#include <algorithm>
#include <cmath>
#include <glm/gtc/matrix_transform.hpp>
#include <memory>
#include <optional>
#define GLM_ENABLE_EXPERIMENTAL
#include <glm/gtx/quaternion.hpp>

#include "base/check.h"
#include "gather/gather_stage.h"
#include "hierarchy/directions.h"
#include "output/irradiance_writer.h"

namespace penumbra::service {

namespace {

using Clock = std::chrono::steady_clock;

double MsSince(Clock::time_point t) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

bool Finite(glm::vec3 v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

bool FiniteNonNegative(glm::vec3 v) {
    for (int i = 0; i < 3; ++i)
        if (!std::isfinite(v[i]) || v[i] < 0.0f) return false;
    return true;
}

std::string NodeList(const Scene& scene, bool dynamicOnly) {
    std::string out;
    for (const auto& n : scene.nodes) {
        if (n.primitives.empty() && n.children.empty()) continue;
        if (dynamicOnly && !n.dynamic) continue;
        out += (out.empty() ? "" : ", ") + n.name;
    }
    return out.empty() ? "(none)" : out;
}

// Gives every primitive of `node` a material of its own (a copy named material@node) so a
// light edit changes that node only; returns the materials it now uses.
std::vector<uint32_t> OwnMaterials(Scene& scene, int node) {
    std::vector<uint32_t> used;
    for (uint32_t pi : scene.nodes[node].primitives) {
        Primitive& p = scene.primitives[pi];
        bool shared = false;
        for (size_t q = 0; q < scene.primitives.size() && !shared; ++q)
            shared =
                scene.primitives[q].material == p.material && scene.primitives[q].nodeIndex != node;
        if (shared) {
            Material copy = scene.materials[p.material];
            copy.name += "@" + scene.nodes[node].name;
            scene.materials.push_back(copy);
            uint32_t fresh = static_cast<uint32_t>(scene.materials.size() - 1);
            for (uint32_t pj : scene.nodes[node].primitives)
                if (scene.primitives[pj].material == p.material)
                    scene.primitives[pj].material = fresh;
        }
        if (std::find(used.begin(), used.end(), p.material) == used.end())
            used.push_back(p.material);
    }
    return used;
}

bool SubtreeHasPrimitives(const Scene& scene, int node) {
    if (!scene.nodes[node].primitives.empty()) return true;
    for (int c : scene.nodes[node].children)
        if (SubtreeHasPrimitives(scene, c)) return true;
    return false;
}

bool SubtreeHasLights(const Scene& scene, int node) {
    for (const auto& l : scene.lights)
        for (int n = l.node; n >= 0; n = scene.nodes[n].parent)
            if (n == node) return true;
    return false;
}

}  // namespace

const glm::vec3* FrameData::Values(size_t p, Channel channel,
                                   std::vector<glm::vec3>& scratch) const {
    const bool hasDirect = !direct.empty();
    if (channel == Channel::kIndirect || (!hasDirect && channel == Channel::kTotal))
        return irradiance[p].data();
    if (!hasDirect) return nullptr;
    if (channel == Channel::kDirect) return direct[p].data();
    scratch.resize(irradiance[p].size());
    for (size_t i = 0; i < scratch.size(); ++i) scratch[i] = irradiance[p][i] + direct[p][i];
    return scratch.data();
}

void CheckSessionSettings(const SessionSettings& s) {
    if (s.iterationsPerFrame < 1 || s.iterationsPerFrame > kMaxIterationsPerFrame)
        throw Error("iterations per frame must be 1…" + std::to_string(kMaxIterationsPerFrame) +
                    ", not " + std::to_string(s.iterationsPerFrame));
    if (!(s.convergedChange >= 0.0)) throw Error("converged_change must be ≥ 0 (0: never idle)");
    CheckGatherRays(s.emitterRays, "emitter_rays");
    CheckGatherRays(s.gatherRays, "gather_rays");
    if (!(s.solver.elementSize >= 0.0f) || !std::isfinite(s.solver.elementSize))
        throw Error("element size must be ≥ 0 metres (0: automatic)");
}

Session::Session(std::string name, Scene scene, SessionSettings settings,
                 const ProgressFn& progress)
    : name_(std::move(name)), settings_(std::move(settings)) {
    CheckSessionSettings(settings_);
    auto start = Clock::now();
    std::vector<std::string> notes;
    solver_ = BuildSolver(scene, true, progress, &notes);
    for (const std::string& n : notes) gatherNote_ += (gatherNote_.empty() ? "" : "; ") + n;
    buildSeconds_ = MsSince(start) / 1000.0;
    solverStatsRaw_ = solver_->Stats();
    motionDeclined_ = !solverStatsRaw_.motionDeclined.empty();
    for (const auto& n : scene.nodes)
        for (uint32_t pi : n.primitives) {
            if (!glm::any(glm::greaterThan(scene.materials[scene.primitives[pi].material].emission,
                                           glm::vec3(0.0f))))
                continue;
            auto it = std::find(lightNodes_.begin(), lightNodes_.end(), n.name);
            if (it == lightNodes_.end()) {
                lightNodes_.push_back(n.name);
                lightPrimitives_.emplace_back();
                it = lightNodes_.end() - 1;
            }
            lightPrimitives_[it - lightNodes_.begin()].push_back(pi);
        }
    auto layout = std::make_shared<std::vector<PrimitiveKey>>();
    for (const auto& p : scene.primitives) layout->push_back({p.node, p.mesh, p.primitive});
    layout_ = layout;
    punctualLights_ = static_cast<int>(scene.lights.size());
    validated_ = scene;
    applied_ = std::move(scene);
    worker_ = std::thread([this] { Run(); });
}

Session::~Session() {
    {
        std::lock_guard lock(mutex_);
        stop_ = true;
    }
    wake_.notify_all();
    frameMade_.notify_all();
    if (worker_.joinable()) worker_.join();
    if (rebuild_ && rebuild_->thread.joinable()) rebuild_->thread.join();
    for (auto& [n, promise] : steps_)
        promise.set_exception(std::make_exception_ptr(
            ServiceError(ErrorKind::kShuttingDown, "the session closed before the step ran")));
}

// --- Edits ----------------------------------------------------------------------------------

uint64_t Session::Queue(std::function<void(Scene&)> apply, bool moves, std::string what,
                        bool lights) {
    // Caller holds mutex_ and has applied `apply` to validated_ already.
    uint64_t id = nextEdit_++;
    pending_.push_back(Pending{id, Clock::now(), std::move(apply), moves, lights, std::move(what)});
    if (!rebuild_) editWaiting_ = true;
    wake_.notify_all();
    return id;
}

uint64_t Session::Submit(const TransformEdit& edit) {
    std::lock_guard lock(mutex_);
    int node = FindNode(validated_, edit.node);
    if (node < 0)
        throw ServiceError(ErrorKind::kNotFound,
                           "no node '" + edit.node + "' in scene '" + name_ +
                               "'; movable nodes: " + NodeList(validated_, true));
    // Lights are always movable; geometry only when marked dynamic.
    const bool geometry = SubtreeHasPrimitives(validated_, node);
    const bool lights = SubtreeHasLights(validated_, node);
    if (geometry && !validated_.nodes[node].dynamic)
        throw ServiceError(ErrorKind::kStaticNode,
                           "node '" + edit.node +
                               "' is static; mark it extras.penumbra.dynamic in the glTF to move "
                               "it (movable nodes: " +
                               NodeList(validated_, true) + ")");
    try {
        SetNodeTransform(validated_, node, edit.local);
    } catch (const Error& e) {
        throw ServiceError(ErrorKind::kInvalidArgument, e.what());
    }
    glm::mat4 local = edit.local;
    std::string what = "moved " + edit.node;
    if (OutsideBounds(validated_, validated_.nodes[node])) what += " (outside its motion bounds)";
    return Queue([node, local](Scene& s) { SetNodeTransform(s, node, local); }, geometry, what,
                 lights);
}

uint64_t Session::Submit(const LightEdit& edit) {
    std::lock_guard lock(mutex_);
    if (int li = FindLight(validated_, edit.light); li >= 0) return SubmitPunctual(li, edit);
    if (std::find(lightNodes_.begin(), lightNodes_.end(), edit.light) == lightNodes_.end()) {
        std::string lights;
        for (const auto& l : validated_.lights) lights += (lights.empty() ? "" : ", ") + l.name;
        for (const auto& l : lightNodes_) lights += (lights.empty() ? "" : ", ") + l;
        throw ServiceError(ErrorKind::kNotFound, "no light '" + edit.light + "' in scene '" +
                                                     name_ +
                                                     "'; lights (punctual, then emissive nodes): " +
                                                     (lights.empty() ? "(none)" : lights));
    }
    if (edit.position || edit.direction || edit.innerCone || edit.outerCone || edit.range)
        throw ServiceError(ErrorKind::kInvalidArgument,
                           "'" + edit.light +
                               "' is an emissive surface: only its colour and intensity can "
                               "change (move its node with SetTransform)");
    if (edit.intensity && (!std::isfinite(*edit.intensity) || *edit.intensity < 0.0f))
        throw ServiceError(ErrorKind::kInvalidArgument,
                           "light intensity must be a finite number ≥ 0");
    if (edit.color && !FiniteNonNegative(*edit.color))
        throw ServiceError(ErrorKind::kInvalidArgument,
                           "light colour must be three finite numbers ≥ 0");
    int node = FindNode(validated_, edit.light);
    LightEdit e = edit;
    // The node's primitives that emitted when the scene was loaded: a lamp's housing stays
    // dark when its bulb is dimmed or brightened (and a bulb turned off can be turned on).
    const std::vector<uint32_t> emitting =
        lightPrimitives_[std::find(lightNodes_.begin(), lightNodes_.end(), edit.light) -
                         lightNodes_.begin()];
    // Emission = colour × intensity, where the current emission E splits into intensity
    // max(E) and colour E / max(E); an absent part keeps its current value.
    auto apply = [node, e, emitting](Scene& s) {
        OwnMaterials(s, node);
        std::vector<uint32_t> materials;
        for (uint32_t pi : emitting)
            if (std::find(materials.begin(), materials.end(), s.primitives[pi].material) ==
                materials.end())
                materials.push_back(s.primitives[pi].material);
        for (uint32_t m : materials) {
            glm::vec3& emission = s.materials[m].emission;
            float peak = std::max(emission.x, std::max(emission.y, emission.z));
            glm::vec3 color = peak > 0.0f ? emission / peak : glm::vec3(1.0f);
            if (e.color) color = *e.color;
            float intensity = e.intensity ? *e.intensity : peak;
            emission = color * intensity;
        }
    };
    apply(validated_);
    return Queue(apply, false, "light " + edit.light);
}

uint64_t Session::SubmitPunctual(int li, const LightEdit& edit) {
    // Caller holds mutex_. Check the light as it will be, then queue the change.
    auto invalid = [](const std::string& why) {
        return ServiceError(ErrorKind::kInvalidArgument, why);
    };
    if (edit.intensity && (!std::isfinite(*edit.intensity) || *edit.intensity < 0.0f))
        throw invalid("light intensity must be a finite number ≥ 0 (cd, or lux if directional)");
    if (edit.color && !FiniteNonNegative(*edit.color))
        throw invalid("light colour must be three finite numbers ≥ 0");
    if (edit.range && (!std::isfinite(*edit.range) || *edit.range < 0.0f))
        throw invalid("light range must be a finite number of metres ≥ 0 (0: infinite)");
    if (edit.position && !Finite(*edit.position))
        throw invalid("light position must be three finite numbers");
    if (edit.direction && (!Finite(*edit.direction) || !(glm::length(*edit.direction) > 1e-12f)))
        throw invalid("light direction must be a finite, non-zero vector");
    PunctualLight next = validated_.lights[li];
    if (edit.innerCone) next.innerCone = *edit.innerCone;
    if (edit.outerCone) next.outerCone = *edit.outerCone;
    if ((edit.innerCone || edit.outerCone) && next.type != LightType::kSpot)
        throw invalid("'" + edit.light + "' is not a spot light: it has no cone");
    if (!(next.innerCone >= 0.0f && next.innerCone < next.outerCone &&
          next.outerCone <= 1.5707964f))
        throw invalid("spot cone angles need 0 ≤ inner < outer ≤ π/2 radians");
    LightEdit e = edit;
    int node = validated_.lights[li].node;
    auto apply = [li, node, e](Scene& s) {
        PunctualLight& light = s.lights[li];
        if (e.color) light.color = *e.color;
        if (e.intensity) light.intensity = *e.intensity;
        if (e.range) light.range = *e.range;
        if (e.innerCone) light.innerCone = *e.innerCone;
        if (e.outerCone) light.outerCone = *e.outerCone;
        if (e.position || e.direction) {
            // The node's new world matrix: at the position, −Z turned onto the direction.
            glm::vec3 p = e.position ? *e.position : light.position;
            glm::vec3 d = glm::normalize(e.direction ? *e.direction : light.direction);
            glm::mat4 world = glm::translate(glm::mat4(1.0f), p) *
                              glm::mat4_cast(glm::rotation(glm::vec3(0, 0, -1), d));
            const SceneNode& n = s.nodes[node];
            glm::mat4 parent = n.parent >= 0 ? s.nodes[n.parent].world : glm::mat4(1.0f);
            SetNodeTransform(s, node, glm::inverse(parent) * world);
        }
    };
    try {
        apply(validated_);
    } catch (const Error& err) {
        throw invalid(err.what());
    }
    return Queue(apply, false, "light " + edit.light, true);
}

uint64_t Session::Submit(const MaterialEdit& edit) {
    std::lock_guard lock(mutex_);
    std::vector<uint32_t> matches;
    for (size_t i = 0; i < validated_.materials.size(); ++i)
        if (validated_.materials[i].name == edit.material ||
            validated_.materials[i].name.rfind(edit.material + "@", 0) == 0)
            matches.push_back(static_cast<uint32_t>(i));
    if (matches.empty()) {
        std::string names;
        for (const auto& m : validated_.materials) names += (names.empty() ? "" : ", ") + m.name;
        throw ServiceError(ErrorKind::kNotFound, "no material '" + edit.material + "' in scene '" +
                                                     name_ + "'; materials: " + names);
    }
    if (edit.albedo && (!FiniteNonNegative(*edit.albedo) ||
                        glm::any(glm::greaterThan(*edit.albedo, glm::vec3(1.0f)))))
        throw ServiceError(
            ErrorKind::kInvalidArgument,
            "albedo must be three numbers in [0, 1] (above 1 a surface creates light)");
    for (auto [value, name] : {std::pair{edit.roughness, "roughness"}, {edit.metallic, "metallic"}})
        if (value && !(*value >= 0.0f && *value <= 1.0f))
            throw ServiceError(ErrorKind::kInvalidArgument,
                               std::string(name) + " must be a number in [0, 1]");
    if (edit.emission && !FiniteNonNegative(*edit.emission))
        throw ServiceError(ErrorKind::kInvalidArgument,
                           "emission must be three finite numbers ≥ 0");
    MaterialEdit e = edit;
    auto apply = [matches, e](Scene& s) {
        for (uint32_t m : matches) {
            // `albedo` is the base colour; the diffuse albedo and any glossy lobe follow.
            if (e.albedo) s.materials[m].baseColor = *e.albedo;
            if (e.roughness) s.materials[m].roughness = *e.roughness;
            if (e.metallic) s.materials[m].metallic = *e.metallic;
            DeriveReflectance(s.materials[m]);
            if (e.emission) s.materials[m].emission = *e.emission;
        }
    };
    apply(validated_);
    return Queue(apply, false, "material " + edit.material);
}

uint64_t Session::Submit(const EnvironmentEdit& edit) {
    std::lock_guard lock(mutex_);
    if (edit.intensity && !(*edit.intensity >= 0.0f && std::isfinite(*edit.intensity)))
        throw ServiceError(ErrorKind::kInvalidArgument,
                           "environment intensity must be a finite number ≥ 0");
    if (edit.rotation && !std::isfinite(*edit.rotation))
        throw ServiceError(ErrorKind::kInvalidArgument, "environment rotation must be finite");
    Environment next = edit.replace ? *edit.replace : validated_.environment;
    if (edit.intensity) next.intensity = *edit.intensity;
    if (edit.rotation) next.rotation = *edit.rotation;
    try {
        ValidateEnvironment(next);
    } catch (const Error& e) {
        throw ServiceError(ErrorKind::kInvalidArgument, e.what());
    }
    // Back occlusion `auto` is decided when the links are built: a sky appearing or going
    // changes which surfaces occlude from both sides, so the links are rebuilt.
    const bool rebuild =
        BackOcclusionChanges(settings_.solver.backOcclusion, validated_.environment, next);
    auto apply = [next](Scene& s) { s.environment = next; };
    apply(validated_);
    std::string what = next.Active() ? "sky " + next.source : "sky off";
    return Queue(apply, rebuild, what, true);
}

// --- Frames ---------------------------------------------------------------------------------

int Session::AddSubscriber(FrameSink sink) {
    FramePtr first;
    int id;
    {
        std::lock_guard lock(mutex_);
        id = nextSubscriber_++;
        subscribers_[id] = sink;
        first = latest_;
        // The replayed frame counts as converged only if nothing is waiting to apply.
        if (first && first->converged && (!converged_ || !pending_.empty() || rebuild_)) {
            auto copy = std::make_shared<FrameData>(*first);
            copy->converged = false;
            first = copy;
        }
    }
    if (first) sink(first);
    return id;
}

void Session::RemoveSubscriber(int id) {
    std::lock_guard lock(mutex_);
    subscribers_.erase(id);
}

FramePtr Session::Latest() {
    std::unique_lock lock(mutex_);
    frameMade_.wait(lock, [&] { return latest_ || stop_; });
    if (!latest_) throw ServiceError(ErrorKind::kShuttingDown, "the session is closing");
    return latest_;
}

uint64_t Session::Step(int iterations) {
    if (iterations < 1 || iterations > 10000)
        throw ServiceError(ErrorKind::kInvalidArgument, "step needs 1 to 10000 iterations");
    std::future<uint64_t> done;
    {
        std::lock_guard lock(mutex_);
        if (stop_) throw ServiceError(ErrorKind::kShuttingDown, "the session is closing");
        std::promise<uint64_t> promise;
        done = promise.get_future();
        steps_.emplace_back(iterations, std::move(promise));
    }
    wake_.notify_all();
    return done.get();
}

Scene Session::SceneSnapshot() const {
    std::lock_guard lock(mutex_);
    return validated_;
}

SolverStats Session::SolverStatistics() const {
    std::lock_guard lock(mutex_);
    return solverStatsRaw_;
}

nlohmann::json Session::StatsJson() const {
    std::lock_guard lock(mutex_);
    nlohmann::json j;
    j["scene"] = name_;
    j["frames"] = frames_;
    j["edits"] = nextEdit_ - 1;
    j["last_applied_edit"] = appliedEdit_;
    j["pending_edits"] = pending_.size();
    j["link_rebuilds"] = rebuilds_;
    j["link_updates"] = linkUpdates_;
    j["rebuilding"] = rebuild_ != nullptr;
    j["subscribers"] = subscribers_.size();
    j["converged"] = converged_;
    if (!diverged_.empty()) j["diverged"] = diverged_;
    j["iterations_per_frame"] = settings_.iterationsPerFrame;
    j["build_seconds"] = buildSeconds_;
    if (!gatherNote_.empty()) j["gather_note"] = gatherNote_;
    // Frames in the last second: the rate while the scene changes, 0 while idle.
    auto now = Clock::now();
    size_t recent = 0;
    for (auto t : recentFrames_)
        if (now - t < std::chrono::seconds(1)) ++recent;
    j["fps"] = recent;
    j["last_frame_ms"] = latest_ ? latest_->frameMs : 0.0;
    j["solver"] = StatsToJson(solverStatsRaw_);
    if (!lastError_.empty()) j["last_error"] = lastError_;
    return j;
}

std::unique_ptr<Solver> Session::BuildSolver(const Scene& scene, bool motionLinks,
                                             const ProgressFn& progress,
                                             std::vector<std::string>* notes) const {
    SolverSettings settings = settings_.solver;
    settings.motionLinks = settings.motionLinks && motionLinks;
    GatherSettings gather;
    gather.emitterRays = settings_.emitterRays;
    gather.gatherRays = settings_.gatherRays;
    return CreateGatheredSolver(scene, settings, gather, progress, notes);
}

void Session::ProduceFrame(int iterations, std::string note, bool interruptible) {
    // Worker thread only, without mutex_: solver_ and applied_ belong to the worker.
    auto start = Clock::now();
    // An edit that comes in while this frame iterates cuts the bounce under way after its
    // current pass (Solver::SetInterrupt), is applied, and this frame goes out at once with
    // it: an edit waits for a pass, not for a bounce. The solver takes the bounce up again in
    // the next frame. A move that needs its links rebuilt waits for the frame boundary.
    bool edited = iterations == 0;  // this frame shows an edit that no iteration followed yet
    if (interruptible) solver_->SetInterrupt(&editWaiting_);
    for (int i = 0; i < iterations; ++i) {
        solver_->Iterate(1);
        if (interruptible && editWaiting_.load(std::memory_order_relaxed)) {
            std::unique_lock lock(mutex_);
            edited = ApplyEditsInPlace(lock, note);
            break;
        }
    }
    solver_->SetInterrupt(nullptr);
    // A diverged solver stops and keeps its last bounded irradiance (SurfelIrradiance):
    // this frame carries that and says why; no more frames are iterated.
    const std::string divergence = solver_->Stats().divergence;
    if (!divergence.empty())
        note += (note.empty() ? "" : "; ") + std::string("stopped: the solution ") + divergence +
                "; the last bounded irradiance is kept";
    std::vector<glm::vec3> surfels = solver_->SurfelIrradiance();
    const double change = RelativeChange(surfels, lastSurfels_);
    auto frame = std::make_shared<FrameData>();
    frame->scene = name_;
    frame->layout = layout_;
    frame->note = std::move(note);
    frame->irradiance.resize(applied_.primitives.size());
    for (size_t p = 0; p < applied_.primitives.size(); ++p)
        frame->irradiance[p] = PrimitiveIrradiance(solver_->GetSurfels(), surfels, applied_, p);
    if (!applied_.lights.empty()) {
        std::vector<glm::vec3> direct = solver_->SurfelIrradiance(Channel::kDirect);
        frame->direct.resize(applied_.primitives.size());
        for (size_t p = 0; p < applied_.primitives.size(); ++p)
            frame->direct[p] = PrimitiveIrradiance(solver_->GetSurfels(), direct, applied_, p);
    }
    SolverStats stats = solver_->Stats();
    passTotals_.resize(stats.passes.size(), 0.0);
    for (size_t i = 0; i < stats.passes.size(); ++i) {
        frame->passes.push_back({stats.passes[i].name, stats.passes[i].msTotal - passTotals_[i]});
        passTotals_[i] = stats.passes[i].msTotal;
    }
    frame->iterations = stats.iterations;
    lastSurfels_ = std::move(surfels);

    std::vector<FrameSink> sinks;
    {
        std::lock_guard lock(mutex_);
        frame->frame = ++frames_;
        frame->lastEdit = appliedEdit_;
        if (!latencyReported_) {
            frame->editLatencyMs = MsSince(appliedReceived_);
            latencyReported_ = true;
        }
        ++framesSinceEdit_;
        converged_ =
            divergence.empty() && !edited &&
            (change < settings_.convergedChange || framesSinceEdit_ >= settings_.maxFramesPerEdit);
        if (!divergence.empty() && diverged_.empty()) {
            diverged_ = divergence;
            lastError_ = "the solution " + divergence + "; iteration stopped";
        }
        frame->converged = converged_;
        frame->frameMs = MsSince(start);
        latest_ = frame;
        solverStatsRaw_ = stats;
        auto now = Clock::now();
        recentFrames_.push_back(now);
        while (recentFrames_.size() > 1 && now - recentFrames_.front() > std::chrono::seconds(1))
            recentFrames_.pop_front();
        for (const auto& [id, sink] : subscribers_) sinks.push_back(sink);
    }
    frameMade_.notify_all();
    for (const auto& sink : sinks) sink(frame);
}

std::string Session::WarmStart(Solver& rebuilt, const Scene& next) {
    // Surfels are numbered primitive by primitive: a primitive that did not move has the
    // same surfels, in the same order, in both solvers, and so has a dynamic node's that
    // moved (it is refined in its own space).
    return rebuilt.WarmStart(
        *solver_, CarrySurfels(applied_, solver_->GetSurfels(), next, rebuilt.GetSurfels()));
}

bool Session::ApplyEditsInPlace(std::unique_lock<std::mutex>& lock, std::string& note) {
    if (rebuild_ || pending_.empty()) return false;
    Scene next = applied_;
    bool lights = false, moves = false;
    std::string moved;
    for (auto& p : pending_) {
        p.apply(next);
        lights = lights || p.lights;
        if (p.moves) moves = true, moved += (moved.empty() ? "" : ", ") + p.what;
    }
    // Moves inside the motion bounds update the links in place (Sec. 3.3); others rebuild.
    if (moves) {
        rebuildReason_ = solver_->GeometryMismatch(next);
        if (!rebuildReason_.empty()) return false;
    }
    const uint64_t last = pending_.back().id;
    const auto received = pending_.back().received;
    pending_.clear();
    editWaiting_ = false;
    applied_ = std::move(next);
    lock.unlock();
    std::string failure, done;
    try {
        if (moves) {
            done = moved + ": " + solver_->UpdateGeometry(applied_);
        }
        solver_->UpdateMaterials(applied_);
        if (lights) solver_->UpdateLights(applied_);  // one shadow pass
    } catch (const std::exception& e) {
        failure = std::string(moves ? "update failed: " : "light update failed: ") + e.what();
    }
    lock.lock();
    if (!done.empty()) {
        if (moves) ++linkUpdates_;
        note += (note.empty() ? "" : "; ") + done;
    }
    if (!failure.empty()) {
        lastError_ = failure;
        note += (note.empty() ? "" : "; ") + failure;
    }
    appliedEdit_ = last;
    appliedReceived_ = received;
    latencyReported_ = false;
    converged_ = false;
    framesSinceEdit_ = 0;
    return true;
}

void Session::Run() {
    std::unique_lock lock(mutex_);
    while (true) {
        wake_.wait(lock, [&] {
            return stop_ || (rebuild_ && rebuild_->done) || (!rebuild_ && !pending_.empty()) ||
                   !steps_.empty() || (!converged_ && diverged_.empty());
        });
        if (stop_) return;
        std::string note;
        if (!gatherNoteSent_) note = gatherNote_, gatherNoteSent_ = true;  // the first frame

        // A finished link rebuild swaps in at this frame boundary.
        if (rebuild_ && rebuild_->done) {
            rebuild_->thread.join();
            if (rebuild_->result) {
                lock.unlock();
                std::string warm = WarmStart(*rebuild_->result, rebuild_->scene);
                lock.lock();
                solver_ = std::move(rebuild_->result);
                applied_ = std::move(rebuild_->scene);
                passTotals_.clear();
                lastSurfels_.clear();  // a new solver: its first frame is never "converged"
                diverged_.clear();
                ++rebuilds_;
                note = "links rebuilt: " + rebuild_->what + "; " + warm;
                if (!rebuild_->reason.empty()) note += " (" + rebuild_->reason + ")";
            } else {
                // The edits were valid but the device could not take them (memory, say):
                // report it and keep serving the scene as it was.
                note = "link rebuild failed (" + rebuild_->error + "); the edits up to " +
                       std::to_string(rebuild_->lastEdit) + " are not applied";
                validated_ = applied_;
                for (auto& p : pending_) p.apply(validated_);
            }
            appliedEdit_ = rebuild_->lastEdit;
            appliedReceived_ = rebuild_->received;
            latencyReported_ = false;
            converged_ = false;
            framesSinceEdit_ = 0;
            rebuild_.reset();
        }

        // Pending edits apply together, atomically, between two iterations (here, or inside
        // ProduceFrame); with a move among them, at this frame boundary, by rebuilding the
        // links on a thread. While links are being rebuilt later edits wait, so frames name
        // their edits in order.
        bool edited = false;  // edits applied here: the next frame goes out without iterating
        if (!rebuild_ && !pending_.empty() && !(edited = ApplyEditsInPlace(lock, note))) {
            Scene next = applied_;
            std::string what;
            for (auto& p : pending_) {
                p.apply(next);
                if (p.moves) what += (what.empty() ? "" : ", ") + p.what;
            }
            rebuild_ = std::make_unique<Rebuild>();
            rebuild_->scene = std::move(next);
            rebuild_->lastEdit = pending_.back().id;
            rebuild_->received = pending_.back().received;
            rebuild_->what = what;
            rebuild_->reason = rebuildReason_;
            rebuildReason_.clear();
            pending_.clear();
            editWaiting_ = false;
            Rebuild* r = rebuild_.get();
            // A scene whose motion links were over budget would be again: skip building them.
            const bool motionLinks = !motionDeclined_;
            r->thread = std::thread([this, r, motionLinks] {
                std::unique_ptr<Solver> built;
                std::string error;
                try {
                    built = BuildSolver(r->scene, motionLinks);
                } catch (const std::exception& e) {
                    error = e.what();
                }
                std::lock_guard guard(mutex_);
                r->result = std::move(built);
                r->error = error;
                r->done = true;
                wake_.notify_all();
            });
        }

        // A device failure stops this session's frames, not the server: it is reported in
        // stats and to the step that hit it, and the next edit tries again.
        auto produce = [&](int iterations, bool interruptible) -> std::exception_ptr {
            lock.unlock();
            std::exception_ptr failure;
            try {
                ProduceFrame(iterations, note, interruptible);
            } catch (const std::exception& e) {
                failure = std::current_exception();
                lock.lock();
                lastError_ = e.what();
                converged_ = true;
                return failure;
            }
            lock.lock();
            return failure;
        };
        if (!steps_.empty()) {
            auto [iterations, promise] = std::move(steps_.front());
            steps_.pop_front();
            if (auto failure = produce(iterations, false))
                promise.set_exception(failure);
            else
                promise.set_value(frames_);
        } else if (!converged_ && diverged_.empty()) {
            produce(edited ? 0 : settings_.iterationsPerFrame, true);
        }
    }
}

}  // namespace penumbra::service
