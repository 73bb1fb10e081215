// Offscreen raster targets whose vertex shaders read their vertices from storage buffers by
// gl_VertexIndex (no vertex input state): RenderTarget, a colour image (RGBA float) with a
// depth buffer, copied into a buffer for readback (`penumbra render`); DepthTarget, the
// nearest depth as a float image, copied into a buffer (the shadow maps).
#pragma once

#include <cstdint>
#include <span>

#include "gpu/buffer.h"
#include "gpu/context.h"
#include "gpu/pipeline.h"

namespace penumbra::gpu {

// An image with its memory and view.
struct Attachment {
    vk::raii::Image image{nullptr};
    vk::raii::DeviceMemory memory{nullptr};
    vk::raii::ImageView view{nullptr};
};
Attachment MakeAttachment(Context& ctx, uint32_t width, uint32_t height, vk::Format format,
                          vk::ImageUsageFlags usage, vk::ImageAspectFlags aspect);

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
    BufferSetLayout sets_;
    uint32_t width_, height_;
    Attachment color_, depth_;
    vk::raii::PipelineLayout layout_{nullptr};
    vk::raii::RenderPass renderPass_{nullptr};
    vk::raii::Framebuffer framebuffer_{nullptr};
    vk::raii::ShaderModule vertex_{nullptr}, fragment_{nullptr};
    vk::raii::Pipeline pipeline_{nullptr};
};

// The nearest depth of a width × height view as a float image: the fixed-function depth
// test (LESS, D32) decides, and the fragment shader writes gl_FragCoord.z into an R32
// colour target cleared to 1, which is what gets copied (lavapipe runs this vectorised; a
// fragment shader keeping depth with atomicMin in a buffer ran one lane at a time; a copy
// of the depth image itself read zeros on Mesa 22.3). Several views reuse the images one
// after another, each copied out.
class DepthTarget {
  public:
    DepthTarget(Context& ctx, std::span<const uint32_t> vertexSpirv,
                std::span<const uint32_t> fragmentSpirv, uint32_t bufferCount,
                uint32_t pushConstantBytes, uint32_t width, uint32_t height);

    vk::raii::DescriptorSet MakeSet(std::span<const Buffer* const> buffers) const {
        return sets_.MakeSet(buffers);
    }
    // Begins the render pass (depth and colour cleared to 1) and binds the pipeline and `set`.
    void Begin(const vk::raii::CommandBuffer& cb, const vk::raii::DescriptorSet& set) const;
    // Ends the render pass and copies the depth (rows top to bottom, float) into `out` from
    // byte `offset`. Readers of `out` need a transfer-write barrier.
    void EndAndCopy(const vk::raii::CommandBuffer& cb, const Buffer& out, size_t offset) const;
    vk::PipelineLayout Layout() const { return *layout_; }
    static constexpr vk::ShaderStageFlags kStages =
        vk::ShaderStageFlagBits::eVertex | vk::ShaderStageFlagBits::eFragment;

  private:
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
