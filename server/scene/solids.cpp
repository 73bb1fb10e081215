// Which surfaces bound solids (solids.h): welding, winding, shells about shared edges and the
// closure test of each shell, per node and across the nodes that do not close alone.
#include "scene/solids.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <unordered_map>

#include "base/check.h"

namespace penumbra {

namespace {

// Distance from `p` to triangle abc (closest point by Voronoi regions, Ericson 5.1.5).
float PointTriangleDistance(const glm::vec3& p, const glm::vec3& a, const glm::vec3& b,
                            const glm::vec3& c) {
    glm::vec3 ab = b - a, ac = c - a, ap = p - a;
    float d1 = glm::dot(ab, ap), d2 = glm::dot(ac, ap);
    if (d1 <= 0 && d2 <= 0) return glm::length(ap);
    glm::vec3 bp = p - b;
    float d3 = glm::dot(ab, bp), d4 = glm::dot(ac, bp);
    if (d3 >= 0 && d4 <= d3) return glm::length(bp);
    float vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0) return glm::length(p - (a + ab * (d1 / (d1 - d3))));
    glm::vec3 cp = p - c;
    float d5 = glm::dot(ab, cp), d6 = glm::dot(ac, cp);
    if (d6 >= 0 && d5 <= d6) return glm::length(cp);
    float vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0) return glm::length(p - (a + ac * (d2 / (d2 - d6))));
    float va = d3 * d6 - d5 * d4;
    if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0)
        return glm::length(p - (b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)))));
    float denom = 1.0f / (va + vb + vc);
    return glm::length(p - (a + ab * (vb * denom) + ac * (vc * denom)));
}

struct OrientedMesh {
    std::vector<glm::vec3> points;      // welded positions
    std::vector<glm::uvec3> triangles;  // wound so the front is where vertex normals point
    glm::vec3 lo{1e30f}, hi{-1e30f};    // bounds of the points
};

// Welds the triangles of the primitives added into one OrientedMesh: positions within a
// `cell` grid step are one point, so meshes welded on one grid drop the same degenerate
// triangles and keep the others in the order added.
class Welder {
  public:
    explicit Welder(float cell) : cell_(cell) {}
    void Add(const Primitive& prim) {
        std::vector<uint32_t> id(prim.positions.size());
        for (size_t i = 0; i < prim.positions.size(); ++i) {
            const glm::vec3 q = glm::round(prim.positions[i] / cell_);
            const std::array<int64_t, 3> k{int64_t(q.x), int64_t(q.y), int64_t(q.z)};
            auto [it, added] = ids_.emplace(k, uint32_t(mesh_.points.size()));
            if (added) mesh_.points.push_back(prim.positions[i]);
            id[i] = it->second;
            mesh_.lo = glm::min(mesh_.lo, prim.positions[i]);
            mesh_.hi = glm::max(mesh_.hi, prim.positions[i]);
        }
        for (size_t t = 0; t + 2 < prim.indices.size(); t += 3) {
            uint32_t i0 = prim.indices[t], i1 = prim.indices[t + 1], i2 = prim.indices[t + 2];
            const glm::vec3 &a = prim.positions[i0], &b = prim.positions[i1];
            const glm::vec3& c = prim.positions[i2];
            const glm::vec3 normal = prim.normals[i0] + prim.normals[i1] + prim.normals[i2];
            if (glm::dot(glm::cross(b - a, c - a), normal) < 0.0f) std::swap(i1, i2);
            const glm::uvec3 v(id[i0], id[i1], id[i2]);
            if (v.x == v.y || v.y == v.z || v.z == v.x) continue;  // degenerate
            mesh_.triangles.push_back(v);
        }
    }
    OrientedMesh Take() { return std::move(mesh_); }

  private:
    struct KeyHash {
        size_t operator()(const std::array<int64_t, 3>& k) const {
            return size_t(k[0] * 73856093) ^ size_t(k[1] * 19349663) ^ size_t(k[2] * 83492791);
        }
    };
    float cell_;
    OrientedMesh mesh_;
    std::unordered_map<std::array<int64_t, 3>, uint32_t, KeyHash> ids_;
};

// A mesh's triangles split into shells: the surfaces of separate solids, joined across the
// edges where they pair. An edge of two triangles joins them. Where several solids of one
// mesh meet at an edge (boxes stacked with their sides flush, a shelf's board against its
// side), its triangles are paired about the edge: going round it, each triangle is joined to
// its neighbour across its back (the solid's inside between them), faces that lie in one
// plane ordered so that the gap between two touching solids is outside both. A shell with an
// edge that does not pair up (a triangle wound against its neighbour, an odd fan) is `broken`:
// it bounds no solid.
struct Shells {
    std::vector<uint32_t> of;  // per triangle
    uint32_t count = 0;
    std::vector<bool> broken;  // per shell
    // The open edges (a, b) as their one triangle runs them, each with that triangle.
    std::vector<std::array<uint32_t, 3>> open;
};

Shells SplitShells(const OrientedMesh& m) {
    const size_t n = m.triangles.size();
    std::vector<uint32_t> parent(n);
    for (size_t t = 0; t < n; ++t) parent[t] = uint32_t(t);
    auto find = [&](uint32_t t) {
        while (parent[t] != t) t = parent[t] = parent[parent[t]];
        return t;
    };
    // Undirected edge (low << 32 | high) → its triangles, each with its corner off the edge
    // and whether it runs low → high.
    struct Wing {
        uint32_t triangle, corner;
        bool forward;
    };
    std::unordered_map<uint64_t, std::vector<Wing>> edges;
    for (size_t t = 0; t < n; ++t)
        for (int e = 0; e < 3; ++e) {
            const uint32_t a = m.triangles[t][e], b = m.triangles[t][(e + 1) % 3],
                           c = m.triangles[t][(e + 2) % 3];
            const uint32_t lo = std::min(a, b), hi = std::max(a, b);
            edges[uint64_t(lo) << 32 | hi].push_back({uint32_t(t), c, a == lo});
        }
    constexpr double kTwoPi = 6.283185307179586, kTie = 1e-4;
    struct Around {
        double angle;
        bool frontAhead;  // its front faces the way the angle grows: the inside lies behind
        uint32_t wing;
    };
    std::vector<Around> around;
    std::vector<std::array<uint32_t, 3>> open;
    std::vector<uint32_t> unpaired;  // triangles on an edge that does not pair up
    auto fail = [&](const std::vector<Wing>& wings) {
        for (const Wing& w : wings) unpaired.push_back(w.triangle);
    };
    for (const auto& [key, wings] : edges) {
        if (wings.size() == 1) {  // an open edge: the shell's boundary
            const uint32_t lo = uint32_t(key >> 32), hi = uint32_t(key);
            open.push_back(wings[0].forward ? std::array<uint32_t, 3>{lo, hi, wings[0].triangle}
                                            : std::array<uint32_t, 3>{hi, lo, wings[0].triangle});
            continue;
        }
        if (wings.size() == 2) {
            if (wings[0].forward == wings[1].forward) {
                fail(wings);
                continue;
            }
            parent[find(wings[0].triangle)] = find(wings[1].triangle);
            continue;
        }
        // The triangles' half-planes about the edge, by angle from the first one's.
        const glm::dvec3 pa(m.points[key >> 32]), pb(m.points[uint32_t(key)]);
        const glm::dvec3 axis = glm::normalize(pb - pa);
        auto across = [&](const Wing& w) {
            const glm::dvec3 q = glm::dvec3(m.points[w.corner]) - pa;
            return q - glm::dot(q, axis) * axis;
        };
        const glm::dvec3 u = glm::normalize(across(wings[0])), v = glm::cross(axis, u);
        around.clear();
        bool degenerate = false;
        for (uint32_t k = 0; k < wings.size() && !degenerate; ++k) {
            const glm::dvec3 w = across(wings[k]);
            degenerate = !(glm::length(w) > 0.0);
            if (degenerate) break;
            double angle = std::atan2(glm::dot(w, v), glm::dot(w, u));
            if (angle < 0.0) angle += kTwoPi;
            if (angle > kTwoPi - kTie) angle -= kTwoPi;  // in one plane with the first
            const glm::uvec3& t = m.triangles[wings[k].triangle];
            const glm::dvec3 normal =
                glm::cross(glm::dvec3(m.points[t.y]) - glm::dvec3(m.points[t.x]),
                           glm::dvec3(m.points[t.z]) - glm::dvec3(m.points[t.x]));
            around.push_back({angle, glm::dot(normal, glm::cross(axis, w)) > 0.0, k});
        }
        if (degenerate) {
            fail(wings);
            continue;
        }
        std::sort(around.begin(), around.end(),
                  [](const Around& x, const Around& y) { return x.angle < y.angle; });
        // Faces in one plane: those whose inside lies behind (the lower angles) first.
        for (size_t i = 0; i < around.size();) {
            size_t j = i + 1;
            while (j < around.size() && around[j].angle - around[j - 1].angle < kTie) ++j;
            std::stable_sort(
                around.begin() + long(i), around.begin() + long(j),
                [](const Around& x, const Around& y) { return x.frontAhead && !y.frontAhead; });
            i = j;
        }
        const size_t count = around.size();
        for (size_t i = 0; i < count; ++i) {
            const Around& x = around[i];
            const Around& y =
                x.frontAhead ? around[(i + count - 1) % count] : around[(i + 1) % count];
            // Its neighbour must turn its inside back to it, and run the edge the other way.
            if (y.frontAhead == x.frontAhead || wings[x.wing].forward == wings[y.wing].forward) {
                fail(wings);
                break;
            }
            parent[find(wings[x.wing].triangle)] = find(wings[y.wing].triangle);
        }
    }
    Shells shells;
    shells.open = std::move(open);
    shells.of.assign(n, 0);
    std::vector<uint32_t> id(n, UINT32_MAX);
    for (size_t t = 0; t < n; ++t) {
        uint32_t& r = id[find(uint32_t(t))];
        if (r == UINT32_MAX) r = shells.count++;
        shells.of[t] = r;
    }
    shells.broken.assign(shells.count, false);
    for (uint32_t t : unpaired) shells.broken[shells.of[t]] = true;
    return shells;
}

// Per shell of `sh` over `m`: whether it bounds a solid. Its edges all pair up; its volume is
// positive and far from flat (a planar open sheet has none, whatever its boundary touches);
// each of its open edges lies on another surface: `sealed(shell, point)`.
template <class Sealed>
std::vector<bool> ClosedShells(const OrientedMesh& m, const Shells& sh, const Sealed& sealed) {
    std::vector<double> area(sh.count, 0.0), volume(sh.count, 0.0);
    for (size_t t = 0; t < m.triangles.size(); ++t) {
        const glm::uvec3& v = m.triangles[t];
        area[sh.of[t]] += 0.5 * glm::length(glm::cross(m.points[v.y] - m.points[v.x],
                                                       m.points[v.z] - m.points[v.x]));
    }
    // Signed volume (divergence theorem) about a point on the shell's open boundary's cap, so
    // a planar cap adds nothing: positive when the fronts face out.
    std::vector<glm::dvec3> origin(sh.count, glm::dvec3(0.0));
    std::vector<uint32_t> openEdges(sh.count, 0);
    for (const auto& [a, b, t] : sh.open) {
        origin[sh.of[t]] += glm::dvec3(m.points[a]);
        ++openEdges[sh.of[t]];
    }
    for (uint32_t k = 0; k < sh.count; ++k)
        if (openEdges[k] > 0) origin[k] /= double(openEdges[k]);
    for (size_t t = 0; t < m.triangles.size(); ++t) {
        const glm::uvec3& v = m.triangles[t];
        const glm::dvec3& o = origin[sh.of[t]];
        volume[sh.of[t]] +=
            glm::dot(glm::dvec3(m.points[v.x]) - o,
                     glm::cross(glm::dvec3(m.points[v.y]) - o, glm::dvec3(m.points[v.z]) - o)) /
            6.0;
    }
    std::vector<bool> closed(sh.count);
    for (uint32_t k = 0; k < sh.count; ++k)
        closed[k] = !sh.broken[k] && volume[k] > 1e-3 * area[k] * std::sqrt(area[k]);
    // The open boundary (tested last: the costliest, and only for shells still in question).
    for (const auto& [a, b, t] : sh.open) {
        const uint32_t k = sh.of[t];
        if (!closed[k]) continue;
        const glm::vec3 &pa = m.points[a], &pb = m.points[b];
        closed[k] = sealed(k, pa) && sealed(k, pb) && sealed(k, 0.5f * (pa + pb));
    }
    return closed;
}

// Union-find over small indices.
struct Groups {
    std::vector<uint32_t> parent;
    explicit Groups(size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), 0u); }
    uint32_t Find(uint32_t x) {
        while (parent[x] != x) x = parent[x] = parent[parent[x]];
        return x;
    }
    // Joins two groups under the smaller root, so a root is its group's smallest index.
    void Join(uint32_t a, uint32_t b) {
        a = Find(a), b = Find(b);
        if (a != b) parent[std::max(a, b)] = std::min(a, b);
    }
};

}  // namespace

std::vector<int> NodeSolids(const Scene& scene) {
    const float diameter = std::max(scene.Diameter(), 1e-6f);
    const float cell = diameter * 1e-6f;   // welds positions far closer than any element
    const float touch = diameter * 1e-4f;  // an open edge this close to a surface is sealed
    const size_t nodes = scene.nodes.size();
    // Each node's triangles, welded and wound front-out, and its shells.
    std::vector<OrientedMesh> meshes(nodes);
    std::vector<Shells> shells(nodes);
    for (size_t n = 0; n < nodes; ++n) {
        Welder w(cell);
        for (uint32_t p : scene.nodes[n].primitives) w.Add(scene.primitives[p]);
        meshes[n] = w.Take();
        shells[n] = SplitShells(meshes[n]);
    }
    // Is `p` on a triangle of a surface other than the shell under test (`ofShell(node,
    // triangle)` says which triangles are that shell's)?
    auto onOtherSurface = [&](const glm::vec3& p, const auto& ofShell) {
        for (size_t o = 0; o < nodes; ++o) {
            const OrientedMesh& m = meshes[o];
            if (glm::any(glm::lessThan(p, m.lo - touch)) ||
                glm::any(glm::greaterThan(p, m.hi + touch)))
                continue;
            for (size_t t = 0; t < m.triangles.size(); ++t) {
                if (ofShell(o, t)) continue;
                const glm::uvec3& v = m.triangles[t];
                if (PointTriangleDistance(p, m.points[v.x], m.points[v.y], m.points[v.z]) <= touch)
                    return true;
            }
        }
        return false;
    };

    // A node whose shells all close solids is a solid of its own.
    std::vector<int> solid(nodes, -1);
    std::vector<uint32_t> open;  // nodes with triangles that do not close alone
    for (size_t n = 0; n < nodes; ++n) {
        if (meshes[n].triangles.empty()) continue;
        const std::vector<bool> closed =
            ClosedShells(meshes[n], shells[n], [&](uint32_t k, const glm::vec3& p) {
                return onOtherSurface(
                    p, [&](size_t o, size_t t) { return o == n && shells[n].of[t] == k; });
            });
        if (std::all_of(closed.begin(), closed.end(), [](bool c) { return c; }))
            solid[n] = int(n);
        else
            open.push_back(uint32_t(n));
    }
    if (open.size() < 2) return solid;

    // The open nodes welded together on the same grid: their triangles in node order, each
    // node's in its own mesh's order (`first` maps a node's triangle to the joint mesh's).
    Welder w(cell);
    constexpr size_t kNone = SIZE_MAX;
    std::vector<size_t> first(nodes, kNone);
    size_t count = 0;
    for (uint32_t n : open) {
        first[n] = count;
        count += meshes[n].triangles.size();
        for (uint32_t p : scene.nodes[n].primitives) w.Add(scene.primitives[p]);
    }
    const OrientedMesh joint = w.Take();
    PENUMBRA_CHECK_EQ(joint.triangles.size(), count);
    const Shells jointShells = SplitShells(joint);
    const std::vector<bool> closed =
        ClosedShells(joint, jointShells, [&](uint32_t k, const glm::vec3& p) {
            return onOtherSurface(p, [&](size_t o, size_t t) {
                return first[o] != kNone && jointShells.of[first[o] + t] == k;
            });
        });
    // A node all of whose triangles lie on closed shells closes solids with the other nodes
    // of those shells; each group is named by its smallest node.
    Groups groups(nodes);
    std::vector<uint32_t> shellNode(jointShells.count, UINT32_MAX);
    std::vector<uint32_t> joined;
    for (uint32_t n : open) {
        const size_t end = first[n] + meshes[n].triangles.size();
        bool all = true;
        for (size_t t = first[n]; all && t < end; ++t) all = closed[jointShells.of[t]];
        if (!all) continue;
        joined.push_back(n);
        for (size_t t = first[n]; t < end; ++t) {
            uint32_t& owner = shellNode[jointShells.of[t]];
            if (owner == UINT32_MAX) owner = n;
            groups.Join(owner, n);
        }
    }
    for (uint32_t n : joined) solid[n] = int(groups.Find(n));
    return solid;
}

std::vector<bool> ClosedNodes(const Scene& scene) {
    const std::vector<int> solid = NodeSolids(scene);
    std::vector<bool> closed(solid.size());
    for (size_t n = 0; n < solid.size(); ++n) closed[n] = solid[n] >= 0;
    return closed;
}

}  // namespace penumbra
