// Moves in place in the antiradiance solver (Sec. 3.3): the shared placement of the surfels
// (scene/motion.h) carried to the hierarchy, the leaves and the links touching a moved group.
#pragma once

#include <cstdint>
#include <vector>

#include "scene/scene.h"

namespace penumbra {

struct AntiradianceModel;  // solvers/antiradiance/model.h

// A move inside the bounds, in two steps. PlaceGroups re-places the surfels (PlaceSurfels),
// nodes, cosine norms, leaves and glossy mirror bins of every group whose node moved in
// `scene` (MotionMismatch, scene/motion.h, must be empty) and returns which groups moved (index g,
// [0] static and never moved); `movedLeaves` (optional) gets each moved leaf's index into `leaves`.
// TouchedLinks lists the links touching a moved group (indices into Links::dynamic), and
// RedoLinks recomputes their form factors, bins and spread levels on the host (MakeLink:
// the same rules as the build, at the new places); the Vulkan back end recomputes them on
// the device instead (VulkanAntiradiance::UpdateLinks). MoveGroups does all three on the
// host and returns the number of links recomputed.
std::vector<uint8_t> PlaceGroups(AntiradianceModel& model, const Scene& scene,
                                 std::vector<uint32_t>* movedLeaves = nullptr);
std::vector<uint32_t> TouchedLinks(const AntiradianceModel& model,
                                   const std::vector<uint8_t>& moved);
void RedoLinks(AntiradianceModel& model, const std::vector<uint32_t>& touched);
size_t MoveGroups(AntiradianceModel& model, const Scene& scene,
                  std::vector<uint32_t>* movedLeaves = nullptr);

}  // namespace penumbra
