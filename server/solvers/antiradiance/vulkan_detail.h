// What the antiradiance's Vulkan files share (vulkan_passes.cpp, vulkan_links.cpp): the
// workgroup size and dispatch sizes (gpu/dispatch.h), SPIR-V words and specialisation constants.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "gpu/dispatch.h"

namespace penumbra::vulkan_detail {

using gpu::Groups;
using gpu::kWorkgroup;

// The passes' specialisation constants (shaders/common.glsl): workgroup size, bins.
inline std::vector<uint32_t> Spec(int bins) { return {kWorkgroup, static_cast<uint32_t>(bins)}; }

}  // namespace penumbra::vulkan_detail
