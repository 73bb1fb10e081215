// The Vulkan device layer: headless instance, device choice (discrete > integrated >
// lavapipe), one compute queue, validation messages captured for tests. The only code
// (with buffer/pipeline) that includes Vulkan headers.
#pragma once

#include <atomic>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>
#include <vulkan/vulkan_raii.hpp>

namespace penumbra::gpu {

enum class DeviceKind { kAnyPreferGpu, kRealGpu, kLavapipe };

// What the device must do beyond compute. kRayTracing: hardware ray tracing through
// VK_KHR_acceleration_structure and VK_KHR_ray_tracing_pipeline (Vulkan 1.2's buffer device
// addresses with them); gpu/ray_tracer.h uses it.
enum class Capability { kCompute, kRayTracing };

class Context {
  public:
    // Throws penumbra::Error naming what is missing (no Vulkan, no such device, no device of
    // `kind` with `need`, and which devices lack what).
    Context(DeviceKind kind, bool validation, Capability need = Capability::kCompute);
    ~Context();
    Context(const Context&) = delete;
    Context& operator=(const Context&) = delete;

    const std::string& DeviceName() const { return name_; }
    bool IsLavapipe() const { return lavapipe_; }
    float TimestampPeriodNs() const { return timestampPeriod_; }
    const vk::PhysicalDeviceLimits& Limits() const { return limits_; }
    // The queue rasterises (the shadow pass and `penumbra render` need it).
    bool Graphics() const { return graphics_; }
    // atomicAdd on floats in storage buffers (VK_EXT_shader_atomic_float), enabled where the
    // device has it (not on a ray-tracing context).
    bool FloatAtomics() const { return floatAtomics_; }
    // 64-bit integers and atomicMin on them in storage buffers (shaderInt64,
    // shaderBufferInt64Atomics: core in Vulkan 1.2, optional), enabled where the device has them.
    bool Int64Atomics() const { return int64Atomics_; }

    const vk::raii::Device& Device() const { return *device_; }
    const vk::raii::PhysicalDevice& Physical() const { return *physical_; }
    const vk::raii::Queue& Queue() const { return *queue_; }
    const vk::raii::CommandPool& CommandPool() const { return *pool_; }
    uint32_t QueueFamily() const { return family_; }

    // Records with `record` into a one-time command buffer, submits and waits.
    template <typename F>
    void RunNow(F&& record) {
        vk::raii::CommandBuffer cb = AllocateCommandBuffer();
        cb.begin({vk::CommandBufferUsageFlagBits::eOneTimeSubmit});
        record(cb);
        cb.end();
        SubmitAndWait(cb);
    }
    vk::raii::CommandBuffer AllocateCommandBuffer() const;
    // Every submission goes through here, where a driver reports a lost device: it throws
    // penumbra::DeviceLost then, and for every later submission on this context.
    void SubmitAndWait(const vk::raii::CommandBuffer& cb) const;

    // Validation-layer messages (warnings and errors) seen so far.
    std::vector<std::string> ValidationMessages() const;
    bool ValidationEnabled() const { return validation_; }

    struct Messages {
        std::mutex mutex;
        std::vector<std::string> list;
    };

  private:
    // The set-up's steps, in order: the instance (and the validation messenger), the device
    // of `kind` (with ray tracing where asked), its queue family, then the logical device
    // with the atomics the device has.
    void CreateInstance(bool validation, bool rayTracing);
    void PickDevice(DeviceKind kind, bool rayTracing);
    void PickQueueFamily();
    void CreateRayTracingDevice(const vk::DeviceQueueCreateInfo& qi);
    void CreateComputeDevice(const vk::DeviceQueueCreateInfo& qi);

    std::unique_ptr<vk::raii::Context> context_;
    std::unique_ptr<vk::raii::Instance> instance_;
    std::unique_ptr<vk::raii::DebugUtilsMessengerEXT> messenger_;
    std::unique_ptr<vk::raii::PhysicalDevice> physical_;
    std::unique_ptr<vk::raii::Device> device_;
    std::unique_ptr<vk::raii::Queue> queue_;
    std::unique_ptr<vk::raii::CommandPool> pool_;
    std::unique_ptr<Messages> messages_;
    vk::PhysicalDeviceLimits limits_{};
    uint32_t family_ = 0;
    float timestampPeriod_ = 1.0f;
    bool lavapipe_ = false;
    bool floatAtomics_ = false;
    bool int64Atomics_ = false;
    bool graphics_ = false;
    bool validation_ = false;
    mutable std::atomic<bool> lost_{false};
    std::string name_;
};

// Fault injection for tests (a device cannot be lost on purpose otherwise): the submission
// `after` submissions from now, on any context, reports VK_ERROR_DEVICE_LOST as a driver
// would, and that context stays lost. A negative `after` turns it off.
void SimulateDeviceLoss(int after);

// True when a Vulkan device other than a CPU implementation exists; its name in `name`.
bool FindRealGpu(std::string* name);

// Wraps a failed vk call: "vkCreateX failed: VK_ERROR_...".
[[noreturn]] void ThrowVulkan(const char* call, vk::Result result);

}  // namespace penumbra::gpu
