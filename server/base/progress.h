// Progress reporting for long work: a single updating line on a terminal, silence otherwise.
// Stages call Update() freely; the reporter rate-limits redraws.
#pragma once

#include <chrono>
#include <string>

namespace penumbra {

class Progress {
  public:
    // Draws only when stderr is a terminal, unless `force` is set.
    explicit Progress(bool enabled);
    ~Progress();

    void Update(const std::string& stage, double fraction);
    void Done();  // clears the line

  private:
    bool enabled_;
    bool drawn_ = false;
    std::chrono::steady_clock::time_point last_{};
};

// True when stderr is an interactive terminal.
bool StderrIsTerminal();

}  // namespace penumbra
