// Hierarchical link refinement (Sec. 3.2) on all cores, then a counting sort by receiver.
#include "links/links.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <numbers>

#include "base/check.h"

namespace penumbra {

// Nodes whose members share an orientation to within ~8°: leaves and planar clusters.
// Their links are calibrated like a single oriented surface.
constexpr float kOrientedCos = 0.99f;
bool Oriented(const HierarchyNode& n) { return n.coneCos >= kOrientedCos; }

// Leaves closer than a few element radii: the link's transfer is the integral over the
// sender's area (NearFieldIrradiance) instead of the point-to-point kernel.
constexpr float kNearRadii = 4.0f;
// A near-field transfer below this fraction of the normal-incidence a_s / d² is zero.
constexpr float kNearTrace = 1e-5f;
bool InNearField(const HierarchyNode& r, const HierarchyNode& s, float dist) {
    return r.IsLeaf() && s.IsLeaf() && dist < kNearRadii * (s.discRadius + r.discRadius);
}

namespace {

struct PendingLink {
    uint32_t receiver;
    Link link;
};

struct Refiner {
    const Hierarchy& h;
    const Directions& dirs;
    const LeafNorms& norms;
    const NearField& near;
    float threshold;          // oracle × ω_bin, for the sender
    float receiverThreshold;  // oracle × receiverOracle × ω_bin
    LinkOracle mode;
    const std::vector<MotionBounds>& motion;

    // Sec. 3.3: the smallest distance the centres of `r` and `s` can come to while their
    // groups move within their bounds (a static node's centre stays where it is; a moving
    // cluster's centre stays inside its group's box, which holds all its members).
    float WorstDistance(const HierarchyNode& r, const HierarchyNode& s) const {
        glm::vec3 lo[2], hi[2];
        const HierarchyNode* n[2] = {&r, &s};
        for (int i = 0; i < 2; ++i) {
            if (n[i]->group == 0) {
                lo[i] = hi[i] = n[i]->center;
            } else {
                lo[i] = motion[n[i]->group - 1].min;
                hi[i] = motion[n[i]->group - 1].max;
            }
        }
        glm::vec3 gap = glm::max(glm::vec3(0.0f), glm::max(lo[0] - hi[1], lo[1] - hi[0]));
        return glm::length(gap);
    }

    template <typename F>
    void Children(uint32_t n, F&& f) const {
        uint32_t left = n + 1;
        uint32_t right = h.nodes[left].end;
        f(left);
        f(right);
    }

    // Fig. 7: a receiver only takes light that arrives on its front side. True when no
    // point of the sender can lie in front of any member of the receiver. A receiver with
    // two-sided members takes light from behind too: they send it on as antiradiance.
    bool Culled(const HierarchyNode& r, const HierarchyNode& s, const glm::vec3& d,
                float dist) const {
        if (r.coneCos <= -1.0f || r.twoSided) return false;
        // Near leaves: kept while any of the sender's extent lies in front (a sender on the
        // edge of a junction has its centre on the receiver's plane and its area in front);
        // MakeLink's integral then says how much arrives.
        if (near.surfels && InNearField(r, s, dist)) {
            const float front = glm::dot(r.normal, d);
            // Neighbours in the receiver's own plane exchange nothing (cos_r = 0 over them).
            const bool coplanar = std::abs(front) <= 1e-4f * dist &&
                                  std::abs(glm::dot(r.normal, s.normal)) >= 0.9999f;
            return coplanar || front <= -s.radius;
        }
        if (r.IsLeaf() && s.IsLeaf()) return glm::dot(r.normal, d) <= 1e-6f * dist;
        if (dist <= r.radius + s.radius) return false;
        if (r.IsLeaf()) return glm::dot(r.normal, d) <= -s.radius;
        // Normal cone vs the cone of directions from receiver to sender: culled when the
        // angle between the normal and the direction to the sender exceeds π/2 + θ, θ = the
        // cone's half angle + the pair's angular spread. In cosines (no inverse
        // trigonometry): cos(axis) < cos(π/2 + θ) = −sin θ, where θ < π/2; never beyond.
        const float cosC = std::clamp(r.coneCos, -1.0f, 1.0f);
        const float sinS = std::min(1.0f, (r.radius + s.radius) / dist);
        if (cosC <= 0.0f || sinS >= 1.0f) return false;  // θ ≥ π/2
        const float sinC = std::sqrt(1.0f - cosC * cosC), cosS = std::sqrt(1.0f - sinS * sinS);
        // θ < π/2 ⟺ cos θ = cosC cosS − sinC sinS > 0.
        if (cosC * cosS - sinC * sinS <= 0.0f) return false;
        const float sinTheta = sinC * cosS + cosC * sinS;
        return glm::dot(r.normal, d) < -sinTheta * dist;
    }

    // One refinement step of pair (r, s): either emits its link, drops it, or hands the
    // child pairs to `pair`.
    template <typename Emit, typename Pair>
    void Step(uint32_t r, uint32_t s, Emit&& emit, Pair&& pair) const {
        const HierarchyNode& R = h.nodes[r];
        const HierarchyNode& S = h.nodes[s];
        if (r == s) {
            // Self-links are always subdivided into all pairs of children.
            if (R.IsLeaf()) return;
            Children(r, [&](uint32_t a) { Children(s, [&](uint32_t b) { pair(a, b); }); });
            return;
        }
        // Clusters over several motion groups change shape as the groups move: never link
        // them, split them (they are only the few nodes above the groups' subtrees).
        if (R.group == kMixedGroup || S.group == kMixedGroup) {
            bool splitSender =
                S.group == kMixedGroup && (R.group != kMixedGroup || S.radius >= R.radius);
            if (splitSender)
                Children(s, [&](uint32_t b) { pair(r, b); });
            else
                Children(r, [&](uint32_t a) { pair(a, s); });
            return;
        }
        glm::vec3 d = S.center - R.center;
        float dist = glm::length(d);
        // A pair whose ends move relative to each other (Sec. 3.3) is linked for the worst
        // case over the motion bounds: the closest the ends can come, and no Fig. 7 culling
        // (they may turn to face each other); a back-facing receiver's form factor is zero
        // while it faces away (MakeLink).
        const bool moving = R.group != S.group;
        if (moving)
            dist = WorstDistance(R, S);
        else if (Culled(R, S, d, dist))
            return;
        if (!(R.IsLeaf() && S.IsLeaf())) {
            float dist2 = std::max(dist * dist, 1e-20f);
            bool overlap = dist <= R.radius + S.radius;
            // Oracle: solid angle of sender (and receiver) against the bin's ω_bin. The
            // conservative mode bounds members by the bounding sphere, refines overlapping
            // pairs and also tests the receiver; the paper's tests the sender's area only,
            // the area mode the areas of both.
            float pi = std::numbers::pi_v<float>;
            const bool conservative = mode == LinkOracle::kConservative;
            float rs = conservative ? S.radius : S.discRadius;
            float rr = conservative ? R.radius : R.discRadius;
            float omegaS = pi * rs * rs / dist2;
            float omegaR = pi * rr * rr / dist2;
            if ((conservative && overlap) || (moving && dist <= R.radius + S.radius) ||
                omegaS > threshold || (mode != LinkOracle::kPaper && omegaR > receiverThreshold)) {
                bool splitSender = R.IsLeaf() || (!S.IsLeaf() && S.radius >= R.radius);
                if (splitSender)
                    Children(s, [&](uint32_t b) { pair(r, b); });
                else
                    Children(r, [&](uint32_t a) { pair(a, s); });
                return;
            }
        }
        Link link = MakeLink(h, dirs, norms, near, r, s);
        // Near leaves the integral says nothing arrives (coplanar neighbours): no link.
        if (!moving && link.formFactor == 0.0f && R.IsLeaf() && S.IsLeaf()) return;
        emit(r, link);
    }

    template <typename Emit>
    void Refine(uint32_t r, uint32_t s, Emit&& emit) const {
        Step(r, s, emit, [&](uint32_t a, uint32_t b) { Refine(a, b, emit); });
    }
};

}  // namespace

LeafNorms ComputeLeafNorms(const Hierarchy& h, const Directions& dirs) {
    LeafNorms n;
    n.in.assign(h.size(), 0.0f);
    n.out.assign(h.size(), 0.0f);
    tbb::parallel_for(size_t(0), h.size(), [&](size_t i) {
        if (!Oriented(h.nodes[i])) return;
        n.in[i] = dirs.CosineNorm(-h.nodes[i].normal);
        n.out[i] = dirs.CosineNorm(h.nodes[i].normal);
    });
    return n;
}

NearField BuildNearField(const Surfels& surfels) {
    NearField near;
    near.surfels = &surfels;
    const auto& tri = surfels.refinedTriangles;
    near.offsets.assign(surfels.size() + 1, 0);
    for (uint32_t v : tri) near.offsets[v + 1]++;
    for (size_t i = 0; i < surfels.size(); ++i) near.offsets[i + 1] += near.offsets[i];
    near.triangles.resize(tri.size());
    std::vector<uint32_t> cursor(near.offsets.begin(), near.offsets.end() - 1);
    for (uint32_t t = 0; t < tri.size(); t += 3)
        for (int k = 0; k < 3; ++k) near.triangles[cursor[tri[t + k]]++] = t;
    return near;
}

namespace {

// Centroids of a 6×6 regular subdivision of a triangle (36 equal sub-triangles), as
// barycentrics (u, v) of its corners b and c; φ = 1 − u − v, the hat function of corner a.
struct NearRule {
    static constexpr int kDiv = 6, kPoints = kDiv * kDiv;
    float u[kPoints], v[kPoints], phi[kPoints];
    NearRule() {
        int k = 0;
        for (int row = 0; row < kDiv; ++row)
            for (int col = 0; col < kDiv - row; ++col)
                for (int up = 0; up < (col + row < kDiv - 1 ? 2 : 1); ++up, ++k) {
                    u[k] = static_cast<float>(3 * col + (up ? 2 : 1)) / (3.0f * kDiv);
                    v[k] = static_cast<float>(3 * row + (up ? 2 : 1)) / (3.0f * kDiv);
                    phi[k] = 1.0f - u[k] - v[k];
                }
    }
};

}  // namespace

float NearFieldIrradiance(const NearField& near, uint32_t s, glm::vec3 p, glm::vec3 n) {
    // The centroid rule integrates linear functions exactly; φ_s at a centroid is the
    // barycentric weight of s's corner.
    static const NearRule rule;
    const Surfels& sf = *near.surfels;
    const glm::vec3 ns = sf.normals[s];
    double sum = 0.0;
    for (uint32_t i = near.offsets[s]; i < near.offsets[s + 1]; ++i) {
        uint32_t t = near.triangles[i];
        const uint32_t* v = &sf.refinedTriangles[t];
        int corner = v[0] == s ? 0 : v[1] == s ? 1 : 2;
        glm::vec3 a = sf.positions[v[corner]], b = sf.positions[v[(corner + 1) % 3]],
                  c = sf.positions[v[(corner + 2) % 3]];
        // The receiver's cosine max(0, n·(q − p)) is linear in q before the clamp: where it is
        // not positive at any corner, the whole triangle sends nothing (a coplanar
        // neighbour's, or one behind the receiver). The margin keeps rounding in a plane from
        // integrating a trace that kNearTrace would drop anyway.
        const float margin =
            1e-5f * std::sqrt(std::max(
                        {glm::dot(a - p, a - p), glm::dot(b - p, b - p), glm::dot(c - p, c - p)}));
        if (std::max({glm::dot(n, a - p), glm::dot(n, b - p), glm::dot(n, c - p)}) <= margin)
            continue;
        const float w = 0.5f * glm::length(glm::cross(b - a, c - a)) / NearRule::kPoints;
        // d = p − q = (p − a) − u (b − a) − v (c − a); cos_s cos_r / d² = |n_s·d| max(0, −n·d)
        // / d⁴ (no square root). Written per point into an array so that the loop vectorises.
        const glm::vec3 pa = p - a, ab = b - a, ac = c - a;
        float part[NearRule::kPoints];
        for (int k = 0; k < NearRule::kPoints; ++k) {
            const float dx = pa.x - rule.u[k] * ab.x - rule.v[k] * ac.x;
            const float dy = pa.y - rule.u[k] * ab.y - rule.v[k] * ac.y;
            const float dz = pa.z - rule.u[k] * ab.z - rule.v[k] * ac.z;
            const float d2 = dx * dx + dy * dy + dz * dz;
            const float cs = std::abs(ns.x * dx + ns.y * dy + ns.z * dz);
            const float cr = std::max(0.0f, -(n.x * dx + n.y * dy + n.z * dz));
            // d = 0 has cs = cr = 0, so the floor on d⁴ leaves it 0 without a branch (a
            // division under a condition does not vectorise).
            part[k] = rule.phi[k] * cs * cr / std::max(d2 * d2, std::numeric_limits<float>::min());
        }
        float triangle = 0.0f;
        for (float x : part) triangle += x;
        sum += static_cast<double>(w) * triangle;
    }
    return static_cast<float>(sum);
}

Link MakeLink(const Hierarchy& h, const Directions& dirs, const LeafNorms& norms,
              const NearField& near, uint32_t receiver, uint32_t sender) {
    const HierarchyNode& R = h.nodes[receiver];
    const HierarchyNode& S = h.nodes[sender];
    glm::vec3 d = R.center - S.center;  // direction of travel: sender → receiver
    float dist2 = glm::dot(d, d);
    float dist = std::sqrt(dist2);
    // Centres that coincide (two faces in contact, e.g. a box's base on the floor element
    // under it) give no direction: light leaves along the sender's normal, or arrives against
    // the receiver's. (d / 0 made it NaN, and the bin of a NaN direction undefined: found by
    // UndefinedBehaviorSanitizer.)
    glm::vec3 u = dist > 0.0f   ? d / dist
                  : Oriented(S) ? S.normal
                  : Oriented(R) ? -R.normal
                                : glm::vec3(0.0f, 1.0f, 0.0f);
    // A leaf sender emits radiance on its front side and antiradiance behind (Fig. 6a), and
    // a leaf receiver takes light on its front only: the bin must lie on the same sides as
    // the true direction, or quantisation would turn radiance into antiradiance at edges.
    const bool orientedS = Oriented(S), orientedR = Oriented(R);
    float cosS = orientedS ? glm::dot(S.normal, u) : 0.0f;
    float cosR = orientedR ? -glm::dot(R.normal, u) : 0.0f;
    // A receiver in the sender's plane (a junction of surfaces, near field only) takes the
    // sender's front: decided with a margin so that rounding cannot flip the side.
    constexpr float kFrontMargin = 1e-4f;
    const bool front = cosS >= -kFrontMargin;
    glm::vec3 sideS = orientedS ? (front ? S.normal : -S.normal) : glm::vec3(0.0f);
    glm::vec3 sideR = orientedR ? -R.normal : glm::vec3(0.0f);
    Link link;
    link.sender = sender;
    link.bin = static_cast<uint16_t>(dirs.LookupWithin(u, sideS, sideR));
    link.level = static_cast<uint16_t>(dirs.LevelFor(std::atan2(S.discRadius, dist)));
    // Eq. 17, F = 1/(d² ω_bin); d² + r_s² is the disc-to-point regularisation, exact for a
    // coaxial disc of radius r_s and negligible once the oracle has made the sender small.
    float f = 1.0f / ((dist2 + S.discRadius * S.discRadius) * dirs.BinSolidAngle());
    // Calibration of oriented ends (leaves, planar clusters): the local pass evaluates
    // cosines at bin centres (and after the σ spread at the receiver), scaled by the
    // per-leaf norms. Rescale F so this link carries the exact cosines of the true
    // direction; bounded, since a bin near a horizon can have a tiny cosine.
    constexpr float kMaxCalibration = 16.0f;
    const glm::vec3 wb = dirs.Direction(link.bin);
    float modelS = 1.0f, modelR = 1.0f;
    if (orientedS) {
        float binCos = std::abs(glm::dot(S.normal, wb));
        modelS = binCos * (front ? norms.out[sender] : 1.0f);
    }
    if (orientedR) {
        float spread = 0.0f;
        for (const BinWeight& nb : dirs.Neighbours(link.level, link.bin))
            spread += nb.weight * std::max(0.0f, -glm::dot(R.normal, dirs.Direction(nb.bin)));
        modelR = spread * norms.in[receiver];
    }
    // Near field: between leaves closer than a few element radii, the transfer is the
    // integral of a_s cos_s cos_r / d² over the sender's area, carried through the models
    // of both ends: F = ∫ / (a_s · model_s · model_r · ω_bin). The centre-to-centre cosines
    // do not enter: at a junction of surfaces they are 0 while the areas face each other.
    if (near.surfels && InNearField(R, S, dist)) {
        float exact = NearFieldIrradiance(near, S.surfel, R.center, R.normal);
        // Coplanar neighbours exchange nothing; rounding leaves them a trace.
        if (exact < kNearTrace * S.area / dist2) exact = 0.0f;
        float model = S.area * modelS * modelR * dirs.BinSolidAngle();
        link.formFactor = model > 0.0f ? exact / model : 0.0f;
        return link;
    }
    if (orientedS) f *= modelS > 0.0f ? std::min(kMaxCalibration, std::abs(cosS) / modelS) : 0.0f;
    if (orientedR)
        f *= modelR > 0.0f ? std::min(kMaxCalibration, std::max(0.0f, cosR) / modelR) : 0.0f;
    link.formFactor = f;
    return link;
}

Links BuildLinks(const Hierarchy& h, const Directions& dirs, const LeafNorms& norms,
                 const NearField& near, const LinkSettings& settings,
                 const std::function<void(double)>& progress) {
    auto start = std::chrono::steady_clock::now();
    Refiner refiner{h,
                    dirs,
                    norms,
                    near,
                    settings.oracle * dirs.BinSolidAngle(),
                    settings.oracle * settings.receiverOracle * dirs.BinSolidAngle(),
                    settings.mode,
                    settings.motion};
    std::unique_ptr<tbb::global_control> limit;
    if (settings.threads > 0)
        limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                      settings.threads);

    // Expand the root self-link breadth first into enough independent pairs to share.
    std::vector<std::pair<uint32_t, uint32_t>> work{{0, 0}}, next;
    std::vector<PendingLink> seedLinks;
    for (int round = 0; round < 16 && !work.empty() && work.size() < 4096; ++round) {
        next.clear();
        for (auto [r, s] : work)
            refiner.Step(
                r, s,
                [&](uint32_t rr, const Link& l) {
                    seedLinks.push_back({rr, l});
                },
                [&](uint32_t a, uint32_t b) { next.emplace_back(a, b); });
        work.swap(next);
    }

    // Pairs within one motion group or between one and anything (both ends of one group
    // other than the static 0, neither a cluster over several) make only links touching a
    // group; the rest (static pairs, and the few over mixed clusters) are refined first, so
    // that the count of links between static nodes is final before the moving ones are made
    // and the motion link budget can stop the build as soon as it is exceeded.
    const auto& nodes = h.nodes;
    auto movingOnly = [&](const std::pair<uint32_t, uint32_t>& p) {
        const uint32_t a = nodes[p.first].group, b = nodes[p.second].group;
        return a != kMixedGroup && b != kMixedGroup && (a != 0 || b != 0);
    };
    std::stable_partition(work.begin(), work.end(), [&](const auto& p) { return !movingOnly(p); });
    const size_t firstMoving =
        static_cast<size_t>(std::find_if(work.begin(), work.end(), movingOnly) - work.begin());
    auto touches = [&](uint32_t r, const Link& l) {
        return nodes[r].group != 0 || nodes[l.sender].group != 0;
    };

    tbb::enumerable_thread_specific<std::vector<PendingLink>> local;
    std::atomic<size_t> done{0};
    std::atomic<size_t> moving{0};
    std::atomic<bool> stop{false};
    size_t cap = 0;  // links touching a group allowed in all (0: no limit)
    auto refineRange = [&](size_t first, size_t last) {
        tbb::parallel_for(
            tbb::blocked_range<size_t>(first, last, 1),
            [&](const tbb::blocked_range<size_t>& range) {
                auto& out = local.local();
                for (size_t i = range.begin(); i != range.end(); ++i) {
                    if (stop.load(std::memory_order_relaxed)) return;
                    const size_t before = out.size();
                    refiner.Refine(work[i].first, work[i].second, [&](uint32_t r, const Link& l) {
                        out.push_back({r, l});
                    });
                    if (cap && i >= firstMoving) {
                        size_t n = moving.fetch_add(out.size() - before) + (out.size() - before);
                        if (n > cap) stop.store(true, std::memory_order_relaxed);
                    }
                }
                size_t n = done.fetch_add(range.size()) + range.size();
                if (progress) progress(static_cast<double>(n) / work.size());
            });
    };
    refineRange(0, firstMoving);
    Links links;
    if (settings.dynamicBudget > 0.0f && !settings.motion.empty()) {
        size_t still = 0, seen = 0;
        auto tally = [&](const std::vector<PendingLink>& v) {
            for (const auto& p : v) (touches(p.receiver, p.link) ? seen : still)++;
        };
        tally(seedLinks);
        for (const auto& v : local) tally(v);
        cap = static_cast<size_t>(settings.dynamicBudget * double(std::max<size_t>(1, still)));
        moving = seen;
        links.staticLinks = still;
        if (seen > cap) stop = true;
    }
    refineRange(firstMoving, work.size());
    if (stop) {
        links.overBudget = true;
        links.dynamicSeen = moving;
        links.buildSeconds =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        return links;
    }

    // Counting sort by receiver; within a receiver by spread level (the CPU gather's
    // fixed-width spread loop then runs the same trip count link after link), then by bin
    // (links of one level and bin are adjacent and spread once), then by sender for
    // locality of I_ex reads. The bins come in a scrambled order, (37·bin) mod 1024 first:
    // neighbouring bins spread into mostly the same accumulator entries, and spreads of
    // neighbouring bins back to back wait on each other's stores (bench/results/FINDINGS.md,
    // "Constants in the code").
    links.offsets.assign(h.size() + 1, 0);
    auto count = [&](const std::vector<PendingLink>& v) {
        for (const auto& p : v) links.offsets[p.receiver + 1]++;
    };
    count(seedLinks);
    for (const auto& v : local) count(v);
    for (size_t i = 0; i < h.size(); ++i) links.offsets[i + 1] += links.offsets[i];
    links.links.resize(links.offsets.back());
    std::vector<uint32_t> cursor(links.offsets.begin(), links.offsets.end() - 1);
    auto place = [&](const std::vector<PendingLink>& v) {
        for (const auto& p : v) links.links[cursor[p.receiver]++] = p.link;
    };
    place(seedLinks);
    for (const auto& v : local) place(v);
    // The order as one 64-bit key: level (< 64) | scrambled bin (10 bits) | bin | sender.
    static_assert(Directions::kLevels <= 64 && Directions::kMaxBins <= 65536);
    auto key = [](const Link& l) {
        return uint64_t(l.level) << 58 | uint64_t((l.bin * 37u) & 1023u) << 48 |
               uint64_t(l.bin) << 32 | l.sender;
    };
    tbb::parallel_for(size_t(0), h.size(), [&](size_t r) {
        std::sort(links.links.begin() + links.offsets[r],
                  links.links.begin() + links.offsets[r + 1],
                  [&](const Link& a, const Link& b) { return key(a) < key(b); });
    });
    if (!settings.motion.empty()) {
        for (uint32_t r = 0; r < h.size(); ++r)
            for (uint32_t i = links.offsets[r]; i < links.offsets[r + 1]; ++i)
                if (touches(r, links.links[i])) {
                    links.dynamic.push_back(i);
                    links.dynamicReceivers.push_back(r);
                }
    }
    links.buildSeconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return links;
}

}  // namespace penumbra
