// Which surfaces bound solids: a scene's triangles welded, wound front-out and split into
// shells, each tested for closure (the back-side rule of Surfels::twoSided rests on it).
#pragma once

#include <vector>

#include "scene/scene.h"

namespace penumbra {

// Per scene node: the solid its triangles bound, or -1 where they bound none. Positions are
// welded and each triangle wound so its front is where its vertex normals point, then split
// into shells: triangles joined across the edges they share, and where several solids meet
// at an edge (boxes stacked flush, a shelf's board against its side) paired about it, each
// with its neighbour across its inside. A shell bounds a solid when each of its edges pairs
// up, each open edge lies on another surface (a box without a bottom standing on a floor or
// on another box), and the enclosed volume is positive (fronts facing out: a closed room
// facing in is no solid).
// A node whose shells all bound solids is a solid of its own: its index. The nodes that do
// not close alone are then welded together, so that a box whose six faces are six nodes (as
// many exporters write them) is a solid too: those nodes whose every triangle lies on a shell
// that bounds a solid share the smallest index among the nodes their shells join.
// -1 for nodes without triangles.
std::vector<int> NodeSolids(const Scene& scene);

// Per scene node: whether it bounds solids, alone or with others (NodeSolids >= 0).
std::vector<bool> ClosedNodes(const Scene& scene);

}  // namespace penumbra
