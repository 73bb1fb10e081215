// The scenes bundled in scenes/: defined here once, written as glTF by make_scenes,
// and built in memory by tests and benchmarks.
#pragma once

#include <string>
#include <vector>

#include "scene/scene_builder.h"

namespace penumbra::scenes {

// Cornell box from the published measurements (Cornell Program of Computer Graphics),
// millimetres → metres, the usual RGB albedos, the ceiling light as an emitting quad
// filling a hole in the ceiling.
SceneBuilder CornellBox();
// An emitting square over a floor with an opaque closed box between them.
SceneBuilder Blocker(bool withBlocker = true);
// A 4 × 4 × 1 m serpentine of four corridors lit by one lamp that faces the first
// corridor's end wall: everything else is lit only indirectly (the paper's Fig. 12 idea).
SceneBuilder Maze();
// Office-scale scene of the benchmark: about 5,600 input triangles (room, workstations,
// shelves, cabinets, emissive ceiling fixtures).
SceneBuilder Office();

// A 4 × 3 × 4 m room with a glossy blue metal cube and a rougher gold column, lit by a
// spot aimed at the cube: most light in the room is reflected directionally (Fig. 15).
SceneBuilder GlossyBox();

// The clutter suite's 2 m room under its ceiling panel with a morphing "blob" (a sphere of
// 0.3 m, 1,091 vertices, dynamic) over a low box: its mesh has two morph targets, `squash`
// (flattened and widened on its base) and `ripple` (a standing wave over its surface),
// posed over the protocol (SetVertices `weights`, `penumbra deform blob --weights a,b`).
SceneBuilder MorphRoom();

struct Bundled {
    std::string file;  // name under scenes/
    SceneBuilder (*make)();
};
std::vector<Bundled> All();

}  // namespace penumbra::scenes
