// Helpers shared by the tests: nearest-surfel lookup and scene files in a temp folder.
#pragma once

#include <cstdio>
#include <filesystem>
#include <glm/glm.hpp>
#include <string>
#include <vector>

#include "scene/surfels.h"

namespace penumbra::testing {

// Index of the surfel closest to `p` whose normal is within 30° of `normal`.
inline size_t NearestSurfel(const Surfels& s, glm::vec3 p, glm::vec3 normal) {
    size_t best = 0;
    float bestD = 1e30f;
    for (size_t i = 0; i < s.size(); ++i) {
        if (s.areas[i] <= 0.0f || glm::dot(s.normals[i], normal) < 0.866f) continue;
        float d = glm::length(s.positions[i] - p);
        if (d < bestD) bestD = d, best = i;
    }
    return best;
}

inline float Mean(glm::vec3 v) { return (v.x + v.y + v.z) / 3.0f; }

// A fresh temporary folder for one test.
inline std::filesystem::path TempDir(const std::string& name) {
    auto dir = std::filesystem::temp_directory_path() / ("penumbra-test-" + name);
    std::filesystem::remove_all(dir);
    std::filesystem::create_directories(dir);
    return dir;
}

}  // namespace penumbra::testing
