// Terminal progress line: "[stage] 42%" redrawn in place at most ten times a second.
#include "base/progress.h"

#include <unistd.h>

#include <cstdio>

namespace penumbra {

bool StderrIsTerminal() { return isatty(STDERR_FILENO) == 1; }

Progress::Progress(bool enabled) : enabled_(enabled) {}

Progress::~Progress() { Done(); }

void Progress::Update(const std::string& stage, double fraction) {
    if (!enabled_) return;
    auto now = std::chrono::steady_clock::now();
    if (drawn_ && fraction < 1.0 && now - last_ < std::chrono::milliseconds(100)) return;
    last_ = now;
    int pct = static_cast<int>(fraction * 100.0 + 0.5);
    std::fprintf(stderr, "\r\033[K%s %3d%%", stage.c_str(), pct);
    std::fflush(stderr);
    drawn_ = true;
}

void Progress::Done() {
    if (enabled_ && drawn_) {
        std::fprintf(stderr, "\r\033[K");
        std::fflush(stderr);
    }
    drawn_ = false;
}

}  // namespace penumbra
