// What each stage around a solver reports, part by part: the direct stage and the sky
// (direct::DescribeLighting fills LightingFigures), moves in place (the solvers that take
// them), and the gather stage's first shot and final gather (GatherStage::Stats). Each is its
// own stage's part of SolverStats (solver/solver.h), which holds the figures common to every
// solver beside them.
#pragma once

#include <cstddef>
#include <string>

namespace penumbra {

struct LightingFigures {
    bool direct = false;      // a direct stage (punctual lights) ran
    int shadowViews = 0;      // shadow maps rendered per light update (cube faces count 6)
    int shadowMapSize = 0;    // texels per side
    double msShadow = 0.0;    // last shadow pass
    double msDirect = 0.0;    // last direct-light initialisation
    std::string environment;  // the sky's source (file or "constant"); empty: none
    float environmentIntensity = 0.0f;
    float environmentRotation = 0.0f;  // radians
};

// Moves in place (SolverSettings::prepareMoves): dynamic nodes prepared to move inside their
// motion bounds, the links touching them (recomputed when they move; 0 for a solver without
// links), moves taken by UpdateGeometry, links those recomputed in all, the last one's time
// (links, leaves, uploads, shadow maps), and why moves in place were asked for and not
// prepared.
struct MotionFigures {
    size_t groups = 0;
    size_t links = 0;
    size_t moves = 0;
    size_t linksUpdated = 0;
    double msLastMove = 0.0;
    std::string declined;
};

// The gather stage (gather/gather_stage.h). Its first shot: shadow rays a surfel for the
// emitters' direct light (0: the solver carries the emission itself), of those the rays to an
// environment map's sun (0: no sun), and the last computation's milliseconds. Its final
// gather (0 rays: none): rays a surfel, the surfels gathered at, the last tracing of their
// hits and the last evaluation of those hits in milliseconds, the rays the last move traced
// again (both parts), the tracings of either part so far, and where it traces.
struct GatherFigures {
    int emitterRays = 0;
    int sunRays = 0;
    double msFirstShot = 0.0;
    int rays = 0;
    size_t targets = 0;
    double msTrace = 0.0;
    double msEvaluate = 0.0;
    size_t raysRetraced = 0;
    size_t traces = 0;
    std::string device;
};

}  // namespace penumbra
