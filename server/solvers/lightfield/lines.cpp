// Tracing and walking the light field's parallel lines (lines.h).
#include "solvers/lightfield/lines.h"

#include <tbb/combinable.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <glm/gtc/quaternion.hpp>
#include <numbers>

#include "base/numeric.h"
#include "base/pcg.h"
#include "rays/sampling.h"

namespace penumbra {
namespace {

// The lines of one direction that meet something: per line its cell and hit count, in cell
// order, and their hits.
struct DirectionLines {
    std::vector<uint32_t> cells;
    std::vector<uint32_t> counts;
    std::vector<LineHit> hits;
};

// Traces cell `cell`'s line into `out` (nothing when it meets nothing).
void TraceCell(const RayScene& rays, const DirectionGrid& g, const glm::vec2& jitter, uint32_t cell,
               std::vector<RayHit>& scratch, DirectionLines& out) {
    const int i = int(cell % uint32_t(g.n)), j = int(cell / uint32_t(g.n));
    if (g.Outside(i, j)) return;
    const glm::vec3 origin =
        g.corner + ((i + jitter.x) * g.side) * g.t + ((j + jitter.y) * g.side) * g.s;
    rays.AllHits(origin, g.d, g.length, scratch);
    if (scratch.empty()) return;
    out.cells.push_back(cell);
    out.counts.push_back(static_cast<uint32_t>(scratch.size()));
    const std::vector<RayTriangle>& tris = rays.Triangles();
    for (const RayHit& h : scratch) {
        LineHit l;
        l.triangle = h.triangle;
        if (glm::dot(tris[h.triangle].normal, g.d) > 0.0f) l.triangle |= kFacesAlong;
        l.u = static_cast<uint16_t>(std::lround(std::clamp(h.u, 0.0f, 1.0f) * 65535.0f));
        l.v = static_cast<uint16_t>(std::lround(std::clamp(h.v, 0.0f, 1.0f) * 65535.0f));
        out.hits.push_back(l);
    }
}

// The batch's arrays from its directions' lines, in direction order.
void Assemble(std::vector<DirectionLines>& parts, LineBatch& b) {
    size_t lines = 0, hits = 0;
    for (const DirectionLines& p : parts) lines += p.counts.size(), hits += p.hits.size();
    b.directionLines.clear();
    b.lineHits.clear();
    b.lineCells.clear();
    b.hits.clear();
    b.lineHits.reserve(lines + 1);
    b.lineCells.reserve(lines);
    b.hits.reserve(hits);
    b.lineHits.push_back(0);
    for (DirectionLines& p : parts) {
        b.directionLines.push_back(static_cast<uint32_t>(b.lineCells.size()));
        for (uint32_t c : p.counts) b.lineHits.push_back(b.lineHits.back() + c);
        b.lineCells.insert(b.lineCells.end(), p.cells.begin(), p.cells.end());
        b.hits.insert(b.hits.end(), p.hits.begin(), p.hits.end());
        p = {};
    }
    b.directionLines.push_back(static_cast<uint32_t>(b.lineCells.size()));
}

}  // namespace

DirectionGrid::DirectionGrid(const LineGrid& grid, const glm::vec3& direction) : d(direction) {
    Basis(d, t, s);
    n = grid.cells;
    side = 2.0f * grid.radius / float(n);
    // Lines start outside the ball and run through it.
    const float back = 1.01f * grid.radius;
    corner = grid.centre - grid.radius * (t + s) - back * d;
    length = 2.0f * back;
}

bool DirectionGrid::Outside(int i, int j) const {
    const float r = 0.5f * side * float(n);
    const float x0 = -r + i * side, y0 = -r + j * side;
    const float nx = std::clamp(0.0f, x0, x0 + side), ny = std::clamp(0.0f, y0, y0 + side);
    return nx * nx + ny * ny > r * r;
}

glm::vec2 DirectionGrid::Jitter(LineJitter mode, uint32_t seed, uint32_t batch, size_t direction,
                                uint32_t cell) {
    // A cell's stream below 2^40 a batch, a direction's in a range of its own.
    const uint64_t stream = mode == LineJitter::kPerCell
                                ? (uint64_t(batch) << 40) | (uint64_t(direction) << 24) | cell
                                : (uint64_t(1) << 61) + (uint64_t(batch) << 24) + direction;
    Pcg32 rng(seed, stream);
    const float a = rng.Uniform();
    return {a, rng.Uniform()};
}

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

std::vector<glm::vec3> RotatedDirections(const std::vector<glm::vec3>& base, uint32_t seed,
                                         uint32_t batch) {
    // Rotation streams apart from the jitter streams (DirectionGrid::Jitter's).
    const glm::mat3 rotation = RandomRotation(seed, (uint64_t(1) << 62) + batch);
    std::vector<glm::vec3> out;
    for (const glm::vec3& d : base) out.push_back(glm::normalize(rotation * d));
    return out;
}

LineBatch TraceBatch(const RayScene& rays, const LineGrid& grid, const std::vector<glm::vec3>& base,
                     uint32_t seed, uint32_t batch) {
    LineBatch b;
    b.batch = batch;
    b.directions = RotatedDirections(base, seed, batch);
    std::vector<DirectionLines> parts(b.directions.size());
    tbb::parallel_for(size_t(0), b.directions.size(), [&](size_t k) {
        const DirectionGrid g(grid, b.directions[k]);
        std::vector<RayHit> scratch;
        const uint32_t cells = uint32_t(g.n) * uint32_t(g.n);
        for (uint32_t c = 0; c < cells; ++c)
            TraceCell(rays, g, DirectionGrid::Jitter(grid.jitter, seed, batch, k, c), c, scratch,
                      parts[k]);
    });
    Assemble(parts, b);
    return b;
}

size_t RetraceBatch(const RayScene& rays, const LineGrid& grid, uint32_t seed, const Bounds& box,
                    LineBatch& b) {
    if (box.Empty()) return 0;
    std::vector<DirectionLines> parts(b.directions.size());
    std::vector<size_t> traced(b.directions.size(), 0);
    tbb::parallel_for(size_t(0), b.directions.size(), [&](size_t k) {
        const DirectionGrid g(grid, b.directions[k]);
        // The box's shadow on the direction's grid, in cells (its corners projected).
        float lo[2] = {1e30f, 1e30f}, hi[2] = {-1e30f, -1e30f};
        for (int c = 0; c < 8; ++c) {
            const glm::vec3 p((c & 1) ? box.hi.x : box.lo.x, (c & 2) ? box.hi.y : box.lo.y,
                              (c & 4) ? box.hi.z : box.lo.z);
            const glm::vec3 q = p - g.corner;
            const float x = glm::dot(q, g.t) / g.side, y = glm::dot(q, g.s) / g.side;
            lo[0] = std::min(lo[0], x), hi[0] = std::max(hi[0], x);
            lo[1] = std::min(lo[1], y), hi[1] = std::max(hi[1], y);
        }
        const int i0 = std::max(0, int(std::floor(lo[0]))), i1 = std::min(g.n - 1, int(hi[0]));
        const int j0 = std::max(0, int(std::floor(lo[1]))), j1 = std::min(g.n - 1, int(hi[1]));
        auto inside = [&](uint32_t cell) {
            const int i = int(cell % uint32_t(g.n)), j = int(cell / uint32_t(g.n));
            return i >= i0 && i <= i1 && j >= j0 && j <= j1;
        };
        // Keep the lines outside the shadow, trace the cells inside it again, in cell order.
        DirectionLines& out = parts[k];
        std::vector<RayHit> scratch;
        uint32_t line = b.directionLines[k];
        const uint32_t end = b.directionLines[k + 1];
        auto keep = [&](uint32_t until) {
            for (; line < end && b.lineCells[line] < until; ++line) {
                if (inside(b.lineCells[line])) continue;
                out.cells.push_back(b.lineCells[line]);
                out.counts.push_back(b.lineHits[line + 1] - b.lineHits[line]);
                out.hits.insert(out.hits.end(), b.hits.begin() + b.lineHits[line],
                                b.hits.begin() + b.lineHits[line + 1]);
            }
        };
        for (int j = j0; j <= j1; ++j)
            for (int i = i0; i <= i1; ++i) {
                const uint32_t c = uint32_t(j) * uint32_t(g.n) + uint32_t(i);
                keep(c);
                if (line < end && b.lineCells[line] == c) ++line;
                TraceCell(rays, g, DirectionGrid::Jitter(grid.jitter, seed, b.batch, k, c), c,
                          scratch, out);
                ++traced[k];
            }
        keep(~0u);
    });
    Assemble(parts, b);
    size_t n = 0;
    for (size_t t : traced) n += t;
    return n;
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
    // Facets with one normal add up to one (max(0, −f·t) is linear in f along a normal): a
    // surfel inside a flat face keeps one instead of six.
    size_t kept = 0;
    for (size_t s = 0; s < surfels; ++s) {
        const size_t first = kept;
        for (uint32_t k = offsets[s]; k < offsets[s + 1]; ++k) {
            const glm::vec3 f = facets[k];
            const float len = glm::length(f);
            bool merged = false;
            for (size_t j = first; j < kept && !merged; ++j)
                if (glm::dot(facets[j], f) >= 0.999999f * glm::length(facets[j]) * len)
                    facets[j] += f, merged = true;
            if (!merged) facets[kept++] = f;
        }
        offsets[s] = static_cast<uint32_t>(first);
    }
    offsets[surfels] = static_cast<uint32_t>(kept);
    facets.resize(kept);
    most.assign(surfels, 0.0f);
    for (size_t s = 0; s < surfels; ++s)
        for (uint32_t k = offsets[s]; k < offsets[s + 1]; ++k) most[s] += glm::length(facets[k]);
}

SurfelSmoothing::SurfelSmoothing(const RayScene& rays, const std::vector<glm::vec3>& positions,
                                 const std::vector<glm::vec3>& normals, int passes)
    : passes_(passes) {
    if (passes <= 0) return;
    const size_t surfels = normals.size();
    std::vector<std::pair<uint32_t, uint32_t>> edges;
    edges.reserve(3 * rays.Triangles().size());
    for (uint32_t t = 0; t < rays.Triangles().size(); ++t) {
        const glm::uvec3& c = rays.Corners(t);
        for (const auto& [a, b] : {std::pair{c.x, c.y}, std::pair{c.y, c.z}, std::pair{c.z, c.x}})
            if (glm::dot(normals[a], normals[b]) >= kSmoothCrease)
                edges.emplace_back(std::min(a, b), std::max(a, b));
    }
    std::sort(edges.begin(), edges.end());
    edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
    // An edge something stands on is cut: a wall across a ceiling, a box on a floor (the
    // segment between the two surfels, lifted off the surface by kSmoothLift of its length,
    // meets a surface).
    std::vector<uint8_t> cut(edges.size(), 0);
    tbb::parallel_for(size_t(0), edges.size(), [&](size_t k) {
        const auto [a, b] = edges[k];
        const glm::vec3 pa = positions[a], pb = positions[b];
        const glm::vec3 lift =
            kSmoothLift * glm::length(pb - pa) * glm::normalize(normals[a] + normals[b]);
        cut[k] = rays.Occluded(pa + lift, pb - pa) || rays.Occluded(pb + lift, pa - pb);
    });
    std::vector<std::pair<uint32_t, uint32_t>> kept;
    kept.reserve(2 * edges.size());
    for (size_t k = 0; k < edges.size(); ++k)
        if (!cut[k]) kept.push_back(edges[k]), kept.emplace_back(edges[k].second, edges[k].first);
    std::sort(kept.begin(), kept.end());
    edges.swap(kept);
    offsets_.assign(surfels + 1, 0);
    for (const auto& e : edges) ++offsets_[e.first + 1];
    for (size_t s = 0; s < surfels; ++s) offsets_[s + 1] += offsets_[s];
    neighbours_.resize(edges.size());
    for (size_t k = 0; k < edges.size(); ++k) neighbours_[k] = edges[k].second;
}

void SurfelSmoothing::Apply(std::vector<glm::vec4>& values, std::vector<glm::vec4>& scratch) const {
    if (passes_ <= 0) return;
    scratch.resize(values.size());
    for (int p = 0; p < passes_; ++p) {
        tbb::parallel_for(size_t(0), values.size(), [&](size_t s) {
            glm::vec4 sum = values[s];
            for (uint32_t k = offsets_[s]; k < offsets_[s + 1]; ++k) sum += values[neighbours_[k]];
            scratch[s] = sum / float(1 + offsets_[s + 1] - offsets_[s]);
        });
        values.swap(scratch);
    }
}

int SmoothingPasses(float side, float elementSize) {
    if (!(elementSize > 0.0f) || side <= elementSize) return 0;
    const float reach = 0.5f * side / elementSize;  // half a cell, in elements
    return std::max(1, int(std::ceil(reach * reach / 0.43f)));
}

namespace {

// A direction of travel's sums per surfel: Σ φ L_I and Σ φ over the hits it received, and
// which surfels were met (to add and clear them after the direction).
struct TravelSums {
    std::vector<glm::vec4> sums;  // per surfel: Σ φ L_I (RGB) and Σ φ (w), side by side
    std::vector<uint32_t> met;
    explicit TravelSums(size_t surfels) : sums(surfels, glm::vec4(0.0f)) {}
    void Receive(uint32_t s, float w, const glm::vec3& l) {
        if (w <= 0.0f) return;
        glm::vec4& sum = sums[s];
        if (sum.w == 0.0f) met.push_back(s);
        sum += glm::vec4(w * l, w);
    }
    // Adds each met surfel's share for light travelling along `travel` (WalkBatch).
    void Flush(const SurfelFacets& facets, const glm::vec3& travel, float cellArea,
               std::vector<glm::vec4>& weighted, const GlossyLines* glossy, size_t column,
               size_t columns) {
        for (uint32_t s : met) {
            const float p = facets.Projected(s, travel);
            const glm::vec3 light(sums[s]);
            const float weight = sums[s].w;
            if (glossy && (*glossy->slot)[s] >= 0 && p > 0.0f)
                glossy->incoming[size_t((*glossy->slot)[s]) * columns + column] =
                    p >= kRatioCells * cellArea ? light / weight : (cellArea / p) * light;
            weighted[s] += p >= kRatioCells * cellArea ? glm::vec4((p / weight) * light, p)
                                                       : cellArea * glm::vec4(light, weight);
            sums[s] = glm::vec4(0.0f);
        }
        met.clear();
    }
};

// What one thread adds up.
struct WalkSums {
    std::vector<glm::vec4> weighted;
    TravelSums travel;
    explicit WalkSums(size_t surfels) : weighted(surfels, glm::vec4(0.0f)), travel(surfels) {}
};

}  // namespace

void WalkBatch(const LineBatch& b, const RayScene& rays, const SurfelFacets& facets, float cellArea,
               const std::vector<glm::vec3>& radiance, const Environment* sky,
               std::vector<glm::vec3>& weighted, std::vector<float>& sampled,
               const GlossyLines* glossy) {
    const size_t surfels = weighted.size();
    const size_t columns = 2 * b.directions.size();
    // Directions no line met a glossy surfel from keep 0.
    if (glossy)
        std::fill(glossy->incoming, glossy->incoming + glossy->slots * columns, glm::vec3(0.0f));
    // A hat that cannot span kRatioCells cells in any direction (P_s ≤ Σ|f|) always takes the
    // first form, Σ φ L_I · A_cell, which needs no sums per direction: its hits add to
    // `weighted` at once (a glossy surfel's record per direction needs them).
    std::vector<uint8_t> small(surfels);
    tbb::parallel_for(size_t(0), surfels, [&](size_t s) {
        small[s] = facets.most[s] < kRatioCells * cellArea && (!glossy || (*glossy->slot)[s] < 0);
    });
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
            for (int k = 0; k < 3; ++k) {
                if (w[k] <= 0.0f) continue;
                if (small[c[k]])
                    sums.weighted[c[k]] += (cellArea * w[k]) * glm::vec4(l, 1.0f);
                else
                    travel.Receive(c[k], w[k], l);
            }
        };
        // A sender's radiance towards travel column `column`: diffuse, plus its glossy
        // surfels' exitant light that way.
        auto exitant = [&](const LineHit& h, size_t column) {
            glm::uvec3 c;
            glm::vec3 w;
            corners(h, c, w);
            glm::vec3 l = w.x * radiance[c.x] + w.y * radiance[c.y] + w.z * radiance[c.z];
            if (glossy)
                for (int k = 0; k < 3; ++k)
                    if (const int32_t g = (*glossy->slot)[c[k]]; g >= 0)
                        l += w[k] * glossy->exitant[size_t(g) * columns + column];
            return l;
        };
        // What of the interface a surface lets through: T of it for glass or a cutout
        // (Material::Passes), nothing for an opaque one, whose black back follows.
        const bool passing = rays.Passing();
        auto through = [&](const LineHit& h, const glm::vec3& l) {
            return passing ? rays.MaterialOf(h.triangle & ~kFacesAlong).transmittance * l
                           : glm::vec3(0.0f);
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
                    l = through(h, l) + exitant(h, k);  // a sender overwrites the interface
                } else {
                    receive(h, l);  // a receiver takes it; its black back follows
                    l = through(h, l);
                }
            }
        }
        travel.Flush(facets, d, cellArea, sums.weighted, glossy, k, columns);
        // Back to front, along −d: the roles swap.
        for (uint32_t line = lines0; line < lines1; ++line) {
            glm::vec3 l = skyAgainst;
            for (uint32_t i = b.lineHits[line + 1]; i-- > b.lineHits[line];) {
                const LineHit& h = b.hits[i];
                if (h.triangle & kFacesAlong) {
                    receive(h, l);
                    l = through(h, l);
                } else {
                    l = through(h, l) + exitant(h, b.directions.size() + k);
                }
            }
        }
        travel.Flush(facets, -d, cellArea, sums.weighted, glossy, b.directions.size() + k, columns);
    });
    local.combine_each([&](const WalkSums& part) {
        for (size_t s = 0; s < surfels; ++s) {
            weighted[s] += glm::vec3(part.weighted[s]);
            sampled[s] += part.weighted[s].w;
        }
    });
}

void LobeWeights(const std::vector<glm::vec3>& directions, const glm::vec3& normal, float exponent,
                 const glm::vec3& t, std::vector<float>& lobe,
                 std::vector<std::pair<uint32_t, float>>& out) {
    out.clear();
    const size_t d = directions.size(), columns = 2 * d;
    auto travel = [&](size_t j) { return j < d ? directions[j] : -directions[j - d]; };
    const float cosIn = -glm::dot(normal, t);
    if (cosIn <= 0.0f) return;
    // Below this cosine the lobe is under 10⁻⁴ of its peak: left out.
    const float floor = std::pow(1e-4f, 1.0f / std::max(exponent, 1e-3f));
    const glm::vec3 r = t + 2.0f * cosIn * normal;  // the mirror image of the travel
    lobe.assign(columns, 0.0f);
    float sum = 0.0f;
    int inside = 0;
    for (size_t j = 0; j < columns; ++j) {
        const float c = glm::dot(r, travel(j));
        lobe[j] = c > floor ? std::pow(c, exponent) : 0.0f;
        sum += lobe[j];
        inside += lobe[j] > 0.0f;
    }
    if (inside < 3) {
        // A lobe narrower than the directions' spacing: the three directions nearest the
        // mirror image, weighted by how much nearer each is than the fourth (the paper's
        // barycentric weights of the three nearest PSFs, Sec. 3.4).
        float best[4] = {-2.0f, -2.0f, -2.0f, -2.0f};
        for (size_t j = 0; j < columns; ++j) {
            float c = glm::dot(r, travel(j));
            for (float& b : best)
                if (c > b) std::swap(c, b);
        }
        sum = 0.0f;
        for (size_t j = 0; j < columns; ++j) {
            const float c = glm::dot(r, travel(j));
            lobe[j] = c >= best[2] ? c - best[3] : 0.0f;
            sum += lobe[j];
        }
    }
    if (!(sum > 0.0f)) return;
    // p̃ Δω = lobe / sum.
    const float scale = (exponent + 2.0f) / (exponent + 1.0f) / sum;
    for (size_t j = 0; j < columns; ++j)
        if (lobe[j] > 0.0f && glm::dot(normal, travel(j)) > 0.0f)
            out.emplace_back(uint32_t(j), lobe[j] * scale);
}

LobeTable::LobeTable(const std::vector<glm::vec3>& directions, const glm::vec3& normal,
                     float exponent) {
    const size_t d = directions.size();
    columns_ = 2 * d;
    std::vector<float> scratch;
    std::vector<std::pair<uint32_t, float>> row;
    for (size_t k = 0; k < columns_; ++k) {
        const glm::vec3 t = k < d ? directions[k] : -directions[k - d];
        LobeWeights(directions, normal, exponent, t, scratch, row);
        // The incoming L cos θ Δω: the Δω is in B_j.
        const float cosIn = -glm::dot(normal, t);
        for (const auto& [j, w] : row) entries_.push_back({uint32_t(k), j, w * cosIn});
    }
}

void LobeTable::Reflect(const glm::vec3& f0, const glm::vec3* incoming, glm::vec3* exitant) const {
    for (size_t j = 0; j < columns_; ++j) exitant[j] = glm::vec3(0.0f);
    for (const Entry& e : entries_) exitant[e.to] += e.weight * incoming[e.from];
    for (size_t j = 0; j < columns_; ++j) exitant[j] *= f0;
}

}  // namespace penumbra
