// Links between hierarchy nodes, refined from the root self-link with the solid-angle
// oracle of Sec. 3.2 and stored grouped by receiver so the global pass gathers.
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

#include "gpu/layout.h"
#include "hierarchy/directions.h"
#include "hierarchy/hierarchy.h"
#include "links/oracle.h"
#include "scene/motion.h"
#include "scene/surfels.h"

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
// GLSL reads bin and level as one uint, binLevel = bin | level << 16 (little-endian).
PENUMBRA_GPU_FIELD(Link, sender, 0);
PENUMBRA_GPU_FIELD(Link, bin, 4);
PENUMBRA_GPU_FIELD(Link, level, 6);
PENUMBRA_GPU_FIELD(Link, formFactor, 8);

struct LinkSettings {
    LinkOracle mode = LinkOracle::kConservative;
    // Refine while sender or receiver subtends more than `oracle` × ω_bin.
    float oracle = 1.0f;
    // Conservative and area modes: refine while the receiver subtends more than oracle ×
    // this × ω_bin (a large receiver takes one direction for all its members).
    float receiverOracle = 0.5f;  // AntiradianceSettings::receiverOracle
    int threads = 0;              // 0: all cores
    // Motion bounds of group g at motion[g − 1] (Surfels::groups); empty: everything static.
    std::vector<MotionBounds> motion;
    // With motion: stop as soon as the links touching a group outnumber the others by more
    // than this factor (Links::overBudget; the links are then incomplete). 0: no limit.
    float dynamicBudget = 0.0f;
};

struct Links {
    std::vector<uint32_t> offsets;  // receiver r's links are [offsets[r], offsets[r+1])
    std::vector<Link> links;
    double buildSeconds = 0.0;
    // Links touching a motion group (Surfels::groups), as indices into `links`, and their
    // receivers: after a move their form factors and bins are recomputed (Sec. 3.3).
    std::vector<uint32_t> dynamic;
    std::vector<uint32_t> dynamicReceivers;
    // LinkSettings::dynamicBudget was exceeded: the build stopped early and these links are
    // incomplete; `dynamicSeen` links touching a group had been made by then, against
    // `staticLinks` others (all of them).
    bool overBudget = false;
    size_t dynamicSeen = 0, staticLinks = 0;

    size_t Count() const { return links.size(); }
};

// Cosine normalisations (Directions::CosineNorm) of oriented nodes (leaves and planar
// clusters), indexed by node; the local pass uses the leaves' and the link build
// calibrates links at oriented ends against them. Zero for other nodes.
struct LeafNorms {
    std::vector<float> in;   // of −n: the side light arrives from
    std::vector<float> out;  // of n: the side light leaves to
};
LeafNorms ComputeLeafNorms(const Hierarchy& h, const Directions& dirs);

// Geometry for the near field: each surfel's adjacent refined triangles, so that a link
// between nearby leaves integrates the sender's area (its linear hat function) instead of
// treating it as a point, which fails where surfaces meet at edges and corners.
struct NearField {
    const Surfels* surfels = nullptr;
    std::vector<uint32_t> offsets;    // surfel s's triangles: [offsets[s], offsets[s+1])
    std::vector<uint32_t> triangles;  // index of the first corner in refinedTriangles
};
NearField BuildNearField(const Surfels& surfels);

// `progress` (may be empty) receives the fraction of work done.
Links BuildLinks(const Hierarchy& h, const Directions& dirs, const LeafNorms& norms,
                 const NearField& near, const LinkSettings& settings,
                 const std::function<void(double)>& progress = {});

// The link a receiver/sender pair would get (used for tests and dynamic updates).
Link MakeLink(const Hierarchy& h, const Directions& dirs, const LeafNorms& norms,
              const NearField& near, uint32_t receiver, uint32_t sender);

// ∫ φ_s |cos_s| cos_r / d² dA over surfel `s`'s area (hat function φ_s over its
// triangles), seen from point `p` with normal `n`: irradiance per unit sender radiance.
float NearFieldIrradiance(const NearField& near, uint32_t s, glm::vec3 p, glm::vec3 n);

}  // namespace penumbra
