// The implicit solver's link creation on a Vulkan device (shaders/implicit_pairs.comp): the
// rounds of candidate pairs of ImplicitLinker::Build (CreateHierarchicalLinks, level by level
// as in Meyer et al. 2009's data-parallel link creation), one dispatch a round, the next
// round's pairs and the recorded ends appended with atomic counters. The ends come back to
// the host, which hands them to the device's compositing (vulkan_composite.h), or composites
// them itself as it does the CPU's ends: the same links, up to float rounding of the device's
// arithmetic near a split or bin boundary.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "gpu/fwd.h"
#include "hierarchy/directions.h"
#include "hierarchy/hierarchy.h"
#include "solvers/implicit/implicit_links.h"

namespace penumbra {

class VulkanLinkCreation {
  public:
    // `bufferBytes`: the most a list of pairs or ends takes on the device (0: the device's
    // storage-buffer range); a round larger than that goes up in chunks. `closest`: the
    // paper's rule (bin-cover closest, CreateClosest) instead of the ends (Create); it needs
    // the device's 64-bit atomics (ClosestUnsupported).
    VulkanLinkCreation(gpu::Context& ctx, const Directions& dirs, float linkThreshold,
                       size_t bufferBytes = 0, bool closest = false);
    ~VulkanLinkCreation();
    VulkanLinkCreation(const VulkanLinkCreation&) = delete;
    VulkanLinkCreation& operator=(const VulkanLinkCreation&) = delete;

    // Every pair from the root's self-pair for `h` as placed now (`frontArea` per node and bin,
    // `slab` per node, ImplicitLinker::Build's): appends the ends to `ends`; `pairs` the
    // candidate pairs examined, `linked` those that became links.
    void Create(const Hierarchy& h, const std::vector<float>& frontArea,
                const std::vector<float>& slab, std::vector<ImplicitLinker::End>& ends,
                size_t& pairs, size_t& linked);

    // The closest rule's rounds (ImplicitLinker's `closest`): every pair as Create examines
    // it, each link kept in its (node, bin) slot when it is the closest there, by 64-bit
    // atomicMin on the device (shaders/implicit_closest.comp); `best` gets the table, per
    // node a row of `bins` keys (depth bits << 32 | sender, all ones for none), as
    // ImplicitLinker::BuildClosest makes it on the CPU.
    void CreateClosest(const Hierarchy& h, const std::vector<float>& frontArea,
                       const std::vector<float>& slab, std::vector<uint64_t>& best, size_t& pairs,
                       size_t& linked);
    // Why the device cannot keep the closest rule's table (empty: it can): it has no 64-bit
    // atomics; a table of `nodes` rows is larger than a storage buffer may be (`bufferBytes`).
    static std::string ClosestUnsupported(const gpu::Context& ctx);
    std::string ClosestUnfit(size_t nodes) const;

    // The front-facing projected areas the last Create took (per node and bin), on the
    // device: the compositing on the same context binds them (vulkan_composite.h).
    const gpu::Buffer& FrontArea() const;

    double msDevice = 0.0;  // uploads, rounds and readbacks of the last Create
    double msBusy = 0.0;    // the device's own time in them (0: no timestamps)
    size_t rounds = 0;      // dispatches of the last Create

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace penumbra
