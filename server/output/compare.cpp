// Error statistics between two irradiance files, the second taken as the reference.
#include "output/compare.h"

#include <algorithm>
#include <cmath>
#include <tuple>

#include "base/check.h"

namespace penumbra {
namespace {

// Running sums of one group of vertices.
struct Sums {
    double diff2 = 0, ref2 = 0, rel = 0, maxRel = -1;
    size_t n = 0;
    int worstPrimitive = -1, worstVertex = -1;

    void Add(const glm::vec3& a, const glm::vec3& b, double floor, int p, int v) {
        glm::dvec3 d = glm::dvec3(a) - glm::dvec3(b);
        double dl = glm::length(d), bl = glm::length(glm::dvec3(b));
        diff2 += dl * dl;
        ref2 += bl * bl;
        double r = dl / std::max(bl, floor);
        rel += r;
        if (r > maxRel) maxRel = r, worstPrimitive = p, worstVertex = v;
        ++n;
    }
    ErrorSummary Summary() const {
        ErrorSummary s;
        s.relRmse = ref2 > 0 ? std::sqrt(diff2 / ref2) : (diff2 > 0 ? INFINITY : 0.0);
        s.meanRel = n ? rel / n : 0.0;
        s.maxRel = std::max(maxRel, 0.0);
        s.vertices = n;
        s.worstPrimitive = worstPrimitive;
        s.worstVertex = worstVertex;
        return s;
    }
};

std::string Describe(const IrradianceRecord& r) {
    return "node '" + r.node + "' mesh " + std::to_string(r.mesh) + " primitive " +
           std::to_string(r.primitive);
}

nlohmann::json SummaryToJson(const ErrorSummary& s, const IrradianceFile& b) {
    nlohmann::json j{{"rel_rmse", s.relRmse},
                     {"mean_rel", s.meanRel},
                     {"max_rel", s.maxRel},
                     {"vertices", s.vertices}};
    if (s.worstPrimitive >= 0) {
        const auto& r = b.primitives[s.worstPrimitive];
        j["worst"] = {{"node", r.node},
                      {"mesh", r.mesh},
                      {"primitive", r.primitive},
                      {"vertex", s.worstVertex}};
    }
    return j;
}

}  // namespace

Comparison Compare(const IrradianceFile& a, const IrradianceFile& b, double floorFraction) {
    if (a.primitives.size() != b.primitives.size())
        throw Error("the files hold " + std::to_string(a.primitives.size()) + " and " +
                    std::to_string(b.primitives.size()) + " primitives");
    using Key = std::tuple<std::string, int, int>;
    std::map<Key, size_t> inA;
    for (size_t i = 0; i < a.primitives.size(); ++i) {
        const auto& r = a.primitives[i];
        if (!inA.emplace(Key{r.node, r.mesh, r.primitive}, i).second)
            throw Error("the first file lists " + Describe(r) + " twice");
    }
    double total = 0;
    size_t count = 0;
    for (const auto& r : b.primitives)
        for (const auto& v : r.irradiance) total += glm::length(glm::dvec3(v)), ++count;
    Comparison c;
    c.floor = count ? floorFraction * total / count : 0.0;
    if (c.floor <= 0) c.floor = 1e-30;

    Sums all;
    std::map<std::string, Sums> nodes;
    for (size_t p = 0; p < b.primitives.size(); ++p) {
        const auto& rb = b.primitives[p];
        auto it = inA.find(Key{rb.node, rb.mesh, rb.primitive});
        if (it == inA.end()) throw Error("the first file has no " + Describe(rb));
        const auto& ra = a.primitives[it->second];
        if (ra.irradiance.size() != rb.irradiance.size())
            throw Error(Describe(rb) + ": " + std::to_string(ra.irradiance.size()) + " and " +
                        std::to_string(rb.irradiance.size()) + " vertices");
        Sums& node = nodes[rb.node];
        for (size_t v = 0; v < rb.irradiance.size(); ++v) {
            all.Add(ra.irradiance[v], rb.irradiance[v], c.floor, int(p), int(v));
            node.Add(ra.irradiance[v], rb.irradiance[v], c.floor, int(p), int(v));
        }
    }
    c.overall = all.Summary();
    for (const auto& [name, sums] : nodes) c.nodes[name] = sums.Summary();
    return c;
}

nlohmann::json ComparisonToJson(const Comparison& c, const IrradianceFile& b) {
    nlohmann::json j = SummaryToJson(c.overall, b);
    j["floor"] = c.floor;
    nlohmann::json nodes = nlohmann::json::object();
    for (const auto& [name, s] : c.nodes) nodes[name] = SummaryToJson(s, b);
    j["nodes"] = std::move(nodes);
    return j;
}

}  // namespace penumbra
