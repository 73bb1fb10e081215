// The antiradiance passes as Vulkan compute on server/gpu: tables resident on the
// device, ping-pong I_ex, one command buffer per iteration with per-pass timestamps.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "gpu/fwd.h"
#include "solver/solver.h"
#include "solvers/antiradiance/backend.h"
#include "solvers/antiradiance/model.h"

namespace penumbra {

class VulkanAntiradiance : public AntiradianceBackend {
  public:
    // `lavapipe`: use the CPU Vulkan device even if a GPU exists; otherwise a real GPU.
    VulkanAntiradiance(const AntiradianceModel& model, bool lavapipe, bool validation);
    ~VulkanAntiradiance() override;

    // AntiradianceBackend: the model's inputs are uploaded again (the Upload* below).
    void Iterate(LocalMode mode) override;  // submits one iteration and waits for it
    std::vector<float> LeafIrradiance() override { return ReadLeafIrradiance(); }
    std::vector<float> Iex() override { return ReadIex(false); }
    void SetIex(const std::vector<float>& iex) override;  // both ping-pong tables
    void InputsChanged(uint32_t inputs) override;
    bool CanUpdateLinks() const override { return true; }
    const char* Tables() const override { return "fp32"; }
    gpu::Context* DirectDevice() override { return &Context(); }
    gpu::Buffer* DirectOut() override { return &DirectBuffer(); }

    std::vector<float> ReadLeafIrradiance();
    // Copies the model's per-leaf attributes (albedo, emission) to the device again.
    void UploadLeaves();
    // Sec. 3.3 on the device (shaders/links.comp): after PlaceGroups, recomputes the bins,
    // spread levels and form factors of the links touching a group with moved[group] set,
    // from the model's nodes and surfels at their new places. The device's links are then
    // the authority: the model's host copy keeps its senders and offsets, not these values.
    // Needs a model with motion links.
    void UpdateLinks(const std::vector<uint8_t>& moved) override;
    // Copies the model's links to the device again (after RedoLinks on the host).
    void UploadLinks();
    // Whether the device is lavapipe, which runs on the host's own cores.
    bool OnCpu() const override;
    // Device time of the last UpdateLinks (0 without timestamps).
    double LinkUpdateMs() const override;
    std::vector<Link> ReadLinks() const;
    // Copies the model's per-leaf direct irradiance (E_d) to the device again.
    void UploadDirect();
    // Copies the model's glossy data (leaves, mirror bins, lobes, reflected direct light) to
    // the device again; buffers are remade when the data outgrew them.
    void UploadGlossy();
    // Copies only the reflected direct light (after a light update; sizes unchanged).
    void UploadGlossyDirect();
    // Copies the model's environment row (radiance per bin) to the device again.
    void UploadEnvironment();
    // The device and the per-leaf E_d buffer (vec4 per leaf) the local pass reads, for the
    // direct pass to render into.
    gpu::Context& Context();
    gpu::Buffer& DirectBuffer();
    std::string DeviceName() const override;
    std::vector<PassTiming> PassTimings() const override;
    size_t TableBytes() const override;
    std::vector<std::string> ValidationMessages() const override;

    // Single passes on the current tables, for GPU ≡ CPU twin tests. The passes are not
    // the CPU twin's one for one: kGlobal gathers the clusters depth by depth, each starting
    // from its parent's row (the CPU's global pass plus its push, on cluster rows); kLocal
    // gathers each leaf on its parent's row and runs the local pass on it without writing
    // the leaf's L_in row; kPull is the CPU's pull.
    enum class Pass { kGlobal, kLocal, kPull };
    void RunPass(Pass pass, LocalMode mode = kBoth);
    // Tables as they are now: I_ex (current), L_in (one row per node; leaf rows are not
    // written by the passes), I_ex (next), irradiance.
    std::vector<float> ReadIex(bool next) const;
    std::vector<float> ReadLin() const;
    void WriteIex(const std::vector<float>& iex, bool next);
    void WriteLin(const std::vector<float>& lin);

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace penumbra
