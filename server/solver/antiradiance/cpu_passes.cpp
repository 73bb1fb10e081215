// CPU passes of the antiradiance solver (Sec. 3.1 global/local, Sec. 3.2 push/pull).
#include "solver/antiradiance/cpu_passes.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstring>
#include <numbers>

namespace penumbra::cpu {
namespace {

using Clock = std::chrono::steady_clock;

// A cheap per-thread tick counter for splitting the fused walk's time into stages.
inline uint64_t Ticks() {
#if defined(__x86_64__) || defined(__i386__)
    return __builtin_ia32_rdtsc();
#else
    return static_cast<uint64_t>(Clock::now().time_since_epoch().count());
#endif
}
double MsSince(Clock::time_point t) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

// Four floats (RGB and a zero pad): one vector update per spread neighbour instead of
// three scalar ones.
using Rgba = float __attribute__((vector_size(16)));

// The root's L_in before its links: the environment per bin (model.h), as RGBA rows.
inline void EnvironmentRows(const AntiradianceModel& m, Rgba* lin) {
    for (size_t b = 0; b < m.environment.size(); ++b) {
        const glm::vec3& e = m.environment[b];
        lin[b] = Rgba{e.x, e.y, e.z, 0.0f};
    }
}

// acc[bin] += Σ over receiver r's links of F · w · I_ex[sender][link bin] (the U operator,
// Eq. 16/17 with the σ spreading of Sec. 3.1), RGB in the first three lanes. The sender
// reads are random rows of a large table: gather a chunk of F·I_ex values first,
// prefetching the next chunk, then spread them (PERFORMANCE-NOTES.md).
inline void GatherRgba(const AntiradianceModel& m, const float* iex, uint32_t r, Rgba* acc) {
    constexpr size_t kChunk = 16;
    const size_t bins = m.Bins();
    const Link* begin = m.links.links.data() + m.links.offsets[r];
    const Link* end = m.links.links.data() + m.links.offsets[r + 1];
    auto source = [&](const Link* l) { return iex + (size_t(l->sender) * bins + l->bin) * 3; };
    for (const Link* l = begin; l < begin + kChunk && l < end; ++l) __builtin_prefetch(source(l));
    Rgba v[kChunk];
    for (const Link* chunk = begin; chunk < end; chunk += kChunk) {
        const size_t n = std::min<size_t>(kChunk, end - chunk);
        for (const Link* l = chunk + kChunk; l < chunk + 2 * kChunk && l < end; ++l)
            __builtin_prefetch(source(l));
        for (size_t k = 0; k < n; ++k) {
            const float* src = source(chunk + k);
            v[k] = chunk[k].formFactor * Rgba{src[0], src[1], src[2], 0.0f};
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
// w the discretised lobe (model.h, GlossyLobe). The incoming light is first gathered at
// the mirror bin of each incoming bin, then each outgoing bin reads its lobe row there (the
// kernel is symmetric): bins · (1 + row width) operations instead of bins².
inline void GlossyReflection(const AntiradianceModel& m, const LeafAttributes& leaf,
                             const float* cosine, const Rgba* lin, Rgba* spec) {
    const int bins = m.Bins();
    const uint32_t g = leaf.flags >> kGlossyShift;
    Rgba arrived[Directions::kMaxBins];
    std::fill(arrived, arrived + bins, Rgba{});
    const uint32_t* mirror = m.mirror.data() + size_t(g) * bins;
    for (int l = 0; l < bins; ++l)
        if (cosine[l] < 0.0f) arrived[mirror[l]] += -cosine[l] * lin[l];
    const GlossyLeaf& gl = m.glossy[g];
    const GlossyLobe& lobe = m.lobes[gl.lobe];
    const Rgba f0 = leaf.area * Rgba{gl.specular.x, gl.specular.y, gl.specular.z, 0.0f};
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
// `lin` holds the leaf's L_in as RGBA rows; `old` and `out` are rows of the RGB I_ex table.
inline void LocalLeaf(const AntiradianceModel& m, const LeafAttributes& leaf,
                      const glm::vec4& direct, const Rgba* lin, const float* old, float* out,
                      float* irradiance, LocalMode mode) {
    const int bins = m.Bins();
    // Cosines of all bins once, from the directions' SoA arrays (vectorises).
    float cosine[Directions::kMaxBins];
    const float *dx = m.dirs.X(), *dy = m.dirs.Y(), *dz = m.dirs.Z();
    const glm::vec3 n = leaf.normal;
    for (int b = 0; b < bins; ++b) cosine[b] = n.x * dx[b] + n.y * dy[b] + n.z * dz[b];

    Rgba e{};
    for (int b = 0; b < bins; ++b) e += std::max(0.0f, -cosine[b]) * lin[b];  // front light
    e *= m.dirs.BinSolidAngle() * leaf.cosNormIn;
    irradiance[0] = e[0];
    irradiance[1] = e[1];
    irradiance[2] = e[2];
    const float scale = leaf.area * leaf.cosNormOut;
    const Rgba front = scale * (Rgba{leaf.emission.x, leaf.emission.y, leaf.emission.z, 0.0f} +
                                Rgba{leaf.albedo.x, leaf.albedo.y, leaf.albedo.z, 0.0f} *
                                    (e + Rgba{direct.x, direct.y, direct.z, 0.0f}) *
                                    (1.0f / std::numbers::pi_v<float>));
    // Front bins get c·front, back bins a⟨n|ω⟩·L_in (c < 0); the other term is zero. A
    // two-sided leaf also sends light arriving at its back on through its front:
    // −a⟨n|ω⟩·L_in for c > 0.
    const bool twoSided = (leaf.flags & kLeafTwoSided) != 0;
    const bool glossy = (leaf.flags & kLeafGlossy) != 0;
    Rgba spec[Directions::kMaxBins];
    if (glossy) {
        if (mode & kReflect)
            GlossyReflection(m, leaf, cosine, lin, spec);
        else
            std::fill(spec, spec + bins, Rgba{});  // only back bins are written
    }
    auto exitant = [&](int b) {
        float c = cosine[b];
        float through = twoSided ? -std::abs(c) : std::min(c, 0.0f);
        Rgba v = std::max(c, 0.0f) * front + leaf.area * through * lin[b];
        if (glossy) v += std::max(c, 0.0f) * spec[b];
        return v;
    };
    auto keep = [&](int b) {
        return cosine[b] > 0.0f ? (mode & kReflect) != 0 : (mode & kAntiradiance) != 0;
    };
    // 16-byte stores at a 12-byte stride: each one's pad lane is overwritten by the next
    // bin's; the row's last bin is stored as three floats so the row's end stays put.
    for (int b = 0; b + 1 < bins; ++b) {
        Rgba o;
        if (mode == kBoth || keep(b))
            o = exitant(b);
        else
            o = Rgba{old[b * 3], old[b * 3 + 1], old[b * 3 + 2], 0.0f};
        std::memcpy(out + b * 3, &o, sizeof(Rgba));
    }
    const int b = bins - 1;
    if (mode == kBoth || keep(b)) {
        Rgba o = exitant(b);
        std::memcpy(out + b * 3, &o, 3 * sizeof(float));
    } else {
        std::memcpy(out + b * 3, old + b * 3, 3 * sizeof(float));
    }
}

// Pull depth by depth from the deepest clusters up; the clusters of one depth are
// independent, so each depth is split over the threads.
void PullRows(const AntiradianceModel& m, float* iex) {
    const size_t row = size_t(m.Bins()) * 3;
    const auto& byDepth = m.hierarchy.byDepth;
    for (size_t d = byDepth.size(); d-- > 0;) {
        const auto& level = byDepth[d];
        tbb::parallel_for(tbb::blocked_range<size_t>(0, level.size(), 16),
                          [&](const tbb::blocked_range<size_t>& range) {
                              for (size_t i = range.begin(); i != range.end(); ++i) {
                                  uint32_t n = level[i];
                                  if (m.leftChild[n] == kNoParent) continue;
                                  float* dst = iex + n * row;
                                  const float* a = iex + m.leftChild[n] * row;
                                  const float* b = iex + m.rightChild[n] * row;
                                  for (size_t k = 0; k < row; ++k) dst[k] = a[k] + b[k];
                              }
                          });
    }
}

// Push depth by depth from the root down: L_in[n] += L_in[parent].
void PushRows(const AntiradianceModel& m, float* lin) {
    const size_t row = size_t(m.Bins()) * 3;
    const auto& byDepth = m.hierarchy.byDepth;
    const auto& nodes = m.hierarchy.nodes;
    for (size_t d = 1; d < byDepth.size(); ++d) {
        const auto& level = byDepth[d];
        tbb::parallel_for(tbb::blocked_range<size_t>(0, level.size(), 16),
                          [&](const tbb::blocked_range<size_t>& range) {
                              for (size_t i = range.begin(); i != range.end(); ++i) {
                                  uint32_t n = level[i];
                                  float* dst = lin + n * row;
                                  const float* src = lin + nodes[n].parent * row;
                                  for (size_t k = 0; k < row; ++k) dst[k] += src[k];
                              }
                          });
    }
}

}  // namespace

void InitEmission(const AntiradianceModel& m, float* iex) {
    const int bins = m.Bins();
    const size_t row = size_t(bins) * 3;
    std::fill(iex, iex + m.TableFloats(), 0.0f);
    for (const auto& leaf : m.leaves) {
        float* out = iex + leaf.node * row;
        glm::vec3 front = leaf.area * leaf.cosNormOut * leaf.emission;
        for (int b = 0; b < bins; ++b) {
            float c = glm::dot(leaf.normal, m.dirs.Direction(b));
            if (c > 0.0f) {
                out[b * 3] = c * front.x;
                out[b * 3 + 1] = c * front.y;
                out[b * 3 + 2] = c * front.z;
            }
        }
    }
    PullRows(m, iex);
}

void GlobalPass(const AntiradianceModel& m, const float* iex, float* lin) {
    const size_t row = size_t(m.Bins()) * 3;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, m.Nodes(), 64),
                      [&](const tbb::blocked_range<size_t>& range) {
                          Rgba acc[Directions::kMaxBins];
                          for (size_t r = range.begin(); r != range.end(); ++r) {
                              std::fill(acc, acc + row / 3, Rgba{});
                              if (r == 0) EnvironmentRows(m, acc);
                              GatherRgba(m, iex, static_cast<uint32_t>(r), acc);
                              float* out = lin + r * row;
                              for (size_t b = 0; b < row / 3; ++b)
                                  for (int c = 0; c < 3; ++c) out[b * 3 + c] = acc[b][c];
                          }
                      });
}

void PushPass(const AntiradianceModel& m, float* lin) { PushRows(m, lin); }

void LocalPass(const AntiradianceModel& m, const float* lin, const float* iexOld, float* iexNew,
               float* irradiance, LocalMode mode) {
    const size_t row = size_t(m.Bins()) * 3;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, m.leaves.size(), 64),
                      [&](const tbb::blocked_range<size_t>& range) {
                          for (size_t i = range.begin(); i != range.end(); ++i) {
                              const auto& leaf = m.leaves[i];
                              Rgba rgba[Directions::kMaxBins];
                              const float* l = lin + leaf.node * row;
                              for (size_t b = 0; b < row / 3; ++b)
                                  rgba[b] = Rgba{l[b * 3], l[b * 3 + 1], l[b * 3 + 2], 0.0f};
                              LocalLeaf(m, leaf, m.leafDirect[i], rgba, iexOld + leaf.node * row,
                                        iexNew + leaf.node * row, irradiance + i * 3, mode);
                          }
                      });
}

void PullPass(const AntiradianceModel& m, float* iex) { PullRows(m, iex); }

// State of one fused iteration; stage cycles are counted per thread.
struct CpuBackend::Walk {
    enum Stage { kGather, kPush, kLocal, kPull, kStages };
    const AntiradianceModel& m;
    const CpuBackend& self;
    const float* iex;
    float* next;
    float* irradiance;
    LocalMode mode;
    size_t row;
    tbb::enumerable_thread_specific<std::array<uint64_t, kStages>> cycles{
        std::array<uint64_t, kStages>{}};

    // Below this many nodes a subtree is walked on the current thread.
    static constexpr uint32_t kGrain = 512;

    void Visit(uint32_t node, const Rgba* parentLin) {
        auto& c = cycles.local();
        Rgba lin[Directions::kMaxBins];
        const size_t bins = row / 3;
        uint64_t t0 = Ticks();
        if (parentLin) {
            std::memcpy(lin, parentLin, bins * sizeof(Rgba));
        } else {
            EnvironmentRows(m, lin);
        }
        uint64_t t1 = Ticks();
        GatherRgba(m, iex, node, lin);
        uint64_t t2 = Ticks();
        c[kPush] += t1 - t0;
        c[kGather] += t2 - t1;
        const HierarchyNode& n = m.hierarchy.nodes[node];
        if (n.IsLeaf()) {
            uint32_t i = self.leafIndex_[node];
            LocalLeaf(m, m.leaves[i], m.leafDirect[i], lin, iex + node * row, next + node * row,
                      irradiance + i * 3, mode);
            cycles.local()[kLocal] += Ticks() - t2;
            return;
        }
        uint32_t left = m.leftChild[node], right = m.rightChild[node];
        if (n.end - node > kGrain)
            tbb::parallel_invoke([&] { Visit(left, lin); }, [&] { Visit(right, lin); });
        else
            Visit(left, lin), Visit(right, lin);
        // Pull while the children's rows are hot.
        uint64_t t3 = Ticks();
        float* dst = next + node * row;
        const float* a = next + left * row;
        const float* b = next + right * row;
        for (size_t k = 0; k < row; ++k) dst[k] = a[k] + b[k];
        cycles.local()[kPull] += Ticks() - t3;
    }
};

CpuBackend::CpuBackend(const AntiradianceModel& model) : m_(model) {
    iex_[0].assign(m_.TableFloats(), 0.0f);
    iex_[1].assign(m_.TableFloats(), 0.0f);
    irradiance_.assign(m_.leaves.size() * 3, 0.0f);
    leafIndex_.assign(m_.Nodes(), 0);
    for (uint32_t i = 0; i < m_.leaves.size(); ++i) leafIndex_[m_.leaves[i].node] = i;
    InitEmission(m_, iex_[0].data());
    iex_[1] = iex_[0];
}

size_t CpuBackend::TableBytes() const {
    return (iex_[0].size() + iex_[1].size() + irradiance_.size()) * sizeof(float);
}

void CpuBackend::Iterate(LocalMode mode) {
    Walk walk{m_,
              *this,
              iex_[cur_].data(),
              iex_[1 - cur_].data(),
              irradiance_.data(),
              mode,
              size_t(m_.Bins()) * 3};
    auto t = Clock::now();
    walk.Visit(0, nullptr);
    double wall = MsSince(t);
    std::array<uint64_t, Walk::kStages> sum{};
    for (const auto& c : walk.cycles)
        for (int k = 0; k < Walk::kStages; ++k) sum[k] += c[k];
    double total = 0;
    for (uint64_t v : sum) total += double(v);
    if (total > 0) {
        msGlobal += wall * sum[Walk::kGather] / total;
        msPush += wall * sum[Walk::kPush] / total;
        msLocal += wall * sum[Walk::kLocal] / total;
        msPull += wall * sum[Walk::kPull] / total;
    }
    cur_ = 1 - cur_;
}

}  // namespace penumbra::cpu
