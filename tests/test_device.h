// The Vulkan device the device-against-CPU tests run on: lavapipe (CI, any machine), or a real
// GPU where PENUMBRA_TEST_VULKAN=gpu is set (the same tests as a check on hardware: they
// compare the device's answer with the CPU back end's, with looser bounds where a real GPU
// rounds otherwise than lavapipe and the CPU).
#pragma once

#include <cstdlib>
#include <cstring>

#include "gpu/context.h"
#include "solver/solver.h"

namespace penumbra::testing {

inline bool TestOnRealGpu() {
    const char* v = std::getenv("PENUMBRA_TEST_VULKAN");
    return v != nullptr && std::strcmp(v, "gpu") == 0;
}

inline DeviceChoice TestVulkanChoice() {
    return TestOnRealGpu() ? DeviceChoice::kGpu : DeviceChoice::kLavapipe;
}

inline gpu::DeviceKind TestVulkanKind() {
    return TestOnRealGpu() ? gpu::DeviceKind::kRealGpu : gpu::DeviceKind::kLavapipe;
}

}  // namespace penumbra::testing
