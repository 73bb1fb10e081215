// Pipelines from embedded SPIR-V whose resources are buffers at bindings 0..N−1 of set 0
// (storage buffers, or texel-buffer views of them), plus a push-constant block: compute
// pipelines (with uint specialization constants by id), and the graphics pipeline of the
// raster targets (gpu/render_target.h).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "base/check.h"
#include "gpu/buffer.h"
#include "gpu/context.h"

namespace penumbra::gpu {

// The words of an embedded SPIR-V array (shaders/: kSpirv_<name>).
template <typename T>
std::span<const uint32_t> Words(const T& array) {
    return {array, sizeof(array) / sizeof(uint32_t)};
}

// What one binding of set 0 holds: a storage buffer, or a buffer read through a uniform
// texel buffer view of 32-bit floats or uints (`samplerBuffer` / `usamplerBuffer`). lavapipe
// (Mesa 22.3) loads a storage buffer lane by lane behind a branch per lane and component,
// but gathers texel fetches into vector registers: random reads in hot loops go faster as
// texel fetches there.
enum class Slot : uint8_t { kStorage, kTexelFloat, kTexelUint };

// Set 0 with one binding per slot (or `count` storage buffers) visible to `stages`, and a
// pool for a few sets of it.
class BufferSetLayout {
  public:
    BufferSetLayout(Context& ctx, uint32_t count, vk::ShaderStageFlags stages);
    BufferSetLayout(Context& ctx, std::vector<Slot> slots, vk::ShaderStageFlags stages);
    // A descriptor set binding `buffers` in order to bindings 0..N−1.
    vk::raii::DescriptorSet MakeSet(std::span<const Buffer* const> buffers) const;
    vk::DescriptorSetLayout Handle() const { return *setLayout_; }

  private:
    Context& ctx_;
    std::vector<Slot> slots_;
    vk::raii::DescriptorSetLayout setLayout_{nullptr};
    vk::raii::DescriptorPool pool_{nullptr};
};

// A compute pipeline. With several specializations it holds one variant per list (the
// shader compiled with other constants: dead code gone), made on first use; all variants
// share the layout, so one descriptor set serves them all.
class Pipeline {
  public:
    Pipeline(Context& ctx, std::span<const uint32_t> spirv, uint32_t bufferCount,
             std::span<const uint32_t> specialization, uint32_t pushConstantBytes);
    Pipeline(Context& ctx, std::span<const uint32_t> spirv, std::vector<Slot> slots,
             std::span<const uint32_t> specialization, uint32_t pushConstantBytes);
    Pipeline(Context& ctx, std::span<const uint32_t> spirv, std::vector<Slot> slots,
             std::vector<std::vector<uint32_t>> variants, uint32_t pushConstantBytes);

    vk::raii::DescriptorSet MakeSet(std::span<const Buffer* const> buffers) const {
        return sets_.MakeSet(buffers);
    }
    vk::Pipeline Handle(size_t variant = 0) const;
    vk::PipelineLayout Layout() const { return *layout_; }

    // Recording a compute pass: binds a variant and the descriptor set its dispatches read
    // (Bind), or only another variant, the set bound before staying (the variants share the
    // layout); then each Dispatch sets the push-constant block (the size the pipeline was
    // made with) and dispatches `groups` workgroups along x.
    void Bind(const vk::raii::CommandBuffer& cb, const vk::raii::DescriptorSet& set,
              size_t variant = 0) const;
    void BindVariant(const vk::raii::CommandBuffer& cb, size_t variant) const;
    template <typename Push>
    void Dispatch(const vk::raii::CommandBuffer& cb, const Push& push, uint32_t groups) const {
        PENUMBRA_CHECK_EQ(sizeof(Push), pushConstantBytes_);
        cb.pushConstants<Push>(*layout_, vk::ShaderStageFlagBits::eCompute, 0, push);
        cb.dispatch(groups, 1, 1);
    }

  private:
    Context& ctx_;
    uint32_t pushConstantBytes_ = 0;
    BufferSetLayout sets_;
    vk::raii::PipelineLayout layout_{nullptr};
    vk::raii::ShaderModule module_{nullptr};
    std::vector<std::vector<uint32_t>> variants_;
    mutable std::vector<vk::raii::Pipeline> pipelines_;
};

// A shader module from SPIR-V words, and a pipeline layout of `sets` plus a push-constant
// block of `pushConstantBytes` (none when 0) visible to `stages`.
vk::raii::ShaderModule MakeShaderModule(Context& ctx, std::span<const uint32_t> spirv);
vk::raii::PipelineLayout MakePipelineLayout(Context& ctx, const BufferSetLayout& sets,
                                            vk::ShaderStageFlags stages,
                                            uint32_t pushConstantBytes);

// A graphics pipeline drawing triangle lists over a width × height area with no vertex input
// (vertex shaders read buffers by gl_VertexIndex) and no culling. With `colorDepth`, subpass 0
// of `renderPass` has one colour attachment (all channels written, no blending) and a depth
// attachment tested with LESS; without, it has no attachments.
vk::raii::Pipeline MakeTrianglePipeline(Context& ctx, vk::ShaderModule vertex,
                                        vk::ShaderModule fragment, vk::PipelineLayout layout,
                                        vk::RenderPass renderPass, uint32_t width, uint32_t height,
                                        bool colorDepth);

// Orders compute writes before later compute reads/writes (a full compute→compute barrier).
void ComputeBarrier(const vk::raii::CommandBuffer& cb);

// Orders writes of stage `from` before shader reads and writes of stage `to`.
void Barrier(const vk::raii::CommandBuffer& cb, vk::PipelineStageFlags from,
             vk::AccessFlags fromAccess, vk::PipelineStageFlags to);

// Orders writes of stage `from` (compute shaders' by default) before the host reads them
// (after the submission's fence).
void HostReadBarrier(const vk::raii::CommandBuffer& cb,
                     vk::PipelineStageFlags from = vk::PipelineStageFlagBits::eComputeShader,
                     vk::AccessFlags fromAccess = vk::AccessFlagBits::eShaderWrite);

}  // namespace penumbra::gpu
