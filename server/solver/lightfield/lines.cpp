// Tracing and walking the light field's parallel lines (lines.h).
#include "solver/lightfield/lines.h"

#include <tbb/combinable.h>
#include <tbb/parallel_for.h>

#include <cmath>
#include <glm/gtc/quaternion.hpp>
#include <numbers>

#include "base/pcg.h"
#include "gather/sampling.h"

namespace penumbra {
namespace {

constexpr float kPi = std::numbers::pi_v<float>;

// The lines of one direction: hits per line (lines that meet nothing left out).
struct DirectionLines {
    std::vector<uint32_t> counts;
    std::vector<LineHit> hits;
};

DirectionLines TraceDirection(const RayScene& rays, const LineGrid& grid, const glm::vec3& d,
                              uint32_t seed, uint64_t stream) {
    DirectionLines out;
    glm::vec3 t, s;
    Basis(d, t, s);
    const int n = grid.cells;
    const float side = 2.0f * grid.radius / float(n);
    // Lines start outside the ball and run through it.
    const float back = 1.01f * grid.radius;
    const glm::vec3 corner = grid.centre - grid.radius * (t + s) - back * d;
    Pcg32 rng(seed, stream);
    std::vector<RayHit> hits;
    const std::vector<RayTriangle>& tris = rays.Triangles();
    const float r2 = grid.radius * grid.radius;
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
            const float a = rng.Uniform(), b = rng.Uniform();  // drawn for every cell
            // Cells wholly outside the ball's disc meet nothing.
            const float x0 = -grid.radius + i * side, y0 = -grid.radius + j * side;
            const float nx = std::clamp(0.0f, x0, x0 + side), ny = std::clamp(0.0f, y0, y0 + side);
            if (nx * nx + ny * ny > r2) continue;
            const glm::vec3 origin = corner + ((i + a) * side) * t + ((j + b) * side) * s;
            rays.AllHits(origin, d, 2.0f * back, hits);
            if (hits.empty()) continue;
            out.counts.push_back(static_cast<uint32_t>(hits.size()));
            for (const RayHit& h : hits) {
                LineHit l;
                l.triangle = h.triangle;
                if (glm::dot(tris[h.triangle].normal, d) > 0.0f) l.triangle |= kFacesAlong;
                l.u = static_cast<uint16_t>(std::lround(std::clamp(h.u, 0.0f, 1.0f) * 65535.0f));
                l.v = static_cast<uint16_t>(std::lround(std::clamp(h.v, 0.0f, 1.0f) * 65535.0f));
                out.hits.push_back(l);
            }
        }
    return out;
}

}  // namespace

std::vector<glm::vec3> HemisphereDirections(int count) {
    // Equal areas in cos θ ∈ (0, 1], golden-angle steps in φ.
    const float golden = kPi * (3.0f - std::sqrt(5.0f));
    std::vector<glm::vec3> dirs(count);
    for (int i = 0; i < count; ++i) {
        const float z = 1.0f - (i + 0.5f) / float(count);
        const float r = std::sqrt(std::max(0.0f, 1.0f - z * z));
        const float phi = golden * float(i);
        dirs[i] = glm::vec3(r * std::cos(phi), r * std::sin(phi), z);
    }
    return dirs;
}

glm::mat3 RandomRotation(uint32_t seed, uint64_t stream) {
    Pcg32 rng(seed, stream);
    const float u1 = rng.Uniform(), u2 = rng.Uniform(), u3 = rng.Uniform();
    const float a = std::sqrt(1.0f - u1), b = std::sqrt(u1);
    const glm::quat q(b * std::cos(2 * kPi * u3), a * std::sin(2 * kPi * u2),
                      a * std::cos(2 * kPi * u2), b * std::sin(2 * kPi * u3));
    return glm::mat3_cast(glm::normalize(q));
}

LineBatch TraceBatch(const RayScene& rays, const LineGrid& grid, const std::vector<glm::vec3>& base,
                     uint32_t seed, uint32_t batch) {
    LineBatch b;
    // Rotation streams apart from the jitter streams (one a direction).
    const glm::mat3 rotation = RandomRotation(seed, (uint64_t(1) << 40) + batch);
    for (const glm::vec3& d : base) b.directions.push_back(glm::normalize(rotation * d));
    std::vector<DirectionLines> parts(b.directions.size());
    tbb::parallel_for(size_t(0), b.directions.size(), [&](size_t k) {
        parts[k] = TraceDirection(rays, grid, b.directions[k], seed,
                                  (uint64_t(batch) << 20) + uint64_t(k));
    });
    size_t lines = 0, hits = 0;
    for (const DirectionLines& p : parts) lines += p.counts.size(), hits += p.hits.size();
    b.lineHits.reserve(lines + 1);
    b.hits.reserve(hits);
    b.lineHits.push_back(0);
    for (DirectionLines& p : parts) {
        b.directionLines.push_back(static_cast<uint32_t>(b.lineHits.size() - 1));
        for (uint32_t c : p.counts) b.lineHits.push_back(b.lineHits.back() + c);
        b.hits.insert(b.hits.end(), p.hits.begin(), p.hits.end());
        p = {};
    }
    b.directionLines.push_back(static_cast<uint32_t>(b.lineHits.size() - 1));
    return b;
}

SurfelFacets::SurfelFacets(const RayScene& rays, size_t surfels) {
    const std::vector<RayTriangle>& tris = rays.Triangles();
    std::vector<uint32_t> count(surfels + 1, 0);
    for (uint32_t t = 0; t < tris.size(); ++t) {
        const glm::uvec3& c = rays.Corners(t);
        ++count[c.x], ++count[c.y], ++count[c.z];
    }
    offsets.assign(surfels + 1, 0);
    for (size_t s = 0; s < surfels; ++s) offsets[s + 1] = offsets[s] + count[s];
    facets.resize(offsets[surfels]);
    std::vector<uint32_t> next(offsets.begin(), offsets.end() - 1);
    for (uint32_t t = 0; t < tris.size(); ++t) {
        const glm::vec3 f = tris[t].normal * (tris[t].area / 3.0f);
        const glm::uvec3& c = rays.Corners(t);
        facets[next[c.x]++] = f, facets[next[c.y]++] = f, facets[next[c.z]++] = f;
    }
}

void SurfelFacets::Coverage(const std::vector<glm::vec3>& directions,
                            std::vector<float>& coverage) const {
    tbb::parallel_for(size_t(0), coverage.size(), [&](size_t s) {
        float sum = 0.0f;
        for (const glm::vec3& d : directions)
            for (uint32_t k = offsets[s]; k < offsets[s + 1]; ++k)
                sum += std::abs(glm::dot(facets[k], d));  // P_s(d) + P_s(−d)
        coverage[s] += sum;
    });
}

namespace {

// A direction of travel's sums per surfel: Σ φ L_I and Σ φ over the hits it received, and
// which surfels were met (to add and clear them after the direction).
struct TravelSums {
    std::vector<glm::vec3> light;
    std::vector<float> weight;
    std::vector<uint32_t> met;
    explicit TravelSums(size_t surfels) : light(surfels, glm::vec3(0.0f)), weight(surfels, 0.0f) {}
    void Receive(uint32_t s, float w, const glm::vec3& l) {
        if (w <= 0.0f) return;
        if (weight[s] == 0.0f) met.push_back(s);
        weight[s] += w;
        light[s] += w * l;
    }
    // Adds each met surfel's share for light travelling along `travel` (WalkBatch).
    void Flush(const SurfelFacets& facets, const glm::vec3& travel, float cellArea,
               std::vector<glm::vec3>& weighted) {
        for (uint32_t s : met) {
            const float p = facets.Projected(s, travel);
            weighted[s] +=
                p >= kRatioCells * cellArea ? (p / weight[s]) * light[s] : cellArea * light[s];
            light[s] = glm::vec3(0.0f), weight[s] = 0.0f;
        }
        met.clear();
    }
};

// What one thread adds up.
struct WalkSums {
    std::vector<glm::vec3> weighted;
    TravelSums travel;
    explicit WalkSums(size_t surfels) : weighted(surfels, glm::vec3(0.0f)), travel(surfels) {}
};

}  // namespace

void WalkBatch(const LineBatch& b, const RayScene& rays, const SurfelFacets& facets, float cellArea,
               const std::vector<glm::vec3>& radiance, const Environment* sky,
               std::vector<glm::vec3>& weighted) {
    const size_t surfels = weighted.size();
    tbb::combinable<WalkSums> local([&] { return WalkSums(surfels); });
    tbb::parallel_for(size_t(0), b.directions.size(), [&](size_t k) {
        WalkSums& sums = local.local();
        TravelSums& travel = sums.travel;
        const glm::vec3 d = b.directions[k];
        // A hit's three surfels and their hat weights.
        auto corners = [&](const LineHit& h, glm::uvec3& c, glm::vec3& w) {
            c = rays.Corners(h.triangle & ~kFacesAlong);
            const float u = h.u * (1.0f / 65535.0f), v = h.v * (1.0f / 65535.0f);
            w = glm::vec3(1.0f - u - v, u, v);
        };
        auto receive = [&](const LineHit& h, const glm::vec3& l) {
            glm::uvec3 c;
            glm::vec3 w;
            corners(h, c, w);
            travel.Receive(c.x, w.x, l), travel.Receive(c.y, w.y, l), travel.Receive(c.z, w.z, l);
        };
        auto exitant = [&](const LineHit& h) {
            glm::uvec3 c;
            glm::vec3 w;
            corners(h, c, w);
            return w.x * radiance[c.x] + w.y * radiance[c.y] + w.z * radiance[c.z];
        };
        const uint32_t lines0 = b.directionLines[k], lines1 = b.directionLines[k + 1];
        // The sky's light travelling along +d arrives from −d, and along −d from +d.
        const glm::vec3 skyAlong = sky ? sky->Radiance(-d) : glm::vec3(0.0f);
        const glm::vec3 skyAgainst = sky ? sky->Radiance(d) : glm::vec3(0.0f);
        // Front to back, the light travelling along +d.
        for (uint32_t line = lines0; line < lines1; ++line) {
            glm::vec3 l = skyAlong;
            for (uint32_t i = b.lineHits[line]; i < b.lineHits[line + 1]; ++i) {
                const LineHit& h = b.hits[i];
                if (h.triangle & kFacesAlong) {
                    l = exitant(h);  // a sender overwrites the interface
                } else {
                    receive(h, l);  // a receiver takes it; its black back follows
                    l = glm::vec3(0.0f);
                }
            }
        }
        travel.Flush(facets, d, cellArea, sums.weighted);
        // Back to front, along −d: the roles swap.
        for (uint32_t line = lines0; line < lines1; ++line) {
            glm::vec3 l = skyAgainst;
            for (uint32_t i = b.lineHits[line + 1]; i-- > b.lineHits[line];) {
                const LineHit& h = b.hits[i];
                if (h.triangle & kFacesAlong) {
                    receive(h, l);
                    l = glm::vec3(0.0f);
                } else {
                    l = exitant(h);
                }
            }
        }
        travel.Flush(facets, -d, cellArea, sums.weighted);
    });
    local.combine_each([&](const WalkSums& part) {
        for (size_t s = 0; s < surfels; ++s) weighted[s] += part.weighted[s];
    });
}

}  // namespace penumbra
