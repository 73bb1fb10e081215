// Hierarchical link refinement (Sec. 3.2) on all cores, then a counting sort by receiver.
#include "links/links.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <memory>
#include <numbers>

#include "base/check.h"

namespace penumbra {
namespace {

struct PendingLink {
    uint32_t receiver;
    Link link;
};

struct Refiner {
    const Hierarchy& h;
    const Directions& dirs;
    float threshold;  // oracle × ω_bin

    template <typename F>
    void Children(uint32_t n, F&& f) const {
        uint32_t left = n + 1;
        uint32_t right = h.nodes[left].end;
        f(left);
        f(right);
    }

    // Fig. 7: a receiver only takes light that arrives on its front side. True when no
    // point of the sender can lie in front of any member of the receiver.
    bool Culled(const HierarchyNode& r, const HierarchyNode& s, const glm::vec3& d,
                float dist) const {
        if (r.coneCos <= -1.0f) return false;
        if (r.IsLeaf() && s.IsLeaf()) return glm::dot(r.normal, d) <= 1e-6f * dist;
        if (dist <= r.radius + s.radius) return false;
        if (r.IsLeaf()) return glm::dot(r.normal, d) <= -s.radius;
        // Normal cone vs the cone of directions from receiver to sender.
        float axisAngle = std::acos(std::clamp(glm::dot(r.normal, d / dist), -1.0f, 1.0f));
        float coneAngle = std::acos(std::clamp(r.coneCos, -1.0f, 1.0f));
        float spread = std::asin(std::min(1.0f, (r.radius + s.radius) / dist));
        return axisAngle > 0.5f * std::numbers::pi_v<float> + coneAngle + spread;
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
        glm::vec3 d = S.center - R.center;
        float dist = glm::length(d);
        if (Culled(R, S, d, dist)) return;
        if (!(R.IsLeaf() && S.IsLeaf())) {
            float dist2 = dist * dist;
            bool overlap = dist <= R.radius + S.radius;
            // Oracle: solid angle of sender (and receiver) against the bin's ω_bin.
            float pi = std::numbers::pi_v<float>;
            float omegaS = pi * S.radius * S.radius / dist2;
            float omegaR = pi * R.radius * R.radius / dist2;
            if (overlap || std::max(omegaS, omegaR) > threshold) {
                bool splitSender = R.IsLeaf() || (!S.IsLeaf() && S.radius >= R.radius);
                if (splitSender)
                    Children(s, [&](uint32_t b) { pair(r, b); });
                else
                    Children(r, [&](uint32_t a) { pair(a, s); });
                return;
            }
        }
        emit(r, MakeLink(h, dirs, r, s));
    }

    template <typename Emit>
    void Refine(uint32_t r, uint32_t s, Emit&& emit) const {
        Step(r, s, emit, [&](uint32_t a, uint32_t b) { Refine(a, b, emit); });
    }
};

}  // namespace

Link MakeLink(const Hierarchy& h, const Directions& dirs, uint32_t receiver, uint32_t sender) {
    const HierarchyNode& R = h.nodes[receiver];
    const HierarchyNode& S = h.nodes[sender];
    glm::vec3 d = R.center - S.center;  // direction of travel: sender → receiver
    float dist2 = glm::dot(d, d);
    float dist = std::sqrt(dist2);
    Link link;
    link.sender = sender;
    link.bin = static_cast<uint16_t>(dirs.Lookup(d / dist));
    link.level = static_cast<uint16_t>(dirs.LevelFor(std::atan2(S.discRadius, dist)));
    // Eq. 17, F = 1/(d² ω_bin); d² + r_s² is the disc-to-point regularisation, exact for a
    // coaxial disc of radius r_s and negligible once the oracle has made the sender small.
    link.formFactor = 1.0f / ((dist2 + S.discRadius * S.discRadius) * dirs.BinSolidAngle());
    return link;
}

Links BuildLinks(const Hierarchy& h, const Directions& dirs, const LinkSettings& settings,
                 const std::function<void(double)>& progress) {
    auto start = std::chrono::steady_clock::now();
    Refiner refiner{h, dirs, settings.oracle * dirs.BinSolidAngle()};
    std::unique_ptr<tbb::global_control> limit;
    if (settings.threads > 0)
        limit = std::make_unique<tbb::global_control>(
            tbb::global_control::max_allowed_parallelism, settings.threads);

    // Expand the root self-link breadth first into enough independent pairs to share.
    std::vector<std::pair<uint32_t, uint32_t>> work{{0, 0}}, next;
    std::vector<PendingLink> seedLinks;
    for (int round = 0; round < 16 && !work.empty() && work.size() < 4096; ++round) {
        next.clear();
        for (auto [r, s] : work)
            refiner.Step(
                r, s, [&](uint32_t rr, const Link& l) { seedLinks.push_back({rr, l}); },
                [&](uint32_t a, uint32_t b) { next.emplace_back(a, b); });
        work.swap(next);
    }

    tbb::enumerable_thread_specific<std::vector<PendingLink>> local;
    std::atomic<size_t> done{0};
    tbb::parallel_for(tbb::blocked_range<size_t>(0, work.size(), 1),
                      [&](const tbb::blocked_range<size_t>& range) {
                          auto& out = local.local();
                          for (size_t i = range.begin(); i != range.end(); ++i) {
                              refiner.Refine(work[i].first, work[i].second,
                                             [&](uint32_t r, const Link& l) {
                                                 out.push_back({r, l});
                                             });
                          }
                          size_t n = done.fetch_add(range.size()) + range.size();
                          if (progress) progress(static_cast<double>(n) / work.size());
                      });

    // Counting sort by receiver; within a receiver, by sender for locality of I_ex reads.
    Links links;
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
    tbb::parallel_for(size_t(0), h.size(), [&](size_t r) {
        std::sort(links.links.begin() + links.offsets[r], links.links.begin() + links.offsets[r + 1],
                  [](const Link& a, const Link& b) {
                      return a.sender != b.sender ? a.sender < b.sender : a.bin < b.bin;
                  });
    });
    links.buildSeconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return links;
}

}  // namespace penumbra
