// A compute pipeline from embedded SPIR-V: storage buffers at bindings 0..N−1 of set 0,
// uint specialization constants by id, and a push-constant block.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "gpu/buffer.h"
#include "gpu/context.h"

namespace penumbra::gpu {

class Pipeline {
  public:
    Pipeline(Context& ctx, std::span<const uint32_t> spirv, uint32_t bufferCount,
             std::span<const uint32_t> specialization, uint32_t pushConstantBytes);

    // A descriptor set binding `buffers` in order to bindings 0..N−1.
    vk::raii::DescriptorSet MakeSet(std::span<const Buffer* const> buffers) const;

    vk::Pipeline Handle() const { return *pipeline_; }
    vk::PipelineLayout Layout() const { return *layout_; }

  private:
    Context& ctx_;
    uint32_t bufferCount_;
    vk::raii::DescriptorSetLayout setLayout_{nullptr};
    vk::raii::PipelineLayout layout_{nullptr};
    vk::raii::DescriptorPool pool_{nullptr};
    vk::raii::ShaderModule module_{nullptr};
    vk::raii::Pipeline pipeline_{nullptr};
};

// Orders compute writes before later compute reads/writes (a full compute→compute barrier).
void ComputeBarrier(const vk::raii::CommandBuffer& cb);

}  // namespace penumbra::gpu
