// The implicit-visibility solver's options (Dong et al. 2007) and its registry entry.
#pragma once

#include "solver/solver.h"
#include "solvers/registry.h"

namespace penumbra {

struct ImplicitSettings {
    int bins = 128;  // direction bins (Directions): the paper's cube-map texels, near-uniform
    // Refine a link end while its bounding sphere's disc, foreshortened as far as the slab
    // holding its members allows, subtends more than this × ω_bin (Sec. 4.2.2:
    // "bigger than the solid angle of the link's respective bin"): below 1, an end smaller
    // than a bin, so that every bin it overlaps gets a part of it (fewer empty bins, a leak
    // under a sky), at more links.
    float linkThreshold = 0.2f;
    // How a leaf's bin is covered (Sec. 4.2.3–4.2.4): false, the closest layer (the links of
    // the leaf and its ancestors in the bin, nearest first, each its own solid angle, until
    // the bin is full); true, the paper's Eq. 5 as written (the closest link of the (node, bin)
    // slot covers the bin, pushed down the tree; no end spread over the bins it overlaps).
    bool closest = false;
};

inline constexpr int kImplicitDefaultBins = 128;
// Behind a final gather (SolverSettings::behindGather), as the antiradiance solver's
// kBinsBehindGather: the gather reads the solver's answer a bounce away, through its own rays,
// and the links (most of a bake's time) scale with the bins (docs/SOLVER.md "Settings behind
// the gather").
inline constexpr int kImplicitBinsBehindGather = 64;

SolverEntry ImplicitEntry();
ImplicitSettings ReadImplicitSettings(const SolverSettings& settings);

}  // namespace penumbra
