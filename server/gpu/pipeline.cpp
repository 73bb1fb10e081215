// Shader modules, layouts, descriptor pools, and compute and raster pipelines.
#include "gpu/pipeline.h"

#include "base/check.h"

namespace penumbra::gpu {

BufferSetLayout::BufferSetLayout(Context& ctx, uint32_t count, vk::ShaderStageFlags stages)
    : BufferSetLayout(ctx, std::vector<Slot>(count, Slot::kStorage), stages) {}

namespace {
vk::DescriptorType TypeOf(Slot slot) {
    return slot == Slot::kStorage ? vk::DescriptorType::eStorageBuffer
                                  : vk::DescriptorType::eUniformTexelBuffer;
}
}  // namespace

BufferSetLayout::BufferSetLayout(Context& ctx, std::vector<Slot> slots, vk::ShaderStageFlags stages)
    : ctx_(ctx), slots_(std::move(slots)) {
    const auto& dev = ctx.Device();
    std::vector<vk::DescriptorSetLayoutBinding> bindings;
    uint32_t storage = 0, texel = 0;
    for (uint32_t i = 0; i < slots_.size(); ++i) {
        bindings.emplace_back(i, TypeOf(slots_[i]), 1, stages);
        ++(slots_[i] == Slot::kStorage ? storage : texel);
    }
    setLayout_ =
        vk::raii::DescriptorSetLayout(dev, vk::DescriptorSetLayoutCreateInfo({}, bindings));
    // Enough sets for the ping-pong variants a pass needs.
    constexpr uint32_t kMaxSets = 8;
    std::vector<vk::DescriptorPoolSize> sizes;
    if (storage) sizes.emplace_back(vk::DescriptorType::eStorageBuffer, storage * kMaxSets);
    if (texel) sizes.emplace_back(vk::DescriptorType::eUniformTexelBuffer, texel * kMaxSets);
    pool_ = vk::raii::DescriptorPool(
        dev, vk::DescriptorPoolCreateInfo(vk::DescriptorPoolCreateFlagBits::eFreeDescriptorSet,
                                          kMaxSets, sizes));
}

vk::raii::DescriptorSet BufferSetLayout::MakeSet(std::span<const Buffer* const> buffers) const {
    PENUMBRA_CHECK_EQ(buffers.size(), slots_.size());
    vk::DescriptorSetLayout raw = *setLayout_;
    vk::raii::DescriptorSets sets(ctx_.Device(), vk::DescriptorSetAllocateInfo(*pool_, raw));
    vk::raii::DescriptorSet set = std::move(sets.front());
    std::vector<vk::DescriptorBufferInfo> infos(buffers.size());
    std::vector<vk::BufferView> views(buffers.size());
    std::vector<vk::WriteDescriptorSet> writes;
    for (uint32_t i = 0; i < buffers.size(); ++i) {
        const Slot slot = slots_[i];
        if (slot == Slot::kStorage) {
            infos[i] = vk::DescriptorBufferInfo(buffers[i]->Handle(), 0, VK_WHOLE_SIZE);
            writes.emplace_back(*set, i, 0, 1, TypeOf(slot), nullptr, &infos[i]);
        } else {
            views[i] = buffers[i]->View(slot == Slot::kTexelFloat ? vk::Format::eR32Sfloat
                                                                  : vk::Format::eR32Uint);
            writes.emplace_back(*set, i, 0, 1, TypeOf(slot), nullptr, nullptr, &views[i]);
        }
    }
    ctx_.Device().updateDescriptorSets(writes, {});
    return set;
}

vk::raii::PipelineLayout MakePipelineLayout(Context& ctx, const BufferSetLayout& sets,
                                            vk::ShaderStageFlags stages,
                                            uint32_t pushConstantBytes) {
    vk::PushConstantRange range(stages, 0, pushConstantBytes);
    vk::DescriptorSetLayout raw = sets.Handle();
    vk::PipelineLayoutCreateInfo li({}, raw);
    if (pushConstantBytes) li.setPushConstantRanges(range);
    return vk::raii::PipelineLayout(ctx.Device(), li);
}

vk::raii::ShaderModule MakeShaderModule(Context& ctx, std::span<const uint32_t> spirv) {
    return vk::raii::ShaderModule(
        ctx.Device(),
        vk::ShaderModuleCreateInfo({}, spirv.size() * sizeof(uint32_t), spirv.data()));
}

Pipeline::Pipeline(Context& ctx, std::span<const uint32_t> spirv, uint32_t bufferCount,
                   std::span<const uint32_t> specialization, uint32_t pushConstantBytes)
    : Pipeline(ctx, spirv, std::vector<Slot>(bufferCount, Slot::kStorage), specialization,
               pushConstantBytes) {}

Pipeline::Pipeline(Context& ctx, std::span<const uint32_t> spirv, std::vector<Slot> slots,
                   std::span<const uint32_t> specialization, uint32_t pushConstantBytes)
    : Pipeline(ctx, spirv, std::move(slots),
               std::vector<std::vector<uint32_t>>{
                   std::vector<uint32_t>(specialization.begin(), specialization.end())},
               pushConstantBytes) {}

Pipeline::Pipeline(Context& ctx, std::span<const uint32_t> spirv, std::vector<Slot> slots,
                   std::vector<std::vector<uint32_t>> variants, uint32_t pushConstantBytes)
    : ctx_(ctx),
      pushConstantBytes_(pushConstantBytes),
      sets_(ctx, std::move(slots), vk::ShaderStageFlagBits::eCompute),
      variants_(std::move(variants)) {
    PENUMBRA_CHECK(!variants_.empty());
    layout_ = MakePipelineLayout(ctx, sets_, vk::ShaderStageFlagBits::eCompute, pushConstantBytes);
    module_ = MakeShaderModule(ctx, spirv);
    Handle(0);  // the first variant now, so that a broken shader fails at set-up
}

void Pipeline::Bind(const vk::raii::CommandBuffer& cb, const vk::raii::DescriptorSet& set,
                    size_t variant) const {
    BindVariant(cb, variant);
    cb.bindDescriptorSets(vk::PipelineBindPoint::eCompute, *layout_, 0, {*set}, {});
}

void Pipeline::BindVariant(const vk::raii::CommandBuffer& cb, size_t variant) const {
    cb.bindPipeline(vk::PipelineBindPoint::eCompute, Handle(variant));
}

vk::Pipeline Pipeline::Handle(size_t variant) const {
    PENUMBRA_CHECK_LT(variant, variants_.size());
    if (pipelines_.empty())
        for (size_t v = 0; v < variants_.size(); ++v) pipelines_.emplace_back(nullptr);
    if (!*pipelines_[variant]) {
        const std::vector<uint32_t>& specialization = variants_[variant];
        std::vector<vk::SpecializationMapEntry> entries;
        for (uint32_t i = 0; i < specialization.size(); ++i)
            entries.emplace_back(i, i * sizeof(uint32_t), sizeof(uint32_t));
        vk::SpecializationInfo spec(static_cast<uint32_t>(entries.size()), entries.data(),
                                    specialization.size() * sizeof(uint32_t),
                                    specialization.data());
        vk::PipelineShaderStageCreateInfo stage({}, vk::ShaderStageFlagBits::eCompute, *module_,
                                                "main", &spec);
        pipelines_[variant] = vk::raii::Pipeline(
            ctx_.Device(), nullptr, vk::ComputePipelineCreateInfo({}, stage, *layout_));
    }
    return *pipelines_[variant];
}

vk::raii::Pipeline MakeTrianglePipeline(Context& ctx, vk::ShaderModule vertex,
                                        vk::ShaderModule fragment, vk::PipelineLayout layout,
                                        vk::RenderPass renderPass, uint32_t width, uint32_t height,
                                        bool colorDepth) {
    vk::PipelineShaderStageCreateInfo stages[] = {
        {{}, vk::ShaderStageFlagBits::eVertex, vertex, "main"},
        {{}, vk::ShaderStageFlagBits::eFragment, fragment, "main"}};

    vk::PipelineVertexInputStateCreateInfo vertexInput;
    vk::PipelineInputAssemblyStateCreateInfo assembly({}, vk::PrimitiveTopology::eTriangleList);
    vk::Viewport viewport(0.0f, 0.0f, float(width), float(height), 0.0f, 1.0f);
    vk::Rect2D scissor({0, 0}, {width, height});
    vk::PipelineViewportStateCreateInfo viewportState({}, viewport, scissor);
    vk::PipelineRasterizationStateCreateInfo raster(
        {}, VK_FALSE, VK_FALSE, vk::PolygonMode::eFill, vk::CullModeFlagBits::eNone,
        vk::FrontFace::eCounterClockwise, VK_FALSE, 0.0f, 0.0f, 0.0f, 1.0f);
    vk::PipelineMultisampleStateCreateInfo multisample({}, vk::SampleCountFlagBits::e1);
    vk::PipelineDepthStencilStateCreateInfo depth({}, VK_TRUE, VK_TRUE, vk::CompareOp::eLess);
    vk::PipelineColorBlendAttachmentState blendAttachment;
    blendAttachment.colorWriteMask =
        vk::ColorComponentFlagBits::eR | vk::ColorComponentFlagBits::eG |
        vk::ColorComponentFlagBits::eB | vk::ColorComponentFlagBits::eA;
    vk::PipelineColorBlendStateCreateInfo blend;
    if (colorDepth) blend.setAttachments(blendAttachment);
    vk::GraphicsPipelineCreateInfo info(
        {}, stages, &vertexInput, &assembly, nullptr, &viewportState, &raster, &multisample,
        colorDepth ? &depth : nullptr, &blend, nullptr, layout, renderPass, 0);
    return vk::raii::Pipeline(ctx.Device(), nullptr, info);
}

void ComputeBarrier(const vk::raii::CommandBuffer& cb) {
    Barrier(cb, vk::PipelineStageFlagBits::eComputeShader, vk::AccessFlagBits::eShaderWrite,
            vk::PipelineStageFlagBits::eComputeShader);
}

void Barrier(const vk::raii::CommandBuffer& cb, vk::PipelineStageFlags from,
             vk::AccessFlags fromAccess, vk::PipelineStageFlags to) {
    vk::MemoryBarrier barrier(fromAccess,
                              vk::AccessFlagBits::eShaderRead | vk::AccessFlagBits::eShaderWrite);
    cb.pipelineBarrier(from, to, {}, barrier, {}, {});
}

void HostReadBarrier(const vk::raii::CommandBuffer& cb, vk::PipelineStageFlags from,
                     vk::AccessFlags fromAccess) {
    const vk::MemoryBarrier barrier(fromAccess, vk::AccessFlagBits::eHostRead);
    cb.pipelineBarrier(from, vk::PipelineStageFlagBits::eHost, {}, barrier, {}, {});
}

}  // namespace penumbra::gpu
