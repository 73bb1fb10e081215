// The lighting service: loaded scene sessions by name, scene loading confined to the scene
// root, and the limits a server enforces. Thread-safe; knows nothing of sockets.
#pragma once

#include <atomic>
#include <chrono>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "service/session.h"

namespace penumbra::service {

struct ServiceLimits {
    size_t maxScenes = 4;  // sessions loaded at once
    // A scene no connection holds (Service::Hold) and nobody watches is dropped once it has
    // been so for this many seconds (Service::DropIdle); 0: kept until --max-scenes needs room.
    double sceneIdleSeconds = 0.0;
    // Scenes one connection may own (build, not join) at once: no client can take every
    // slot of maxScenes and keep them.
    size_t maxScenesPerClient = 2;
    size_t maxSceneTriangles = 2'000'000;
    uint64_t maxSceneBytes = uint64_t(1) << 30;  // the buffers a scene file declares
    size_t maxUploadBytes = 64u << 20;           // an uploaded .glb
};

// What a connection may do (protocol/SPEC.md, "Roles"). A server without --token-file gives
// every client kUser; a token file gives each of its tokens a role. Every role may join
// scenes, subscribe and read; beyond that:
//   viewer  nothing more;
//   user    loads scenes (which it then owns), edits, reloads and unloads the scenes it owns
//           and those whose owner has gone (or that no connection built);
//   editor  a user that also edits and reloads scenes other clients own;
//   admin   an editor that also unloads them, and owns scenes beyond --max-scenes-per-client.
enum class Role { kViewer, kUser, kEditor, kAdmin };
const char* RoleName(Role role);
// "viewer", "editor", "admin" (the roles a token file names); nullopt for anything else.
std::optional<Role> RoleNamed(const std::string& name);

// What a request would do to a scene, for Service::CheckMay.
enum class Change { kEdit, kReload, kUnload };

struct LoadRequest {
    std::string path;          // relative to the scene root
    std::vector<uint8_t> glb;  // or an uploaded .glb
    std::string name;          // session name for an upload
    SessionSettings settings;
    bool reload = false;
    // The environment: a sky file under the scene root, or a constant colour, or neither.
    std::string environmentPath;
    bool hasEnvironmentColor = false;
    glm::vec3 environmentColor{0.0f};
    float environmentIntensity = 1.0f;
    float environmentRotation = 0.0f;  // radians
    // A sun (azimuth°, elevation°, lux: scene/sun_sky.h AddSun), and a clear sky for it.
    std::optional<glm::vec3> sun;
    bool clearSky = false;
    float turbidity = 3.0f;
    // Refined output (scene/refine_output.h): the longest edge after subdivision, metres;
    // 0: the file's vertices.
    float refine = 0.0f;
    // Told how the build goes (stage, fraction of it), from the loading thread; may be empty.
    ProgressFn progress;
    // The connection asking (Service::Own), 0 in-process, and its role: a reload of a scene
    // another connected client owns is refused unless the role allows it (CheckMay).
    uint64_t by = 0;
    Role role = Role::kUser;
};

struct LoadResult {
    std::shared_ptr<Session> session;
    bool reused = false;
    // Scenes dropped to make room (no connection held them and nobody watched them).
    std::vector<std::string> evicted;
    // A reload: the scene's earlier session was replaced by `session` (its subscribers are
    // to be moved over: net::Server::SceneReplaced).
    bool replaced = false;
};

// The solver settings a service starts from: the library's defaults, with dynamic nodes
// prepared to move in place (SolverSettings::prepareMoves; for the antiradiance, links built
// for their motion bounds, updated in place instead of rebuilt), unless that would more than
// double the scene's links (then moves rebuild). Options here apply to the solvers that
// declare them (Service::DefaultsFor).
inline SolverSettings ServiceDefaults() {
    SolverSettings s;
    s.prepareMoves = true;
    // At most as many links for the dynamic nodes as for the rest.
    s.options["motion-link-budget"] = "1";
    return s;
}

class Service {
  public:
    Service(std::filesystem::path sceneRoot, ServiceLimits limits,
            SolverSettings defaults = ServiceDefaults());
    ~Service();

    // Loads (or joins) the scene's session. Blocks while the solver builds. At --max-scenes,
    // the scenes loaded longest ago that no connection holds (Hold) and nobody subscribes to
    // are dropped to make room; only when every one is held is the load refused. Throws
    // ServiceError: kOutsideRoot, kLoadFailed, kLimitReached, kInvalidArgument.
    LoadResult Load(const LoadRequest& request);
    // Connection `holder` loaded or joined scene `name` and is still there; Release when it
    // goes (every scene it held).
    void Hold(const std::string& name, uint64_t holder);
    // Connection `owner` built scene `name` (its load was no join): it owns the scene until
    // it goes (Release) or the scene does, unless another connected client owns it already
    // (a reload by an editor keeps the owner).
    void Own(const std::string& name, uint64_t owner);
    void Release(uint64_t holder);
    // Drops scene `name` ("": the newest) for connection `by` of role `role`, if CheckMay
    // allows. Returns the session, for the caller to tell its subscribers and to let go of
    // (its worker stops when the last reference goes). Throws ServiceError kNoScene,
    // kForbidden.
    std::shared_ptr<Session> Unload(const std::string& name, uint64_t by, Role role);
    // Throws ServiceError kForbidden unless connection `by`, of role `role`, may make
    // `change` to scene `name`: a viewer never; its owner (Own) always; anyone but a viewer
    // once the owner has gone, or when no connection built it; while the owner is connected,
    // an editor may edit or reload it and only an admin unload it.
    void CheckMay(const std::string& name, uint64_t by, Role role, Change change) const;
    // The named session; "" means the only one loaded, or the newest if several are.
    std::shared_ptr<Session> Find(const std::string& name) const;
    // A path under the scene root, refusing absolute paths, ".." escapes and symlinks that
    // lead outside it. Throws ServiceError(kOutsideRoot / kNotFound).
    std::filesystem::path Resolve(const std::string& relative) const;
    // A sky: the equirectangular OpenEXR at `path` under the scene root, or the constant
    // `color`, intensity 1, not turned. Throws ServiceError (kOutsideRoot, kNotFound,
    // kLoadFailed for a bad file, kInvalidArgument for a bad colour or both given).
    Environment MakeEnvironment(const std::string& path,
                                const std::optional<glm::vec3>& color) const;
    // The scenes that no connection has held and nobody has watched for
    // limits.sceneIdleSeconds by `now` (the first call that finds one so starts its clock),
    // taken out of the service; their names in `names`. The caller lets go of them.
    std::vector<std::shared_ptr<Session>> DropIdle(std::chrono::steady_clock::time_point now,
                                                   std::vector<std::string>& names);
    nlohmann::json StatsJson() const;
    // Drops every session (their workers stop); later loads are refused.
    void Shutdown();

    const ServiceLimits& Limits() const { return limits_; }
    const SolverSettings& Defaults() const { return defaults_; }
    // The defaults for solver `name`: its name, the common settings, and those of the
    // defaults' options it declares. penumbra::Error for a solver that is not registered.
    SolverSettings DefaultsFor(const std::string& name) const;

  private:
    // Load's work on the calling thread; a new session's worker is not started.
    LoadResult LoadHere(const LoadRequest& request);
    // With mutex_ held: whether no connection holds scene `name` and nobody watches it;
    // scene `name` taken out of every table (its session returned); CheckMay's test.
    bool Unheld(const std::string& name) const;
    std::shared_ptr<Session> Take(std::string name);
    void CheckMayLocked(const std::string& name, uint64_t by, Role role, Change change) const;

    const std::filesystem::path root_;
    const ServiceLimits limits_;
    const SolverSettings defaults_;
    mutable std::mutex mutex_;
    std::map<std::string, std::shared_ptr<Session>> sessions_;
    // Orders the sessions' work: those a client holds or watches first (Attention).
    const std::shared_ptr<Attention> attention_ = std::make_shared<Attention>();
    std::vector<std::string> order_;                     // load order, newest last
    std::map<std::string, std::set<uint64_t>> holders_;  // scene -> connections holding it
    std::map<std::string, uint64_t> owners_;             // scene -> the connection that built it
    // Scenes found unheld and unwatched (DropIdle), since when.
    std::map<std::string, std::chrono::steady_clock::time_point> idleSince_;
    uint64_t evictions_ = 0, unloads_ = 0, expirations_ = 0;
    size_t loading_ = 0;
    bool shutdown_ = false;
    // Set by Shutdown before anything else: a load in flight stops at its next progress
    // report (its build's progress callback throws ShuttingDown).
    std::atomic<bool> stopping_{false};
};

}  // namespace penumbra::service
