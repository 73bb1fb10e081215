// The implicit linker's push-down (implicit_links.h): the ends sorted by node, bin and
// depth, then each leaf's bins covered front to back by the links of the leaf and its
// ancestors (Sec. 4.2.3–4.2.4 as a closest layer), or by each slot's closest link (the
// paper's rule), and the leaves' shares written out.
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <utility>

#include "base/check.h"
#include "solvers/implicit/implicit_links.h"
#include "solvers/implicit/link_geometry.h"

namespace penumbra {

using link_geometry::kEdgeCoverage;
using link_geometry::kFillCoverage;
using link_geometry::SolidBox;
using link_geometry::SolidBoxes;

void ImplicitLinker::SortEnds(const Hierarchy& h,
                              const std::vector<std::vector<EndRange>>& sources) {
    const auto& nodes = h.nodes;
    const size_t bins = static_cast<size_t>(dirs_.Count());
    const uint32_t binCount = uint32_t(bins);
    // An end's node, slot / bins, as a multiply (the division was a tenth of the counting and
    // the scatter below): exact for every 32-bit slot with m = ⌊2⁴²/bins⌋ + 1, as bins ≤ 2¹⁰.
    static_assert(Directions::kMaxBins <= 1024);
    const uint64_t magic = (uint64_t(1) << 42) / bins + 1;
    auto nodeOf = [magic](uint32_t slot) {
        return uint32_t((static_cast<unsigned __int128>(slot) * magic) >> 42);
    };
    const size_t nodeCount = nodes.size();
    std::vector<std::vector<uint32_t>> at(sources.size());  // per source and node: its place
    tbb::parallel_for(size_t(0), sources.size(), [&](size_t s) {
        at[s].assign(nodeCount, 0);
        for (const auto& [b, e] : sources[s])
            for (const End* p = b; p != e; ++p) ++at[s][nodeOf(p->slot)];
    });
    std::vector<size_t> nodeFirst(nodeCount + 1);
    size_t total = 0;
    for (size_t n = 0; n < nodeCount; ++n) {
        nodeFirst[n] = total;
        for (auto& a : at) total += std::exchange(a[n], uint32_t(total));
    }
    nodeFirst[nodeCount] = total;
    PENUMBRA_CHECK(total < 0xffffffffu);  // `first` holds them as 32 bits
    scratch_->byNode.resize(total);
    scratch_->ends.resize(total);
    End* const byNode = scratch_->byNode.data();
    End* const ends = scratch_->ends.data();
    tbb::parallel_for(size_t(0), sources.size(), [&](size_t s) {
        uint32_t* fill = at[s].data();
        for (const auto& [b, e] : sources[s])
            for (const End* p = b; p != e; ++p) byNode[fill[nodeOf(p->slot)]++] = *p;
    });
    // Each node's ends by bin, each bin's run nearest first. A node's occupied bins are bits
    // (`occupied`), and run j of node n (its j-th occupied bin) spans ends[runs[runFirst[n] +
    // j], runs[runFirst[n] + j + 1]): a few megabytes, where a start for every (node, bin)
    // slot was 30 MB a frame to write.
    const size_t words = (bins + 63) / 64;
    std::vector<uint64_t>& occupied = scratch_->occupied;  // every word written below
    occupied.resize(nodeCount * words);
    std::vector<uint32_t>& runFirst = scratch_->runFirst;
    runFirst.resize(nodeCount + 1);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, nodeCount, 64), [&](const auto& range) {
        for (size_t n = range.begin(); n != range.end(); ++n) {
            uint64_t* occ = occupied.data() + n * words;
            std::fill(occ, occ + words, uint64_t(0));
            const uint32_t base = uint32_t(n) * binCount;
            for (size_t k = nodeFirst[n]; k < nodeFirst[n + 1]; ++k) {
                const uint32_t b = byNode[k].slot - base;
                occ[b >> 6] |= uint64_t(1) << (b & 63);
            }
            uint32_t count = 0;
            for (size_t w = 0; w < words; ++w) count += uint32_t(std::popcount(occ[w]));
            runFirst[n] = count + 1;  // its runs' starts and its end, summed below
        }
    });
    for (size_t n = 0, sum = 0; n <= nodeCount; ++n)
        sum += std::exchange(runFirst[n], uint32_t(sum));
    std::vector<uint32_t>& runs = scratch_->runs;
    runs.resize(runFirst[nodeCount]);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, nodeCount, 32), [&](const auto& range) {
        std::vector<uint32_t> fill(bins, 0u);  // per bin: its count, then where its next end goes
        for (size_t n = range.begin(); n != range.end(); ++n) {
            const uint32_t lo = uint32_t(nodeFirst[n]), hi = uint32_t(nodeFirst[n + 1]);
            const uint32_t base = uint32_t(n) * binCount;
            const uint64_t* occ = occupied.data() + n * words;
            uint32_t* run = runs.data() + runFirst[n];
            for (uint32_t k = lo; k < hi; ++k) ++fill[byNode[k].slot - base];
            uint32_t j = 0, o = lo;
            for (size_t w = 0; w < words; ++w)
                for (uint64_t bits = occ[w]; bits; bits &= bits - 1) {
                    const uint32_t b = uint32_t(w * 64 + std::countr_zero(bits));
                    run[j++] = o;
                    o += std::exchange(fill[b], o);
                }
            run[j] = hi;
            for (uint32_t k = lo; k < hi; ++k) ends[fill[byNode[k].slot - base]++] = byNode[k];
            for (uint32_t r = 0; r < j; ++r) {
                if (run[r + 1] - run[r] > 1)
                    std::sort(ends + run[r], ends + run[r + 1], [](const End& x, const End& y) {
                        // The sender breaks ties: the order never depends on the threads.
                        return x.dist < y.dist || (x.dist == y.dist && x.sender < y.sender);
                    });
            }
            for (size_t w = 0; w < words; ++w)  // `fill` back to zeros for the next node
                for (uint64_t bits = occ[w]; bits; bits &= bits - 1)
                    fill[w * 64 + std::countr_zero(bits)] = 0;
        }
    });
}

// One thread's walk over a range of leaves in the hierarchy's pre-order (Composite): the
// leaf's chain (its ancestors and itself, root first) and per bin the runs of the chain's
// nodes that hold ends there, in the same order. The next leaf's chain keeps the part it
// shares: a node's runs are pushed when the walk enters it and popped when it leaves, not
// looked up again for every leaf and bin.
struct ImplicitLinker::LeafWalk {
    using Head = std::pair<const End*, const End*>;
    // A closed solid's flat senders met in one bin so far: the solid angles of those facing
    // the leaf and of those turned away, the nearest facing one and its depth.
    struct SolidCover {
        uint32_t solid;
        float facing, away, near;
        uint32_t front;
    };
    // Where a solid's near faces were met (solid, bin, sender).
    struct Front {
        uint32_t solid, bin, sender;
    };
    // A bin not covered whole, with its shares' range in the leaf's list.
    struct Partial {
        uint32_t bin;
        size_t first, end;
    };

    const ImplicitLinker& linker;
    const Hierarchy& h;
    const std::vector<float>& frontArea;
    const std::vector<uint32_t>& solid;
    const float thin;
    const std::vector<SolidBox>& boxes;
    const size_t bins;
    const float omegaBin;
    // The ends by node and bin (SortEnds): node n's occupied bins are bits of
    // occupied[n · words …], its runs runs[runFirst[n] …] into ends.
    const End* const ends;
    const uint32_t* const runs;
    const uint32_t* const runFirst;
    const uint64_t* const occupied;
    const size_t words;
    // A bin more than a spacing above the receiver's horizon lies above it whole (one
    // nearer the horizon is partly below it, where nothing covers it).
    const float aboveHorizon;

    std::vector<uint32_t> chain;
    std::vector<std::vector<Head>>& atBin;  // the thread's stacks (empty between tasks)
    std::vector<Head> heads;
    std::vector<SolidCover> solids;
    // Per leaf: the bins where each solid's near faces were met, and the shares of its far
    // faces in bins without them (share index, solid).
    std::vector<Front> fronts;
    std::vector<std::pair<size_t, uint32_t>> unseen;
    // Per bin the solid angle its shares cover (−1: not a front bin) and its cosine to the
    // leaf's normal; the bins not covered whole.
    std::vector<float> cover, rise;
    std::vector<Partial> partial;

    void Enter(uint32_t n) {
        chain.push_back(n);
        const uint32_t* run = runs + runFirst[n];
        const uint64_t* occ = occupied + n * words;
        for (size_t w = 0; w < words; ++w)
            for (uint64_t bits = occ[w]; bits; bits &= bits - 1, ++run)
                atBin[w * 64 + std::countr_zero(bits)].push_back({ends + run[0], ends + run[1]});
    }
    void Leave() {
        const uint64_t* occ = occupied + size_t(chain.back()) * words;
        chain.pop_back();
        for (size_t w = 0; w < words; ++w)
            for (uint64_t bits = occ[w]; bits; bits &= bits - 1)
                atBin[w * 64 + std::countr_zero(bits)].pop_back();
    }
    void Finish() {
        while (!chain.empty()) Leave();  // the thread's stacks empty for its next task
    }

    // Leaf h.leaves[i]'s shares into `list`.
    void Cover(size_t i, std::vector<Entry>& list) {
        const auto& nodes = h.nodes;
        const uint32_t leaf = h.leaves[i];
        while (!chain.empty() && !(chain.back() <= leaf && leaf < nodes[chain.back()].end)) Leave();
        if (chain.empty()) Enter(0);
        for (uint32_t n = chain.back(); n != leaf;) {
            const uint32_t left = n + 1, right = nodes[left].end;
            n = leaf < right ? left : right;
            Enter(n);
        }
        const glm::vec3& normal = nodes[leaf].normal;
        const float norm = linker.dirs_.CosineNorm(normal);
        list.clear();
        fronts.clear();
        unseen.clear();
        partial.clear();
        std::fill(cover.begin(), cover.end(), -1.0f);
        for (size_t b = 0; b < bins; ++b) {
            const float c = glm::dot(normal, linker.dirs_.Direction(uint32_t(b)));
            rise[b] = c;
            if (!(c > 0.0f)) continue;
            const size_t bin0 = list.size();
            const float left = FillBin(uint32_t(b), leaf, c * norm, list);
            cover[b] = omegaBin - left;
            if (left > 1e-4f * omegaBin) partial.push_back({uint32_t(b), bin0, list.size()});
        }
        FillPartialBins(norm, list);
        ShowNearFaces(list);
    }

    // Bin b of `leaf`: the chain's slots for it, each sorted nearest first, merged until the
    // bin is full (most fill after a few links), each end's share `weight` (the bin's cosine
    // factor) times the solid angle it covers. Returns the solid angle left uncovered.
    float FillBin(uint32_t b, uint32_t leaf, float weight, std::vector<Entry>& list) {
        const auto& nodes = h.nodes;
        const glm::vec3& normal = nodes[leaf].normal;
        const glm::vec3& centre = nodes[leaf].center;
        const glm::vec3& w = linker.dirs_.Direction(b);
        // (The leaf's first: of two ends at one depth, the nearer node's is taken.)
        heads.assign(atBin[b].rbegin(), atBin[b].rend());
        float left = omegaBin;
        solids.clear();
        while (left > 1e-4f * omegaBin) {
            Head* next = nullptr;
            for (auto& head : heads)
                if (head.first != head.second && (!next || head.first->dist < next->first->dist))
                    next = &head;
            if (!next) break;
            const End& e = *next->first++;
            float omega = e.omega;
            uint32_t sender = e.sender;
            bool farOnly = false;  // a solid's far face, none of its near ones in the bin
            const uint32_t of = solid.empty() ? kNoSolid : solid[e.sender];
            // A flat sender of a closed solid is a near face (it faces the leaf) or a far one.
            // A cluster of one is a far face where it shows the leaf more than twice the area
            // turned away from it that it turns towards it: read through the tables it would
            // be nearly black where the solid's near faces left the bin part covered (a
            // box's far side and its top at a corner; bench/results/FINDINGS.md, "Implicit
            // visibility: measured"). A cluster that shows both sides alike (a whole solid:
            // closed, it shows as much either way) stays as it was: seen from inside (a floor
            // under a box without a bottom) it is no near face.
            const bool flat = nodes[e.sender].coneCos >= kFlatCone;
            auto turnedAway = [&] {
                const float* row = frontArea.data() + size_t(e.sender) * bins;
                return row[b] > 2.0f * row[linker.dirs_.Opposite(b)];
            };
            if (of != kNoSolid && (flat || turnedAway())) {
                const HierarchyNode& s = nodes[e.sender];
                const bool facing = flat && glm::dot(s.normal, centre - s.center) > 0.0f;
                auto it = std::find_if(solids.begin(), solids.end(),
                                       [&](const SolidCover& c) { return c.solid == of; });
                if (it == solids.end())
                    it = solids.insert(solids.end(), {of, 0.0f, 0.0f, e.dist, e.sender});
                if (facing) {
                    if (it->facing == 0.0f) {
                        it->near = e.dist;
                        it->front = e.sender;
                        fronts.push_back({of, b, e.sender});
                    }
                    it->facing += omega;
                } else if (it->facing > 0.0f) {
                    // Behind the solid's near faces by `thin` or more, across the solid
                    // (along the far face's normal), or at the outline of a thin one (the
                    // bin's cone leaves its box: at a slab's edge the far face would add to the
                    // near one's cover of the bin what lies beyond the slab): it adds only what
                    // it covers beyond them. Either way what it covers stands for the solid as
                    // seen from here, its near face (black, it would darken the gaps the near
                    // faces' ends leave).
                    if ((e.dist - it->near) * std::abs(glm::dot(s.normal, w)) >= thin ||
                        !boxes[of].Holds(centre, w, linker.binRadius_, normal)) {
                        const float before = std::max(it->facing, it->away);
                        it->away += omega;
                        omega = std::max(it->facing, it->away) - before;
                    }
                    sender = it->front;
                } else {
                    farOnly = true;
                }
            }
            const float take = std::min(left, omega);
            if (!(take > 0.0f)) continue;
            if (farOnly) unseen.push_back({list.size(), of});
            list.push_back({b, sender, weight * take});
            left -= take;
        }
        return left;
    }

    // A bin partly covered (kFillCoverage or more) is a surface the discretisation left gaps
    // in (its ends' centres fall into the bins unevenly): its shares fill it, unless a front
    // bin next to it, above the horizon, is nearly empty (kEdgeCoverage): then it lies at the
    // edge of what is there, against the environment (a blocker's silhouette under a sky:
    // filled, its bins would make it look larger than it is). What a bin's shares leave
    // unfilled shows the environment.
    void FillPartialBins(float norm, std::vector<Entry>& list) const {
        for (const Partial& p : partial) {
            float left = omegaBin - cover[p.bin];
            bool fill = cover[p.bin] >= kFillCoverage * omegaBin;
            for (uint32_t j : linker.dirs_.Adjacent(p.bin))
                if (fill && cover[j] >= 0.0f && cover[j] < kEdgeCoverage * omegaBin &&
                    rise[j] > aboveHorizon)
                    fill = false;
            if (fill) {
                const float scale = omegaBin / cover[p.bin];
                for (size_t k = p.first; k < p.end; ++k) list[k].weight *= scale;
                left = 0.0f;
            }
            if (left > 1e-4f * omegaBin)
                list.push_back({p.bin, kNoSender, rise[p.bin] * norm * left});
        }
    }

    // A solid whose near faces this leaf sees somewhere has it outside: its far faces lie
    // behind near ones everywhere, also where the near faces' ends fell into other bins; such
    // a share shows the near face met in the closest bin. A leaf that sees only far faces of a
    // solid is inside it (a floor under a box without a bottom): they block, black.
    void ShowNearFaces(std::vector<Entry>& list) const {
        for (const auto& [k, of] : unseen) {
            const glm::vec3& w = linker.dirs_.Direction(list[k].bin);
            float best = -2.0f;
            for (const Front& f : fronts)
                if (f.solid == of) {
                    const float cw = glm::dot(w, linker.dirs_.Direction(f.bin));
                    if (cw > best) best = cw, list[k].sender = f.sender;
                }
        }
    }
};

void ImplicitLinker::Composite(const Hierarchy& h, const std::vector<float>& frontArea,
                               const std::vector<uint32_t>& solid, float thin) {
    const size_t leaves = h.leaves.size();
    const size_t bins = static_cast<size_t>(dirs_.Count());
    // A thin solid's far faces fill a bin only inside the solid's outline, where its near
    // faces' ends left gaps (SolidBoxes).
    const std::vector<SolidBox> boxes = SolidBoxes(h, solid, thin);
    std::vector<std::vector<Entry>>& perLeaf = scratch_->perLeaf;
    perLeaf.resize(leaves);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, leaves, 64), [&](const auto& range) {
        LeafWalk walk{*this,
                      h,
                      frontArea,
                      solid,
                      thin,
                      boxes,
                      bins,
                      dirs_.BinSolidAngle(),
                      scratch_->ends.data(),
                      scratch_->runs.data(),
                      scratch_->runFirst.data(),
                      scratch_->occupied.data(),
                      (bins + 63) / 64,
                      std::sin(dirs_.Spacing()),
                      {},
                      scratch_->stacks.local(),
                      {},
                      {},
                      {},
                      {},
                      std::vector<float>(bins),
                      std::vector<float>(bins),
                      {}};
        walk.atBin.resize(bins);
        for (size_t i = range.begin(); i != range.end(); ++i) walk.Cover(i, perLeaf[i]);
        walk.Finish();
    });
}

void ImplicitLinker::WriteShares(const Hierarchy& h, ImplicitLinks& out) const {
    // Each leaf's shares (Scratch::perLeaf) one after another, and how each sender's light is
    // read (ImplicitLinks::travel).
    const auto& nodes = h.nodes;
    const size_t leaves = h.leaves.size();
    const std::vector<std::vector<Entry>>& perLeaf = scratch_->perLeaf;
    out.offsets.assign(leaves + 1, 0);
    for (size_t i = 0; i < leaves; ++i)
        out.offsets[i + 1] = out.offsets[i] + uint32_t(perLeaf[i].size());
    const size_t count = out.offsets[leaves];
    out.bin.resize(count);
    out.sender.resize(count);
    out.weight.resize(count);
    out.travel.resize(count);
    std::atomic<size_t> empty{0};
    tbb::parallel_for(size_t(0), leaves, [&](size_t i) {
        const uint32_t leaf = h.leaves[i];
        size_t k = out.offsets[i], none = 0;
        for (const Entry& e : perLeaf[i]) {
            out.bin[k] = e.bin;
            out.sender[k] = e.sender;
            out.weight[k] = e.weight;
            if (e.sender == kNoSender) {
                out.travel[k] = dirs_.Opposite(e.bin);
                ++none;
            } else {
                const HierarchyNode& from = nodes[e.sender];
                const glm::vec3 toLeaf = nodes[leaf].center - from.center;
                if (from.coneCos >= kFlatCone)
                    out.travel[k] = glm::dot(from.normal, toLeaf) > 0.0f ? kFacing : kAway;
                else
                    out.travel[k] = glm::dot(toLeaf, toLeaf) > 0.0f
                                        ? dirs_.Lookup(glm::normalize(toLeaf))
                                        : dirs_.Opposite(e.bin);
            }
            ++k;
        }
        empty += none;
    });
    out.empty = empty;
}

void ImplicitLinker::BuildClosest(const Hierarchy& h,
                                  const std::vector<std::vector<EndRange>>& sources,
                                  ImplicitLinks& out) {
    // CreateHierarchicalLinks' per-bin minimum (Sec. 4.2.2): every end keeps its slot's
    // closest, as a 64-bit (depth bits, sender) key by compare-and-swap (a positive float's
    // bits order as it does; the sender breaks ties, so the threads' order never shows).
    const auto& nodes = h.nodes;
    const size_t bins = static_cast<size_t>(dirs_.Count());
    constexpr uint64_t kNone = ~uint64_t(0);
    auto start = std::chrono::steady_clock::now();
    std::vector<uint64_t>& best = scratch_->closest;
    best.resize(nodes.size() * bins);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, best.size(), 1 << 16), [&](const auto& r) {
        std::fill(best.begin() + r.begin(), best.begin() + r.end(), kNone);
    });
    tbb::parallel_for(size_t(0), sources.size(), [&](size_t l) {
        for (const auto& [first, last] : sources[l])
            tbb::parallel_for(
                tbb::blocked_range<const End*>(first, last, 4096), [&](const auto& r) {
                    for (const End* p = r.begin(); p != r.end(); ++p) {
                        // The slots are scattered over the table: fetch a few ends ahead.
                        constexpr size_t kAhead = 16;
                        if (size_t(r.end() - p) > kAhead)
                            __builtin_prefetch(&best[p[kAhead].slot], 1);
                        const uint64_t key =
                            uint64_t(std::bit_cast<uint32_t>(p->dist)) << 32 | p->sender;
                        std::atomic_ref<uint64_t> slot(best[p->slot]);
                        uint64_t old = slot.load(std::memory_order_relaxed);
                        while (key < old &&
                               !slot.compare_exchange_weak(old, key, std::memory_order_relaxed)) {
                        }
                    }
                });
    });
    out.msCreate += MsSince(start);
    PushClosest(h, out);
}

void ImplicitLinker::PushClosest(const Hierarchy& h, ImplicitLinks& out) {
    const auto& nodes = h.nodes;
    const size_t bins = static_cast<size_t>(dirs_.Count());
    const float omegaBin = dirs_.BinSolidAngle();
    constexpr uint64_t kNone = ~uint64_t(0);
    std::vector<uint64_t>& best = scratch_->closest;
    PENUMBRA_CHECK_EQ(best.size(), nodes.size() * bins);
    // RefineHierarchicalLinks + PushdownLinks (Sec. 4.2.3–4.2.4): each node's slots take its
    // parent's where those are closer, top down; then each leaf's front bins are its closest
    // links, each covering the bin, or the environment where there is none. The nodes above
    // kSplit levels one after another, then each subtree below them in a task of its own, in
    // pre-order (a parent's row before its children's, still in cache), its leaves' shares
    // made as the walk reaches them.
    constexpr uint32_t kSplit = 6;
    auto push = [&](uint32_t n) {
        uint64_t* row = best.data() + size_t(n) * bins;
        const uint64_t* up = best.data() + size_t(nodes[n].parent) * bins;
        for (size_t b = 0; b < bins; ++b) row[b] = std::min(row[b], up[b]);
    };
    std::vector<uint32_t> tasks;  // the subtrees' roots
    for (uint32_t n = 0; n < nodes.size();) {
        if (nodes[n].depth < kSplit && !nodes[n].IsLeaf()) {
            if (n != 0) push(n);
            ++n;
        } else {
            tasks.push_back(n);
            n = nodes[n].end;
        }
    }
    const size_t leaves = h.leaves.size();
    std::vector<std::vector<Entry>>& perLeaf = scratch_->perLeaf;
    perLeaf.resize(leaves);
    tbb::parallel_for(size_t(0), tasks.size(), [&](size_t t) {
        const uint32_t root = tasks[t];
        size_t i = size_t(std::lower_bound(h.leaves.begin(), h.leaves.end(), root) -
                          h.leaves.begin());  // the subtree's first leaf
        for (uint32_t n = root; n < std::max(nodes[root].end, root + 1); ++n) {
            if (n != 0) push(n);
            if (!nodes[n].IsLeaf()) continue;
            const uint64_t* row = best.data() + size_t(n) * bins;
            std::vector<Entry>& list = perLeaf[i++];
            list.clear();
            for (size_t b = 0; b < bins; ++b) {  // cos⁺ a front bin, normalised below
                const float c = glm::dot(nodes[n].normal, dirs_.Direction(uint32_t(b)));
                if (!(c > 0.0f)) continue;
                const uint32_t sender = row[b] == kNone ? kNoSender : uint32_t(row[b]);
                list.push_back({uint32_t(b), sender, c});
            }
            // Directions::CosineNorm from the same cosines: Σ weight = π.
            double sum = 0.0;
            for (const Entry& e : list) sum += e.weight;
            const float scale = dirs_.CosineNormOfSum(sum) * omegaBin;
            for (Entry& e : list) e.weight *= scale;
        }
    });
    WriteShares(h, out);
}

}  // namespace penumbra
