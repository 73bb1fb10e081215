// Dispatch sizes of the compute passes whose shaders run `kWorkgroup` invocations a group
// (local_size_x, or specialisation constant 0 where a pass sets it): one definition for every
// solver's device passes.
#pragma once

#include <algorithm>
#include <cstdint>

namespace penumbra::gpu {

inline constexpr uint32_t kWorkgroup = 64;
// The least maxComputeWorkGroupCount[0] Vulkan allows.
inline constexpr uint32_t kMaxGroups = 65535;

// One invocation per item.
inline uint32_t Groups(uint64_t invocations) {
    return static_cast<uint32_t>((invocations + kWorkgroup - 1) / kWorkgroup);
}

// For a shader that strides over its items by the whole grid: at least one group, at most
// kMaxGroups.
inline uint32_t StridedGroups(uint64_t invocations) {
    return static_cast<uint32_t>(std::clamp<uint64_t>(Groups(invocations), 1, kMaxGroups));
}

}  // namespace penumbra::gpu
