// Fuzz target: the environment map reader (OpenEXR through Imf, then the pixel checks of
// LoadEnvironment) and the sky sampler built on what it reads. Reading may fail with
// penumbra::Error; nothing may crash, leak or hang.
#include <cstdint>

#include "base/check.h"
#include "fuzz_util.h"
#include "scene/environment.h"

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
