// Acceleration structures, the ray-tracing pipeline and its shader binding table
// (gpu/ray_tracer.h). Build inputs and rays live in host-visible memory, hits in host-visible
// cached memory (each written or read once a call); the acceleration structures and their
// scratch in device-local memory.
#include "gpu/ray_tracer.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cstring>

#include "base/check.h"
#include "base/numeric.h"
#include "gpu/buffer.h"
#include "gpu/context.h"
#include "gpu/pipeline.h"
#include "shaders/trace_rchit_spv.h"
#include "shaders/trace_rgen_spv.h"
#include "shaders/trace_rmiss_spv.h"

namespace penumbra::gpu {
namespace {

constexpr uint32_t kBatch = 1u << 20;  // rays a dispatch

vk::DeviceSize Align(vk::DeviceSize x, vk::DeviceSize a) { return (x + a - 1) / a * a; }

// Where a buffer's memory lies: the device's own; host-visible for the host to write
// (uncached, write-combined where the device offers it); host-visible and cached for the host
// to read (reading uncached memory runs at a few hundred MB/s).
enum class Memory { kDevice, kUpload, kReadback };

// A buffer with a device address, bound to memory of its own.
struct AddressedBuffer {
    vk::raii::Buffer buffer{nullptr};
    vk::raii::DeviceMemory memory{nullptr};
    vk::DeviceSize bytes = 0;
    vk::DeviceAddress address = 0;
    void* mapped = nullptr;  // host-visible ones

    AddressedBuffer() = default;
    AddressedBuffer(const Context& ctx, vk::DeviceSize size, vk::BufferUsageFlags usage,
                    Memory where) {
        bytes = std::max<vk::DeviceSize>(size, 16);
        buffer = vk::raii::Buffer(
            ctx.Device(),
            vk::BufferCreateInfo({}, bytes, usage | vk::BufferUsageFlagBits::eShaderDeviceAddress));
        const auto req = buffer.getMemoryRequirements();
        const vk::MemoryPropertyFlags host =
            vk::MemoryPropertyFlagBits::eHostVisible | vk::MemoryPropertyFlagBits::eHostCoherent;
        uint32_t type = UINT32_MAX;
        if (where == Memory::kDevice)
            type = FindMemory(ctx, req.memoryTypeBits, vk::MemoryPropertyFlagBits::eDeviceLocal);
        if (where == Memory::kReadback)
            type =
                FindMemory(ctx, req.memoryTypeBits, host | vk::MemoryPropertyFlagBits::eHostCached);
        if (where != Memory::kDevice && type == UINT32_MAX)
            type = FindMemory(ctx, req.memoryTypeBits, host);
        if (type == UINT32_MAX)
            throw Error("Vulkan device " + ctx.DeviceName() + " has no " +
                        (where == Memory::kDevice ? "device-local" : "host-visible") +
                        " memory for a ray-tracing buffer");
        vk::MemoryAllocateFlagsInfo flags(vk::MemoryAllocateFlagBits::eDeviceAddress);
        vk::MemoryAllocateInfo ai(req.size, type);
        ai.pNext = &flags;
        memory = vk::raii::DeviceMemory(ctx.Device(), ai);
        buffer.bindMemory(*memory, 0);
        address = ctx.Device().getBufferAddress(vk::BufferDeviceAddressInfo(*buffer));
        if (where != Memory::kDevice) mapped = memory.mapMemory(0, bytes);
    }
};

// The usage of buffers read by an acceleration-structure build.
constexpr vk::BufferUsageFlags kBuildInput =
    vk::BufferUsageFlagBits::eAccelerationStructureBuildInputReadOnlyKHR;

}  // namespace

struct RayTracer::Impl {
    Context ctx;
    vk::PhysicalDeviceRayTracingPipelinePropertiesKHR rtProps;
    vk::PhysicalDeviceAccelerationStructurePropertiesKHR asProps;

    // Acceleration structures: bottom level over the triangles, top level with one instance.
    AddressedBuffer corners, instances, blasStorage, tlasStorage, scratch;
    vk::raii::AccelerationStructureKHR blas{nullptr}, tlas{nullptr};
    uint32_t triangles = 0;

    // Pipeline: set 0 = (0) the top level, (1) rays, (2) hits; push constant: count.
    vk::raii::DescriptorSetLayout setLayout{nullptr};
    vk::raii::PipelineLayout layout{nullptr};
    vk::raii::Pipeline pipeline{nullptr};
    vk::raii::DescriptorPool pool{nullptr};
    AddressedBuffer table;  // shader binding table: raygen, miss, hit regions
    vk::StridedDeviceAddressRegionKHR raygen, miss, hit, callable;

    AddressedBuffer rays, hits;
    double buildMs = 0.0, traceMs = 0.0;

    Impl(DeviceKind kind, bool validation) : ctx(kind, validation, Capability::kRayTracing) {
        const auto chain =
            ctx.Physical()
                .getProperties2<vk::PhysicalDeviceProperties2,
                                vk::PhysicalDeviceRayTracingPipelinePropertiesKHR,
                                vk::PhysicalDeviceAccelerationStructurePropertiesKHR>();
        rtProps = chain.get<vk::PhysicalDeviceRayTracingPipelinePropertiesKHR>();
        asProps = chain.get<vk::PhysicalDeviceAccelerationStructurePropertiesKHR>();
        MakePipeline();
    }

    void MakePipeline() {
        const auto stages = vk::ShaderStageFlagBits::eRaygenKHR;
        std::array<vk::DescriptorSetLayoutBinding, 3> bindings = {
            vk::DescriptorSetLayoutBinding(0, vk::DescriptorType::eAccelerationStructureKHR, 1,
                                           stages),
            vk::DescriptorSetLayoutBinding(1, vk::DescriptorType::eStorageBuffer, 1, stages),
            vk::DescriptorSetLayoutBinding(2, vk::DescriptorType::eStorageBuffer, 1, stages)};
        setLayout = vk::raii::DescriptorSetLayout(ctx.Device(),
                                                  vk::DescriptorSetLayoutCreateInfo({}, bindings));
        vk::PushConstantRange push(stages, 0, sizeof(uint32_t));
        vk::DescriptorSetLayout raw = *setLayout;
        layout =
            vk::raii::PipelineLayout(ctx.Device(), vk::PipelineLayoutCreateInfo({}, raw, push));
        std::array<vk::DescriptorPoolSize, 2> sizes = {
            vk::DescriptorPoolSize(vk::DescriptorType::eAccelerationStructureKHR, 1),
            vk::DescriptorPoolSize(vk::DescriptorType::eStorageBuffer, 2)};
        pool = vk::raii::DescriptorPool(
            ctx.Device(), vk::DescriptorPoolCreateInfo(
                              vk::DescriptorPoolCreateFlagBits::eFreeDescriptorSet, 1, sizes));

        auto module = [&](const auto& words) {
            return vk::raii::ShaderModule(
                ctx.Device(), vk::ShaderModuleCreateInfo({}, sizeof(words), std::data(words)));
        };
        vk::raii::ShaderModule rgen = module(kSpirv_trace_rgen), rmiss = module(kSpirv_trace_rmiss),
                               rchit = module(kSpirv_trace_rchit);
        std::array<vk::PipelineShaderStageCreateInfo, 3> shaderStages = {
            vk::PipelineShaderStageCreateInfo({}, vk::ShaderStageFlagBits::eRaygenKHR, *rgen,
                                              "main"),
            vk::PipelineShaderStageCreateInfo({}, vk::ShaderStageFlagBits::eMissKHR, *rmiss,
                                              "main"),
            vk::PipelineShaderStageCreateInfo({}, vk::ShaderStageFlagBits::eClosestHitKHR, *rchit,
                                              "main")};
        const uint32_t unused = VK_SHADER_UNUSED_KHR;
        std::array<vk::RayTracingShaderGroupCreateInfoKHR, 3> groups = {
            vk::RayTracingShaderGroupCreateInfoKHR(vk::RayTracingShaderGroupTypeKHR::eGeneral, 0,
                                                   unused, unused, unused),
            vk::RayTracingShaderGroupCreateInfoKHR(vk::RayTracingShaderGroupTypeKHR::eGeneral, 1,
                                                   unused, unused, unused),
            vk::RayTracingShaderGroupCreateInfoKHR(
                vk::RayTracingShaderGroupTypeKHR::eTrianglesHitGroup, unused, 2, unused, unused)};
        vk::RayTracingPipelineCreateInfoKHR info({}, shaderStages, groups, 1);
        info.layout = *layout;
        pipeline = vk::raii::Pipeline(ctx.Device(), nullptr, nullptr, info);

        // The table: each group's handle at the start of a region of its own.
        const vk::DeviceSize handle = rtProps.shaderGroupHandleSize;
        const vk::DeviceSize stride = Align(handle, rtProps.shaderGroupHandleAlignment);
        const vk::DeviceSize region = Align(stride, rtProps.shaderGroupBaseAlignment);
        const auto handles = pipeline.getRayTracingShaderGroupHandlesKHR<uint8_t>(
            0, 3, static_cast<size_t>(3 * handle));
        // One base alignment more, so that the first region can start on one.
        table = AddressedBuffer(ctx, 3 * region + rtProps.shaderGroupBaseAlignment,
                                vk::BufferUsageFlagBits::eShaderBindingTableKHR, Memory::kUpload);
        const vk::DeviceSize base =
            Align(table.address, rtProps.shaderGroupBaseAlignment) - table.address;
        auto* bytes = static_cast<uint8_t*>(table.mapped);
        for (int g = 0; g < 3; ++g)
            std::memcpy(bytes + base + g * region, handles.data() + g * handle, handle);
        raygen = vk::StridedDeviceAddressRegionKHR(table.address + base, stride, stride);
        miss = vk::StridedDeviceAddressRegionKHR(table.address + base + region, stride, stride);
        hit = vk::StridedDeviceAddressRegionKHR(table.address + base + 2 * region, stride, stride);
    }

    // Makes `storage` and `as` of `type` for the sizes of `geometry`, and records its build.
    void RecordBuild(const vk::raii::CommandBuffer& cb,
                     const vk::AccelerationStructureGeometryKHR& geometry, uint32_t count,
                     vk::AccelerationStructureTypeKHR type, AddressedBuffer& storage,
                     vk::raii::AccelerationStructureKHR& as, AddressedBuffer& scratchBuffer) {
        vk::AccelerationStructureBuildGeometryInfoKHR info(
            type, vk::BuildAccelerationStructureFlagBitsKHR::ePreferFastTrace,
            vk::BuildAccelerationStructureModeKHR::eBuild, {}, {}, geometry);
        const auto sizes = ctx.Device().getAccelerationStructureBuildSizesKHR(
            vk::AccelerationStructureBuildTypeKHR::eDevice, info, count);
        storage = AddressedBuffer(ctx, sizes.accelerationStructureSize,
                                  vk::BufferUsageFlagBits::eAccelerationStructureStorageKHR,
                                  Memory::kDevice);
        as = vk::raii::AccelerationStructureKHR(
            ctx.Device(), vk::AccelerationStructureCreateInfoKHR(
                              {}, *storage.buffer, 0, sizes.accelerationStructureSize, type));
        const vk::DeviceSize align = asProps.minAccelerationStructureScratchOffsetAlignment;
        scratchBuffer = AddressedBuffer(ctx, sizes.buildScratchSize + align,
                                        vk::BufferUsageFlagBits::eStorageBuffer, Memory::kDevice);
        info.dstAccelerationStructure = *as;
        info.scratchData.deviceAddress = Align(scratchBuffer.address, align);
        const vk::AccelerationStructureBuildRangeInfoKHR range(count, 0, 0, 0);
        const vk::AccelerationStructureBuildRangeInfoKHR* ranges = &range;
        cb.buildAccelerationStructuresKHR(info, ranges);
    }

    void Build(std::span<const glm::vec3> points) {
        PENUMBRA_CHECK(points.size() % 3 == 0);
        const auto start = std::chrono::steady_clock::now();
        triangles = static_cast<uint32_t>(points.size() / 3);
        if (triangles == 0) throw Error("ray tracing: no triangles to build over");
        // The device may hold on to nothing of the last build while this one is recorded.
        ctx.Device().waitIdle();
        tlas = vk::raii::AccelerationStructureKHR(nullptr);
        blas = vk::raii::AccelerationStructureKHR(nullptr);
        corners = AddressedBuffer(ctx, points.size_bytes(), kBuildInput, Memory::kUpload);
        std::memcpy(corners.mapped, points.data(), points.size_bytes());

        vk::AccelerationStructureGeometryTrianglesDataKHR tri(
            vk::Format::eR32G32B32Sfloat, corners.address, sizeof(glm::vec3),
            static_cast<uint32_t>(points.size() - 1), vk::IndexType::eNoneKHR);
        vk::AccelerationStructureGeometryKHR bottom(vk::GeometryTypeKHR::eTriangles, tri,
                                                    vk::GeometryFlagBitsKHR::eOpaque);
        AddressedBuffer blasScratch, tlasScratch;
        ctx.RunNow([&](const vk::raii::CommandBuffer& cb) {
            RecordBuild(cb, bottom, triangles, vk::AccelerationStructureTypeKHR::eBottomLevel,
                        blasStorage, blas, blasScratch);
        });
        vk::AccelerationStructureInstanceKHR instance;
        const std::array<std::array<float, 4>, 3> identity = {
            {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}}};
        instance.transform = vk::TransformMatrixKHR(identity);
        instance.mask = 0xFF;
        instance.flags = static_cast<VkGeometryInstanceFlagsKHR>(
            vk::GeometryInstanceFlagBitsKHR::eTriangleFacingCullDisable);
        instance.accelerationStructureReference = ctx.Device().getAccelerationStructureAddressKHR(
            vk::AccelerationStructureDeviceAddressInfoKHR(*blas));
        instances = AddressedBuffer(ctx, sizeof instance, kBuildInput, Memory::kUpload);
        std::memcpy(instances.mapped, &instance, sizeof instance);
        vk::AccelerationStructureGeometryInstancesDataKHR data(VK_FALSE, instances.address);
        vk::AccelerationStructureGeometryKHR top(vk::GeometryTypeKHR::eInstances, data,
                                                 vk::GeometryFlagBitsKHR::eOpaque);
        ctx.RunNow([&](const vk::raii::CommandBuffer& cb) {
            RecordBuild(cb, top, 1, vk::AccelerationStructureTypeKHR::eTopLevel, tlasStorage, tlas,
                        tlasScratch);
        });
        buildMs = MsSince(start);
    }

    std::vector<TraceHit> Trace(std::span<const TraceRay> in) {
        if (!*tlas) throw Error("ray tracing: Trace before Build");
        const auto start = std::chrono::steady_clock::now();
        std::vector<TraceHit> out(in.size());
        if (in.empty()) return out;
        const size_t batch = std::min<size_t>(in.size(), kBatch);
        if (rays.bytes < batch * sizeof(TraceRay)) {
            rays = AddressedBuffer(ctx, batch * sizeof(TraceRay),
                                   vk::BufferUsageFlagBits::eStorageBuffer, Memory::kUpload);
            hits = AddressedBuffer(ctx, batch * sizeof(TraceHit),
                                   vk::BufferUsageFlagBits::eStorageBuffer, Memory::kReadback);
        }
        vk::DescriptorSetLayout raw = *setLayout;
        vk::raii::DescriptorSets sets(ctx.Device(), vk::DescriptorSetAllocateInfo(*pool, raw));
        vk::raii::DescriptorSet& set = sets.front();
        vk::AccelerationStructureKHR top = *tlas;
        vk::WriteDescriptorSetAccelerationStructureKHR asWrite(top);
        vk::DescriptorBufferInfo rayInfo(*rays.buffer, 0, VK_WHOLE_SIZE),
            hitInfo(*hits.buffer, 0, VK_WHOLE_SIZE);
        std::array<vk::WriteDescriptorSet, 3> writes = {
            vk::WriteDescriptorSet(*set, 0, 0, 1, vk::DescriptorType::eAccelerationStructureKHR),
            vk::WriteDescriptorSet(*set, 1, 0, vk::DescriptorType::eStorageBuffer, {}, rayInfo),
            vk::WriteDescriptorSet(*set, 2, 0, vk::DescriptorType::eStorageBuffer, {}, hitInfo)};
        writes[0].pNext = &asWrite;
        ctx.Device().updateDescriptorSets(writes, {});
        for (size_t first = 0; first < in.size(); first += batch) {
            const uint32_t count = static_cast<uint32_t>(std::min(batch, in.size() - first));
            std::memcpy(rays.mapped, in.data() + first, count * sizeof(TraceRay));
            ctx.RunNow([&](const vk::raii::CommandBuffer& cb) {
                cb.bindPipeline(vk::PipelineBindPoint::eRayTracingKHR, *pipeline);
                cb.bindDescriptorSets(vk::PipelineBindPoint::eRayTracingKHR, *layout, 0, *set, {});
                cb.pushConstants<uint32_t>(*layout, vk::ShaderStageFlagBits::eRaygenKHR, 0, count);
                cb.traceRaysKHR(raygen, miss, hit, callable, count, 1, 1);
                // The host reads the hits after the fence.
                HostReadBarrier(cb, vk::PipelineStageFlagBits::eRayTracingShaderKHR);
            });
            std::memcpy(out.data() + first, hits.mapped, count * sizeof(TraceHit));
        }
        traceMs = MsSince(start);
        return out;
    }
};

RayTracer::RayTracer(DeviceKind kind, bool validation) {
    try {
        impl_ = std::make_unique<Impl>(kind, validation);
    } catch (const vk::SystemError& e) {
        throw Error(std::string("Vulkan ray tracing set-up failed: ") + e.what());
    }
}

RayTracer::~RayTracer() = default;

const std::string& RayTracer::DeviceName() const { return impl_->ctx.DeviceName(); }

void RayTracer::Build(std::span<const glm::vec3> corners) {
    try {
        impl_->Build(corners);
    } catch (const vk::SystemError& e) {
        throw Error(std::string("Vulkan acceleration-structure build failed: ") + e.what());
    }
}

std::vector<TraceHit> RayTracer::Trace(std::span<const TraceRay> rays) {
    try {
        return impl_->Trace(rays);
    } catch (const vk::SystemError& e) {
        throw Error(std::string("Vulkan ray tracing failed: ") + e.what());
    }
}

double RayTracer::BuildMs() const { return impl_->buildMs; }
double RayTracer::TraceMs() const { return impl_->traceMs; }

std::vector<std::string> RayTracer::ValidationMessages() const {
    return impl_->ctx.ValidationMessages();
}

}  // namespace penumbra::gpu
