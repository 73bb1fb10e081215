// Buffer allocation and the upload → copy → readback paths.
#include "gpu/buffer.h"

#include "base/check.h"

namespace penumbra::gpu {
uint32_t FindMemory(const Context& ctx, uint32_t typeBits, vk::MemoryPropertyFlags want) {
    auto mem = ctx.Physical().getMemoryProperties();
    for (uint32_t i = 0; i < mem.memoryTypeCount; ++i)
        if ((typeBits & (1u << i)) && (mem.memoryTypes[i].propertyFlags & want) == want) return i;
    return UINT32_MAX;
}

namespace {

// A host-visible buffer for staging copies; host-cached memory where the device has it (the
// host reads a readback).
struct Staging {
    vk::raii::Buffer buffer{nullptr};
    vk::raii::DeviceMemory memory{nullptr};
    void* mapped = nullptr;

    Staging(const Context& ctx, size_t bytes) {
        buffer = vk::raii::Buffer(ctx.Device(),
                                  vk::BufferCreateInfo({}, bytes,
                                                       vk::BufferUsageFlagBits::eTransferSrc |
                                                           vk::BufferUsageFlagBits::eTransferDst));
        auto req = buffer.getMemoryRequirements();
        const vk::MemoryPropertyFlags host =
            vk::MemoryPropertyFlagBits::eHostVisible | vk::MemoryPropertyFlagBits::eHostCoherent;
        uint32_t type =
            FindMemory(ctx, req.memoryTypeBits, host | vk::MemoryPropertyFlagBits::eHostCached);
        if (type == UINT32_MAX) type = FindMemory(ctx, req.memoryTypeBits, host);
        if (type == UINT32_MAX) throw Error("Vulkan device has no host-visible memory");
        memory = vk::raii::DeviceMemory(ctx.Device(), vk::MemoryAllocateInfo(req.size, type));
        buffer.bindMemory(*memory, 0);
        mapped = memory.mapMemory(0, bytes);
    }
};

}  // namespace

Buffer::Buffer(Context& ctx, size_t bytes)
    : ctx_(ctx), bytes_((std::max<size_t>(bytes, 4) + 3) & ~size_t(3)) {
    if (bytes_ > ctx.Limits().maxStorageBufferRange)
        throw Error("a " + std::to_string(bytes_ >> 20) +
                    " MiB table exceeds this Vulkan device's " +
                    std::to_string(ctx.Limits().maxStorageBufferRange >> 20) +
                    " MiB storage-buffer limit; use fewer bins, a larger element size, or "
                    "--device cpu");
    buffer_ = vk::raii::Buffer(
        ctx.Device(), vk::BufferCreateInfo({}, bytes_,
                                           vk::BufferUsageFlagBits::eStorageBuffer |
                                               vk::BufferUsageFlagBits::eUniformTexelBuffer |
                                               vk::BufferUsageFlagBits::eTransferSrc |
                                               vk::BufferUsageFlagBits::eTransferDst));
    auto req = buffer_.getMemoryRequirements();
    // Prefer memory that is both device-local and host-visible (lavapipe, resizable BAR).
    uint32_t type = FindMemory(ctx, req.memoryTypeBits,
                               vk::MemoryPropertyFlagBits::eDeviceLocal |
                                   vk::MemoryPropertyFlagBits::eHostVisible |
                                   vk::MemoryPropertyFlagBits::eHostCoherent);
    bool mappable = type != UINT32_MAX;
    if (!mappable)
        type = FindMemory(ctx, req.memoryTypeBits, vk::MemoryPropertyFlagBits::eDeviceLocal);
    if (type == UINT32_MAX) throw Error("Vulkan device has no usable memory type for a buffer");
    try {
        memory_ = vk::raii::DeviceMemory(ctx.Device(), vk::MemoryAllocateInfo(req.size, type));
    } catch (const vk::SystemError& e) {
        throw Error("vkAllocateMemory (" + std::to_string(bytes_ >> 20) +
                    " MiB) failed: " + e.what());
    }
    buffer_.bindMemory(*memory_, 0);
    cached_ = mappable && (ctx.Physical().getMemoryProperties().memoryTypes[type].propertyFlags &
                           vk::MemoryPropertyFlagBits::eHostCached);
    if (mappable) {
        mapped_ = memory_.mapMemory(0, bytes_);
        std::memset(mapped_, 0, bytes_);
    } else {
        ctx.RunNow(
            [&](const vk::raii::CommandBuffer& cb) { cb.fillBuffer(*buffer_, 0, bytes_, 0); });
    }
}

vk::BufferView Buffer::View(vk::Format format) const {
    for (const auto& [f, view] : views_)
        if (f == format) return *view;
    // Every format used here is 32 bits a texel.
    if (bytes_ / 4 > ctx_.Limits().maxTexelBufferElements)
        throw Error("a " + std::to_string(bytes_ >> 20) +
                    " MiB table exceeds this Vulkan device's " +
                    std::to_string(ctx_.Limits().maxTexelBufferElements) +
                    "-element texel-buffer limit; use fewer bins, a larger element size, or "
                    "--device cpu");
    views_.emplace_back(
        format, vk::raii::BufferView(ctx_.Device(), vk::BufferViewCreateInfo({}, *buffer_, format,
                                                                             0, VK_WHOLE_SIZE)));
    return *views_.back().second;
}

void Buffer::Upload(const void* data, size_t bytes, size_t offset) {
    PENUMBRA_CHECK_LE(offset + bytes, bytes_);
    if (mapped_) {
        std::memcpy(static_cast<char*>(mapped_) + offset, data, bytes);
        return;
    }
    Staging staging(ctx_, bytes);
    std::memcpy(staging.mapped, data, bytes);
    ctx_.RunNow([&](const vk::raii::CommandBuffer& cb) {
        cb.copyBuffer(*staging.buffer, *buffer_, vk::BufferCopy(0, offset, bytes));
    });
}

void Buffer::Download(void* data, size_t bytes, size_t offset) const {
    PENUMBRA_CHECK_LE(offset + bytes, bytes_);
    if (mapped_ && cached_) {
        std::memcpy(data, static_cast<const char*>(mapped_) + offset, bytes);
        return;
    }
    if (bytes > readbackBytes_) {
        Staging staging(ctx_, bytes);
        readback_ = std::move(staging.buffer);
        readbackMemory_ = std::move(staging.memory);
        readbackMapped_ = staging.mapped;
        readbackBytes_ = bytes;
    }
    ctx_.RunNow([&](const vk::raii::CommandBuffer& cb) {
        cb.copyBuffer(*buffer_, *readback_, vk::BufferCopy(offset, 0, bytes));
    });
    std::memcpy(data, readbackMapped_, bytes);
}

}  // namespace penumbra::gpu
