// Writes the bundled scenes (tools/bundled_scenes.cpp) as glTF into a folder.
// Usage: make_scenes OUTDIR [--clutter]; --clutter writes the stability suite
// (tools/clutter_scenes.h) and the sunlit maze instead.
#include <cstdio>
#include <cstring>

#include "base/check.h"
#include "bundled_scenes.h"
#include "clutter_scenes.h"

int main(int argc, char** argv) {
    const bool clutter = argc == 3 && std::strcmp(argv[2], "--clutter") == 0;
    if (argc != 2 && !clutter) {
        std::fprintf(stderr, "usage: make_scenes OUTDIR [--clutter]\n");
        return 2;
    }
    try {
        if (clutter) {
            for (auto& s : penumbra::scenes::ClutterSuite()) {
                std::string path = std::string(argv[1]) + "/" + s.name;
                s.builder.WriteGltf(path);
                std::printf("wrote %s\n", path.c_str());
            }
            const std::string maze = std::string(argv[1]) + "/sunlit-maze.gltf";
            penumbra::scenes::SunlitMaze().WriteGltf(maze);
            std::printf("wrote %s\n", maze.c_str());
            return 0;
        }
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
