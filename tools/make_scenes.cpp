// Writes the bundled scenes (tools/bundled_scenes.cpp) as glTF into a folder.
// Usage: make_scenes OUTDIR
#include <cstdio>

#include "base/check.h"
#include "bundled_scenes.h"

int main(int argc, char** argv) {
    if (argc != 2) {
        std::fprintf(stderr, "usage: make_scenes OUTDIR\n");
        return 2;
    }
    try {
        for (const auto& s : penumbra::scenes::All()) {
            std::string path = std::string(argv[1]) + "/" + s.file;
            s.make().WriteGltf(path);
            std::printf("wrote %s\n", path.c_str());
        }
    } catch (const penumbra::Error& e) {
        std::fprintf(stderr, "make_scenes: %s\n", e.what());
        return 1;
    }
    return 0;
}
