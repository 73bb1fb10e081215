// One loaded scene shared by every client (protocol/SPEC.md, Session): the solver on
// its device, a worker thread that applies edits atomically between frames, produces frames
// while the scene changes and idles once it has converged.
#pragma once

#include <array>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <future>
#include <glm/glm.hpp>
#include <map>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "scene/scene.h"
#include "solver/solver.h"

namespace penumbra::service {

// Errors a request can earn; the net layer maps them to protocol error codes.
enum class ErrorKind {
    kInvalidArgument,
    kNotFound,
    kNoScene,
    kOutsideRoot,
    kLoadFailed,
    kStaticNode,
    kUnsupported,
    kLimitReached,
    kShuttingDown,
    kForbidden
};

class ServiceError : public std::runtime_error {
  public:
    ServiceError(ErrorKind kind, const std::string& message)
        : std::runtime_error(message), kind_(kind) {}
    ErrorKind kind() const { return kind_; }

  private:
    ErrorKind kind_;
};

using penumbra::Channel;

struct SessionSettings {
    SolverSettings solver;
    int iterationsPerFrame = 1;  // bounces (Solver::Iterate) per streamed frame
    // The gather stage (gather/gather_stage.h): shadow rays per surfel for the emitters'
    // direct light, the solver's first shot (0: the solver carries the emission itself), and
    // final gather rays per input vertex (0: the solver's own answer). On by default, as in
    // bake: light, material and sky edits re-read cached rays, a move re-traces the rays
    // near what moved.
    int emitterRays = 256;
    int gatherRays = 256;
    // The scene counts as converged (and the worker idles) when a frame changes the
    // irradiance by less than this fraction: Σ|ΔE| / Σ|E| over all surfels.
    double convergedChange = 1e-3;
    // Frames after the last edit at most, even if the change never falls below the bound.
    int maxFramesPerEdit = 400;
};

inline constexpr int kMaxIterationsPerFrame = 64;
// A moved emitter's first shot is traced again in parts of about this many milliseconds, one a
// frame (GatherSettings::shotPartMs): the office's whole shot takes ~0.3 s on 2 cores.
inline constexpr double kShotPartMs = 30.0;

// Throws penumbra::Error naming what is wrong with `settings`: iterations per frame
// (1…kMaxIterationsPerFrame), the converged change (≥ 0), the gather's rays
// (CheckGatherRays), the element size (≥ 0, finite). The solver's own options are
// CheckSolverSettings' (solvers/registry.h).
void CheckSessionSettings(const SessionSettings& settings);

// Durations counted in fixed buckets, the shape of a Prometheus histogram (net/metrics.cpp):
// how long edits took to reach a frame, and how long frames took to make.
struct LatencyHistogram {
    // Upper bounds in seconds; one bucket more holds what is over the last.
    static constexpr std::array<double, 12> kBounds{0.005, 0.01, 0.025, 0.05, 0.1,  0.25,
                                                    0.5,   1.0,  2.5,   5.0,  10.0, 30.0};
    std::array<uint64_t, kBounds.size() + 1> counts{};
    double sumSeconds = 0.0;
    uint64_t count = 0;

    void Observe(double seconds);
    // {"le": bounds, "cumulative": counts at or under each bound, "sum": s, "count": n}.
    nlohmann::json Json() const;
};

// Which sessions have frames to make that someone is waiting for. A session that no
// connection holds and nobody subscribes to (its loader has gone) is in the background: it
// still converges, but only while no foreground session has frames to make, so that scenes
// left behind by clients that went away do not slow the frames of those still connected.
class Attention {
  public:
    // A foreground session starts (+1) or stops (-1) having frames to make.
    void Busy(int delta) { busy_.fetch_add(delta, std::memory_order_relaxed); }
    bool ForegroundBusy() const { return busy_.load(std::memory_order_relaxed) > 0; }

  private:
    std::atomic<int> busy_{0};
};

// Which glTF primitive an irradiance array belongs to.
struct PrimitiveKey {
    std::string node;
    int mesh = -1, primitive = -1;
};

// One frame as the session produced it; shared (read-only) by every subscriber.
struct FrameData {
    std::string scene;
    // The session that made it: unique in the process, so a scene reloaded under the same
    // name (whose frames are numbered from 1 again) never passes for the one it replaced.
    uint64_t session = 0;
    uint64_t frame = 0;
    uint64_t lastEdit = 0;
    uint64_t iterations = 0;
    double frameMs = 0.0;
    double editLatencyMs = 0.0;
    bool converged = false;
    std::vector<PassTiming> passes;  // device ms of each pass in this frame
    std::string note;
    // `indirect` irradiance per scene primitive, in the primitive's input vertex order.
    std::vector<std::vector<glm::vec3>> irradiance;
    // `direct` (punctual lights, shadowed) the same way; empty when the scene has none.
    std::vector<std::vector<glm::vec3>> direct;
    std::shared_ptr<const std::vector<PrimitiveKey>> layout;  // one key per primitive

    // Primitive p's irradiance in `channel`, one RGB per input vertex: `total` is their sum,
    // made here into `scratch`; null where it is all zero (`direct` without punctual lights).
    const glm::vec3* Values(size_t p, Channel channel, std::vector<glm::vec3>& scratch) const;
};
using FramePtr = std::shared_ptr<const FrameData>;

// Edits, validated on submission and applied by the worker between frames.
// How far past the loaded scene's bounds a move may take geometry, in scene diameters.
inline constexpr float kMoveReach = 10.0f;

struct TransformEdit {
    std::string node;
    glm::mat4 local{1.0f};
};
// A deformation of a dynamic node's mesh: its vertices in its own space (and normals, or
// none: computed), scene/scene.h SetNodeVertices, or its morph target weights.
struct DeformEdit {
    std::string node;
    std::vector<glm::vec3> positions, normals;
    std::optional<std::vector<float>> weights;
};
struct LightEdit {
    std::string light;  // a punctual light (its or its node's name) or an emissive node
    std::optional<glm::vec3> color;
    std::optional<float> intensity;
    // Punctual lights only: world-space placement, spot cone (radians), range (metres).
    std::optional<glm::vec3> position, direction;
    std::optional<float> innerCone, outerCone, range;
};
struct MaterialEdit {
    std::string material;
    std::optional<glm::vec3> albedo;  // glTF base colour
    std::optional<glm::vec3> emission;
    std::optional<float> roughness, metallic;  // glTF factors, [0, 1]
};

// The sky: `replace` it (with an Environment made by Service::MakeEnvironment, or an
// inactive one for none), then scale and turn it when given.
struct EnvironmentEdit {
    std::optional<Environment> replace;
    std::optional<float> intensity;
    std::optional<float> rotation;  // radians about +Y
    // The scene's sun (its light called "sun") moved to azimuth°, elevation° and, when given,
    // `sunIlluminance` lux; a clear sky follows it (a new one for its turbidity).
    std::optional<glm::vec2> sun;
    std::optional<float> sunIlluminance;
    // A new clear sky for the sun (where it is, or `sun`), of `turbidity` (or the current
    // clear sky's, else 3).
    bool clearSky = false;
    std::optional<float> turbidity;
};

class Session {
  public:
    // Builds the solver (seconds on large scenes) and starts the worker. Throws
    // penumbra::Error for bad settings or an unusable device.
    // `attention`, shared by a service's sessions, orders their work (Attention); without
    // it the session never yields. `start` false: no frames until Start (the worker thread
    // is then the caller's child, with its priority, not the builder's).
    Session(std::string name, Scene scene, SessionSettings settings,
            const ProgressFn& progress = {}, std::shared_ptr<Attention> attention = nullptr,
            bool start = true);
    void Start();  // starts the worker, if not yet started
    ~Session();    // stops the worker; subscribers get no further frames

    const std::string& Name() const { return name_; }
    const SessionSettings& Settings() const { return settings_; }

    // Validates the edit against the scene as it will be once earlier edits apply and
    // queues it; returns its edit id. Throws ServiceError (unknown node, static node,
    // NaN or singular matrix, negative intensity...).
    uint64_t Submit(const TransformEdit& edit);
    // A deformation: taken in place by a solver that relinks every frame (implicit), by a
    // re-trace near it (light field), else by a rebuild, like a move out of its bounds.
    uint64_t Submit(const DeformEdit& edit);
    uint64_t Submit(const LightEdit& edit);
    uint64_t Submit(const MaterialEdit& edit);
    // A sky change re-bins the environment between iterations; one that gives a scene loaded
    // without a sky its first (or takes its only one away) also rebuilds the links, since
    // back occlusion (`auto`) follows whether there is a sky, as a move does.
    uint64_t Submit(const EnvironmentEdit& edit);

    using FrameSink = std::function<void(const FramePtr&)>;
    // Every later frame goes to `sink` (on the worker thread: keep it short). The newest
    // frame so far, if any, is delivered at once so a watcher starts with a picture.
    int AddSubscriber(FrameSink sink);
    void RemoveSubscriber(int id);
    size_t SubscriberCount() const;
    // Whether a connection holds the scene (Service::Hold; true until the service says
    // otherwise). Unheld and unsubscribed, the session is in the background (Attention).
    void SetHeld(bool held);

    // The newest frame, waiting for the first one if none exists yet.
    FramePtr Latest();
    // Runs `iterations` more solver iterations now (even when converged), as one frame;
    // returns that frame's number once it exists.
    uint64_t Step(int iterations);

    // Scene as of the newest applied edits (copy, for SceneInfo replies).
    Scene SceneSnapshot() const;
    SolverStats SolverStatistics() const;
    nlohmann::json StatsJson() const;
    double BuildSeconds() const { return buildSeconds_; }
    // KHR_lights_punctual lights in the scene.
    int PunctualLights() const { return punctualLights_; }

  private:
    struct Pending {
        uint64_t id;
        std::chrono::steady_clock::time_point received;
        std::function<void(Scene&)> apply;  // changes the working scene
        bool moves = false;                 // geometry changed: links must be rebuilt
        bool lights = false;                // punctual lights changed: a shadow pass
        std::string what;                   // for the frame note
    };
    // Links rebuilt on a thread of their own while the old solver keeps producing frames.
    struct Rebuild {
        std::thread thread;
        Scene scene;
        uint64_t lastEdit = 0;
        std::chrono::steady_clock::time_point received;
        std::vector<std::chrono::steady_clock::time_point> receivedEach;  // every edit's
        std::string what;
        std::string reason;  // why the move could not update the links in place
        bool done = false;   // set by the thread, under mutex_
        std::unique_ptr<Solver> result;
        std::string error;
        bool deviceLost = false;  // the error was the device's loss
    };

    uint64_t Queue(std::function<void(Scene&)> apply, bool moves, std::string what,
                   bool lights = false);
    uint64_t SubmitPunctual(int light, const LightEdit& edit);
    void Run();
    // `iterations` bounces, then the frame (0: the frame of an edit just applied, at once).
    // `interruptible`: an edit that arrives during the frame cuts the bounce under way after
    // the current pass (Solver::SetInterrupt); edits that apply in place (materials, lights,
    // sky, moves inside their bounds) are applied and the frame goes out at once with them;
    // a move that rebuilds links ends the frame there (the rebuild starts at the boundary).
    // An edit thus waits for one pass, not for the rest of a bounce.
    void ProduceFrame(int iterations, std::string note, bool interruptible);
    // Applies the pending edits to the solver when none of them moves geometry. Called with
    // `lock` held (released around the solver update); returns false, applying nothing, when
    // an edit needs a link rebuild or one is running. A failed update is put in `note`.
    bool ApplyEditsInPlace(std::unique_lock<std::mutex>& lock, std::string& note);
    // The session's solver for `scene`: motion links where the settings ask for them and
    // `prepareMoves` allows (false: the usual links), behind the gather stage where the
    // settings ask for it and the scene allows (`notes`, when given, gets why a part of it
    // was declined or changed: CreateGatheredSolver).
    std::unique_ptr<Solver> BuildSolver(const Scene& scene, bool prepareMoves,
                                        const ProgressFn& progress = {},
                                        std::vector<std::string>* notes = nullptr) const;
    // Starts `rebuilt` (built for `next`) from the current solver's solution on the surfels
    // that did not move; returns what it did, for the frame note.
    std::string WarmStart(Solver& rebuilt, const Scene& next);
    // After a DeviceLost (deviceLost_ says why): the solver rebuilt for applied_ on the CPU
    // back end, which later builds use too; the note says so. False when that is not
    // possible (already on the CPU, or the CPU build failed): the session stops its frames
    // and reports why, as for any device failure. Worker thread, `lock` held (released while
    // building).
    bool FallBackToCpu(std::unique_lock<std::mutex>& lock, std::string& note);
    // Builds the solver for applied_ again (BuildSolver, with `lock` released meanwhile) and
    // swaps it in for the current one, which is destroyed outside the lock; the frame state
    // starts again. False, the current solver kept, when the build failed (`error` says
    // why); `seconds` the build's time either way. Worker thread, `lock` held.
    bool SwapInRebuilt(std::unique_lock<std::mutex>& lock, std::string& error, double& seconds);
    // After a divergence (diverged_ says where) with no rebuild under way: the solver rebuilt
    // for applied_ as the fallback solver (FallbackSettings: the light-field solver), which
    // later builds use too; the note and stats (`solver_fallback`) say so. False when there is
    // none to go on with (the session's solver is the fallback) or its build failed: the
    // session stops its frames, as before. Worker thread, `lock` held (released while
    // building).
    bool FallBackToAnotherSolver(std::unique_lock<std::mutex>& lock, std::string& note);

    // Declared first, so destroyed last: once the solver and its tables are freed, the heap's
    // free pages go back to the system (glibc keeps them otherwise, in its per-thread arenas,
    // and a server whose scenes come and go would never shrink).
    struct ReturnFreedMemory {
        ~ReturnFreedMemory();
    } returnFreedMemory_;
    const std::string name_;
    const uint64_t id_;  // FrameData::session
    // Where a move may take geometry: the loaded scene's bounds grown by kMoveReach of its
    // diameter on every side (a 1e38 translation or a 1e6 scale is refused, not rebuilt).
    glm::vec3 reachLo_{0.0f}, reachHi_{0.0f};
    const SessionSettings settings_;
    double buildSeconds_ = 0.0;
    int punctualLights_ = 0;

    mutable std::mutex mutex_;  // guards everything below
    std::condition_variable wake_;
    std::condition_variable frameMade_;
    bool stop_ = false;
    Scene validated_;  // the scene with every submitted edit applied (for validation)
    Scene applied_;    // the scene the solver has (edits up to appliedEdit_)
    std::unique_ptr<Solver> solver_;
    std::unique_ptr<Rebuild> rebuild_;
    std::deque<Pending> pending_;
    std::deque<std::pair<int, std::promise<uint64_t>>> steps_;
    uint64_t nextEdit_ = 1;
    uint64_t appliedEdit_ = 0;
    std::chrono::steady_clock::time_point appliedReceived_{};
    bool latencyReported_ = true;
    // When each edit applied since the last frame was acknowledged: the next frame observes
    // their latencies in editLatency_. frameTime_ observes every frame's time.
    std::vector<std::chrono::steady_clock::time_point> unreported_;
    LatencyHistogram editLatency_, frameTime_;
    std::map<int, FrameSink> subscribers_;
    int nextSubscriber_ = 1;
    FramePtr latest_;
    // settled_: the solver's answer stopped changing (or the frame cap for an edit was met),
    // so no frame is iterated until something changes; converged_: settled with every
    // acknowledged edit applied (what frames and stats say).
    bool converged_ = false, settled_ = false;
    int framesSinceEdit_ = 0;
    std::vector<glm::vec3> lastSurfels_;
    uint64_t frames_ = 0, rebuilds_ = 0, linkUpdates_ = 0;
    int deviceFallbacks_ = 0;    // FallBackToCpu done (0 or 1)
    std::string rebuildReason_;  // Solver::GeometryMismatch of the moves about to rebuild
    // The first build found motion links over budget: rebuilds build the usual links only.
    bool motionDeclined_ = false;
    std::deque<std::chrono::steady_clock::time_point> recentFrames_;  // for fps
    std::vector<double> passTotals_;                                  // ms, as of last frame
    std::shared_ptr<const std::vector<PrimitiveKey>> layout_;
    // Why the gather stage (or part of it) is off for this scene, said in the first frame's
    // note and in stats (`gather_note`); empty when it runs as asked.
    std::string gatherNote_;
    bool gatherNoteSent_ = false;
    std::vector<std::string> lightNodes_;                 // nodes that emitted light when loaded
    std::vector<std::vector<uint32_t>> lightPrimitives_;  // per light node: its emitting ones
    SolverStats solverStatsRaw_;
    std::string lastError_;
    // The solver's SolverStats::divergence once it stopped: no more iterations until a rebuild
    // brings a new solver; frames keep the last bounded irradiance.
    std::string diverged_;
    // FallBackToAnotherSolver tried (once a session); `fallback_` the settings every build
    // uses from then on when `fellBack_`, `solverFallback_` why (stats). Written by the worker
    // only while no rebuild thread runs, which reads them in BuildSolver.
    bool fallbackTried_ = false, fellBack_ = false;
    SolverSettings fallback_;
    std::string solverFallback_;
    // Why the device was lost, until FallBackToCpu has taken it (empty: it was not).
    std::string deviceLost_;
    // Set by FallBackToCpu: every build from then on is on the CPU back end.
    std::atomic<bool> onCpu_{false};
    std::atomic<bool> editWaiting_{false};  // an edit is queued and no rebuild runs
    // Attention: held_ by a connection (SetHeld); busy_, the worker has frames to make;
    // counted_, counted busy in attention_ (busy_ and in the foreground).
    const std::shared_ptr<Attention> attention_;
    bool held_ = true, busy_ = false, counted_ = false;
    bool Background() const { return !held_ && subscribers_.empty(); }
    void Recount();  // counted_ brought in line with busy_ and Background(); mutex_ held
    std::thread worker_;
};

}  // namespace penumbra::service
