// Scene sessions by name, loading under the scene root, limits.
#include "service/service.h"

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#ifdef __linux__
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>
#endif

#include <algorithm>
#include <fstream>
#include <random>
#include <thread>

#include "base/check.h"
#include "scene/gltf_loader.h"
#include "scene/refine_output.h"
#include "scene/sun_sky.h"
#include "solvers/registry.h"

namespace penumbra::service {

namespace fs = std::filesystem;

namespace {

// `message` with every `path` in it written as `as`: a client learns names relative to the
// scene root, never the server's own paths.
std::string Replace(std::string message, const std::string& path, const std::string& as) {
    if (path.empty()) return message;
    for (size_t at = message.find(path); at != std::string::npos;
         at = message.find(path, at + as.size()))
        message.replace(at, path.size(), as);
    return message;
}

// The calling thread (only it) at a lower priority than the rest of the process (Linux's
// nice 10): while scenes stream, the operating system gives it what their frames leave.
void LowerThisThreadsPriority() {
#ifdef __linux__
    setpriority(PRIO_PROCESS, static_cast<id_t>(syscall(SYS_gettid)), 10);  // best effort
#endif
}

}  // namespace

const char* RoleName(Role role) {
    switch (role) {
        case Role::kViewer:
            return "viewer";
        case Role::kUser:
            return "user";
        case Role::kEditor:
            return "editor";
        case Role::kAdmin:
            return "admin";
    }
    return "?";
}

std::optional<Role> RoleNamed(const std::string& name) {
    for (Role r : {Role::kViewer, Role::kEditor, Role::kAdmin})
        if (name == RoleName(r)) return r;
    return std::nullopt;
}

Service::Service(fs::path sceneRoot, ServiceLimits limits, SolverSettings defaults)
    : root_(fs::weakly_canonical(sceneRoot)), limits_(limits), defaults_(std::move(defaults)) {
    // TBB starts its worker threads from the thread that first asks for them, with that
    // thread's priority: asked from here, before a load's lowered thread could be the first.
    tbb::parallel_for(0, 4 * tbb::this_task_arena::max_concurrency(),
                      [](int) { std::this_thread::sleep_for(std::chrono::milliseconds(2)); });
}

SolverSettings Service::DefaultsFor(const std::string& name) const {
    const SolverEntry& entry = FindSolver(name);
    SolverSettings s = defaults_;
    s.solver = entry.name;
    s.options.clear();
    for (const auto& [option, value] : defaults_.options)
        for (const OptionSpec& spec : entry.options)
            if (spec.name == option) s.options[option] = value;
    return s;
}

Service::~Service() { Shutdown(); }

fs::path Service::Resolve(const std::string& relative) const {
    if (relative.empty()) throw ServiceError(ErrorKind::kInvalidArgument, "no scene path given");
    fs::path p(relative);
    if (p.is_absolute())
        throw ServiceError(ErrorKind::kOutsideRoot,
                           "'" + relative + "' is absolute; give a path under the scene root");
    // Canonical form resolves "..", "." and symlinks; what remains must lie under the root.
    std::error_code ec;
    fs::path full = fs::weakly_canonical(root_ / p, ec);
    if (ec) throw ServiceError(ErrorKind::kNotFound, "'" + relative + "': " + ec.message());
    auto [r, f] = std::mismatch(root_.begin(), root_.end(), full.begin(), full.end());
    if (r != root_.end())
        throw ServiceError(ErrorKind::kOutsideRoot,
                           "'" + relative + "' lies outside the scene root");
    if (!fs::is_regular_file(full, ec))
        throw ServiceError(ErrorKind::kNotFound,
                           "no scene file '" + relative + "' under the scene root");
    return full;
}

Environment Service::MakeEnvironment(const std::string& path,
                                     const std::optional<glm::vec3>& color) const {
    if (!path.empty() && color)
        throw ServiceError(ErrorKind::kInvalidArgument,
                           "give an environment file or an environment colour, not both");
    Environment env;
    try {
        if (!path.empty()) {
            fs::path sky = Resolve(path);
            env = LoadEnvironment(sky.string());
            env.source = fs::relative(sky, root_).generic_string();
        } else if (color) {
            env = ConstantEnvironment(*color);
        }
        ValidateEnvironment(env);
    } catch (const Error& e) {
        throw ServiceError(path.empty() ? ErrorKind::kInvalidArgument : ErrorKind::kLoadFailed,
                           e.what());
    }
    return env;
}

LoadResult Service::Load(const LoadRequest& request) {
    // The load (the file read and decoded, the solver built) on a thread of its own at a lower
    // priority, so that the frames of the scenes already loaded slow as little as they can;
    // the new session's worker then starts from here, at the usual priority.
    LoadResult result;
    std::exception_ptr failed;
    std::thread loader([&] {
        LowerThisThreadsPriority();
        try {
            result = LoadHere(request);
        } catch (...) {
            failed = std::current_exception();
        }
    });
    loader.join();
    if (failed) std::rethrow_exception(failed);
    if (!result.reused) result.session->Start();
    return result;
}

LoadResult Service::LoadHere(const LoadRequest& request) {
    // Name the session and find the file before anything slow happens.
    std::string name;
    fs::path file;
    bool upload = !request.glb.empty();
    if (upload) {
        if (!request.path.empty())
            throw ServiceError(ErrorKind::kInvalidArgument,
                               "give either a scene path or an uploaded .glb, not both");
        if (request.glb.size() > limits_.maxUploadBytes)
            throw ServiceError(ErrorKind::kLimitReached,
                               "uploaded .glb of " + std::to_string(request.glb.size()) +
                                   " bytes exceeds the limit of " +
                                   std::to_string(limits_.maxUploadBytes));
        name = request.name.empty() ? "upload.glb" : request.name;
    } else {
        file = Resolve(request.path);
        name = fs::relative(file, root_).generic_string();
    }
    LoadResult result;
    std::vector<std::shared_ptr<Session>> dropped;  // stopped outside the lock
    {
        std::lock_guard lock(mutex_);
        if (shutdown_) throw ServiceError(ErrorKind::kShuttingDown, "the server is shutting down");
        auto it = sessions_.find(name);
        if (it != sessions_.end() && !request.reload) return {it->second, true, {}};
        if (it == sessions_.end() && request.role == Role::kViewer)
            throw ServiceError(ErrorKind::kForbidden,
                               "this client's token has the viewer role: it may join a loaded "
                               "scene (LoadScene of its name), not load '" +
                                   name + "'");
        if (request.by != 0 && it == sessions_.end() && request.role != Role::kAdmin) {
            const size_t owned = std::count_if(owners_.begin(), owners_.end(), [&](const auto& o) {
                return o.second == request.by;
            });
            if (owned >= limits_.maxScenesPerClient)
                throw ServiceError(ErrorKind::kLimitReached,
                                   "this client already owns " + std::to_string(owned) +
                                       " loaded scenes (--max-scenes-per-client " +
                                       std::to_string(limits_.maxScenesPerClient) +
                                       "): unload one first");
        }
        if (it != sessions_.end()) CheckMayLocked(name, request.by, request.role, Change::kReload);
        size_t others = sessions_.size() - (it != sessions_.end() ? 1 : 0);
        while (others + loading_ >= limits_.maxScenes) {
            // The scene loaded longest ago that no connection holds and nobody watches.
            auto victim = std::find_if(order_.begin(), order_.end(), [&](const std::string& n) {
                return n != name && Unheld(n);
            });
            if (victim == order_.end())
                throw ServiceError(ErrorKind::kLimitReached,
                                   "already " + std::to_string(others + loading_) +
                                       " scenes loaded or loading, each held by a connected "
                                       "client or watched (--max-scenes " +
                                       std::to_string(limits_.maxScenes) + ")");
            result.evicted.push_back(*victim);
            dropped.push_back(Take(*victim));
            ++evictions_;
            --others;
        }
        ++loading_;
    }
    struct Done {
        Service* s;
        ~Done() {
            std::lock_guard lock(s->mutex_);
            --s->loading_;
        }
    } done{this};

    Scene scene;
    std::string staged;  // an upload's temporary file, named as the upload in messages
    try {
        if (upload) {
            // tinygltf reads files: the upload goes through a private temporary one.
            fs::path tmp = fs::temp_directory_path() /
                           ("penumbra-upload-" + std::to_string(std::random_device{}()) + ".glb");
            staged = tmp.string();
            {
                std::ofstream out(tmp, std::ios::binary);
                out.write(reinterpret_cast<const char*>(request.glb.data()),
                          static_cast<std::streamsize>(request.glb.size()));
                if (!out) throw Error("cannot stage the upload in " + tmp.string());
            }
            try {
                scene = LoadGltf(tmp.string(), GltfFiles{fs::path(), limits_.maxSceneTriangles,
                                                         limits_.maxUploadBytes});
            } catch (...) {
                fs::remove(tmp);
                throw;
            }
            fs::remove(tmp);
            scene.source = name;
        } else {
            scene = LoadGltf(file.string(),
                             GltfFiles{root_, limits_.maxSceneTriangles, limits_.maxSceneBytes});
            scene.source = name;
        }
    } catch (const GltfLimitError& e) {
        // Refused from what the file declares, before its buffers were read.
        throw ServiceError(ErrorKind::kLimitReached,
                           Replace(Replace(e.what(), staged, name), root_.string() + "/", "") +
                               " (--max-scene-triangles, --max-scene-bytes)");
    } catch (const Error& e) {
        throw ServiceError(ErrorKind::kLoadFailed,
                           Replace(Replace(e.what(), staged, name), root_.string() + "/", ""));
    }
    // The sky: a file under the root (never outside it) or a constant colour.
    if (!request.environmentPath.empty() || request.hasEnvironmentColor)
        scene.environment = MakeEnvironment(request.environmentPath,
                                            request.hasEnvironmentColor
                                                ? std::optional<glm::vec3>(request.environmentColor)
                                                : std::nullopt);
    try {
        // A sun and its clear sky (scene/sun_sky.h).
        if (request.sun) AddSun(scene, {request.sun->x, request.sun->y}, request.sun->z);
        if (request.clearSky) {
            if (!request.sun)
                throw Error("a clear sky (sky \"clear\") needs a sun: its position sets it");
            if (scene.environment.Present())
                throw Error("give a clear sky or an environment, not both");
            if (request.environmentRotation != 0.0f)
                throw Error("environment rotation does not turn a clear sky: turn the sun");
            scene.environment = ClearSky({request.sun->x, request.sun->y}, request.turbidity);
        }
        scene.environment.intensity = request.environmentIntensity;
        scene.environment.rotation = request.environmentRotation;
        ValidateEnvironment(scene.environment);
    } catch (const Error& e) {
        throw ServiceError(ErrorKind::kInvalidArgument, e.what());
    }
    if (request.refine > 0.0f) {
        try {
            RefineForOutput(scene, request.refine, limits_.maxSceneTriangles);
        } catch (const Error& e) {
            throw ServiceError(ErrorKind::kLimitReached,
                               name + ": " + e.what() + " (--max-scene-triangles)");
        }
    }
    if (scene.TriangleCount() > limits_.maxSceneTriangles)
        throw ServiceError(
            ErrorKind::kLimitReached,
            name + " has " + std::to_string(scene.TriangleCount()) + " triangles; the limit is " +
                std::to_string(limits_.maxSceneTriangles) + " (--max-scene-triangles)");
    std::shared_ptr<Session> session;
    try {
        // A shutdown stops the build at its next progress report instead of waiting for it.
        // The session keeps its callback for work it does later (its first frame's gather):
        // the request's own reporting ends when Load does.
        auto loading = std::make_shared<std::atomic<bool>>(true);
        auto cancel = [this, loading, report = request.progress](const std::string& stage,
                                                                 double fraction) {
            if (stopping_.load(std::memory_order_relaxed))
                throw ServiceError(ErrorKind::kShuttingDown, "the server is shutting down");
            if (report && loading->load()) report(stage, fraction);
        };
        struct EndReports {
            std::atomic<bool>& loading;
            ~EndReports() { loading = false; }
        } endReports{*loading};
        // The build's parallel work in a low-priority arena: TBB's workers serve the frames
        // of the scenes already loaded first, so that a load (another client's, say) slows
        // their streams as little as it can (docs/SERVICE.md).
        tbb::task_arena arena(tbb::task_arena::automatic, 1, tbb::task_arena::priority::low);
        arena.execute([&] {
            session = std::make_shared<Session>(name, std::move(scene), request.settings, cancel,
                                                attention_, false);
        });
    } catch (const Error& e) {
        throw ServiceError(ErrorKind::kInvalidArgument, name + ": " + e.what());
    }
    std::shared_ptr<Session> replaced;
    {
        std::lock_guard lock(mutex_);
        if (shutdown_) throw ServiceError(ErrorKind::kShuttingDown, "the server is shutting down");
        auto it = sessions_.find(name);
        if (it != sessions_.end()) replaced = it->second;
        sessions_[name] = session;
        std::erase(order_, name);
        order_.push_back(name);
    }
    result.session = session;
    result.replaced = replaced != nullptr;
    return result;  // `replaced` stops once its last user lets go
}

void Service::Hold(const std::string& name, uint64_t holder) {
    std::lock_guard lock(mutex_);
    auto it = sessions_.find(name);
    if (it == sessions_.end()) return;
    holders_[name].insert(holder);
    it->second->SetHeld(true);
}

void Service::Own(const std::string& name, uint64_t owner) {
    std::lock_guard lock(mutex_);
    // A reload keeps the scene's owner while it is connected: an editor's reload of another
    // client's scene does not take it over.
    if (sessions_.count(name)) owners_.emplace(name, owner);
}

void Service::Release(uint64_t holder) {
    std::lock_guard lock(mutex_);
    for (auto& [name, held] : holders_)
        if (auto it = sessions_.find(name);
            held.erase(holder) && held.empty() && it != sessions_.end())
            it->second->SetHeld(false);
    std::erase_if(owners_, [&](const auto& entry) { return entry.second == holder; });
}

std::shared_ptr<Session> Service::Unload(const std::string& name, uint64_t by, Role role) {
    std::lock_guard lock(mutex_);
    if (sessions_.empty())
        throw ServiceError(ErrorKind::kNoScene, "no scene is loaded, so none can be unloaded");
    const std::string scene = name.empty() ? order_.back() : name;
    auto it = sessions_.find(scene);
    if (it == sessions_.end())
        throw ServiceError(ErrorKind::kNoScene, "no scene '" + scene + "' is loaded");
    CheckMayLocked(scene, by, role, Change::kUnload);
    ++unloads_;
    return Take(scene);
}

bool Service::Unheld(const std::string& name) const {
    auto held = holders_.find(name);
    return (held == holders_.end() || held->second.empty()) &&
           sessions_.at(name)->SubscriberCount() == 0;
}

std::shared_ptr<Session> Service::Take(std::string name) {  // a copy: order_ holds `name`
    std::shared_ptr<Session> session = sessions_.at(name);
    sessions_.erase(name);
    holders_.erase(name);
    owners_.erase(name);
    idleSince_.erase(name);
    std::erase(order_, name);
    return session;
}

void Service::CheckMay(const std::string& name, uint64_t by, Role role, Change change) const {
    std::lock_guard lock(mutex_);
    CheckMayLocked(name, by, role, change);
}

void Service::CheckMayLocked(const std::string& name, uint64_t by, Role role, Change change) const {
    const char* verb = change == Change::kEdit     ? "edit"
                       : change == Change::kReload ? "reload"
                                                   : "unload";
    if (role == Role::kViewer)
        throw ServiceError(ErrorKind::kForbidden, std::string("this client's token has the viewer "
                                                              "role: it may watch scene '") +
                                                      name + "', not " + verb + " it");
    if (role == Role::kAdmin || (role == Role::kEditor && change != Change::kUnload)) return;
    if (auto owner = owners_.find(name); owner != owners_.end() && owner->second != by)
        throw ServiceError(
            ErrorKind::kForbidden,
            "scene '" + name +
                "' was loaded by another client, which is still connected: only "
                "it may " +
                verb + " the scene" +
                (change == Change::kUnload ? " (or a client whose token has the admin role)"
                                           : " (or a client whose token has the editor role)"));
}
std::shared_ptr<Session> Service::Find(const std::string& name) const {
    std::lock_guard lock(mutex_);
    if (sessions_.empty())
        throw ServiceError(ErrorKind::kNoScene, "no scene is loaded; send LoadScene first");
    if (name.empty()) return sessions_.at(order_.back());
    auto it = sessions_.find(name);
    if (it == sessions_.end()) {
        std::string names;
        for (const auto& n : order_) names += (names.empty() ? "" : ", ") + n;
        throw ServiceError(ErrorKind::kNoScene,
                           "no scene '" + name + "' is loaded; loaded: " + names);
    }
    return it->second;
}

std::vector<std::shared_ptr<Session>> Service::DropIdle(std::chrono::steady_clock::time_point now,
                                                        std::vector<std::string>& names) {
    std::vector<std::shared_ptr<Session>> dropped;
    if (!(limits_.sceneIdleSeconds > 0.0)) return dropped;
    const auto limit = std::chrono::duration<double>(limits_.sceneIdleSeconds);
    std::vector<std::string> expired;
    std::lock_guard lock(mutex_);
    for (const std::string& name : order_) {
        if (!Unheld(name)) {
            idleSince_.erase(name);
            continue;
        }
        const auto since = idleSince_.try_emplace(name, now).first->second;
        if (now - since >= limit) expired.push_back(name);
    }
    for (const std::string& name : expired) dropped.push_back(Take(name));
    expirations_ += expired.size();
    names.insert(names.end(), expired.begin(), expired.end());
    return dropped;
}

nlohmann::json Service::StatsJson() const {
    std::vector<std::shared_ptr<Session>> sessions;
    {
        std::lock_guard lock(mutex_);
        for (const auto& n : order_) sessions.push_back(sessions_.at(n));
    }
    nlohmann::json j;
    {
        std::lock_guard lock(mutex_);
        j["evicted_scenes"] = evictions_;
        j["unloaded_scenes"] = unloads_;
        j["expired_scenes"] = expirations_;
    }
    j["scenes"] = nlohmann::json::array();
    for (const auto& s : sessions) j["scenes"].push_back(s->StatsJson());
    return j;
}

void Service::Shutdown() {
    stopping_ = true;
    std::map<std::string, std::shared_ptr<Session>> sessions;
    {
        std::lock_guard lock(mutex_);
        shutdown_ = true;
        sessions.swap(sessions_);
        order_.clear();
        holders_.clear();
    }
    sessions.clear();  // sessions still held by a request finish with it
}

}  // namespace penumbra::service
