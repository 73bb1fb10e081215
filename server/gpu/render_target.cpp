// Colour and depth attachments, the render pass that clears them and leaves the colour
// image ready to copy, and the graphics pipeline (depth test, no culling).
#include "gpu/render_target.h"

#include "base/check.h"

namespace penumbra::gpu {
namespace {

constexpr vk::Format kDepth = vk::Format::eD32Sfloat;

}  // namespace

Attachment MakeAttachment(Context& ctx, uint32_t width, uint32_t height, vk::Format format,
                          vk::ImageUsageFlags usage, vk::ImageAspectFlags aspect) {
    Attachment a;
    vk::ImageCreateInfo info({}, vk::ImageType::e2D, format, vk::Extent3D(width, height, 1), 1, 1,
                             vk::SampleCountFlagBits::e1, vk::ImageTiling::eOptimal, usage);
    a.image = vk::raii::Image(ctx.Device(), info);
    auto req = a.image.getMemoryRequirements();
    uint32_t type = FindMemory(ctx, req.memoryTypeBits, vk::MemoryPropertyFlagBits::eDeviceLocal);
    if (type == UINT32_MAX) throw Error("Vulkan device has no memory for a render target");
    a.memory = vk::raii::DeviceMemory(ctx.Device(), vk::MemoryAllocateInfo(req.size, type));
    a.image.bindMemory(*a.memory, 0);
    a.view = vk::raii::ImageView(
        ctx.Device(), vk::ImageViewCreateInfo({}, *a.image, vk::ImageViewType::e2D, format, {},
                                              vk::ImageSubresourceRange(aspect, 0, 1, 0, 1)));
    return a;
}

RenderTarget::RenderTarget(Context& ctx, std::span<const uint32_t> vertexSpirv,
                           std::span<const uint32_t> fragmentSpirv, uint32_t bufferCount,
                           uint32_t pushConstantBytes, uint32_t width, uint32_t height,
                           vk::Format color)
    : sets_(ctx, bufferCount, kStages),
      width_(width),
      height_(height),
      pushConstantBytes_(pushConstantBytes) {
    PENUMBRA_CHECK(color == vk::Format::eR32G32B32A32Sfloat || color == vk::Format::eR32Sfloat);
    texelBytes_ = color == vk::Format::eR32Sfloat ? 4 : 16;
    const auto& dev = ctx.Device();
    color_ = MakeAttachment(
        ctx, width, height, color,
        vk::ImageUsageFlagBits::eColorAttachment | vk::ImageUsageFlagBits::eTransferSrc,
        vk::ImageAspectFlagBits::eColor);
    depth_ =
        MakeAttachment(ctx, width, height, kDepth, vk::ImageUsageFlagBits::eDepthStencilAttachment,
                       vk::ImageAspectFlagBits::eDepth);

    layout_ = MakePipelineLayout(ctx, sets_, kStages, pushConstantBytes);

    // Colour: cleared, stored, left in TRANSFER_SRC for the copy. Depth: cleared, dropped.
    vk::AttachmentDescription attachments[] = {{{},
                                                color,
                                                vk::SampleCountFlagBits::e1,
                                                vk::AttachmentLoadOp::eClear,
                                                vk::AttachmentStoreOp::eStore,
                                                vk::AttachmentLoadOp::eDontCare,
                                                vk::AttachmentStoreOp::eDontCare,
                                                vk::ImageLayout::eUndefined,
                                                vk::ImageLayout::eTransferSrcOptimal},
                                               {{},
                                                kDepth,
                                                vk::SampleCountFlagBits::e1,
                                                vk::AttachmentLoadOp::eClear,
                                                vk::AttachmentStoreOp::eDontCare,
                                                vk::AttachmentLoadOp::eDontCare,
                                                vk::AttachmentStoreOp::eDontCare,
                                                vk::ImageLayout::eUndefined,
                                                vk::ImageLayout::eDepthStencilAttachmentOptimal}};
    vk::AttachmentReference colorRef(0, vk::ImageLayout::eColorAttachmentOptimal);
    vk::AttachmentReference depthRef(1, vk::ImageLayout::eDepthStencilAttachmentOptimal);
    vk::SubpassDescription subpass({}, vk::PipelineBindPoint::eGraphics, {}, colorRef, {},
                                   &depthRef);
    vk::SubpassDependency dependencies[] = {
        // A previous copy has read the colour image before this pass clears it.
        {VK_SUBPASS_EXTERNAL, 0, vk::PipelineStageFlagBits::eTransfer,
         vk::PipelineStageFlagBits::eColorAttachmentOutput, vk::AccessFlagBits::eTransferRead,
         vk::AccessFlagBits::eColorAttachmentWrite},
        // The colour writes finish before the copy that follows the pass reads them.
        {0, VK_SUBPASS_EXTERNAL, vk::PipelineStageFlagBits::eColorAttachmentOutput,
         vk::PipelineStageFlagBits::eTransfer, vk::AccessFlagBits::eColorAttachmentWrite,
         vk::AccessFlagBits::eTransferRead}};
    renderPass_ =
        vk::raii::RenderPass(dev, vk::RenderPassCreateInfo({}, attachments, subpass, dependencies));
    vk::ImageView views[] = {*color_.view, *depth_.view};
    framebuffer_ = vk::raii::Framebuffer(
        dev, vk::FramebufferCreateInfo({}, *renderPass_, views, width, height, 1));

    vertex_ = MakeShaderModule(ctx, vertexSpirv);
    fragment_ = MakeShaderModule(ctx, fragmentSpirv);
    // No culling: one-sided surfaces are seen from both sides (backs are black in the shader).
    pipeline_ = MakeTrianglePipeline(ctx, *vertex_, *fragment_, *layout_, *renderPass_, width,
                                     height, true);
}

void RenderTarget::Begin(const vk::raii::CommandBuffer& cb, const vk::raii::DescriptorSet& set,
                         const float clear[4]) const {
    vk::ClearValue values[] = {
        vk::ClearColorValue(std::array<float, 4>{clear[0], clear[1], clear[2], clear[3]}),
        vk::ClearDepthStencilValue(1.0f, 0)};
    vk::RenderPassBeginInfo begin(*renderPass_, *framebuffer_,
                                  vk::Rect2D({0, 0}, {width_, height_}), values);
    cb.beginRenderPass(begin, vk::SubpassContents::eInline);
    cb.bindPipeline(vk::PipelineBindPoint::eGraphics, *pipeline_);
    cb.bindDescriptorSets(vk::PipelineBindPoint::eGraphics, *layout_, 0, {*set}, {});
}

void RenderTarget::EndAndCopy(const vk::raii::CommandBuffer& cb, const Buffer& out,
                              size_t offset) const {
    PENUMBRA_CHECK_LE(offset + size_t(width_) * height_ * texelBytes_, out.Bytes());
    cb.endRenderPass();
    vk::BufferImageCopy region(offset, 0, 0,
                               vk::ImageSubresourceLayers(vk::ImageAspectFlagBits::eColor, 0, 0, 1),
                               {0, 0, 0}, {width_, height_, 1});
    cb.copyImageToBuffer(*color_.image, vk::ImageLayout::eTransferSrcOptimal, out.Handle(), region);
    // The copy lands before the host reads the buffer (SubmitAndWait waits on the fence).
    HostReadBarrier(cb, vk::PipelineStageFlagBits::eTransfer, vk::AccessFlagBits::eTransferWrite);
}

}  // namespace penumbra::gpu
