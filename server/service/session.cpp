// The shared scene session: the worker's frame loop, edits applied in place or by a
// rebuild, warm starts, frames to subscribers (edit validation: edits.cpp).
#include "service/session.h"

#include <malloc.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <memory>
#include <new>
#include <optional>
#include <system_error>

#include "base/check.h"
#include "base/numeric.h"
#include "gather/gather_stage.h"
#include "output/irradiance_writer.h"
#include "solvers/registry.h"

namespace penumbra::service {

namespace {

using Clock = std::chrono::steady_clock;

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

namespace {
uint64_t NextSessionId() {
    static std::atomic<uint64_t> next{1};
    return next.fetch_add(1, std::memory_order_relaxed);
}
}  // namespace

Session::Session(std::string name, Scene scene, SessionSettings settings,
                 const ProgressFn& progress, std::shared_ptr<Attention> attention, bool startWorker)
    : name_(std::move(name)),
      id_(NextSessionId()),
      settings_(std::move(settings)),
      attention_(std::move(attention)) {
    CheckSessionSettings(settings_);
    auto start = Clock::now();
    std::vector<std::string> notes;
    solver_ = BuildSolver(scene, true, progress, &notes);
    for (const std::string& n : notes) gatherNote_ += (gatherNote_.empty() ? "" : "; ") + n;
    buildSeconds_ = MsSince(start) / 1000.0;
    solverStatsRaw_ = solver_->Stats();
    motionDeclined_ = !solverStatsRaw_.motion.declined.empty();
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
    const float reach = kMoveReach * std::max(scene.Diameter(), 1e-3f);
    reachLo_ = scene.BoundsMin() - reach;
    reachHi_ = scene.BoundsMax() + reach;
    validated_ = scene;
    applied_ = std::move(scene);
    if (startWorker) Start();
}

void Session::Start() {
    if (!worker_.joinable()) worker_ = std::thread([this] { Run(); });
}

Session::ReturnFreedMemory::~ReturnFreedMemory() {
#ifdef __GLIBC__
    malloc_trim(0);
#endif
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
    busy_ = false;
    Recount();
    for (auto& [n, promise] : steps_)
        promise.set_exception(std::make_exception_ptr(
            ServiceError(ErrorKind::kShuttingDown, "the session closed before the step ran")));
}

// --- Frames ---------------------------------------------------------------------------------

int Session::AddSubscriber(FrameSink sink) {
    FramePtr first;
    int id;
    {
        std::lock_guard lock(mutex_);
        id = nextSubscriber_++;
        subscribers_[id] = sink;
        Recount();
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
    Recount();
}

void Session::SetHeld(bool held) {
    {
        std::lock_guard lock(mutex_);
        held_ = held;
        Recount();
    }
    wake_.notify_all();  // a yielding worker comes to the foreground at once
}

void Session::Recount() {
    const bool counts = busy_ && !Background();
    if (counts != counted_ && attention_) attention_->Busy(counts ? 1 : -1);
    counted_ = counts;
}

size_t Session::SubscriberCount() const {
    std::lock_guard lock(mutex_);
    return subscribers_.size();
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

void LatencyHistogram::Observe(double seconds) {
    size_t bucket = 0;
    while (bucket < kBounds.size() && seconds > kBounds[bucket]) ++bucket;
    ++counts[bucket];
    sumSeconds += seconds;
    ++count;
}

nlohmann::json LatencyHistogram::Json() const {
    nlohmann::json cumulative = nlohmann::json::array();
    uint64_t total = 0;
    for (size_t i = 0; i < kBounds.size(); ++i) cumulative.push_back(total += counts[i]);
    return {{"le", kBounds}, {"cumulative", cumulative}, {"sum", sumSeconds}, {"count", count}};
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
    j["device_fallbacks"] = deviceFallbacks_;
    j["rebuilding"] = rebuild_ != nullptr;
    j["subscribers"] = subscribers_.size();
    j["converged"] = converged_ && pending_.empty() && !rebuild_;
    if (!diverged_.empty()) j["diverged"] = diverged_;
    if (!solverFallback_.empty()) j["solver_fallback"] = solverFallback_;
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
    j["edit_to_frame_seconds"] = editLatency_.Json();
    j["frame_seconds"] = frameTime_.Json();
    j["solver"] = StatsToJson(solverStatsRaw_);
    if (!lastError_.empty()) j["last_error"] = lastError_;
    return j;
}

std::unique_ptr<Solver> Session::BuildSolver(const Scene& scene, bool prepareMoves,
                                             const ProgressFn& progress,
                                             std::vector<std::string>* notes) const {
    SolverSettings settings = fellBack_ ? fallback_ : settings_.solver;
    settings.prepareMoves = settings.prepareMoves && prepareMoves;
    if (onCpu_) settings.device = DeviceChoice::kCpu;
    GatherSettings gather;
    gather.emitterRays = settings_.emitterRays;
    gather.gatherRays = settings_.gatherRays;
    // A moved emitter's first shot goes out in parts over the frames that follow its move.
    gather.shotPartMs = kShotPartMs;
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
    frame->session = id_;
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
    if (!stats.catchingUp.empty())
        frame->note += (frame->note.empty() ? "" : "; ") + stats.catchingUp;
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
        for (const auto& received : unreported_) editLatency_.Observe(MsSince(received) / 1e3);
        unreported_.clear();
        ++framesSinceEdit_;
        settled_ =
            divergence.empty() && !edited && stats.catchingUp.empty() &&
            (change < settings_.convergedChange || framesSinceEdit_ >= settings_.maxFramesPerEdit);
        // The frame contract (protocol/SPEC.md): converged only with every edit acknowledged
        // before it applied, none waiting in the queue or in a rebuild.
        converged_ = settled_ && pending_.empty() && !rebuild_;
        if (!divergence.empty() && diverged_.empty()) {
            diverged_ = divergence;
            lastError_ = "the solution " + divergence + "; iteration stopped";
        }
        frame->converged = converged_;
        frame->frameMs = MsSince(start);
        frameTime_.Observe(frame->frameMs / 1e3);
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
    for (const auto& p : pending_) unreported_.push_back(p.received);
    pending_.clear();
    editWaiting_ = false;
    applied_ = std::move(next);
    lock.unlock();
    std::string failure, done, lost;
    try {
        if (moves) {
            done = moved + ": " + solver_->UpdateGeometry(applied_);
        }
        solver_->UpdateMaterials(applied_);
        if (lights) solver_->UpdateLights(applied_);  // one shadow pass
    } catch (const DeviceLost& e) {
        lost = e.what();
    } catch (const std::exception& e) {
        failure = std::string(moves ? "update failed: " : "light update failed: ") + e.what();
    }
    lock.lock();
    if (!lost.empty()) deviceLost_ = lost;  // the edits are in applied_: the CPU takes them
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
    converged_ = settled_ = false;
    framesSinceEdit_ = 0;
    return true;
}

void Session::Run() {
    std::unique_lock lock(mutex_);
    const auto work = [&] {
        return stop_ || (rebuild_ && rebuild_->done) || (!rebuild_ && !pending_.empty()) ||
               !steps_.empty() || (!settled_ && diverged_.empty()) ||
               (!diverged_.empty() && !rebuild_ && !fallbackTried_);
    };
    while (true) {
        if (!work()) {
            busy_ = false;
            Recount();
            wake_.wait(lock, work);
        }
        if (stop_) return;
        busy_ = true;
        Recount();
        // In the background (Attention), a session that only has its convergence to work on
        // waits while a foreground one has frames to make. Edits, steps and finished
        // rebuilds are someone's request: they never wait.
        if (Background() && attention_ && attention_->ForegroundBusy() && pending_.empty() &&
            steps_.empty() && !(rebuild_ && rebuild_->done)) {
            wake_.wait_for(lock, std::chrono::milliseconds(50));
            continue;
        }
        std::string note;
        if (!gatherNoteSent_) note = gatherNote_, gatherNoteSent_ = true;  // the first frame

        // A finished link rebuild swaps in at this frame boundary.
        if (rebuild_ && rebuild_->done) {
            if (rebuild_->thread.joinable()) rebuild_->thread.join();
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
            } else if (rebuild_->deviceLost) {
                // The edits stand: the CPU back end builds them (FallBackToCpu, below).
                applied_ = std::move(rebuild_->scene);
                deviceLost_ = rebuild_->error;
            } else {
                // The edits were valid but the device could not take them (memory, say):
                // report it and keep serving the scene as it was.
                note = "link rebuild failed (" + rebuild_->error + "); the edits up to " +
                       std::to_string(rebuild_->lastEdit) + " are not applied";
                lastError_ = note;
                validated_ = applied_;
                for (auto& p : pending_) p.apply(validated_);
            }
            appliedEdit_ = rebuild_->lastEdit;
            appliedReceived_ = rebuild_->received;
            unreported_.insert(unreported_.end(), rebuild_->receivedEach.begin(),
                               rebuild_->receivedEach.end());
            latencyReported_ = false;
            converged_ = settled_ = false;
            framesSinceEdit_ = 0;
            rebuild_.reset();
        }
        // A lost device (an edit's update or a rebuild met it): the CPU back end from here,
        // before any edit reaches the lost solver.
        if (!deviceLost_.empty()) FallBackToCpu(lock, note);
        // A diverged solution: the fallback solver from here (once; a rebuild under way
        // brings a new solver of its own first).
        if (!diverged_.empty() && !rebuild_ && !fallbackTried_) FallBackToAnotherSolver(lock, note);

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
            for (const auto& p : pending_) rebuild_->receivedEach.push_back(p.received);
            rebuild_->what = what;
            rebuild_->reason = rebuildReason_;
            rebuildReason_.clear();
            pending_.clear();
            editWaiting_ = false;
            Rebuild* r = rebuild_.get();
            // A scene whose motion links were over budget would be again: skip building them.
            const bool prepareMoves = !motionDeclined_;
            auto build = [this, r, prepareMoves] {
                std::unique_ptr<Solver> built;
                std::string error;
                bool lost = false;
                try {
                    built = BuildSolver(r->scene, prepareMoves);
                } catch (const DeviceLost& e) {
                    error = e.what();
                    lost = true;
                } catch (const std::bad_alloc&) {
                    error = "out of memory while building the new links";
                } catch (const std::exception& e) {
                    error = e.what();
                }
                std::lock_guard guard(mutex_);
                r->result = std::move(built);
                r->error = error;
                r->deviceLost = lost;
                r->done = true;
                wake_.notify_all();
            };
            try {
                r->thread = std::thread(build);
            } catch (const std::system_error& e) {  // no memory for its stack, say
                r->error = std::string("cannot start the rebuild: ") + e.what();
                r->done = true;
            }
        }

        // A device failure stops this session's frames, not the server: it is reported in
        // stats and to the step that hit it, and the next edit tries again. A lost device is
        // left for the CPU back end, and the frame made again there.
        auto produce = [&](int iterations, bool interruptible) -> std::exception_ptr {
            for (bool retried = false;; retried = true) {
                lock.unlock();
                try {
                    ProduceFrame(iterations, note, interruptible);
                    lock.lock();
                    return nullptr;
                } catch (const std::exception& e) {
                    lock.lock();
                    if (!retried && dynamic_cast<const DeviceLost*>(&e)) {
                        deviceLost_ = e.what();
                        if (FallBackToCpu(lock, note)) continue;
                    }
                    lastError_ = e.what();
                    converged_ = settled_ = true;
                    return std::current_exception();
                }
            }
        };
        if (!steps_.empty()) {
            auto [iterations, promise] = std::move(steps_.front());
            steps_.pop_front();
            if (auto failure = produce(iterations, false))
                promise.set_exception(failure);
            else
                promise.set_value(frames_);
        } else if (!settled_ && diverged_.empty()) {
            produce(edited ? 0 : settings_.iterationsPerFrame, true);
        }
    }
}

}  // namespace penumbra::service
