// The light-field solver's options (Mortensen, Khanna, Slater 2008: virtual light field
// propagation) and its registry entry.
#pragma once

#include <cstdint>

#include "solver/solver.h"
#include "solvers/registry.h"

namespace penumbra {

struct LightfieldSettings {
    // Line directions a batch (each used both ways: 2× as many directions of travel), the
    // paper's parallel subfields; a batch's set is a new random rotation of the same set.
    int directions = 64;
    // Lines a side of each subfield's square over the scene's bounding sphere; 0: cells half
    // an element wide (every element met by a few lines of every direction it faces).
    int cells = 0;
    // Batches traced and kept: the answer's directions are batches × directions (the paper's
    // figures use 512 two-way directions). Iterations past these carry further bounces over
    // the kept lines without new rays.
    int batches = 8;
    uint32_t seed = 1;  // the rotations' and the lines' jitter
    // On a Vulkan device (--device gpu or lavapipe): surfaces peeled a submission along each
    // direction's lines; more submissions follow while a line has surfaces left.
    int layers = 8;
    // Passes of smoothing the estimate over the refined mesh (SurfelSmoothing, lines.h) where
    // the cells are wider than the surfels; −1: from the cells and the element size.
    int smoothing = -1;
};

SolverEntry LightfieldEntry();
LightfieldSettings ReadLightfieldSettings(const SolverSettings& settings);

}  // namespace penumbra
