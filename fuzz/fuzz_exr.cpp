// Fuzz target: the environment map reader (OpenEXR through Imf, then the pixel checks of
// LoadEnvironment) and the sky sampler built on what it reads. Reading may fail with
// penumbra::Error; nothing may crash, leak or hang. OpenEXR's header size limit is lowered to
// 1024 a side: at the server's (16384) a header of a few bytes may declare an image whose
// line and compression buffers, hundreds of megabytes, are allocated and zeroed before its
// pixels are found missing (a tenth of a second an input, page faults); the checks are the
// same code either way.
#include <OpenEXR/ImfHeader.h>

#include <cstdint>

#include "base/check.h"
#include "fuzz_util.h"
#include "scene/environment.h"

extern "C" int LLVMFuzzerInitialize(int*, char***) {
    Imf::Header::setMaxImageSize(1024, 1024);
    Imf::Header::setMaxTileSize(1024, 1024);
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    penumbra::fuzz::InputFile file(data, size, ".exr");
    try {
        const penumbra::Environment sky = penumbra::LoadEnvironment(file.Path());
        const penumbra::SkyParts parts = penumbra::SplitSky(sky);
        float pdf;
        if (parts.Split()) parts.sampler.Sample({0.5f, 0.5f}, pdf);
    } catch (const penumbra::Error&) {
    }
    return 0;
}
