// Shader module, layouts, descriptor pool and specialised compute pipeline.
#include "gpu/pipeline.h"

namespace penumbra::gpu {

Pipeline::Pipeline(Context& ctx, std::span<const uint32_t> spirv, uint32_t bufferCount,
                   std::span<const uint32_t> specialization, uint32_t pushConstantBytes)
    : ctx_(ctx), bufferCount_(bufferCount) {
    const auto& dev = ctx.Device();
    std::vector<vk::DescriptorSetLayoutBinding> bindings;
    for (uint32_t i = 0; i < bufferCount; ++i)
        bindings.emplace_back(i, vk::DescriptorType::eStorageBuffer, 1,
                              vk::ShaderStageFlagBits::eCompute);
    setLayout_ =
        vk::raii::DescriptorSetLayout(dev, vk::DescriptorSetLayoutCreateInfo({}, bindings));
    vk::PushConstantRange range(vk::ShaderStageFlagBits::eCompute, 0, pushConstantBytes);
    vk::DescriptorSetLayout raw = *setLayout_;
    vk::PipelineLayoutCreateInfo li({}, raw);
    if (pushConstantBytes) li.setPushConstantRanges(range);
    layout_ = vk::raii::PipelineLayout(dev, li);

    // Enough sets for the ping-pong variants a pass needs.
    constexpr uint32_t kMaxSets = 8;
    vk::DescriptorPoolSize size(vk::DescriptorType::eStorageBuffer, bufferCount * kMaxSets);
    pool_ = vk::raii::DescriptorPool(
        dev, vk::DescriptorPoolCreateInfo(vk::DescriptorPoolCreateFlagBits::eFreeDescriptorSet,
                                          kMaxSets, size));

    module_ = vk::raii::ShaderModule(
        dev, vk::ShaderModuleCreateInfo({}, spirv.size() * sizeof(uint32_t), spirv.data()));
    std::vector<vk::SpecializationMapEntry> entries;
    for (uint32_t i = 0; i < specialization.size(); ++i)
        entries.emplace_back(i, i * sizeof(uint32_t), sizeof(uint32_t));
    vk::SpecializationInfo spec(static_cast<uint32_t>(entries.size()), entries.data(),
                                specialization.size_bytes(), specialization.data());
    vk::PipelineShaderStageCreateInfo stage({}, vk::ShaderStageFlagBits::eCompute, *module_, "main",
                                            &spec);
    pipeline_ =
        vk::raii::Pipeline(dev, nullptr, vk::ComputePipelineCreateInfo({}, stage, *layout_));
}

vk::raii::DescriptorSet Pipeline::MakeSet(std::span<const Buffer* const> buffers) const {
    vk::DescriptorSetLayout raw = *setLayout_;
    vk::raii::DescriptorSets sets(ctx_.Device(), vk::DescriptorSetAllocateInfo(*pool_, raw));
    vk::raii::DescriptorSet set = std::move(sets.front());
    std::vector<vk::DescriptorBufferInfo> infos;
    infos.reserve(buffers.size());
    for (const Buffer* b : buffers) infos.emplace_back(b->Handle(), 0, VK_WHOLE_SIZE);
    std::vector<vk::WriteDescriptorSet> writes;
    for (uint32_t i = 0; i < buffers.size(); ++i)
        writes.emplace_back(*set, i, 0, 1, vk::DescriptorType::eStorageBuffer, nullptr, &infos[i]);
    ctx_.Device().updateDescriptorSets(writes, {});
    return set;
}

void ComputeBarrier(const vk::raii::CommandBuffer& cb) {
    vk::MemoryBarrier barrier(vk::AccessFlagBits::eShaderWrite,
                              vk::AccessFlagBits::eShaderRead | vk::AccessFlagBits::eShaderWrite);
    cb.pipelineBarrier(vk::PipelineStageFlagBits::eComputeShader,
                       vk::PipelineStageFlagBits::eComputeShader, {}, barrier, {}, {});
}

}  // namespace penumbra::gpu
