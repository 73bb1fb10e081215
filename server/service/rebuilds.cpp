// A session's solver built again for the scene it has: to carry on after a move that needed
// new links (the warm start), after a lost device (the CPU back end) and after a diverged
// solution (the fallback solver). Worker thread, as session.h says of each.
#include <chrono>
#include <cstdio>

#include "base/numeric.h"
#include "scene/motion.h"
#include "service/session.h"
#include "solvers/registry.h"

namespace penumbra::service {

std::string Session::WarmStart(Solver& rebuilt, const Scene& next) {
    // Surfels are numbered primitive by primitive: a primitive that did not move has the
    // same surfels, in the same order, in both solvers, and so has a dynamic node's that
    // moved (it is refined in its own space).
    return rebuilt.WarmStart(
        *solver_, CarrySurfels(applied_, solver_->GetSurfels(), next, rebuilt.GetSurfels()));
}

bool Session::SwapInRebuilt(std::unique_lock<std::mutex>& lock, std::string& error,
                            double& seconds) {
    const Scene scene = applied_;
    const bool prepareMoves = !motionDeclined_;
    lock.unlock();
    const auto start = std::chrono::steady_clock::now();
    std::unique_ptr<Solver> next;
    try {
        next = BuildSolver(scene, prepareMoves);
    } catch (const std::exception& e) {
        error = e.what();
    }
    seconds = MsSince(start) / 1000.0;
    lock.lock();
    if (!next) return false;
    std::swap(solver_, next);  // the old solver goes below, outside the lock
    passTotals_.clear();
    lastSurfels_.clear();
    diverged_.clear();
    solverStatsRaw_ = solver_->Stats();
    converged_ = settled_ = false;
    framesSinceEdit_ = 0;
    lock.unlock();
    next.reset();
    lock.lock();
    return true;
}

namespace {

// "; why (built in S s)" appended to `note`.
void AddBuiltNote(std::string& note, const std::string& why, double seconds) {
    char built[32];
    std::snprintf(built, sizeof(built), "%.1f", seconds);
    note += (note.empty() ? "" : "; ") + why + " (built in " + built + " s)";
}

}  // namespace

bool Session::FallBackToCpu(std::unique_lock<std::mutex>& lock, std::string& note) {
    const std::string why = std::move(deviceLost_);
    deviceLost_.clear();
    if (settings_.solver.device == DeviceChoice::kCpu || onCpu_) return false;
    onCpu_ = true;
    std::string error;
    double seconds = 0.0;
    if (!SwapInRebuilt(lock, error, seconds)) {
        lastError_ = "device lost (" + why + "), and the CPU back end failed too: " + error;
        note += (note.empty() ? "" : "; ") + lastError_;
        return false;
    }
    ++deviceFallbacks_;
    lastError_ = "device lost (" + why + "); the session goes on with the CPU back end";
    AddBuiltNote(note, lastError_, seconds);
    return true;
}

bool Session::FallBackToAnotherSolver(std::unique_lock<std::mutex>& lock, std::string& note) {
    fallbackTried_ = true;
    SolverSettings fallback;
    if (!FallbackSettings(settings_.solver, fallback)) return false;
    const std::string why = "the " + settings_.solver.solver + " solution " + diverged_;
    fallback_ = fallback;
    fellBack_ = true;
    std::string error;
    double seconds = 0.0;
    if (!SwapInRebuilt(lock, error, seconds)) {
        fellBack_ = false;
        lastError_ = why + ", and the " + fallback.solver + " solver failed too: " + error;
        note += (note.empty() ? "" : "; ") + lastError_;
        return false;
    }
    solverFallback_ = why + "; the session went on with the " + fallback.solver + " solver";
    AddBuiltNote(note, why + "; going on with the " + fallback.solver + " solver", seconds);
    return true;
}

}  // namespace penumbra::service
