// The CPU back end's kernels, written once for both I_ex table formats (cpu_passes.h):
// fp32 rows of I_ex itself (the layout the shaders share), and fp16 rows of I_ex over the
// node's area (cpu_half.cpp). Internal to the CPU back end: included by cpu_passes.cpp
// (fp32, baseline ISA) and cpu_half.cpp (fp16, built with F16C). Everything here is a
// template on the row format or has internal linkage, so each file keeps its own code.
#pragma once

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstring>
#include <numbers>

#include "solvers/antiradiance/model.h"

namespace penumbra::cpu::detail {

// Four floats (RGB and a zero pad): one vector update per spread neighbour instead of
// three scalar ones.
using Rgba = float __attribute__((vector_size(16)));

// A cheap per-thread tick counter for splitting the fused walk's time into stages.
static inline uint64_t Ticks() {
#if defined(__x86_64__) || defined(__i386__)
    return __builtin_ia32_rdtsc();
#else
    return static_cast<uint64_t>(std::chrono::steady_clock::now().time_since_epoch().count());
#endif
}

// fp32 rows of I_ex: bins × RGB floats per node, exactly the shaders' table.
struct FloatRows {
    using Elem = float;
    static constexpr bool kScaled = false;  // rows hold I_ex itself
    static constexpr size_t kPad = 0;       // elements after the last row
    static Rgba Load(const float* p) { return Rgba{p[0], p[1], p[2], 0.0f}; }
    // Stores value(b) for `bins` bins as RGB. 16-byte
    // stores at a 12-byte stride: each one's pad lane is overwritten by the next bin's;
    // the last bin is stored as three floats so the row's end stays put. Returns 0 (no
    // range to track).
    template <class Value>
    static float Store(float* out, int bins, Value&& value) {
        for (int b = 0; b + 1 < bins; ++b) {
            Rgba v = value(b);
            std::memcpy(out + b * 3, &v, sizeof(Rgba));
        }
        Rgba v = value(bins - 1);
        std::memcpy(out + (bins - 1) * 3, &v, 3 * sizeof(float));
        return 0.0f;
    }
    // dst = a + b (a cluster's I_ex is the sum of its children's; the weights are 1).
    static void Sum(float* dst, const float* a, float, const float* b, float, size_t n) {
        for (size_t k = 0; k < n; ++k) dst[k] = a[k] + b[k];
    }
};

// The root's L_in before its links: the environment per bin (model.h), as RGBA rows.
static inline void EnvironmentRows(const AntiradianceModel& m, Rgba* lin) {
    for (size_t b = 0; b < m.environment.size(); ++b) {
        const glm::vec3& e = m.environment[b];
        lin[b] = Rgba{e.x, e.y, e.z, 0.0f};
    }
}

// Links whose sender rows Gather reads ahead (measured: 16 → 32 cut the office's gather
// by a tenth; 64 was slower).
inline constexpr size_t kGatherChunk = 32;

// Starts the reads of receiver r's first senders' rows (Gather's first chunk): Gather does
// for its own receiver, the walk for the next one while a node's local pass runs.
template <class Rows>
inline void PrefetchSenders(const AntiradianceModel& m, const typename Rows::Elem* iex,
                            uint32_t r) {
    const size_t bins = m.Bins();
    const Link* begin = m.links.links.data() + m.links.offsets[r];
    const size_t count =
        std::min<size_t>(kGatherChunk, m.links.offsets[r + 1] - m.links.offsets[r]);
    for (const Link* l = begin; l < begin + count; ++l)
        __builtin_prefetch(iex + (size_t(l->sender) * bins + l->bin) * 3);
}

// acc[bin] += Σ over receiver r's links of F · w · I_ex[sender][link bin] (the U operator,
// Eq. 16/17 with the σ spreading of Sec. 3.1), RGB in the first three lanes. A scaled
// format's rows hold I_ex / senderScale[sender]. The sender reads are random rows of a
// large table: gather a chunk of F·I_ex values first, prefetching the next chunk, then
// spread them (measured: docs/STATUS.md, issue 2).
template <class Rows>
inline void Gather(const AntiradianceModel& m, const typename Rows::Elem* iex,
                   const float* senderScale, uint32_t r, Rgba* acc) {
    constexpr size_t kChunk = kGatherChunk;
    const size_t bins = m.Bins();
    const Link* begin = m.links.links.data() + m.links.offsets[r];
    const Link* end = m.links.links.data() + m.links.offsets[r + 1];
    auto source = [&](const Link* l) { return iex + (size_t(l->sender) * bins + l->bin) * 3; };
    PrefetchSenders<Rows>(m, iex, r);
    Rgba v[kChunk];
    for (const Link* chunk = begin; chunk < end; chunk += kChunk) {
        const size_t n = std::min<size_t>(kChunk, end - chunk);
        for (const Link* l = chunk + kChunk; l < chunk + 2 * kChunk && l < end; ++l)
            __builtin_prefetch(source(l));
        for (size_t k = 0; k < n; ++k) {
            float f = chunk[k].formFactor;
            if constexpr (Rows::kScaled) f *= senderScale[chunk[k].sender];
            v[k] = f * Rows::Load(source(chunk + k));
        }
        for (size_t k = 0; k < n; ++k) {
            Rgba sum = v[k];
            // Links of one (level, bin) are adjacent: spread their sum once.
            while (k + 1 < n && chunk[k + 1].bin == chunk[k].bin &&
                   chunk[k + 1].level == chunk[k].level)
                sum += v[++k];
            const BinWeight* nb = m.dirs.Padded(chunk[k].level, chunk[k].bin);
            const int width = m.dirs.PaddedWidth(chunk[k].level);
            for (int j = 0; j < width; ++j) acc[nb[j].bin] += nb[j].weight * sum;
        }
    }
}

// The glossy lobe's share of Eq. 18 at glossy leaf g, per outgoing bin ω_j in front, times
// a (the leaf's area): a F0 [ω_bin Σ_l w(mirror(ω_l), ω_j) ⟨n|−ω_l⟩ L_in(ω_l) + direct(ω_j)],
// w the discretised lobe (model.h, GlossyLobe), `area` a (times the table's scale). The incoming
// light is first gathered at the mirror bin of each incoming bin, then each outgoing bin reads its
// lobe row there (the kernel is symmetric): bins · (1 + row width) operations instead of bins².
static inline void GlossyReflection(const AntiradianceModel& m, const LeafAttributes& leaf,
                                    float area, const float* cosine, const Rgba* lin, Rgba* spec) {
    const int bins = m.Bins();
    const uint32_t g = leaf.flags >> kGlossyShift;
    Rgba arrived[Directions::kMaxBins];
    std::fill(arrived, arrived + bins, Rgba{});
    const uint32_t* mirror = m.mirror.data() + size_t(g) * bins;
    for (int l = 0; l < bins; ++l)
        if (cosine[l] < 0.0f) arrived[mirror[l]] += -cosine[l] * lin[l];
    const GlossyLeaf& gl = m.glossy[g];
    const GlossyLobe& lobe = m.lobes[gl.lobe];
    const Rgba f0 = area * Rgba{gl.specular.x, gl.specular.y, gl.specular.z, 0.0f};
    const float omega = m.dirs.BinSolidAngle();
    const glm::vec4* direct = m.glossyDirect.data() + size_t(g) * bins;
    for (int j = 0; j < bins; ++j) {
        if (cosine[j] <= 0.0f) {
            spec[j] = Rgba{};
            continue;
        }
        const BinWeight* row = m.lobeWeights.data() + lobe.start + size_t(j) * lobe.width;
        Rgba sum{};
        for (uint32_t k = 0; k < lobe.width; ++k) sum += row[k].weight * arrived[row[k].bin];
        spec[j] = f0 * (omega * sum + Rgba{direct[j].x, direct[j].y, direct[j].z, 0.0f});
    }
}

// Local pass of one leaf for a diffuse BRDF f = ρ/π. Eq. 18 reduces to
// I_L(ω_j) = a ⟨n|ω_j⟩ (L_e + ρ (E + E_d) / π), with E = ω_bin Σ_l ⟨n|−ω_l⟩ L_in(ω_l)
// and E_d the shadow-mapped direct light (Sec. 3.3), which J never sees.
// Eq. 19: I_A(ω_j) = a ⟨n|−ω_j⟩ L_in(ω_j); I_ex = I_L − I_A on separate hemispheres.
// A glossy leaf adds its lobe's reflection (GlossyReflection) to I_L.
// `lin` holds the leaf's L_in as RGBA rows; `old` and `out` are the leaf's rows of the
// I_ex tables, holding I_ex / oldScale and I_ex · outScale (1 and 1 for fp32 rows).
// Returns Rows::Store's value.
template <class Rows>
inline float LocalLeaf(const AntiradianceModel& m, const LeafAttributes& leaf,
                       const glm::vec4& direct, const Rgba* lin, const typename Rows::Elem* old,
                       float oldScale, typename Rows::Elem* out, float outScale, float* irradiance,
                       LocalMode mode) {
    const int bins = m.Bins();
    // Cosines of all bins once, from the directions' SoA arrays (vectorises).
    float cosine[Directions::kMaxBins];
    const float *dx = m.dirs.X(), *dy = m.dirs.Y(), *dz = m.dirs.Z();
    const glm::vec3 n = leaf.normal;
    for (int b = 0; b < bins; ++b) cosine[b] = n.x * dx[b] + n.y * dy[b] + n.z * dz[b];

    // Per-bin weights of the sums below, in loops that vectorise: the front light's
    // ⟨n|−ω⟩⁺, the reflected light's ⟨n|ω⟩⁺ and what goes on as antiradiance (below).
    // Everything written carries the area a; the table's scale rides along with it.
    const float area = leaf.area * outScale;
    const bool twoSided = (leaf.flags & kLeafTwoSided) != 0;
    float incoming[Directions::kMaxBins], outgoing[Directions::kMaxBins];
    float through[Directions::kMaxBins];
    for (int b = 0; b < bins; ++b) {
        incoming[b] = std::max(0.0f, -cosine[b]);
        outgoing[b] = std::max(cosine[b], 0.0f);
    }
    if (twoSided)
        for (int b = 0; b < bins; ++b) through[b] = area * -std::abs(cosine[b]);
    else
        for (int b = 0; b < bins; ++b) through[b] = area * std::min(cosine[b], 0.0f);

    // Physical bounds the discrete antiradiance can break (docs/SOLVER.md "Stability"):
    // antiradiance sent on carries the light a leaf blocks, which is never negative, so it
    // reads each bin's L_in at zero or above; and the irradiance E is never negative. With
    // them an antiradiance step is an order-reversing map between 0 and the unoccluded
    // incidence, bounded however deep the stack, where unbounded Jacobi steps on a stack of
    // d occluders swing through transients of binomial size and diverge in float. E keeps
    // the bins' signed sum: over-cancelling bins offset leaking ones in it.
    Rgba blocked[Directions::kMaxBins];
    const Rgba zero{};
    for (int k = 0; k < bins; ++k) blocked[k] = lin[k] > zero ? lin[k] : zero;
    Rgba e{}, e1{};  // front light, two sums to halve the chain of additions
    int b = 0;
    for (; b + 1 < bins; b += 2) {
        e += incoming[b] * lin[b];
        e1 += incoming[b + 1] * lin[b + 1];
    }
    if (b < bins) e += incoming[b] * lin[b];
    e = (e + e1) * (m.dirs.BinSolidAngle() * leaf.cosNormIn);
    e = e > zero ? e : zero;
    irradiance[0] = e[0];
    irradiance[1] = e[1];
    irradiance[2] = e[2];
    const float scale = area * leaf.cosNormOut;
    const Rgba front = scale * (Rgba{leaf.emission.x, leaf.emission.y, leaf.emission.z, 0.0f} +
                                Rgba{leaf.albedo.x, leaf.albedo.y, leaf.albedo.z, 0.0f} *
                                    (e + Rgba{direct.x, direct.y, direct.z, 0.0f}) *
                                    (1.0f / std::numbers::pi_v<float>));
    // Front bins get c·front, back bins a⟨n|ω⟩·L_in (c < 0); the other term is zero. A
    // two-sided leaf also sends light arriving at its back on through its front:
    // −a⟨n|ω⟩·L_in for c > 0.
    const bool glossy = (leaf.flags & kLeafGlossy) != 0;
    Rgba spec[Directions::kMaxBins];
    if (glossy) {
        if (mode & kReflect)
            GlossyReflection(m, leaf, area, cosine, lin, spec);
        else
            std::fill(spec, spec + bins, Rgba{});  // only back bins are written
    }
    auto exitant = [&](int b) { return outgoing[b] * front + through[b] * blocked[b]; };
    if (glossy)
        for (int b = 0; b < bins; ++b) spec[b] = outgoing[b] * spec[b];
    auto exitantGlossy = [&](int b) { return exitant(b) + spec[b]; };
    if (mode == kBoth)
        return glossy ? Rows::Store(out, bins, exitantGlossy) : Rows::Store(out, bins, exitant);
    // Hemispheres the mode does not update keep the old row.
    const float carry = oldScale * outScale;
    return Rows::Store(out, bins, [&](int b) {
        bool keep = cosine[b] > 0.0f ? (mode & kReflect) != 0 : (mode & kAntiradiance) != 0;
        if (!keep) return carry * Rows::Load(old + b * 3);
        return glossy ? exitantGlossy(b) : exitant(b);
    });
}

// What a fused iteration needs (CpuBackend::Iterate). For a scaled format, row n of the
// read table holds I_ex / readScale[n] and row n of the written one I_ex · writeScale[n];
// a cluster's row is pullLeft[n] · its left child's + pullRight[n] · its right child's.
template <class Elem>
struct WalkTables {
    const Elem* iex;
    Elem* next;
    const float* readScale = nullptr;
    const float* writeScale = nullptr;
    const float* pullLeft = nullptr;
    const float* pullRight = nullptr;
};

enum Stage { kGatherStage, kPushStage, kLocalStage, kPullStage, kStages };
struct WalkResult {
    std::array<uint64_t, kStages> cycles{};  // summed over the threads
    float maxStored = 0.0f;                  // Rows::Store's largest return
};

// One parallel walk of the hierarchy fuses all four passes (cpu_passes.h, CpuBackend).
template <class Rows>
class FusedWalk {
  public:
    FusedWalk(const AntiradianceModel& m, const uint32_t* leafIndex,
              const WalkTables<typename Rows::Elem>& t, float* irradiance, LocalMode mode)
        : m_(m),
          leafIndex_(leafIndex),
          t_(t),
          irradiance_(irradiance),
          mode_(mode),
          row_(size_t(m.Bins()) * 3) {}

    WalkResult Run() {
        Visit(0, nullptr);
        WalkResult r;
        for (const auto& s : state_) {
            for (int k = 0; k < kStages; ++k) r.cycles[k] += s.cycles[k];
            r.maxStored = std::max(r.maxStored, s.maxStored);
        }
        return r;
    }

  private:
    struct ThreadState {
        std::array<uint64_t, kStages> cycles{};
        float maxStored = 0.0f;
    };
    // Below this many nodes a subtree is walked on the current thread.
    static constexpr uint32_t kGrain = 512;

    void Visit(uint32_t node, const Rgba* parentLin) {
        ThreadState& s = state_.local();
        Rgba lin[Directions::kMaxBins];
        const size_t bins = row_ / 3;
        uint64_t t0 = Ticks();
        if (parentLin)
            std::memcpy(lin, parentLin, bins * sizeof(Rgba));
        else
            EnvironmentRows(m_, lin);
        uint64_t t1 = Ticks();
        Gather<Rows>(m_, t_.iex, t_.readScale, node, lin);
        uint64_t t2 = Ticks();
        s.cycles[kPushStage] += t1 - t0;
        s.cycles[kGatherStage] += t2 - t1;
        const HierarchyNode& n = m_.hierarchy.nodes[node];
        // The next node in the walk's order (left child, or the next subtree after a leaf):
        // its first senders' rows start on their way while this node's local pass runs.
        if (node + 1 < m_.hierarchy.nodes.size()) PrefetchSenders<Rows>(m_, t_.iex, node + 1);
        if (n.IsLeaf()) {
            uint32_t i = leafIndex_[node];
            float oldScale = Rows::kScaled ? t_.readScale[node] : 1.0f;
            float outScale = Rows::kScaled ? t_.writeScale[node] : 1.0f;
            float stored = LocalLeaf<Rows>(m_, m_.leaves[i], m_.leafDirect[i], lin,
                                           t_.iex + node * row_, oldScale, t_.next + node * row_,
                                           outScale, irradiance_ + i * 3, mode_);
            ThreadState& after = state_.local();
            after.maxStored = std::max(after.maxStored, stored);
            after.cycles[kLocalStage] += Ticks() - t2;
            return;
        }
        uint32_t left = m_.leftChild[node], right = m_.rightChild[node];
        if (n.end - node > kGrain)
            tbb::parallel_invoke([&] { Visit(left, lin); }, [&] { Visit(right, lin); });
        else
            Visit(left, lin), Visit(right, lin);
        // Pull while the children's rows are hot.
        uint64_t t3 = Ticks();
        Rows::Sum(t_.next + node * row_, t_.next + left * row_,
                  Rows::kScaled ? t_.pullLeft[node] : 1.0f, t_.next + right * row_,
                  Rows::kScaled ? t_.pullRight[node] : 1.0f, row_);
        state_.local().cycles[kPullStage] += Ticks() - t3;
    }

    const AntiradianceModel& m_;
    const uint32_t* leafIndex_;
    WalkTables<typename Rows::Elem> t_;
    float* irradiance_;
    LocalMode mode_;
    size_t row_;
    tbb::enumerable_thread_specific<ThreadState> state_;
};

// The fp16 format (cpu_half.cpp, built with F16C; callers check
// CpuBackend::HalfSupported first).
// Rows hold I_ex · scale[node] as half floats, 3 per bin, and kHalfPad halves after the
// last row. HalfWalk runs FusedWalk on them; HalfEncode writes rows from fp32 I_ex and
// returns the largest |value| it had to store (values past fp16's range are clamped);
// HalfDecode writes fp32 I_ex back (scale[node] there is the inverse).
inline constexpr size_t kHalfPad = 4;
WalkResult HalfWalk(const AntiradianceModel& m, const uint32_t* leafIndex,
                    const WalkTables<uint16_t>& t, float* irradiance, LocalMode mode);
float HalfEncode(const float* iex, size_t nodes, size_t row, const float* scale, uint16_t* out);
void HalfDecode(const uint16_t* rows, size_t nodes, size_t row, const float* scale, float* out);

}  // namespace penumbra::cpu::detail
