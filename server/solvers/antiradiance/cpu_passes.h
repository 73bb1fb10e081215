// The antiradiance passes in C++ on the same table layout as the shaders: the CPU twin
// of every GPU pass (for tests) and the fused fast path of `--device cpu`.
// Tables are float[node][bin][rgb]: I_ex (exitant intensity), L_in (incident radiance).
#pragma once

#include <vector>

#include "solvers/antiradiance/backend.h"
#include "solvers/antiradiance/model.h"

namespace penumbra::cpu {

// I_ex of the leaves = emitted intensity a·cos·L_e (front bins), 0 behind; pulled up.
void InitEmission(const AntiradianceModel& m, float* iex);

// Global pass (U): L_in[r] = Σ_links F · w_σ · I_ex[s][bin] for every node r.
void GlobalPass(const AntiradianceModel& m, const float* iex, float* lin);
// Push: L_in of every node += L_in of its parent, parents first (depth order).
void PushPass(const AntiradianceModel& m, float* lin);
// Local pass at the leaves (K: Eq. 18, J: Eq. 19). Hemispheres not in `mode` keep
// `iexOld`. Writes per-leaf irradiance (rgb) to `irradiance`.
void LocalPass(const AntiradianceModel& m, const float* lin, const float* iexOld, float* iexNew,
               float* irradiance, LocalMode mode);
// Pull: interior I_ex = Σ children, bottom up (deepest clusters first).
void PullPass(const AntiradianceModel& m, float* iex);

// How the CPU back end stores its I_ex tables: fp32 I_ex (the shaders' layout), or fp16
// I_ex over each node's area (cpu_half.cpp; needs F16C): half the memory traffic of the
// gather's random reads and of the rows written, to about 5·10⁻⁴ relative.
enum class TableFormat { kFloat, kHalf };

// The CPU back end: one parallel walk of the hierarchy per iteration fuses all four
// passes (cpu_walk.h). Each node's L_in = its parent's (pushed down on the stack) + its
// own links' gather; leaves run the local pass; clusters sum their children's fresh I_ex
// rows while they are still in cache. Only I_ex (ping-pong) lives in memory.
class CpuBackend : public AntiradianceBackend {
  public:
    // Throws penumbra::Error for kHalf on a CPU without F16C.
    CpuBackend(const AntiradianceModel& model, TableFormat format);
    static bool HalfSupported();  // whether kHalf runs on this CPU
    std::string DeviceName() const override { return "cpu"; }
    bool OnCpu() const override { return true; }
    void Iterate(LocalMode mode) override;
    std::vector<float> LeafIrradiance() override { return irradiance_; }
    size_t TableBytes() const override;
    TableFormat Format() const { return format_; }
    const char* Tables() const override { return format_ == TableFormat::kHalf ? "fp16" : "fp32"; }
    // fp32 I_ex whatever the format; SetIex replaces both ping-pong tables.
    std::vector<float> Iex() override;
    void SetIex(const std::vector<float>& iex) override;
    // The fp16 tables' scale follows what an iteration adds, measured here once instead of
    // every iteration; the rest of the model is read in place.
    void InputsChanged(uint32_t inputs) override;
    std::vector<PassTiming> PassTimings() const override;
    // Milliseconds per stage since construction: each stage's share of the threads' time,
    // scaled to the wall time of the fused walk.
    double msGlobal = 0, msPush = 0, msLocal = 0, msPull = 0;

  private:
    static float ScaleFor(float peak);

    const AntiradianceModel& m_;
    TableFormat format_;
    std::vector<float> iex_[2];  // kFloat
    std::vector<float> irradiance_;
    std::vector<uint32_t> leafIndex_;  // node → index into m_.leaves
    int cur_ = 0;
    // kHalf: rows of half_[cur_] hold I_ex · scale_ / norm_[node] (norm_: the node's area,
    // 1 without one); readScale_ = norm_ / scale_, writeScale_ the next table's inverse;
    // a cluster's row = pullLeft_ · left child's + pullRight_ · right child's; peak_ the
    // largest |I_ex / area| written last.
    std::vector<uint16_t> half_[2];
    std::vector<float> norm_, readScale_, writeScale_, pullLeft_, pullRight_;
    float scale_ = 1.0f, peak_ = 0.0f;
    float inputPeak_ = 0.0f;  // InputsChanged
};

}  // namespace penumbra::cpu
