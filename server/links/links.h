// Links between hierarchy nodes, refined from the root self-link with the solid-angle
// oracle of Sec. 3.2 and stored grouped by receiver so the global pass gathers.
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

#include "hierarchy/directions.h"
#include "hierarchy/hierarchy.h"

namespace penumbra {

// One sender→receiver transfer through a direction bin (Sec. 4.1, "Links").
// Layout shared with shaders/common.glsl (struct Link); keep both in step.
struct Link {
    uint32_t sender;   // hierarchy node that emits I_ex
    uint16_t bin;      // bin of the direction sender → receiver (direction of travel)
    uint16_t level;    // spread level (cone size σ) in Directions
    float formFactor;  // Eq. 17: 1 / (d² ω_bin), with d² regularised by the sender's disc
};
static_assert(sizeof(Link) == 12);
static_assert(offsetof(Link, bin) == 4 && offsetof(Link, level) == 6 &&
              offsetof(Link, formFactor) == 8);

struct LinkSettings {
    // Refine while sender or receiver subtends more than `oracle` × ω_bin.
    float oracle = 1.0f;
    int threads = 0;  // 0: all cores
};

struct Links {
    std::vector<uint32_t> offsets;  // receiver r's links are [offsets[r], offsets[r+1])
    std::vector<Link> links;
    double buildSeconds = 0.0;

    size_t Count() const { return links.size(); }
};

// `progress` (may be empty) receives the fraction of work done.
Links BuildLinks(const Hierarchy& h, const Directions& dirs, const LinkSettings& settings,
                 const std::function<void(double)>& progress = {});

// The link a receiver/sender pair would get (used for tests and dynamic updates).
Link MakeLink(const Hierarchy& h, const Directions& dirs, uint32_t receiver, uint32_t sender);

}  // namespace penumbra
