// The one internal interface of the antiradiance back ends: the fused CPU walk
// (cpu_passes.h) and the Vulkan compute passes (vulkan_passes.h). The solver
// (antiradiance_solver.h) drives either through it without asking which; a new solver with
// more than one back end copies this shape.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "gpu/fwd.h"
#include "solver/solver.h"
#include "solvers/antiradiance/model.h"

namespace penumbra {

class AntiradianceBackend {
  public:
    virtual ~AntiradianceBackend() = default;
    virtual std::string DeviceName() const = 0;  // "cpu", "vulkan:<device>"
    // Whether it runs on the host's own cores (the CPU back end, lavapipe).
    virtual bool OnCpu() const = 0;
    // One pass of all four stages (global, push, local in `mode`, pull), waited for.
    virtual void Iterate(LocalMode mode) = 0;
    // Per-leaf irradiance E (RGB, leaf order) as the last pass left it.
    virtual std::vector<float> LeafIrradiance() = 0;
    // The I_ex table the next pass reads (fp32, node × bin × RGB), and replacing it.
    virtual std::vector<float> Iex() = 0;
    virtual void SetIex(const std::vector<float>& iex) = 0;
    // What of the model changed since the back end last read it (Inputs, or-ed): a device
    // copies those again; the CPU back end reads the model in place and re-measures what an
    // iteration adds (its fp16 tables' scale).
    enum Inputs : uint32_t {
        kLeaves = 1,        // LeafAttributes (albedo, emission, normals after a move)
        kDirect = 2,        // leafDirect
        kGlossy = 4,        // the glossy data (leaves, mirror bins, lobes)
        kGlossyDirect = 8,  // glossyDirect alone
        kEnvironment = 16,  // the sky's bins
        kLinks = 32,        // links recomputed on the host (RedoLinks)
    };
    virtual void InputsChanged(uint32_t inputs) = 0;
    // Sec. 3.3: whether it can recompute the links of a move itself (UpdateLinks: after
    // PlaceGroups, the links touching a group with moved[group] set), and that update's last
    // device time.
    virtual bool CanUpdateLinks() const { return false; }
    virtual void UpdateLinks(const std::vector<uint8_t>& moved) {
        (void)moved;
        throw Error("this back end recomputes no links itself");
    }
    virtual double LinkUpdateMs() const { return 0.0; }
    virtual std::vector<PassTiming> PassTimings() const = 0;
    virtual size_t TableBytes() const = 0;
    virtual const char* Tables() const = 0;  // "fp32" | "fp16"
    virtual std::vector<std::string> ValidationMessages() const { return {}; }
    // Where the direct stage renders E_d for the local pass to read (direct_stage.h): a
    // device and a buffer of one vec4 per leaf; null on the CPU back end (reads leafDirect).
    virtual gpu::Context* DirectDevice() { return nullptr; }
    virtual gpu::Buffer* DirectOut() { return nullptr; }
};

}  // namespace penumbra
