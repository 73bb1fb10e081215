// An offscreen colour image (RGBA float) with a depth buffer, and a raster pipeline that
// draws triangles into it: the vertex shader reads its vertices from storage buffers by
// gl_VertexIndex (no vertex input state), the fragment shader writes colour. The image is
// copied into a buffer for readback. Used by `penumbra render`.
#pragma once

#include <cstdint>
#include <span>

#include "gpu/buffer.h"
#include "gpu/context.h"
#include "gpu/pipeline.h"

namespace penumbra::gpu {

class RenderTarget {
  public:
    RenderTarget(Context& ctx, std::span<const uint32_t> vertexSpirv,
                 std::span<const uint32_t> fragmentSpirv, uint32_t bufferCount,
                 uint32_t pushConstantBytes, uint32_t width, uint32_t height);

    vk::raii::DescriptorSet MakeSet(std::span<const Buffer* const> buffers) const {
        return sets_.MakeSet(buffers);
    }
    // Begins the render pass (colour cleared to `clear`, depth to 1) and binds the pipeline
    // and `set`.
    void Begin(const vk::raii::CommandBuffer& cb, const vk::raii::DescriptorSet& set,
               const float clear[4]) const;
    // Ends the render pass and copies the colour image (rows top to bottom, RGBA float)
    // into `out`, which must hold width × height × 16 bytes.
    void EndAndCopy(const vk::raii::CommandBuffer& cb, const Buffer& out) const;
    vk::PipelineLayout Layout() const { return *layout_; }
    static constexpr vk::ShaderStageFlags kStages =
        vk::ShaderStageFlagBits::eVertex | vk::ShaderStageFlagBits::eFragment;

  private:
    struct Attachment {
        vk::raii::Image image{nullptr};
        vk::raii::DeviceMemory memory{nullptr};
        vk::raii::ImageView view{nullptr};
    };
    Attachment MakeAttachment(Context& ctx, vk::Format format, vk::ImageUsageFlags usage,
                              vk::ImageAspectFlags aspect) const;

    BufferSetLayout sets_;
    uint32_t width_, height_;
    Attachment color_, depth_;
    vk::raii::PipelineLayout layout_{nullptr};
    vk::raii::RenderPass renderPass_{nullptr};
    vk::raii::Framebuffer framebuffer_{nullptr};
    vk::raii::ShaderModule vertex_{nullptr}, fragment_{nullptr};
    vk::raii::Pipeline pipeline_{nullptr};
};

}  // namespace penumbra::gpu
