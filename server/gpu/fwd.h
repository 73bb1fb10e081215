// The Vulkan layer's handles, named without Vulkan's headers: for the headers that pass a
// device or a buffer along without touching either.
#pragma once

namespace penumbra::gpu {
class Buffer;
class Context;
}  // namespace penumbra::gpu
