// Refined output for coarse meshes (issue 62): a mesh whose triangles are larger than the
// light's detail (an IFC wall is 8 vertices, all at its corners) is subdivided before it is
// lit, so that the irradiance a renderer gets per vertex can show the light across it.
#pragma once

#include "scene/scene.h"

namespace penumbra {

// Subdivides every triangle of `scene` by longest-edge bisection until no edge (world space)
// is longer than `edge` metres; shared edges are split once, at their midpoints, so each
// primitive stays watertight where it was. Every per-vertex list (positions and normals in
// world, own and rest space, the texture coordinates read, morph targets) is interpolated at
// a midpoint; a flat-normal copy (Primitive::copyOf) becomes an output vertex of its own.
// Primitives left with more vertices get `refined` set and `parentTriangles` (each new
// triangle's input triangle); the output writes their geometry instead of the input's.
// Throws penumbra::Error for an edge that is not positive and finite, or when the result
// would pass `maxTriangles`.
void RefineForOutput(Scene& scene, float edge, size_t maxTriangles = 50'000'000);

}  // namespace penumbra
