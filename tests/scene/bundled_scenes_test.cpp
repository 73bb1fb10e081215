// scenes/*.gltf are what tools/make_scenes writes: regenerate and compare byte for byte.
#include "bundled_scenes.h"

#include <gtest/gtest.h>

#include "test_util.h"

namespace penumbra {
namespace {

TEST(BundledScenes, CommittedFilesMatchTheGenerator) {
    auto dir = testing::TempDir("scenes");
    for (const auto& s : scenes::All()) {
        std::string fresh = (dir / s.file).string();
        s.make().WriteGltf(fresh);
        EXPECT_EQ(testing::ReadFile(fresh),
                  testing::ReadFile(std::string(PENUMBRA_SOURCE_DIR) + "/scenes/" + s.file))
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
