// Storage buffers with upload and readback. Device-local memory; uploads write it directly
// where it is host-visible (lavapipe, a real GPU's resizable BAR), else through a staging
// copy. Readbacks read it directly only where it is also host-cached (lavapipe): a real
// GPU's BAR memory is uncached, and reading it over the bus made the light field's lines 9×
// slower on an H100 than copying it to host-cached memory first (bench/results/gpu-h100.md),
// so those go through a readback buffer kept with the buffer.
#pragma once

#include <algorithm>
#include <cstring>
#include <memory>
#include <utility>
#include <vector>

#include "gpu/context.h"

namespace penumbra::gpu {

// Index of a memory type allowed by `typeBits` with all of `want`, or UINT32_MAX.
uint32_t FindMemory(const Context& ctx, uint32_t typeBits, vk::MemoryPropertyFlags want);

class Buffer {
  public:
    // A storage buffer of `bytes` (rounded up to 4), zero-filled.
    Buffer(Context& ctx, size_t bytes);

    size_t Bytes() const { return bytes_; }
    vk::Buffer Handle() const { return *buffer_; }
    // A view of the whole buffer as a uniform texel buffer of one 32-bit `format` (made on
    // first use, kept with the buffer). Throws when the device's texel-buffer limit is below
    // the buffer's size.
    vk::BufferView View(vk::Format format) const;

    // Copies `bytes` from `data` to the buffer at byte `offset`.
    void Upload(const void* data, size_t bytes, size_t offset = 0);
    // Copies `bytes` of the buffer from byte `offset` to `data`.
    void Download(void* data, size_t bytes, size_t offset = 0) const;

    template <typename T>
    void Upload(const std::vector<T>& v) {
        Upload(v.data(), v.size() * sizeof(T));
    }
    template <typename T>
    std::vector<T> Download() const {
        std::vector<T> v(bytes_ / sizeof(T));
        Download(v.data(), v.size() * sizeof(T));
        return v;
    }

  private:
    Context& ctx_;
    size_t bytes_;
    vk::raii::Buffer buffer_{nullptr};
    vk::raii::DeviceMemory memory_{nullptr};
    void* mapped_ = nullptr;
    bool cached_ = false;  // mapped_ is host-cached: read it directly
    // The readback copy (host-visible, host-cached where the device has such memory), made on
    // the first download that needs it and grown to the largest.
    mutable vk::raii::Buffer readback_{nullptr};
    mutable vk::raii::DeviceMemory readbackMemory_{nullptr};
    mutable void* readbackMapped_ = nullptr;
    mutable size_t readbackBytes_ = 0;
    mutable std::vector<std::pair<vk::Format, vk::raii::BufferView>> views_;
};

// A buffer of at least 16 bytes: an empty array still gets a buffer to bind.
inline std::unique_ptr<Buffer> MakeBuffer(Context& ctx, size_t bytes) {
    return std::make_unique<Buffer>(ctx, std::max<size_t>(bytes, 16));
}

}  // namespace penumbra::gpu
