// What the gather stage's files share (gather_stage.cpp, gather_trace.cpp,
// gather_glossy.cpp): the random streams of its patterns, the short-hit rule.
#pragma once

#include <cstdint>

#include "base/numeric.h"

namespace penumbra::gather_detail {

// Streams of the gather's patterns, apart from the first shot's (which uses stream = surfel).
inline constexpr uint64_t kGatherStream = 0x9e3779b97f4a7c15ull;
inline constexpr uint64_t kSecondStream = 0x5851f42d4c957f2dull;
inline constexpr uint64_t kLobeStream = 0x2545f4914f6cdd1dull;
inline constexpr uint64_t kGlintStream = 0x6a09e667f3bcc909ull;

// A hit closer than this × the solver's element size is gathered again (GatherStage::kShort):
// past half an element the answers stopped improving while the tracing time went on growing
// (bench/results/FINDINGS.md, "Constants in the code").
inline constexpr float kShortHit = 0.5f;

}  // namespace penumbra::gather_detail
