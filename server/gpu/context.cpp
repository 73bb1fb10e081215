// Instance, device selection, validation capture and command submission.
#include "gpu/context.h"

#include <algorithm>
#include <array>
#include <cstring>
#include <utility>

#include "base/check.h"

namespace penumbra::gpu {
namespace {

constexpr const char* kValidationLayer = "VK_LAYER_KHRONOS_validation";

VKAPI_ATTR VkBool32 VKAPI_CALL OnMessage(VkDebugUtilsMessageSeverityFlagBitsEXT severity,
                                         VkDebugUtilsMessageTypeFlagsEXT,
                                         const VkDebugUtilsMessengerCallbackDataEXT* data,
                                         void* user) {
    if (severity < VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT) return VK_FALSE;
    auto* messages = static_cast<Context::Messages*>(user);
    std::lock_guard<std::mutex> lock(messages->mutex);
    messages->list.emplace_back(data && data->pMessage ? data->pMessage : "(no text)");
    return VK_FALSE;
}

int Rank(const vk::PhysicalDeviceProperties& p) {
    switch (p.deviceType) {
        case vk::PhysicalDeviceType::eDiscreteGpu:
            return 3;
        case vk::PhysicalDeviceType::eIntegratedGpu:
            return 2;
        case vk::PhysicalDeviceType::eVirtualGpu:
            return 1;
        default:
            return 0;  // CPU (lavapipe) and other
    }
}

}  // namespace

void ThrowVulkan(const char* call, vk::Result result) {
    throw Error(std::string(call) + " failed: " + vk::to_string(result));
}

namespace {

constexpr std::array<const char*, 3> kRayTracingExtensions = {
    VK_KHR_ACCELERATION_STRUCTURE_EXTENSION_NAME, VK_KHR_RAY_TRACING_PIPELINE_EXTENSION_NAME,
    VK_KHR_DEFERRED_HOST_OPERATIONS_EXTENSION_NAME};

// What `device` lacks for ray tracing ("" when nothing): API version, extensions, features.
std::string RayTracingGaps(const vk::raii::PhysicalDevice& device) {
    const auto props = device.getProperties();
    if (props.apiVersion < VK_API_VERSION_1_2) return "Vulkan 1.2";
    std::string missing;
    const auto have = device.enumerateDeviceExtensionProperties();
    for (const char* want : kRayTracingExtensions)
        if (std::none_of(have.begin(), have.end(), [&](const vk::ExtensionProperties& e) {
                return std::strcmp(e.extensionName, want) == 0;
            }))
            missing += (missing.empty() ? "" : ", ") + std::string(want);
    if (!missing.empty()) return missing;
    const auto chain =
        device.getFeatures2<vk::PhysicalDeviceFeatures2, vk::PhysicalDeviceVulkan12Features,
                            vk::PhysicalDeviceAccelerationStructureFeaturesKHR,
                            vk::PhysicalDeviceRayTracingPipelineFeaturesKHR>();
    if (!chain.get<vk::PhysicalDeviceVulkan12Features>().bufferDeviceAddress)
        return "the bufferDeviceAddress feature";
    if (!chain.get<vk::PhysicalDeviceAccelerationStructureFeaturesKHR>().accelerationStructure)
        return "the accelerationStructure feature";
    if (!chain.get<vk::PhysicalDeviceRayTracingPipelineFeaturesKHR>().rayTracingPipeline)
        return "the rayTracingPipeline feature";
    return "";
}

// The drivers' lifetime. The Vulkan loader unloads a driver when the last instance that
// loaded it is destroyed. NVIDIA's driver (580, on an H200) leaves threads of its
// own running ("[vkcf] Analysis"), and a process that destroyed its last context and went on
// (the service benchmark after its GPU case, before the next) died of a segmentation fault
// that no handler of ours could report; other projects have met the same on that driver
// (llama.cpp issue 10528, Halide issue 8497). So the first context opens one instance of the
// process's own that is never destroyed: the driver stays loaded until the process ends.
// Instances and devices are also made and destroyed one at a time: the same driver is
// reported to crash when contexts are made on several threads at once (kvark/blade issue 336;
// the service builds a session's solver and its gather's ray tracer on the loading thread, a
// rebuild on another).
std::mutex gLifetime;
// Held for the life of the process, never destroyed: a static's destructor at exit would
// unload the driver under its threads again.
vk::raii::Context* gKeptLoader = nullptr;
vk::raii::Instance* gKeptInstance = nullptr;

void KeepDriversLoaded() {
    static bool tried = false;
    if (std::exchange(tried, true)) return;
    try {
        gKeptLoader = new vk::raii::Context();
        vk::ApplicationInfo app("penumbra (keeps the drivers loaded)", 1, "penumbra", 1,
                                VK_API_VERSION_1_1);
        gKeptInstance = new vk::raii::Instance(*gKeptLoader, vk::InstanceCreateInfo({}, &app));
    } catch (const std::exception&) {
        // No loader or no instance: the context's own set-up says what is missing.
    }
}

}  // namespace

Context::Context(DeviceKind kind, bool validation, Capability need)
    : messages_(std::make_unique<Messages>()) {
    const bool rayTracing = need == Capability::kRayTracing;
    std::lock_guard lifetime(gLifetime);
    KeepDriversLoaded();
    try {
        context_ = std::make_unique<vk::raii::Context>();
    } catch (const std::exception& e) {
        throw Error(std::string("Vulkan is not available (loader missing?): ") + e.what());
    }
    try {
        CreateInstance(validation, rayTracing);
        PickDevice(kind, rayTracing);
        PickQueueFamily();
        float priority = 1.0f;
        vk::DeviceQueueCreateInfo qi({}, family_, 1, &priority);
        if (rayTracing)
            CreateRayTracingDevice(qi);
        else
            CreateComputeDevice(qi);
        queue_ = std::make_unique<vk::raii::Queue>(*device_, family_, 0);
        pool_ = std::make_unique<vk::raii::CommandPool>(
            *device_,
            vk::CommandPoolCreateInfo(vk::CommandPoolCreateFlagBits::eResetCommandBuffer, family_));
    } catch (const vk::SystemError& e) {
        throw Error(std::string("Vulkan set-up failed: ") + e.what());
    }
}

void Context::CreateInstance(bool validation, bool rayTracing) {
    std::vector<const char*> layers, extensions;
    if (validation) {
        bool found = false;
        for (const auto& l : context_->enumerateInstanceLayerProperties())
            if (std::strcmp(l.layerName, kValidationLayer) == 0) found = true;
        if (!found)
            throw Error(
                "Vulkan validation requested but VK_LAYER_KHRONOS_validation is not "
                "installed (Debian package vulkan-validationlayers)");
        layers.push_back(kValidationLayer);
        extensions.push_back(VK_EXT_DEBUG_UTILS_EXTENSION_NAME);
        validation_ = true;
    }
    vk::ApplicationInfo app("penumbra", 1, "penumbra", 1,
                            rayTracing ? VK_API_VERSION_1_2 : VK_API_VERSION_1_1);
    vk::InstanceCreateInfo info({}, &app, layers, extensions);
    instance_ = std::make_unique<vk::raii::Instance>(*context_, info);
    if (validation_) {
        vk::DebugUtilsMessengerCreateInfoEXT mi(
            {},
            vk::DebugUtilsMessageSeverityFlagBitsEXT::eWarning |
                vk::DebugUtilsMessageSeverityFlagBitsEXT::eError,
            vk::DebugUtilsMessageTypeFlagBitsEXT::eGeneral |
                vk::DebugUtilsMessageTypeFlagBitsEXT::eValidation |
                vk::DebugUtilsMessageTypeFlagBitsEXT::ePerformance,
            &OnMessage, messages_.get());
        messenger_ = std::make_unique<vk::raii::DebugUtilsMessengerEXT>(*instance_, mi);
    }
}

void Context::PickDevice(DeviceKind kind, bool rayTracing) {
    // Device choice: discrete > integrated > virtual > CPU, or lavapipe when asked.
    vk::raii::PhysicalDevices all(*instance_);
    int best = -1, bestRank = -1;
    std::string gaps;  // with `need`: the devices of `kind` that lack it, and what
    for (size_t i = 0; i < all.size(); ++i) {
        auto props = all[i].getProperties();
        bool isCpu = props.deviceType == vk::PhysicalDeviceType::eCpu;
        if (kind == DeviceKind::kLavapipe && !isCpu) continue;
        if (kind == DeviceKind::kRealGpu && isCpu) continue;
        if (rayTracing) {
            const std::string gap = RayTracingGaps(all[i]);
            if (!gap.empty()) {
                gaps += (gaps.empty() ? "" : "; ") + std::string(props.deviceName.data()) +
                        " lacks " + gap;
                continue;
            }
        }
        if (Rank(props) > bestRank) bestRank = Rank(props), best = static_cast<int>(i);
    }
    if (best < 0 && !gaps.empty())
        throw Error(
            "no Vulkan device can trace rays (VK_KHR_acceleration_structure and "
            "VK_KHR_ray_tracing_pipeline): " +
            gaps);
    if (best < 0) {
        throw Error(kind == DeviceKind::kLavapipe
                        ? "no CPU Vulkan device (lavapipe) found; install mesa-vulkan-drivers"
                    : kind == DeviceKind::kRealGpu
                        ? "no GPU Vulkan device found (only CPU implementations); use "
                          "--device cpu or --device lavapipe"
                        : "no Vulkan device found");
    }
    physical_ = std::make_unique<vk::raii::PhysicalDevice>(std::move(all[best]));
    auto props = physical_->getProperties();
    name_ = props.deviceName.data();
    lavapipe_ = props.deviceType == vk::PhysicalDeviceType::eCpu;
    limits_ = props.limits;
    timestampPeriod_ = props.limits.timestampPeriod;
}

void Context::PickQueueFamily() {
    auto families = physical_->getQueueFamilyProperties();
    // A queue that computes and, for the shadow pass, rasterises; else compute only.
    family_ = UINT32_MAX;
    const auto both = vk::QueueFlagBits::eCompute | vk::QueueFlagBits::eGraphics;
    for (uint32_t i = 0; i < families.size() && family_ == UINT32_MAX; ++i)
        if ((families[i].queueFlags & both) == both) family_ = i;
    for (uint32_t i = 0; i < families.size() && family_ == UINT32_MAX; ++i)
        if (families[i].queueFlags & vk::QueueFlagBits::eCompute) family_ = i;
    graphics_ = static_cast<bool>(families[family_ == UINT32_MAX ? 0 : family_].queueFlags &
                                  vk::QueueFlagBits::eGraphics);
    if (family_ == UINT32_MAX) throw Error("Vulkan device " + name_ + " has no compute queue");
    if (families[family_].timestampValidBits == 0) timestampPeriod_ = 0.0f;
}

// 64-bit atomicMin in storage buffers where the device has it (the implicit solver's closest
// link a (node, bin) slot): Vulkan 1.2's feature on a ray-tracing context (a 1.2 instance).
void Context::CreateRayTracingDevice(const vk::DeviceQueueCreateInfo& qi) {
    vk::PhysicalDeviceFeatures features;
    const bool shaderInt64 = physical_->getFeatures().shaderInt64;
    vk::StructureChain<vk::DeviceCreateInfo, vk::PhysicalDeviceVulkan12Features,
                       vk::PhysicalDeviceAccelerationStructureFeaturesKHR,
                       vk::PhysicalDeviceRayTracingPipelineFeaturesKHR>
        chain;
    chain.get<vk::DeviceCreateInfo>()
        .setQueueCreateInfos(qi)
        .setPEnabledExtensionNames(kRayTracingExtensions)
        .setPEnabledFeatures(&features);
    int64Atomics_ =
        shaderInt64 &&
        physical_->getFeatures2<vk::PhysicalDeviceFeatures2, vk::PhysicalDeviceVulkan12Features>()
            .get<vk::PhysicalDeviceVulkan12Features>()
            .shaderBufferInt64Atomics;
    features.shaderInt64 = int64Atomics_;
    chain.get<vk::PhysicalDeviceVulkan12Features>().bufferDeviceAddress = VK_TRUE;
    chain.get<vk::PhysicalDeviceVulkan12Features>().shaderBufferInt64Atomics = int64Atomics_;
    chain.get<vk::PhysicalDeviceAccelerationStructureFeaturesKHR>().accelerationStructure = VK_TRUE;
    chain.get<vk::PhysicalDeviceRayTracingPipelineFeaturesKHR>().rayTracingPipeline = VK_TRUE;
    device_ = std::make_unique<vk::raii::Device>(*physical_, chain.get<vk::DeviceCreateInfo>());
}

// VK_KHR_shader_atomic_int64's 64-bit atomics on a compute context (a 1.1 instance), and float
// atomics in storage buffers where the device has them (the light field's walk adds what each
// line brings to its surfels with them).
void Context::CreateComputeDevice(const vk::DeviceQueueCreateInfo& qi) {
    vk::PhysicalDeviceFeatures features;
    const bool shaderInt64 = physical_->getFeatures().shaderInt64;
    const auto have = physical_->enumerateDeviceExtensionProperties();
    auto has = [&](const char* name) {
        return std::any_of(have.begin(), have.end(), [&](const vk::ExtensionProperties& e) {
            return std::strcmp(e.extensionName, name) == 0;
        });
    };
    if (has(VK_EXT_SHADER_ATOMIC_FLOAT_EXTENSION_NAME))
        floatAtomics_ = physical_
                            ->getFeatures2<vk::PhysicalDeviceFeatures2,
                                           vk::PhysicalDeviceShaderAtomicFloatFeaturesEXT>()
                            .get<vk::PhysicalDeviceShaderAtomicFloatFeaturesEXT>()
                            .shaderBufferFloat32AtomicAdd;
    if (shaderInt64 && has(VK_KHR_SHADER_ATOMIC_INT64_EXTENSION_NAME))
        int64Atomics_ = physical_
                            ->getFeatures2<vk::PhysicalDeviceFeatures2,
                                           vk::PhysicalDeviceShaderAtomicInt64Features>()
                            .get<vk::PhysicalDeviceShaderAtomicInt64Features>()
                            .shaderBufferInt64Atomics;
    features.shaderInt64 = int64Atomics_;
    vk::StructureChain<vk::DeviceCreateInfo, vk::PhysicalDeviceShaderAtomicFloatFeaturesEXT,
                       vk::PhysicalDeviceShaderAtomicInt64Features>
        chain;
    std::vector<const char*> extensions;
    chain.get<vk::DeviceCreateInfo>().setQueueCreateInfos(qi).setPEnabledFeatures(&features);
    if (floatAtomics_) {
        extensions.push_back(VK_EXT_SHADER_ATOMIC_FLOAT_EXTENSION_NAME);
        chain.get<vk::PhysicalDeviceShaderAtomicFloatFeaturesEXT>().shaderBufferFloat32AtomicAdd =
            VK_TRUE;
    } else {
        chain.unlink<vk::PhysicalDeviceShaderAtomicFloatFeaturesEXT>();
    }
    if (int64Atomics_) {
        extensions.push_back(VK_KHR_SHADER_ATOMIC_INT64_EXTENSION_NAME);
        chain.get<vk::PhysicalDeviceShaderAtomicInt64Features>().shaderBufferInt64Atomics = VK_TRUE;
    } else {
        chain.unlink<vk::PhysicalDeviceShaderAtomicInt64Features>();
    }
    chain.get<vk::DeviceCreateInfo>().setPEnabledExtensionNames(extensions);
    device_ = std::make_unique<vk::raii::Device>(*physical_, chain.get<vk::DeviceCreateInfo>());
}

Context::~Context() {
    try {
        if (device_) device_->waitIdle();
    } catch (const vk::SystemError&) {  // a lost device: nothing to wait for
    }
    std::lock_guard lifetime(gLifetime);
    // Members go in reverse declaration order: pool, queue, device, ..., instance.
    pool_.reset();
    queue_.reset();
    device_.reset();
    physical_.reset();
    messenger_.reset();
    instance_.reset();
}

vk::raii::CommandBuffer Context::AllocateCommandBuffer() const {
    vk::CommandBufferAllocateInfo ai(**pool_, vk::CommandBufferLevel::ePrimary, 1);
    vk::raii::CommandBuffers cbs(*device_, ai);
    return std::move(cbs.front());
}

namespace {
std::atomic<int> gSimulatedLoss{-1};  // submissions until a simulated loss; < 0: none
}  // namespace

void SimulateDeviceLoss(int after) { gSimulatedLoss = after; }

void Context::SubmitAndWait(const vk::raii::CommandBuffer& cb) const {
    if (lost_) throw DeviceLost(name_ + ": the device was lost earlier (VK_ERROR_DEVICE_LOST)");
    int countdown = gSimulatedLoss.load();
    while (countdown >= 0 && !gSimulatedLoss.compare_exchange_weak(countdown, countdown - 1)) {
    }
    if (countdown == 0) {
        lost_ = true;
        throw DeviceLost(name_ + ": vkQueueSubmit failed: VK_ERROR_DEVICE_LOST (simulated)");
    }
    vk::raii::Fence fence(*device_, vk::FenceCreateInfo());
    vk::CommandBuffer raw = *cb;
    vk::SubmitInfo si({}, {}, raw);
    vk::Result r;
    try {
        queue_->submit(si, *fence);
        r = device_->waitForFences({*fence}, VK_TRUE, UINT64_MAX);
    } catch (const vk::DeviceLostError& e) {
        lost_ = true;
        throw DeviceLost(name_ + ": " + e.what());
    }
    if (r != vk::Result::eSuccess) ThrowVulkan("vkWaitForFences", r);
}

std::vector<std::string> Context::ValidationMessages() const {
    std::lock_guard<std::mutex> lock(messages_->mutex);
    return messages_->list;
}

bool FindRealGpu(std::string* name) {
    std::lock_guard lifetime(gLifetime);
    KeepDriversLoaded();
    try {
        vk::raii::Context context;
        vk::ApplicationInfo app("penumbra-probe", 1, "penumbra", 1, VK_API_VERSION_1_1);
        vk::raii::Instance instance(context, vk::InstanceCreateInfo({}, &app));
        vk::raii::PhysicalDevices all(instance);
        for (const auto& pd : all) {
            auto props = pd.getProperties();
            if (props.deviceType != vk::PhysicalDeviceType::eCpu &&
                props.deviceType != vk::PhysicalDeviceType::eOther) {
                if (name) *name = props.deviceName.data();
                return true;
            }
        }
    } catch (const std::exception&) {
        // No loader or no ICD: no GPU.
    }
    return false;
}

}  // namespace penumbra::gpu
