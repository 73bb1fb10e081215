// Storage buffers with upload and readback. Device-local memory; a staging copy is used
// when that memory is not host-visible (real GPUs), a direct map when it is (lavapipe).
#pragma once

#include <cstring>
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
    mutable std::vector<std::pair<vk::Format, vk::raii::BufferView>> views_;
};

}  // namespace penumbra::gpu
