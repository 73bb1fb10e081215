// Per-vertex comparison of two irradiance files (A against reference B): relative RMSE,
// mean and max relative error, overall and per node.
#pragma once

#include <map>
#include <nlohmann/json.hpp>
#include <string>

#include "output/irradiance_writer.h"

namespace penumbra {

inline constexpr double kDefaultFloor = 0.01;

struct ErrorSummary {
    double relRmse = 0;  // √(Σ|a−b|²) / √(Σ|b|²), |·| the RGB vector length
    double meanRel = 0;  // mean over vertices of |a−b| / max(|b|, floor)
    double maxRel = 0;   // the largest of those
    size_t vertices = 0;
    // Where maxRel is: primitive index into B's list and vertex index.
    int worstPrimitive = -1;
    int worstVertex = -1;
};

struct Comparison {
    ErrorSummary overall;
    std::map<std::string, ErrorSummary> nodes;
    // Relative errors are taken against max(|b|, floor) so that vertices B says are dark
    // (inside closed objects, say) do not dominate: floor = floorFraction × the mean |b|.
    double floor = 0;
};

// Primitives are matched by (node, mesh, primitive); both files must hold the same ones with
// the same vertex counts. Throws penumbra::Error naming the first mismatch.
Comparison Compare(const IrradianceFile& a, const IrradianceFile& b,
                   double floorFraction = kDefaultFloor);

// `{"rel_rmse", "mean_rel", "max_rel", "vertices", "worst": {...}, "nodes": {name: {...}}}`.
nlohmann::json ComparisonToJson(const Comparison& c, const IrradianceFile& b);

}  // namespace penumbra
