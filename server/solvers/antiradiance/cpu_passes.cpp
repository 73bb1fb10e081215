// CPU passes of the antiradiance solver (Sec. 3.1 global/local, Sec. 3.2 push/pull).
#include "solvers/antiradiance/cpu_passes.h"

#include <tbb/parallel_for.h>

#if defined(PENUMBRA_HAVE_F16C)
#include <cpuid.h>
#endif

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>

#include "base/check.h"
#include "base/numeric.h"
#include "solvers/antiradiance/cpu_walk.h"

namespace penumbra::cpu {
namespace {

using Clock = std::chrono::steady_clock;
using detail::FloatRows;
using detail::Rgba;

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
    tbb::parallel_for(
        tbb::blocked_range<size_t>(0, m.Nodes(), 64), [&](const tbb::blocked_range<size_t>& range) {
            Rgba acc[Directions::kMaxBins];
            for (size_t r = range.begin(); r != range.end(); ++r) {
                std::fill(acc, acc + row / 3, Rgba{});
                if (r == 0) detail::EnvironmentRows(m, acc);
                detail::Gather<FloatRows>(m, iex, nullptr, static_cast<uint32_t>(r), acc);
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
                              detail::LocalLeaf<FloatRows>(
                                  m, leaf, m.leafDirect[i], rgba, iexOld + leaf.node * row, 1.0f,
                                  iexNew + leaf.node * row, 1.0f, irradiance + i * 3, mode);
                          }
                      });
}

void PullPass(const AntiradianceModel& m, float* iex) { PullRows(m, iex); }

#if defined(PENUMBRA_HAVE_F16C)
// CPUID leaf 1, ECX: F16C (GCC's __builtin_cpu_supports("f16c") is unknown to clang 14).
bool CpuBackend::HalfSupported() {
    unsigned a, b, c, d;
    return __get_cpuid(1, &a, &b, &c, &d) && (c & bit_F16C);
}
#else
// No cpu_half.cpp on this architecture: the fp16 entry points are never reached (the
// constructor refuses kHalf first).
bool CpuBackend::HalfSupported() { return false; }
detail::WalkResult detail::HalfWalk(const AntiradianceModel&, const uint32_t*,
                                    const WalkTables<uint16_t>&, float*, LocalMode) {
    PENUMBRA_CHECK(false);
    return {};
}
float detail::HalfEncode(const float*, size_t, size_t, const float*, uint16_t*) {
    PENUMBRA_CHECK(false);
    return 0.0f;
}
void detail::HalfDecode(const uint16_t*, size_t, size_t, const float*, float*) {
    PENUMBRA_CHECK(false);
}
#endif

CpuBackend::CpuBackend(const AntiradianceModel& model, TableFormat format)
    : m_(model), format_(format) {
    if (format_ == TableFormat::kHalf && !HalfSupported())
        throw Error("fp16 tables need a CPU with F16C (x86-64); use fp32 tables");
    irradiance_.assign(m_.leaves.size() * 3, 0.0f);
    leafIndex_.assign(m_.Nodes(), 0);
    for (uint32_t i = 0; i < m_.leaves.size(); ++i) leafIndex_[m_.leaves[i].node] = i;
    std::vector<float> iex(m_.TableFloats(), 0.0f);
    InitEmission(m_, iex.data());
    if (format_ == TableFormat::kHalf) {
        // Rows over the node's area (cpu_half.cpp): a cluster's row is the area-weighted
        // mean of its children's.
        std::vector<float> area(m_.Nodes(), 0.0f);
        for (const LeafAttributes& leaf : m_.leaves) area[leaf.node] = leaf.area;
        const auto& byDepth = m_.hierarchy.byDepth;
        for (size_t d = byDepth.size(); d-- > 0;)
            for (uint32_t n : byDepth[d])
                if (m_.leftChild[n] != kNoParent)
                    area[n] = area[m_.leftChild[n]] + area[m_.rightChild[n]];
        // A node without area has I_ex = 0 (every term of Eq. 18/19 carries a).
        norm_.resize(m_.Nodes());
        for (size_t n = 0; n < norm_.size(); ++n) norm_[n] = area[n] > 0.0f ? area[n] : 1.0f;
        pullLeft_.assign(m_.Nodes(), 0.0f);
        pullRight_.assign(m_.Nodes(), 0.0f);
        for (size_t n = 0; n < norm_.size(); ++n)
            if (m_.leftChild[n] != kNoParent) {
                pullLeft_[n] = norm_[m_.leftChild[n]] / norm_[n];
                pullRight_[n] = norm_[m_.rightChild[n]] / norm_[n];
            }
        for (auto& t : half_) t.assign(m_.TableFloats() + detail::kHalfPad, 0);
        readScale_.resize(m_.Nodes());
        writeScale_.resize(m_.Nodes());
        SetIex(iex);
    } else {
        iex_[0] = iex;
        iex_[1] = std::move(iex);
    }
}

size_t CpuBackend::TableBytes() const {
    return (iex_[0].size() + iex_[1].size() + irradiance_.size()) * sizeof(float) +
           (half_[0].size() + half_[1].size()) * sizeof(uint16_t);
}

// fp16 rows are scaled so the largest |I_ex / area| expected sits near 2^kPeakExponent:
// 2^6 below fp16's largest value, against light that grows within an iteration, with
// 2^24 of normal range below it.
static constexpr int kPeakExponent = 10;

float CpuBackend::ScaleFor(float peak) {
    if (!(peak > 0.0f) || !std::isfinite(peak)) return 1.0f;
    return std::ldexp(1.0f, kPeakExponent - std::ilogb(peak) - 1);
}

void CpuBackend::InputsChanged(uint32_t) {
    // What this iteration adds to a leaf's I_ex / area whatever the transport: emission,
    // reflected direct light, the sky (which every node's L_in starts from) and the
    // lobes' direct reflection. Light arriving from surfaces is bounded by the last table.
    auto maxOf = [](const auto& v) { return std::max({v.x, v.y, v.z}); };
    float peak = 0.0f;
    for (size_t i = 0; i < m_.leaves.size(); ++i) {
        const LeafAttributes& leaf = m_.leaves[i];
        peak = std::max(peak, maxOf(leaf.emission) + maxOf(leaf.albedo) * maxOf(m_.leafDirect[i]) /
                                                         std::numbers::pi_v<float>);
    }
    for (const glm::vec3& e : m_.environment) peak = std::max(peak, maxOf(e) + 0.0f);
    for (size_t g = 0; g < m_.glossy.size(); ++g) {
        const float f0 = maxOf(m_.glossy[g].specular);
        for (int j = 0; j < m_.Bins(); ++j)
            peak = std::max(peak, f0 * maxOf(m_.glossyDirect[g * m_.Bins() + j]));
    }
    inputPeak_ = peak;
}

std::vector<PassTiming> CpuBackend::PassTimings() const {
    return {{"global", msGlobal}, {"push", msPush}, {"local", msLocal}, {"pull", msPull}};
}

std::vector<float> CpuBackend::Iex() {
    if (format_ == TableFormat::kFloat) return iex_[cur_];
    std::vector<float> out(m_.TableFloats());
    detail::HalfDecode(half_[cur_].data(), m_.Nodes(), size_t(m_.Bins()) * 3, readScale_.data(),
                       out.data());
    return out;
}

void CpuBackend::SetIex(const std::vector<float>& iex) {
    PENUMBRA_CHECK_EQ(iex.size(), m_.TableFloats());
    if (format_ == TableFormat::kFloat) {
        iex_[0] = iex_[1] = iex;
        return;
    }
    const size_t row = size_t(m_.Bins()) * 3;
    float peak = 0.0f;
    for (size_t n = 0; n < m_.Nodes(); ++n)
        for (size_t k = 0; k < row; ++k)
            peak = std::max(peak, std::abs(iex[n * row + k]) / norm_[n]);
    InputsChanged(~0u);
    peak_ = std::max(peak, inputPeak_);
    scale_ = ScaleFor(peak_);
    for (size_t n = 0; n < m_.Nodes(); ++n) writeScale_[n] = scale_ / norm_[n];
    for (size_t n = 0; n < m_.Nodes(); ++n) readScale_[n] = norm_[n] / scale_;
    detail::HalfEncode(iex.data(), m_.Nodes(), row, writeScale_.data(), half_[0].data());
    half_[1] = half_[0];
}

void CpuBackend::Iterate(LocalMode mode) {
    auto t = Clock::now();
    detail::WalkResult r;
    if (format_ == TableFormat::kFloat) {
        detail::WalkTables<float> tables{iex_[cur_].data(), iex_[1 - cur_].data()};
        r = detail::FusedWalk<FloatRows>(m_, leafIndex_.data(), tables, irradiance_.data(), mode)
                .Run();
    } else {
        // The table read holds I_ex · scale_ / area (readScale_ undoes it); the one written
        // gets a scale for the larger of the last iteration's peak and what this one adds.
        float next = ScaleFor(std::max(peak_, inputPeak_));
        for (size_t n = 0; n < m_.Nodes(); ++n) writeScale_[n] = next / norm_[n];
        detail::WalkTables<uint16_t> tables{half_[cur_].data(), half_[1 - cur_].data(),
                                            readScale_.data(),  writeScale_.data(),
                                            pullLeft_.data(),   pullRight_.data()};
        r = detail::HalfWalk(m_, leafIndex_.data(), tables, irradiance_.data(), mode);
        // Leaves' rows bound the clusters' (area-weighted means of them).
        peak_ = r.maxStored / next;
        scale_ = next;
        for (size_t n = 0; n < m_.Nodes(); ++n) readScale_[n] = norm_[n] / scale_;
    }
    double wall = MsSince(t);
    double total = 0;
    for (uint64_t v : r.cycles) total += double(v);
    if (total > 0) {
        msGlobal += wall * r.cycles[detail::kGatherStage] / total;
        msPush += wall * r.cycles[detail::kPushStage] / total;
        msLocal += wall * r.cycles[detail::kLocalStage] / total;
        msPull += wall * r.cycles[detail::kPullStage] / total;
    }
    cur_ = 1 - cur_;
}

}  // namespace penumbra::cpu
