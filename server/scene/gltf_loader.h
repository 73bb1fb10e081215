// Reads glTF 2.0 (.gltf/.glb) through tinygltf into a world-space Scene.
// Errors name the file, the offending object and the reason (penumbra::Error).
#pragma once

#include <string>

#include "scene/scene.h"

namespace tinygltf {
class Model;
}

namespace penumbra {

// True for a binary glTF (.glb) path.
bool IsGlbPath(const std::string& path);

// Reads a .gltf/.glb file into a tinygltf model; throws penumbra::Error naming the file.
void ReadGltfModel(const std::string& path, tinygltf::Model* model);

// Loads `path`. Throws penumbra::Error for unreadable, malformed or unsupported input.
Scene LoadGltf(const std::string& path);

// sRGB-encoded 8-bit value to linear [0, 1].
float SrgbToLinear(float encoded);

}  // namespace penumbra
