// An offscreen raster target: a float colour image with a depth buffer (test LESS), drawn by
// a vertex shader that reads its vertices from storage buffers by gl_VertexIndex (no vertex
// input state) and a fragment shader, and copied into a buffer. `penumbra render` draws
// RGBA colour into it; the shadow pass draws each view's nearest depth as R32 (the fragment
// shader writes gl_FragCoord.z where the fixed-function depth test lets it: lavapipe runs
// this vectorised, where a fragment shader keeping depth with atomicMin in a buffer ran one
// lane at a time, and a copy of the depth image itself read zeros on Mesa 22.3). A target
// may be drawn and copied several times in one command buffer.
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
    // `color`: eR32G32B32A32Sfloat or eR32Sfloat.
    RenderTarget(Context& ctx, std::span<const uint32_t> vertexSpirv,
                 std::span<const uint32_t> fragmentSpirv, uint32_t bufferCount,
                 uint32_t pushConstantBytes, uint32_t width, uint32_t height,
                 vk::Format color = vk::Format::eR32G32B32A32Sfloat);

    vk::raii::DescriptorSet MakeSet(std::span<const Buffer* const> buffers) const {
        return sets_.MakeSet(buffers);
    }
    // Begins the render pass (colour cleared to `clear`, depth to 1) and binds the pipeline
    // and `set`.
    void Begin(const vk::raii::CommandBuffer& cb, const vk::raii::DescriptorSet& set,
               const float clear[4]) const;
    // Ends the render pass and copies the colour image (rows top to bottom, float texels)
    // into `out` from byte `offset`; the copy is made visible to the host and to transfers
    // (other readers need their own barrier).
    void EndAndCopy(const vk::raii::CommandBuffer& cb, const Buffer& out, size_t offset = 0) const;
    // Sets the push-constant block (the size the target was made with) for the next draw.
    template <typename Block>
    void Push(const vk::raii::CommandBuffer& cb, const Block& block) const {
        PENUMBRA_CHECK_EQ(sizeof(Block), pushConstantBytes_);
        cb.pushConstants<Block>(*layout_, kStages, 0, block);
    }
    vk::PipelineLayout Layout() const { return *layout_; }
    static constexpr vk::ShaderStageFlags kStages =
        vk::ShaderStageFlagBits::eVertex | vk::ShaderStageFlagBits::eFragment;

  private:
    BufferSetLayout sets_;
    uint32_t width_, height_, texelBytes_, pushConstantBytes_;
    Attachment color_, depth_;
    vk::raii::PipelineLayout layout_{nullptr};
    vk::raii::RenderPass renderPass_{nullptr};
    vk::raii::Framebuffer framebuffer_{nullptr};
    vk::raii::ShaderModule vertex_{nullptr}, fragment_{nullptr};
    vk::raii::Pipeline pipeline_{nullptr};
};

}  // namespace penumbra::gpu
