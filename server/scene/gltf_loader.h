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

// Writes `model` to `path`: .gltf (JSON, its one buffer and its images embedded as data URIs)
// or .glb (every buffer and image in the one BIN chunk), in a form the Khronos validator
// accepts. tinygltf alone writes a .glb's second buffer and its images as data URIs and an
// infinite perspective camera as "zfar": 0; here the buffers are merged into one, images
// given by URI (relative to `inputDir`, or data URIs) are moved into buffer views, and a
// zfar of 0 is left out. Throws penumbra::Error when an image cannot be read or the file
// cannot be written.
void WriteGltfModel(tinygltf::Model model, const std::string& path,
                    const std::string& inputDir = ".");

// Loads `path`. Throws penumbra::Error for unreadable, malformed or unsupported input.
Scene LoadGltf(const std::string& path);

// sRGB-encoded 8-bit value to linear [0, 1].
float SrgbToLinear(float encoded);

}  // namespace penumbra
