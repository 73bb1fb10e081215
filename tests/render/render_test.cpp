// `penumbra render` (issue 5): images of the stated size in EXR (read back with OpenEXR) and
// PNG, from the glTF camera of the Cornell box; the heat map of a file against itself is all
// zero error; the raster matches the camera (a floor seen from above fills the frame); bad
// options fail with exit code 1.
#include <gtest/gtest.h>
#include <stb/stb_image.h>

#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>

#include "base/image.h"
#include "render/renderer.h"
#include "scene/gltf_loader.h"
#include "test_util.h"

namespace penumbra {
namespace {

using testing::Execute;
const std::string kCornell = std::string(PENUMBRA_SOURCE_DIR) + "/scenes/cornell-box.gltf";

TEST(Render, WritesExrAndPngOfTheStatedSize) {
    auto dir = testing::TempDir("render");
    std::string exr = (dir / "cb.exr").string(), png = (dir / "cb.png").string();
    auto r = Execute("render " + kCornell + " -o " + exr + " -o " + png +
                     " --size 96x64 --iterations 2 --element-size 0.1 --device cpu "
                     "--render-device lavapipe --validation");
    ASSERT_EQ(r.exitCode, 0) << r.output;
    EXPECT_NE(r.output.find("camera 'camera'"), std::string::npos) << r.output;  // the file's
    Image image = ReadExr(exr);
    ASSERT_EQ(image.width, 96);
    ASSERT_EQ(image.height, 64);
    // The back wall fills the centre (lit, white-ish); the ceiling light is the brightest.
    glm::vec3 centre = image.At(48, 32);
    EXPECT_GT(centre.x, 0.0f);
    float brightest = 0.0f;
    int brightestY = 0;
    for (int y = 0; y < image.height; ++y)
        for (int x = 0; x < image.width; ++x)
            if (image.At(x, y).y > brightest) brightest = image.At(x, y).y, brightestY = y;
    EXPECT_LT(brightestY, 16) << "the light panel is at the top of the picture";
    // Red wall on the left, green on the right (as in the published view).
    // The aspect is 3:2 and the fov vertical: at mid-height the red wall spans about x 18…34,
    // the green one x 66…78. The light is warm (17, 12, 4 nits), so the green wall's G/R is
    // about 2 (0.45 · 12 against 0.14 · 17 and its bounces), not more.
    glm::vec3 left = image.At(24, 32), right = image.At(70, 32);
    EXPECT_GT(left.x, 2.0f * left.y);
    EXPECT_GT(right.y, 1.5f * right.x);

    int w = 0, h = 0, n = 0;
    ASSERT_TRUE(stbi_info(png.c_str(), &w, &h, &n)) << "not a PNG";
    EXPECT_EQ(w, 96);
    EXPECT_EQ(h, 64);
    EXPECT_EQ(n, 3);
}

// Issue 62: with --lighting the light comes from the file: a scene without lights of its own
// is no concern, and render does not warn "no light".
TEST(Render, LightingFromAFileNeedsNoLightsInTheScene) {
    auto dir = testing::TempDir("render-unlit");
    const std::string json = (dir / "lit.json").string(), dark = (dir / "dark.gltf").string();
    auto bake = Execute("bake " + kCornell + " -o " + json +
                        " --iterations 2 --element-size 0.2 --device cpu -q");
    ASSERT_EQ(bake.exitCode, 0) << bake.output;
    nlohmann::json doc = nlohmann::json::parse(std::ifstream(kCornell));
    for (auto& m : doc["materials"]) m.erase("emissiveFactor");
    std::ofstream(dark) << doc.dump();
    auto unlit = Execute("bake " + dark + " -o " + (dir / "zero.json").string() +
                         " --iterations 1 --element-size 0.2 --device cpu -q");
    EXPECT_NE(unlit.output.find("no light"), std::string::npos) << unlit.output;
    auto r = Execute("render " + dark + " --lighting " + json + " -o " +
                     (dir / "lit.png").string() + " --size 32x32 --device cpu");
    ASSERT_EQ(r.exitCode, 0) << r.output;
    EXPECT_EQ(r.output.find("no light"), std::string::npos) << r.output;
}

TEST(Render, HeatMapOfAFileAgainstItselfShowsNoError) {
    auto dir = testing::TempDir("render-heat");
    std::string json = (dir / "lit.json").string(), png = (dir / "heat.exr").string();
    auto bake = Execute("bake " + kCornell + " -o " + json +
                        " --iterations 2 --element-size 0.1 --device cpu -q");
    ASSERT_EQ(bake.exitCode, 0) << bake.output;
    auto r = Execute("render " + kCornell + " --lighting " + json + " --compare " + json + " -o " +
                     png + " --size 48x48 --render-device lavapipe --validation");
    ASSERT_EQ(r.exitCode, 0) << r.output;
    Image heat = ReadExr(png);
    glm::vec3 zero = render::HeatColor(0.0f);
    int covered = 0;
    for (const glm::vec3& p : heat.pixels) {
        if (p == glm::vec3(0.0f)) continue;  // background or a surface's back
        ++covered;
        EXPECT_NEAR(p.x, zero.x, 2e-3f);
        EXPECT_NEAR(p.z, zero.z, 2e-3f);
    }
    EXPECT_GT(covered, 48 * 48 / 2);
}

// A 2 m white floor lit uniformly, seen straight down from 1 m with a 90° field of view:
// exactly the floor fills the frame and every pixel is ρE/π.
TEST(Render, CameraMatchesTheRaster) {
    SceneBuilder b;
    uint32_t white = b.AddMaterial("white", glm::vec3(0.5f));
    b.AddQuad("floor", white, {-1, 0, -1}, {1, 0, -1}, {1, 0, 1}, {-1, 0, 1}, {0, 1, 0}, 4);
    Scene scene = b.Build();
    std::vector<std::vector<glm::vec3>> e{
        std::vector<glm::vec3>(scene.primitives[0].positions.size(), glm::vec3(3.0f))};
    render::Mesh mesh = render::ShadedInputMesh(scene, e);
    Camera cam = render::ParseCamera("0,1,0,0,0,0,90");
    render::RenderSettings rs;
    rs.width = rs.height = 64;
    rs.lavapipe = true;
    rs.validation = true;
    render::RenderOutput out = render::Rasterize(mesh, cam, rs);
    for (const auto& m : out.validationMessages) ADD_FAILURE() << "validation: " << m;
    const float want = 0.5f * 3.0f / std::numbers::pi_v<float>;
    int lit = 0;
    for (const glm::vec3& p : out.image.pixels) lit += std::abs(p.x - want) < 1e-5f;
    // Pixel centres inside the frustum all land on the floor; the border row may miss.
    EXPECT_GE(lit, 62 * 62);
    // Looking at the floor from below: its back, black.
    render::RenderOutput below =
        render::Rasterize(mesh, render::ParseCamera("0,-1,0,0,0,0,90"), rs);
    for (const glm::vec3& p : below.image.pixels) EXPECT_EQ(p, glm::vec3(0.0f));
}

TEST(Render, BadOptionsFailClearly) {
    auto dir = testing::TempDir("render-bad");
    std::string out = (dir / "x.png").string();
    for (const auto& [options, message] : std::vector<std::pair<std::string, std::string>>{
             {"--size 0x10", "image size"},
             {"--size big", "--size"},
             {"--camera 1,2,3", "7 numbers"},
             {"--camera-name nope", "no perspective camera called 'nope'"},
             {"--lighting /nonexistent.json", "/nonexistent.json"}}) {
        auto r = Execute("render " + kCornell + " -o " + out + " --device cpu " +
                         "--iterations 0 --element-size 0.2 " + options);
        EXPECT_EQ(r.exitCode, 1) << options << "\n" << r.output;
        EXPECT_NE(r.output.find(message), std::string::npos) << options << "\n" << r.output;
    }
    auto r = Execute("render " + kCornell + " -o " + (dir / "x.jpg").string());
    EXPECT_EQ(r.exitCode, 1);
    EXPECT_NE(r.output.find(".exr or .png"), std::string::npos) << r.output;
}

// Issue 24: a full disk (files that are links to /dev/full) is an error with the reason,
// exit 1, for every kind of output; before, a PNG was written short and reported done.
TEST(Render, AFullDiskIsAnError) {
    auto dir = testing::TempDir("full-disk");
    for (const char* name : {"out.png", "out.exr", "out.json", "out.glb"})
        std::filesystem::create_symlink("/dev/full", dir / name);
    const std::string base = " --device cpu --iterations 1 --element-size 0.2 -q";
    for (const char* name : {"out.png", "out.exr"}) {
        auto r = Execute("render " + kCornell + " -o " + (dir / name).string() + base);
        EXPECT_EQ(r.exitCode, 1) << name << "\n" << r.output;
        EXPECT_NE(r.output.find("No space left on device"), std::string::npos) << name << "\n"
                                                                               << r.output;
    }
    for (const char* name : {"out.json", "out.glb"}) {
        auto r = Execute("bake " + kCornell + " -o " + (dir / name).string() + base);
        EXPECT_EQ(r.exitCode, 1) << name << "\n" << r.output;
        EXPECT_NE(r.output.find((dir / name).string()), std::string::npos) << name << "\n"
                                                                           << r.output;
    }
}

}  // namespace
}  // namespace penumbra
