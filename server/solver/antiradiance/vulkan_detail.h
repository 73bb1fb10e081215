// What the antiradiance's Vulkan files share (vulkan_passes.cpp, vulkan_links.cpp): the
// workgroup size, dispatch sizes, SPIR-V words and specialisation constants.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

namespace penumbra::vulkan_detail {

inline constexpr uint32_t kWorkgroup = 64;

inline uint32_t Groups(uint64_t invocations) {
    return static_cast<uint32_t>((invocations + kWorkgroup - 1) / kWorkgroup);
}

// The passes' specialisation constants (shaders/common.glsl): workgroup size, bins.
inline std::vector<uint32_t> Spec(int bins) { return {kWorkgroup, static_cast<uint32_t>(bins)}; }

}  // namespace penumbra::vulkan_detail
