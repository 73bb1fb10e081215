// The direct stage's and the sky's figures in a solver's stats: the one place that knows
// both (direct/ sits below the solver contract's users and reports its own figures).
#pragma once

#include "direct/direct_stage.h"
#include "solver/solver.h"

namespace penumbra {

inline void AddLightingFigures(const direct::LightingFigures& f, SolverStats& s) {
    if (f.direct) {
        s.shadowViews = f.shadowViews;
        s.shadowMapSize = f.shadowMapSize;
        s.msShadow = f.msShadow;
        s.msDirect = f.msDirect;
    }
    if (!f.environment.empty()) {
        s.environment = f.environment;
        s.environmentIntensity = f.environmentIntensity;
        s.environmentRotation = f.environmentRotation;
    }
}

}  // namespace penumbra
