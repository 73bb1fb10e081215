// scenes/*.gltf are what tools/make_scenes writes: regenerate and compare byte for byte.
#include "bundled_scenes.h"

#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

#include "test_util.h"

namespace penumbra {
namespace {

std::string Slurp(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
}

TEST(BundledScenes, CommittedFilesMatchTheGenerator) {
    auto dir = testing::TempDir("scenes");
    for (const auto& s : scenes::All()) {
        std::string fresh = (dir / s.file).string();
        s.make().WriteGltf(fresh);
        EXPECT_EQ(Slurp(fresh), Slurp(std::string(PENUMBRA_SOURCE_DIR) + "/scenes/" + s.file))
            << s.file << " differs from tools/bundled_scenes.cpp: run "
            << "build/tools/make_scenes scenes";
    }
}

TEST(BundledScenes, OfficeHasPaperScale) {
    Scene office = scenes::Office().Build();
    EXPECT_GT(office.TriangleCount(), 5000u);
    EXPECT_LT(office.TriangleCount(), 6200u);
}

}  // namespace
}  // namespace penumbra
