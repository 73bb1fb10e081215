// CPU passes of the antiradiance solver (Sec. 3.1 global/local, Sec. 3.2 push/pull).
#include "solver/antiradiance/cpu_passes.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <numbers>

namespace penumbra::cpu {
namespace {

using Clock = std::chrono::steady_clock;
double MsSince(Clock::time_point t) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

// acc[bin][rgb] += Σ over receiver r's links of F · w · I_ex[sender][link bin] (the U
// operator, Eq. 16/17 with the σ spreading of Sec. 3.1). The sender reads are random
// rows of a large table: gather a chunk of F·I_ex values first, prefetching the next
// chunk, then spread them (PERFORMANCE-NOTES.md).
inline void Gather(const AntiradianceModel& m, const float* iex, uint32_t r, float* acc) {
    constexpr size_t kChunk = 16;
    const size_t bins = m.Bins();
    const Link* begin = m.links.links.data() + m.links.offsets[r];
    const Link* end = m.links.links.data() + m.links.offsets[r + 1];
    auto source = [&](const Link* l) { return iex + (size_t(l->sender) * bins + l->bin) * 3; };
    for (const Link* l = begin; l < begin + kChunk && l < end; ++l) __builtin_prefetch(source(l));
    float v[kChunk][3];
    for (const Link* chunk = begin; chunk < end; chunk += kChunk) {
        const size_t n = std::min<size_t>(kChunk, end - chunk);
        for (const Link* l = chunk + kChunk; l < chunk + 2 * kChunk && l < end; ++l)
            __builtin_prefetch(source(l));
        for (size_t k = 0; k < n; ++k) {
            const float* src = source(chunk + k);
            const float f = chunk[k].formFactor;
            v[k][0] = f * src[0];
            v[k][1] = f * src[1];
            v[k][2] = f * src[2];
        }
        for (size_t k = 0; k < n; ++k) {
            for (const BinWeight& nb : m.dirs.Neighbours(chunk[k].level, chunk[k].bin)) {
                float* dst = acc + nb.bin * 3;
                dst[0] += nb.weight * v[k][0];
                dst[1] += nb.weight * v[k][1];
                dst[2] += nb.weight * v[k][2];
            }
        }
    }
}

// Local pass of one leaf for a diffuse BRDF f = ρ/π. Eq. 18 reduces to
// I_L(ω_j) = a ⟨n|ω_j⟩ (L_e + ρ E / π), with E = ω_bin Σ_l ⟨n|−ω_l⟩ L_in(ω_l).
// Eq. 19: I_A(ω_j) = a ⟨n|−ω_j⟩ L_in(ω_j); I_ex = I_L − I_A on separate hemispheres.
inline void LocalLeaf(const AntiradianceModel& m, const LeafAttributes& leaf, const float* lin,
                      const float* old, float* out, float* irradiance, LocalMode mode) {
    const int bins = m.Bins();
    const auto& dirs = m.dirs.All();
    float e0 = 0, e1 = 0, e2 = 0;
    for (int b = 0; b < bins; ++b) {
        float c = glm::dot(leaf.normal, dirs[b]);
        if (c < 0.0f) {
            e0 -= c * lin[b * 3];
            e1 -= c * lin[b * 3 + 1];
            e2 -= c * lin[b * 3 + 2];
        }
    }
    float scale = m.dirs.BinSolidAngle() * leaf.cosNormIn;
    glm::vec3 e(e0 * scale, e1 * scale, e2 * scale);
    irradiance[0] = e.x;
    irradiance[1] = e.y;
    irradiance[2] = e.z;
    glm::vec3 radiance = leaf.emission + leaf.albedo * e * (1.0f / std::numbers::pi_v<float>);
    glm::vec3 front = leaf.area * leaf.cosNormOut * radiance;
    for (int b = 0; b < bins; ++b) {
        float c = glm::dot(leaf.normal, dirs[b]);
        float* o = out + b * 3;
        if (c > 0.0f) {
            if (mode & kReflect) {
                o[0] = c * front.x;
                o[1] = c * front.y;
                o[2] = c * front.z;
            } else {
                std::memcpy(o, old + b * 3, 3 * sizeof(float));
            }
        } else {
            if (mode & kAntiradiance) {
                float w = leaf.area * c;  // −a⟨n|−ω⟩
                o[0] = w * lin[b * 3];
                o[1] = w * lin[b * 3 + 1];
                o[2] = w * lin[b * 3 + 2];
            } else {
                std::memcpy(o, old + b * 3, 3 * sizeof(float));
            }
        }
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

// Push depth by depth from the root down: L_in[n] += L_in[parent]. `clustersOnly`
// leaves the leaves alone (the fused back end adds the parent's row itself).
void PushRows(const AntiradianceModel& m, float* lin, bool clustersOnly) {
    const size_t row = size_t(m.Bins()) * 3;
    const auto& byDepth = m.hierarchy.byDepth;
    const auto& nodes = m.hierarchy.nodes;
    for (size_t d = 1; d < byDepth.size(); ++d) {
        const auto& level = byDepth[d];
        tbb::parallel_for(tbb::blocked_range<size_t>(0, level.size(), 16),
                          [&](const tbb::blocked_range<size_t>& range) {
                              for (size_t i = range.begin(); i != range.end(); ++i) {
                                  uint32_t n = level[i];
                                  if (clustersOnly && nodes[n].IsLeaf()) continue;
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
                          for (size_t r = range.begin(); r != range.end(); ++r) {
                              float* acc = lin + r * row;
                              std::fill(acc, acc + row, 0.0f);
                              Gather(m, iex, static_cast<uint32_t>(r), acc);
                          }
                      });
}

void PushPass(const AntiradianceModel& m, float* lin) { PushRows(m, lin, false); }

void LocalPass(const AntiradianceModel& m, const float* lin, const float* iexOld, float* iexNew,
               float* irradiance, LocalMode mode) {
    const size_t row = size_t(m.Bins()) * 3;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, m.leaves.size(), 64),
                      [&](const tbb::blocked_range<size_t>& range) {
                          for (size_t i = range.begin(); i != range.end(); ++i) {
                              const auto& leaf = m.leaves[i];
                              LocalLeaf(m, leaf, lin + leaf.node * row, iexOld + leaf.node * row,
                                        iexNew + leaf.node * row, irradiance + i * 3, mode);
                          }
                      });
}

void PullPass(const AntiradianceModel& m, float* iex) { PullRows(m, iex); }

CpuBackend::CpuBackend(const AntiradianceModel& model) : m_(model) {
    iex_[0].assign(m_.TableFloats(), 0.0f);
    iex_[1].assign(m_.TableFloats(), 0.0f);
    lin_.assign(m_.TableFloats(), 0.0f);
    irradiance_.assign(m_.leaves.size() * 3, 0.0f);
    InitEmission(m_, iex_[0].data());
    iex_[1] = iex_[0];
}

size_t CpuBackend::TableBytes() const {
    return (iex_[0].size() + iex_[1].size() + lin_.size() + irradiance_.size()) * sizeof(float);
}

void CpuBackend::Iterate(LocalMode mode) {
    const size_t row = size_t(m_.Bins()) * 3;
    const float* iex = iex_[cur_].data();
    float* next = iex_[1 - cur_].data();
    float* lin = lin_.data();
    const auto& interior = m_.hierarchy.interior;

    // Global pass for cluster receivers.
    auto t = Clock::now();
    tbb::parallel_for(tbb::blocked_range<size_t>(0, interior.size(), 32),
                      [&](const tbb::blocked_range<size_t>& range) {
                          for (size_t i = range.begin(); i != range.end(); ++i) {
                              float* acc = lin + interior[i] * row;
                              std::fill(acc, acc + row, 0.0f);
                              Gather(m_, iex, interior[i], acc);
                          }
                      });
    msGlobal += MsSince(t);

    // Push among clusters (depth order: a parent's row is final before its children's).
    t = Clock::now();
    PushRows(m_, lin, true);
    msPush += MsSince(t);

    // Leaves: pushed L_in of the parent + own links, then the local pass, fused so the
    // leaf's L_in never leaves the cache.
    t = Clock::now();
    tbb::parallel_for(tbb::blocked_range<size_t>(0, m_.leaves.size(), 64),
                      [&](const tbb::blocked_range<size_t>& range) {
                          std::vector<float> acc(row);
                          for (size_t i = range.begin(); i != range.end(); ++i) {
                              const auto& leaf = m_.leaves[i];
                              if (leaf.parent != kNoParent)
                                  std::memcpy(acc.data(), lin + leaf.parent * row,
                                              row * sizeof(float));
                              else
                                  std::fill(acc.begin(), acc.end(), 0.0f);
                              Gather(m_, iex, leaf.node, acc.data());
                              LocalLeaf(m_, leaf, acc.data(), iex + leaf.node * row,
                                        next + leaf.node * row, irradiance_.data() + i * 3, mode);
                          }
                      });
    msLocal += MsSince(t);

    t = Clock::now();
    PullRows(m_, next);
    msPull += MsSince(t);
    cur_ = 1 - cur_;
}

}  // namespace penumbra::cpu
