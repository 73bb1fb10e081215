// The implicit solver's compositing on a Vulkan device (shaders/implicit_composite.comp):
// RefineHierarchicalLinks and PushdownLinks (Dong et al. 2007, Sec. 4.2.3-4.2.4) as
// ImplicitLinker::Build does them on the CPU, from the ends the device's rounds made
// (vulkan_links.h). The ends are counted by (node, bin) slot, scanned, scattered and each slot
// sorted nearest first; then each (leaf, front bin) merges its chain's slots until the bin is
// full, with the closed solids' rules, the partial fill and the far faces' fronts, and each
// share's travel is found. The shares come back to the host, which sets the bounce's factors
// from them (ImplicitSolver::Relink; the bounce runs on the device again, vulkan_bounce.h).
// The same shares as the CPU's compositing of the same ends, in the same order, up to the
// device's float rounding at a threshold.
#pragma once

#include <glm/vec4.hpp>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "gpu/fwd.h"
#include "hierarchy/directions.h"
#include "hierarchy/hierarchy.h"
#include "solvers/implicit/implicit_links.h"

namespace penumbra {

class VulkanCompositing {
  public:
    // `binRadius`: ImplicitLinker::BinRadius(). `mostSolids`: how many closed solids the
    // device tracks in one bin (a bin that meets more is composited on the host).
    VulkanCompositing(gpu::Context& ctx, const Directions& dirs, float binRadius,
                      uint32_t mostSolids = 32);
    ~VulkanCompositing();
    VulkanCompositing(const VulkanCompositing&) = delete;
    VulkanCompositing& operator=(const VulkanCompositing&) = delete;

    // Why `h`'s compositing of `ends` ends does not run on the device (its chains too deep, a
    // table or list beyond the device's storage-buffer range, 32-bit indices or its scan's
    // reach), or empty.
    std::string Unfit(const Hierarchy& h, size_t ends) const;
    // Composites `ends` (ImplicitLinker::End, in any order) for `h` into `out`'s offsets,
    // bin, sender, weight, travel and empty, as ImplicitLinker::Build does: `frontArea` per
    // node and bin on the device (Build's, as VulkanLinkCreation::FrontArea holds them on the
    // same context), `solid` per node
    // (or empty), `boxes` per closed solid its box's lo and hi, `thin` Build's. Returns false,
    // leaving `out` as it was, when a bin met more closed solids than `mostSolids`, a slot
    // holds more ends than its sort takes (4,096), the shares overflow the storage-buffer
    // range, a closed solid's number does not fit 30 bits, or a bin's two merges (the count,
    // then the write) disagree (a loop cut short: lavapipe ends a shader's loops after
    // 65,535 iterations in all); `Why()` says which. Then the host composites.
    bool Composite(const Hierarchy& h, const gpu::Buffer& frontArea,
                   const std::vector<uint32_t>& solid, const std::vector<glm::vec4>& boxes,
                   float thin, std::span<const ImplicitLinker::End> ends, ImplicitLinks& out);
    // Why the last Composite returned false (empty after one that ran).
    const std::string& Why() const { return why_; }

    double msDevice = 0.0;  // uploads, dispatches and readbacks of the last Composite
    double msBusy = 0.0;    // the device's own time in them (0: no timestamps)
    size_t runs = 0;        // Composites that ran on the device

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
    std::string why_;
};

}  // namespace penumbra
