// Fuzz target: the glTF loader, as an uploaded scene reaches it (a file of the uploaded
// bytes): a binary .glb when the input starts with its magic, JSON .gltf otherwise. Loading
// may fail with penumbra::Error; nothing may crash, leak or hang.
#include <cstdint>
#include <cstring>

#include "base/check.h"
#include "fuzz_util.h"
#include "scene/gltf_loader.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    const bool binary = size >= 4 && std::memcmp(data, "glTF", 4) == 0;
    penumbra::fuzz::InputFile file(data, size, binary ? ".glb" : ".gltf");
    try {
        // As an upload is loaded: no external files.
        penumbra::LoadGltf(file.Path(), penumbra::GltfFiles{std::filesystem::path()});
    } catch (const penumbra::Error&) {
    }
    return 0;
}
