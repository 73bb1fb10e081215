// Writes per-vertex irradiance in the two bake formats: JSON (for scripts) and the input
// glTF with a float RGB COLOR_0 on every primitive (for viewers).
#pragma once

#include <glm/glm.hpp>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "scene/scene.h"
#include "solver/solver.h"

namespace penumbra {

inline constexpr const char* kIrradianceUnits =
    "irradiance in lux (lm/m^2) for emission given in nits (cd/m^2)";

struct IrradianceResult {
    std::string solver;  // "antiradiance", "reference", ...
    std::string channel = "indirect";
    // One array per scene primitive, in the primitive's input vertex order.
    std::vector<std::vector<glm::vec3>> primitives;
    // Standard error of each value, per channel, when the producer estimates one (the
    // path-traced reference); empty otherwise.
    std::vector<std::vector<glm::vec3>> standardError;
    nlohmann::json stats = nlohmann::json::object();
};

// Gathers per-primitive irradiance from a solver that has run.
IrradianceResult CollectIrradiance(const Scene& scene, Solver& solver,
                                   Channel channel = Channel::kIndirect);

// `{"units", "solver", "channel", "primitives": [...], "stats": {...}, "warnings": [...]}`
// (warnings: SceneWarnings, possibly none); each primitive
// `{"node", "mesh", "primitive", "irradiance": [[r,g,b], ...]}` and, with standard
// errors, `"stderr": [[r,g,b], ...]`. `path` "-" writes to standard output.
void WriteIrradianceJson(const std::string& path, const Scene& scene,
                         const IrradianceResult& result);
// The `stats` object of the JSON output.
nlohmann::json StatsToJson(const SolverStats& stats);

// One primitive of an irradiance JSON file, as read back.
struct IrradianceRecord {
    std::string node;
    int mesh = -1;
    int primitive = -1;
    std::vector<glm::vec3> irradiance;
};
struct IrradianceFile {
    std::string solver, channel;
    std::vector<IrradianceRecord> primitives;
};
// The in-memory equivalent of writing `result` and reading it back.
IrradianceFile ToIrradianceFile(const Scene& scene, const IrradianceResult& result);
// Reads a file written by WriteIrradianceJson; throws penumbra::Error naming the file and
// what is wrong with it.
IrradianceFile ReadIrradianceJson(const std::string& path);
// The same from a .glb or .gltf that bake or reference wrote: each primitive's _IRRADIANCE,
// keyed as the glTF loader names it (node, mesh and primitive of this file, whose meshes are
// the output's own: a refined output's, say). Throws penumbra::Error.
IrradianceFile ReadIrradianceGltf(const std::string& path);

// The vertex attribute that carries irradiance (lux, float RGB) in glTF out: application
// data, so an underscore name (glTF 2.0, 3.7.2.1).
inline constexpr const char* kIrradianceAttribute = "_IRRADIANCE";
// What glTF out puts in COLOR_0 for viewers: nothing, or the irradiance scaled so that the
// scene's 99th-percentile luminance is 1 and clamped to [0, 1] (linear, as COLOR_0 is).
enum class DisplayColor { kNone, kToneMapped };
DisplayColor ParseDisplayColor(const std::string& name);  // none | tonemapped

// Copies glTF `input` to `output` (.glb or .gltf, WriteGltfModel) with _IRRADIANCE =
// irradiance added to every primitive, and COLOR_0 as `color` says (replacing any it had);
// meshes shared by several nodes are duplicated so each gets its own values.
void WriteIrradianceGltf(const std::string& input, const std::string& output, const Scene& scene,
                         const IrradianceResult& result,
                         DisplayColor color = DisplayColor::kToneMapped);

}  // namespace penumbra
