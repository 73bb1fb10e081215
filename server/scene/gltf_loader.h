// Reads glTF 2.0 (.gltf/.glb) through tinygltf into a world-space Scene.
// Errors name the file, the offending object and the reason (penumbra::Error).
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>

#include "base/check.h"
#include "scene/scene.h"

namespace tinygltf {
class Model;
}

namespace penumbra {

// True for a binary glTF (.glb) path.
bool IsGlbPath(const std::string& path);

// Where a glTF's external files (buffers and images given by a URI that is not a data URI)
// may be read from. `root` unset: anywhere (a user's own files, offline). Set: each must
// resolve, symlinks followed, to a file inside that folder (the service's --scene-root);
// set to an empty path: none at all (an uploaded .glb must hold everything it uses). A URI
// that leads elsewhere fails the load, naming it.
//
// `maxTriangles` and `maxBufferBytes` (0: none): what the file declares (its accessors'
// counts times the nodes that place each mesh, its buffers' byteLength) is checked against
// them before any buffer is read or allocated; past either, GltfLimitError.
struct GltfFiles {
    std::optional<std::filesystem::path> root;
    size_t maxTriangles = 0;
    uint64_t maxBufferBytes = 0;
};

// A file that declares more than GltfFiles allows.
class GltfLimitError : public Error {
  public:
    using Error::Error;
};

// Reads a .gltf/.glb file into a tinygltf model; throws penumbra::Error naming the file.
void ReadGltfModel(const std::string& path, tinygltf::Model* model, const GltfFiles& files = {});

// Writes `model` to `path`: .gltf (JSON, its one buffer embedded as a data URI, every image
// in that buffer) or .glb (every buffer and image in the one BIN chunk), in a form the Khronos
// validator accepts. tinygltf alone writes a .glb's second buffer and its images as data URIs and
// an infinite perspective camera as "zfar": 0; here the buffers are merged into one, images given
// by URI (relative to `inputDir`, or data URIs) are moved into buffer views, and a zfar of 0 is
// left out. Throws penumbra::Error when an image cannot be read or the file cannot be written.
void WriteGltfModel(tinygltf::Model model, const std::string& path,
                    const std::string& inputDir = ".");

// Loads `path`, its external files confined as `files` says. Throws penumbra::Error for
// unreadable, malformed or unsupported input, or a file outside the confinement.
Scene LoadGltf(const std::string& path, const GltfFiles& files = {});

// sRGB-encoded 8-bit value to linear [0, 1].
float SrgbToLinear(float encoded);

}  // namespace penumbra
