// `penumbra bake` as a real process: JSON and glTF outputs on the bundled Cornell box,
// and clear errors with exit code 1 for bad input.
#include <gtest/gtest.h>
#include <tiny_gltf.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "base/image.h"
#include "clutter_scenes.h"
#include "gpu/context.h"
#include "output/irradiance_writer.h"
#include "scene/scene_builder.h"
#include "scene/sun_sky.h"
#include "test_util.h"

namespace penumbra {
namespace {

const std::string kCornell = std::string(PENUMBRA_SOURCE_DIR) + "/scenes/cornell-box.gltf";
using testing::Execute;
using testing::ProcessResult;

// Bakes the Cornell box to `name`.json with `options`; the output must parse.
struct JsonBake {
    ProcessResult run;
    nlohmann::json json;
};
JsonBake BakeJson(const std::string& name, const std::string& options) {
    auto out = testing::TempDir(name) / "cb.json";
    JsonBake b{Execute("bake " + kCornell + " -o " + out.string() + " " + options), {}};
    if (b.run.exitCode == 0) {
        std::ifstream in(out);
        b.json = nlohmann::json::parse(in);
    }
    return b;
}

TEST(BakeCli, WritesJsonWithStatsInInputVertexOrder) {
    auto [r, j] =
        BakeJson("bake-json",
                 "--solver antiradiance --bins 64 --iterations 4 --element-size 0.08 --device cpu");
    ASSERT_EQ(r.exitCode, 0) << r.output;
    EXPECT_EQ(j["solver"], "antiradiance");
    EXPECT_EQ(j["channel"], "indirect");
    EXPECT_NE(j["units"].get<std::string>().find("lux"), std::string::npos);
    for (const char* key : {"elements", "links", "bins", "iterations", "link_build_seconds",
                            "device", "ms_per_iteration", "passes"})
        EXPECT_TRUE(j["stats"].contains(key)) << key;
    EXPECT_EQ(j["stats"]["bins"], 64);
    EXPECT_EQ(j["stats"]["iterations"], 4);
    EXPECT_EQ(j["stats"]["device"], "cpu");
    EXPECT_TRUE(j["stats"]["passes"].contains("global_ms_per_iteration"));
    ASSERT_EQ(j["primitives"].size(), 8u);  // one per node: materials differ by node
    // The floor is a 8 × 8 tile grid: 81 vertices. The ones under the blocks get no light
    // (never negative); the others are lit from the ceiling light.
    const auto& floor = j["primitives"][0];
    EXPECT_EQ(floor["node"], "floor");
    ASSERT_EQ(floor["irradiance"].size(), 81u);
    int lit = 0;
    for (const auto& v : floor["irradiance"]) {
        EXPECT_GE(v[0].get<double>(), 0.0);
        lit += v[0].get<double>() > 0.0;
    }
    EXPECT_GT(lit, 60);
}

// glTF out: the irradiance in _IRRADIANCE (float lux, as the JSON has it) on every primitive,
// a display COLOR_0 in [0, 1] unless --color0 none, everything in the one BIN chunk.
TEST(BakeCli, WritesGlbWithIrradiancePerPrimitive) {
    const auto dir = testing::TempDir("bake-glb");
    for (const std::string color0 : {"tonemapped", "none"}) {
        const std::string out = (dir / ("lit-" + color0 + ".glb")).string();
        ProcessResult r = Execute("bake " + kCornell + " -o " + out + " --color0 " + color0 +
                                  " --iterations 2 --element-size 0.1 --device cpu -q");
        ASSERT_EQ(r.exitCode, 0) << r.output;
        tinygltf::Model model;
        tinygltf::TinyGLTF io;
        std::string err, warn;
        ASSERT_TRUE(io.LoadBinaryFromFile(&model, &err, &warn, out)) << err;
        EXPECT_EQ(model.buffers.size(), 1u);
        EXPECT_TRUE(model.buffers[0].uri.empty());
        float brightest = 0.0f, highest = 0.0f;
        for (const auto& mesh : model.meshes)
            for (const auto& prim : mesh.primitives) {
                ASSERT_TRUE(prim.attributes.count("_IRRADIANCE")) << mesh.name;
                const auto& e = model.accessors[prim.attributes.at("_IRRADIANCE")];
                const auto& pos = model.accessors[prim.attributes.at("POSITION")];
                EXPECT_EQ(e.count, pos.count) << mesh.name;
                EXPECT_EQ(e.type, TINYGLTF_TYPE_VEC3);
                EXPECT_EQ(e.componentType, TINYGLTF_COMPONENT_TYPE_FLOAT);
                brightest = std::max(brightest, float(e.maxValues.at(1)));
                EXPECT_EQ(prim.attributes.count("COLOR_0"), color0 == "none" ? 0u : 1u);
                if (!prim.attributes.count("COLOR_0")) continue;
                const auto& c = model.accessors[prim.attributes.at("COLOR_0")];
                EXPECT_EQ(c.count, pos.count);
                for (double v : c.maxValues) highest = std::max(highest, float(v));
                for (double v : c.minValues) EXPECT_GE(v, 0.0);
            }
        EXPECT_GT(brightest, 1.0f);  // lux, not a colour
        if (color0 == "tonemapped") {
            EXPECT_LE(highest, 1.0f);
            EXPECT_GT(highest, 0.5f);
        }
    }
    ProcessResult bad = Execute("bake " + kCornell + " -o " + (dir / "x.glb").string() +
                                " --color0 hdr --device cpu -q");
    EXPECT_NE(bad.exitCode, 0);
    EXPECT_NE(bad.output.find("--color0 must be none or tonemapped"), std::string::npos)
        << bad.output;
}

// The Khronos glTF validator (npm gltf-validator, installed by `make check`) on what bake
// writes for every bundled scene, binary and JSON: no error, no warning.
TEST(BakeCli, GltfOutputPassesTheKhronosValidator) {
    const std::string tools = std::string(PENUMBRA_SOURCE_DIR) + "/tests/tools";
    ASSERT_TRUE(std::filesystem::exists(tools + "/node_modules/gltf-validator"))
        << "the validator is not installed: run scripts/install-deps.sh (make check does)";
    const auto dir = testing::TempDir("bake-validate");
    std::vector<std::string> inputs;
    for (const char* name :
         {"cornell-box", "blocker", "maze", "office", "glossy-box", "morph-room"})
        inputs.push_back(std::string(PENUMBRA_SOURCE_DIR) + "/scenes/" + name + ".gltf");
    // Issue 62: a .gltf whose texture is a file beside it, written to another folder, keeps
    // its image (Debian's assimp-testmodels, which install-deps installs).
    const std::string textured = "/usr/share/assimp/models/glTF2/BoxTextured-glTF/BoxTextured.gltf";
    if (std::filesystem::exists(textured)) inputs.push_back(textured);
    for (const std::string& input : inputs) {
        const std::string name = std::filesystem::path(input).stem().string();
        for (const char* ext : {".glb", ".gltf"}) {
            const std::string out = (dir / (name + ext)).string();
            ProcessResult r = Execute("bake " + input + " -o " + out +
                                      " --gather off --direct-rays 0 --iterations 1 "
                                      "--element-size 0.5 --device cpu -q");
            ASSERT_EQ(r.exitCode, 0) << r.output;
            FILE* pipe =
                popen(("node " + tools + "/validate_gltf.js " + out + " 2>&1").c_str(), "r");
            ASSERT_NE(pipe, nullptr);
            std::string report;
            std::array<char, 4096> buf;
            while (size_t n = fread(buf.data(), 1, buf.size(), pipe)) report.append(buf.data(), n);
            const int status = pclose(pipe);
            EXPECT_EQ(WIFEXITED(status) ? WEXITSTATUS(status) : -1, 0) << out << ":\n" << report;
            const auto j = nlohmann::json::parse(report, nullptr, false);
            ASSERT_FALSE(j.is_discarded()) << report;
            EXPECT_EQ(j["errors"], 0) << out << ":\n" << report;
            EXPECT_EQ(j["warnings"], 0) << out << ":\n" << report;
        }
    }
}

// Issue 62, refined output for coarse meshes: a 2 m floor of two triangles under a lamp 0.5 m
// above its middle. At its four corners the light's pool cannot show; with --refine 0.1 the
// output carries the subdivided floor, every edge at most 0.1 m, each vertex lit as the
// point light's closed form (I h / d³) says, in the glTF (which passes the validator) as in
// the JSON, and the reference refines the same way so that `compare` pairs them.
TEST(BakeCli, RefinedOutputShowsTheLightAcrossACoarseMesh) {
    auto dir = testing::TempDir("refine");
    SceneBuilder b;
    b.AddQuad("floor", b.AddMaterial("grey", glm::vec3(0.5f)), {-1, 0, -1}, {1, 0, -1}, {1, 0, 1},
              {-1, 0, 1}, {0, 1, 0}, 1);
    PunctualLight lamp;
    lamp.name = "lamp";
    lamp.intensity = 100.0f;
    lamp.position = {0.0f, 0.5f, 0.0f};
    b.AddLight(lamp);
    const std::string scene = (dir / "floor.gltf").string();
    b.WriteGltf(scene);
    auto bake = [&](const std::string& out, const std::string& options) {
        return Execute("bake " + scene + " -o " + (dir / out).string() +
                       " --device cpu --channel direct -q " + options);
    };
    ProcessResult coarse = bake("coarse.json", "");
    ASSERT_EQ(coarse.exitCode, 0) << coarse.output;
    const auto coarseJson = nlohmann::json::parse(std::ifstream(dir / "coarse.json"));
    EXPECT_EQ(coarseJson["primitives"][0]["irradiance"].size(), 4u);
    EXPECT_FALSE(coarseJson["primitives"][0].contains("refined"));

    ProcessResult fine = bake("fine.json", "--refine 0.1");
    ASSERT_EQ(fine.exitCode, 0) << fine.output;
    const auto j = nlohmann::json::parse(std::ifstream(dir / "fine.json"));
    const auto& prim = j["primitives"][0];
    ASSERT_TRUE(prim.contains("refined")) << prim.dump().substr(0, 400);
    const auto& positions = prim["refined"]["positions"];
    const auto& indices = prim["refined"]["indices"];
    ASSERT_EQ(positions.size(), prim["irradiance"].size());
    EXPECT_GT(positions.size(), 400u);
    EXPECT_EQ(prim["refined"]["parent_triangles"].size() * 3, indices.size());
    auto at = [&](size_t i) {
        return glm::vec3(positions[i][0].get<float>(), positions[i][1].get<float>(),
                         positions[i][2].get<float>());
    };
    for (size_t t = 0; t < indices.size(); t += 3)
        for (int k = 0; k < 3; ++k)
            ASSERT_LE(glm::distance(at(indices[t + k]), at(indices[t + (k + 1) % 3])),
                      0.1f + 1e-5f);
    double lo = 1e30, hi = 0.0;
    for (size_t i = 0; i < positions.size(); ++i) {
        const glm::vec3 p = at(i);
        const double d = glm::distance(p, lamp.position);
        const double closed = 100.0 * 0.5 / (d * d * d);
        const double e = prim["irradiance"][i][1].get<double>();
        EXPECT_NEAR(e, closed, 0.01 * closed) << "vertex " << i << " at " << p.x << ", " << p.z;
        lo = std::min(lo, e), hi = std::max(hi, e);
    }
    EXPECT_GT(hi / lo, 8.0) << "the pool of light, from under the lamp to the corners";

    // The glTF: the refined floor, valid.
    ProcessResult glb = bake("fine.glb", "--refine 0.1");
    ASSERT_EQ(glb.exitCode, 0) << glb.output;
    tinygltf::Model model;
    tinygltf::TinyGLTF loader;
    std::string err, warn;
    ASSERT_TRUE(loader.LoadBinaryFromFile(&model, &err, &warn, (dir / "fine.glb").string())) << err;
    const auto& out = model.meshes[0].primitives[0];
    EXPECT_EQ(model.accessors[out.attributes.at("POSITION")].count, positions.size());
    EXPECT_EQ(model.accessors[out.attributes.at("_IRRADIANCE")].count, positions.size());
    EXPECT_EQ(model.accessors[out.indices].count, indices.size());
    const std::string tools = std::string(PENUMBRA_SOURCE_DIR) + "/tests/tools";
    ProcessResult valid = testing::Shell("node " + tools + "/validate_gltf.js " +
                                         (dir / "fine.glb").string() + " 2>&1");
    const auto report = nlohmann::json::parse(valid.output, nullptr, false);
    ASSERT_FALSE(report.is_discarded()) << valid.output;
    EXPECT_EQ(report["errors"], 0) << valid.output;

    // The reference refines alike: compare pairs them vertex by vertex.
    ProcessResult ref = Execute("reference " + scene + " -o " + (dir / "ref.json").string() +
                                " --channel direct --samples 4 -q --refine 0.1");
    ASSERT_EQ(ref.exitCode, 0) << ref.output;
    ProcessResult cmp = Execute("compare " + (dir / "fine.json").string() + " " +
                                (dir / "ref.json").string() + " --max-rmse 0.02");
    EXPECT_EQ(cmp.exitCode, 0) << cmp.output;
    // The glTF's own _IRRADIANCE reads as lighting: compared, and drawn on its refined mesh.
    ProcessResult fromGlb = Execute("compare " + (dir / "fine.glb").string() + " " +
                                    (dir / "ref.json").string() + " --max-rmse 0.02");
    EXPECT_EQ(fromGlb.exitCode, 0) << fromGlb.output;
    ProcessResult drawn = Execute("render " + (dir / "fine.glb").string() + " --lighting " +
                                  (dir / "fine.glb").string() + " --mesh input --size 64x48 -o " +
                                  (dir / "fine.png").string());
    EXPECT_EQ(drawn.exitCode, 0) << drawn.output;
    // A bad edge is refused by name.
    ProcessResult bad = bake("bad.json", "--refine -1");
    EXPECT_EQ(bad.exitCode, 2) << bad.output;
}

// `-o -`: the JSON on standard output, nothing else there (-q keeps stderr quiet too).
TEST(BakeCli, DashWritesJsonToStandardOutput) {
    ProcessResult r =
        Execute("bake " + kCornell + " -o - --iterations 1 --element-size 0.2 --device cpu -q");
    ASSERT_EQ(r.exitCode, 0) << r.output;
    const auto j = nlohmann::json::parse(r.output, nullptr, false);
    ASSERT_FALSE(j.is_discarded()) << r.output.substr(0, 400);
    EXPECT_EQ(j["primitives"].size(), 8u);
    EXPECT_EQ(j["units"], kIrradianceUnits);
}

TEST(BakeCli, LavapipeDeviceRuns) {
    auto [r, j] = BakeJson("bake-lvp",
                           "--iterations 1 --element-size 0.15 --device lavapipe "
                           "--validation");
    ASSERT_EQ(r.exitCode, 0) << r.output;
    EXPECT_NE(j["stats"]["device"].get<std::string>().find("vulkan:"), std::string::npos);
}

TEST(BakeCli, AutoDevicePicksCpuUnlessARealGpuExists) {
    auto [r, j] = BakeJson("bake-auto", "--iterations 1 --element-size 0.15 -q");
    ASSERT_EQ(r.exitCode, 0) << r.output;
    std::string device = j["stats"]["device"];
    if (gpu::FindRealGpu(nullptr))
        EXPECT_EQ(device.rfind("vulkan:", 0), 0u) << device;
    else
        EXPECT_EQ(device, "cpu") << "lavapipe only: auto must take the native back end";
}

TEST(BakeCli, BadInputGivesExitCodeOneAndAMessage) {
    ProcessResult missing = Execute("bake /nonexistent.gltf -o /tmp/x.json");
    EXPECT_EQ(missing.exitCode, 1) << missing.output;
    EXPECT_NE(missing.output.find("/nonexistent.gltf: cannot open"), std::string::npos)
        << missing.output;
    EXPECT_EQ(missing.output.find("File open error"), std::string::npos) << missing.output;

    ProcessResult bins =
        Execute("bake " + kCornell + " -o /tmp/x.json --solver antiradiance --bins 5");
    EXPECT_EQ(bins.exitCode, 1) << bins.output;
    EXPECT_NE(bins.output.find("bin count 5"), std::string::npos) << bins.output;
    // Another solver's option without --solver: the default (lightfield) does not take it,
    // and the message says whose it is.
    ProcessResult unnamed = Execute("bake " + kCornell + " -o /tmp/x.json --bins 64");
    EXPECT_EQ(unnamed.exitCode, 1) << unnamed.output;
    EXPECT_NE(unnamed.output.find("'bins' is an option of antiradiance and implicit: name that "
                                  "solver, e.g. --solver antiradiance"),
              std::string::npos)
        << unnamed.output;

    ProcessResult ext = Execute("bake " + kCornell + " -o /tmp/x.txt");
    EXPECT_EQ(ext.exitCode, 1) << ext.output;
    EXPECT_NE(ext.output.find(".json, .glb or .gltf"), std::string::npos) << ext.output;

    ProcessResult device = Execute("bake " + kCornell + " -o /tmp/x.json --device tpu");
    EXPECT_EQ(device.exitCode, 1) << device.output;
    EXPECT_NE(device.output.find("unknown device 'tpu'"), std::string::npos) << device.output;
    EXPECT_NE(device.output.rfind("penumbra: error:", 0), std::string::npos)
        << "the message is the first line: " << device.output;
}

// A scene that nothing lights bakes (to zeros) with a warning that says why, even with -q.
TEST(BakeCli, AnUnlitSceneGetsAWarning) {
    auto dir = testing::TempDir("unlit");
    SceneBuilder b;
    b.AddQuad("floor", b.AddMaterial("grey", glm::vec3(0.5f)), {-1, 0, -1}, {1, 0, -1}, {1, 0, 1},
              {-1, 0, 1}, {0, 1, 0});
    b.WriteGltf((dir / "dark.gltf").string());
    ProcessResult r = Execute("bake " + (dir / "dark.gltf").string() + " -o " +
                              (dir / "x.json").string() + " -q");
    EXPECT_EQ(r.exitCode, 0) << r.output;
    EXPECT_NE(r.output.find("warning: " + (dir / "dark.gltf").string() + ": no light"),
              std::string::npos)
        << r.output;
    const nlohmann::json j = nlohmann::json::parse(std::ifstream(dir / "x.json"));
    ASSERT_EQ(j["warnings"].size(), 1u) << j["warnings"].dump();
    EXPECT_NE(j["warnings"][0].get<std::string>().find("no light"), std::string::npos);
    ProcessResult lit = Execute("bake " + kCornell + " -o " + (dir / "y.json").string() + " -q");
    EXPECT_EQ(lit.output.find("warning"), std::string::npos) << lit.output;
    EXPECT_TRUE(nlohmann::json::parse(std::ifstream(dir / "y.json"))["warnings"].empty());
}

// Usage errors exit 2 with one line (a typo'd command gets the nearest one); --version.
TEST(BakeCli, UsageErrorsExitTwoAndNameTheNearestCommand) {
    ProcessResult typo = Execute("bak " + kCornell);
    EXPECT_EQ(typo.exitCode, 2) << typo.output;
    EXPECT_NE(typo.output.find("unknown command 'bak'; did you mean 'bake'?"), std::string::npos)
        << typo.output;
    ProcessResult bins = Execute("bake " + kCornell + " -o /tmp/x.json --bins many");
    EXPECT_EQ(bins.exitCode, 2) << bins.output;
    EXPECT_NE(bins.output.find("--bins"), std::string::npos) << bins.output;
    ProcessResult none = Execute("");
    EXPECT_EQ(none.exitCode, 2) << none.output;
    ProcessResult version = Execute("--version");
    EXPECT_EQ(version.exitCode, 0) << version.output;
    EXPECT_EQ(version.output.rfind("penumbra ", 0), 0u) << version.output;
}

}  // namespace
}  // namespace penumbra

namespace penumbra {
namespace {

// `--environment` and `--environment-color`: the Cornell box is open at the front, so a sky
// adds light; stats name the sky; a bad sky file fails with exit code 1 and its name.
TEST(BakeCli, EnvironmentLightsTheSceneThroughItsOpening) {
    const std::string base =
        "--solver antiradiance --bins 64 --iterations 4 --element-size 0.1 --device cpu";
    auto dark = BakeJson("bake-nosky", base);
    ASSERT_EQ(dark.run.exitCode, 0) << dark.run.output;
    EXPECT_FALSE(dark.json["stats"].contains("environment"));

    auto dir = testing::TempDir("sky-file");
    Image sky(32, 16);
    for (auto& p : sky.pixels) p = glm::vec3(0.5f);
    WriteExr((dir / "sky.exr").string(), sky);
    auto lit = BakeJson("bake-sky", base + " --environment " + (dir / "sky.exr").string() +
                                        " --environment-intensity 2 --environment-rotation 45");
    ASSERT_EQ(lit.run.exitCode, 0) << lit.run.output;
    const auto& env = lit.json["stats"]["environment"];
    EXPECT_NE(env["source"].get<std::string>().find("sky.exr"), std::string::npos);
    EXPECT_EQ(env["intensity"], 2.0);
    EXPECT_NEAR(env["rotation_degrees"].get<double>(), 45.0, 1e-3);
    EXPECT_GT(lit.json["stats"]["two_sided_elements"].get<int>(), 0);
    // A constant sky of the same radiance gives the same light.
    auto constant = BakeJson("bake-constant", base + " --environment-color 1,1,1");
    ASSERT_EQ(constant.run.exitCode, 0) << constant.run.output;
    double sumDark = 0, sumLit = 0, sumConstant = 0;
    const auto& floorDark = dark.json["primitives"][0]["irradiance"];
    for (size_t i = 0; i < floorDark.size(); ++i) {
        sumDark += floorDark[i][0].get<double>();
        sumLit += lit.json["primitives"][0]["irradiance"][i][0].get<double>();
        sumConstant += constant.json["primitives"][0]["irradiance"][i][0].get<double>();
    }
    EXPECT_GT(sumLit, sumDark * 1.05);
    EXPECT_NEAR(sumConstant, sumLit, 1e-3 * sumLit);
    // A flat map has no sun; a map with one sends rays to it in the first shot.
    EXPECT_EQ(lit.json["stats"]["emitter_direct"]["sun_rays"], 0);
    WriteExr((dir / "sunny.exr").string(),
             testing::SunnyMap(64, glm::normalize(glm::vec3(0, 0.3f, -1)), 0.1f, 500.0f, 0.5f));
    auto sunny =
        BakeJson("bake-sunny", "--device cpu --environment " + (dir / "sunny.exr").string());
    ASSERT_EQ(sunny.run.exitCode, 0) << sunny.run.output;
    EXPECT_EQ(sunny.json["stats"]["emitter_direct"]["sun_rays"], 128);
    EXPECT_NE(sunny.run.output.find("128 to the sky's sun"), std::string::npos) << sunny.run.output;

    auto missing = BakeJson("bake-sky-missing", base + " --environment /nonexistent/sky.exr");
    EXPECT_EQ(missing.run.exitCode, 1);
    EXPECT_NE(missing.run.output.find("/nonexistent/sky.exr"), std::string::npos)
        << missing.run.output;
    auto both = BakeJson("bake-sky-both", base + " --environment a.exr --environment-color 1,1,1");
    EXPECT_NE(both.run.exitCode, 0);
    auto negative = BakeJson("bake-sky-neg", base + " --environment-color 1,-1,1");
    EXPECT_EQ(negative.run.exitCode, 1) << negative.run.output;
}

// Issue 62: surfaces that pass light. A floor under a box of glass (no bottom) sees the sky and
// the sun only through one pane: E = π L T under a constant sky L, E = lux · sin(elevation) · T
// in the sun, where T is the glass's transmittance: 1 − α for alphaMode BLEND, the base colour
// for KHR_materials_transmission (black glass: it reflects nothing itself). The default bake and
// the reference both.
TEST(BakeCli, GlassLetsTheSkyAndTheSunThroughTinted) {
    auto dir = testing::TempDir("glass");
    SceneBuilder b;
    b.AddQuad("floor", b.AddMaterial("grey", glm::vec3(0.5f)), {-1, 0, -1}, {1, 0, -1}, {1, 0, 1},
              {-1, 0, 1}, {0, 1, 0}, 4);
    b.AddBox("glass", b.AddMaterial("glass", glm::vec3(0.0f)), {0, 0.6f, 0}, {2.4f, 1.2f, 2.4f},
             0.0f, false);
    b.WriteGltf((dir / "plain.gltf").string());
    nlohmann::json doc = nlohmann::json::parse(std::ifstream(dir / "plain.gltf"));
    for (auto& m : doc["materials"])
        if (m["name"] == "glass") {
            m["alphaMode"] = "BLEND";
            m["pbrMetallicRoughness"]["baseColorFactor"] = {0.0, 0.0, 0.0, 0.2};
        }
    std::ofstream(dir / "blend.gltf") << doc.dump();
    for (auto& m : doc["materials"])
        if (m["name"] == "glass") {
            m.erase("alphaMode");
            m["pbrMetallicRoughness"]["baseColorFactor"] = {1.0, 0.5, 0.25, 1.0};
            m["extensions"]["KHR_materials_transmission"]["transmissionFactor"] = 1.0;
        }
    doc["extensionsUsed"] = {"KHR_materials_transmission"};
    std::ofstream(dir / "tinted.gltf") << doc.dump();
    for (auto& m : doc["materials"])
        if (m["name"] == "glass")
            m["extensions"]["KHR_materials_transmission"]["transmissionFactor"] = 0.0,
            m["alphaMode"] = "BLEND",
            m["pbrMetallicRoughness"]["baseColorFactor"] = {0.0, 0.0, 0.0, 0.0};
    std::ofstream(dir / "open.gltf") << doc.dump();  // the glass wholly transparent: T = 1

    WriteExr(
        (dir / "sunny.exr").string(),
        testing::SunnyMap(64, glm::normalize(glm::vec3(0.3f, 1.0f, -0.2f)), 0.1f, 500.0f, 0.5f));
    auto floorOf = [&](const std::string& command, const std::string& scene) {
        const auto out = dir / (scene + ".json");
        const auto run =
            Execute(command + " " + (dir / (scene + ".gltf")).string() + " -o " + out.string());
        EXPECT_EQ(run.exitCode, 0) << run.output;
        EXPECT_NE(run.output.find("pass light"), std::string::npos) << run.output;
        std::vector<glm::vec3> floor;
        if (run.exitCode != 0) return floor;
        for (const auto& p : nlohmann::json::parse(std::ifstream(out))["primitives"])
            if (p["node"] == "floor")
                for (const auto& e : p["irradiance"])
                    floor.emplace_back(e[0].get<float>(), e[1].get<float>(), e[2].get<float>());
        return floor;
    };
    const float pi = 3.14159265f;
    for (const std::string& command :
         {std::string("bake --device cpu"), std::string("reference --samples 256")}) {
        for (const glm::vec3& e :
             floorOf(command + " --environment-color 1,1,1 --channel total", "blend"))
            for (int c = 0; c < 3; ++c) EXPECT_NEAR(e[c], pi * 0.8f, 0.03f * pi) << command;
        const glm::vec3 tint(1.0f, 0.5f, 0.25f);
        for (const glm::vec3& e :
             floorOf(command + " --environment-color 1,1,1 --channel total", "tinted"))
            for (int c = 0; c < 3; ++c) EXPECT_NEAR(e[c], pi * tint[c], 0.03f * pi) << command;
        // A sky map with a sun in it (the first shot's rays to the sun, the gather's to the
        // rest): through the tinted glass, T times what the open box lets in.
        const std::string map =
            " --environment " + (dir / "sunny.exr").string() + " --channel total";
        const std::vector<glm::vec3> open = floorOf(command + map, "open"),
                                     tinted = floorOf(command + map, "tinted");
        ASSERT_EQ(open.size(), tinted.size());
        for (size_t i = 0; i < open.size(); ++i)
            for (int c = 0; c < 3; ++c)
                EXPECT_NEAR(tinted[i][c], tint[c] * open[i][c], 0.03f * open[i][c]) << command;
        // The sun at 60°: 1,000 lux · sin 60° through the pane.
        for (const glm::vec3& e : floorOf(command + " --sun 30,60,1000 --channel direct", "tinted"))
            for (int c = 0; c < 3; ++c) EXPECT_NEAR(e[c], 866.0f * tint[c], 5.0f) << command;
    }
}

// Issue 62: `--sun AZIMUTH,ELEVATION,LUX` and `--sky clear` on an open plane facing up: the sun
// gives E = lux · sin(elevation), the clear sky its integral ∫ L cos θ dω over the map.
TEST(BakeCli, SunAndClearSkyLightAnOpenPlaneAsTheirClosedForms) {
    auto dir = testing::TempDir("sun-sky");
    SceneBuilder b;
    b.AddQuad("ground", b.AddMaterial("grey", glm::vec3(0.5f)), {-5, 0, -5}, {5, 0, -5}, {5, 0, 5},
              {-5, 0, 5}, {0, 1, 0}, 2);
    b.WriteGltf((dir / "ground.gltf").string());
    auto bake = [&](const std::string& name, const std::string& options) {
        JsonBake r{Execute("bake " + (dir / "ground.gltf").string() + " -o " +
                           (dir / (name + ".json")).string() + " --device cpu " + options),
                   {}};
        if (r.run.exitCode == 0)
            r.json = nlohmann::json::parse(std::ifstream(dir / (name + ".json")));
        return r;
    };
    auto sun = bake("sun", "--sun 135,30,80000 --channel direct");
    ASSERT_EQ(sun.run.exitCode, 0) << sun.run.output;
    for (const auto& e : sun.json["primitives"][0]["irradiance"])
        EXPECT_NEAR(e[1].get<double>(), 40000.0, 4.0);

    // The sky's irradiance on the plane by quadrature over the map's pixels.
    const Environment sky = ClearSky({135.0f, 30.0f}, 3.0f, 256);
    glm::dvec3 skyE(0.0);
    const int w = sky.image->width, h = sky.image->height;
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const glm::vec3 d = EquirectDirection((x + 0.5f) / w, (y + 0.5f) / h);
            const double solidAngle =
                (2.0 * M_PI / w) * (M_PI / h) * std::sin(M_PI * (y + 0.5) / h);
            skyE += glm::dvec3(sky.image->At(x, y)) * double(std::max(d.y, 0.0f)) * solidAngle;
        }
    EXPECT_GT(skyE.y, 5000.0);  // a clear day's sky: thousands of lux
    auto both = bake("sun-sky", "--sun 135,30,80000 --sky clear --channel total");
    ASSERT_EQ(both.run.exitCode, 0) << both.run.output;
    EXPECT_NE(both.json["stats"]["environment"]["source"].get<std::string>().find("Preetham"),
              std::string::npos);
    for (const auto& e : both.json["primitives"][0]["irradiance"])
        for (int c = 0; c < 3; ++c)
            EXPECT_NEAR(e[c].get<double>(), 40000.0 + skyE[c], 0.02 * (40000.0 + skyE[c])) << c;

    // A clear sky needs a sun; a turbidity outside the model's range is refused by name.
    EXPECT_EQ(bake("no-sun", "--sky clear").run.exitCode, 2);
    auto hazy = bake("hazy", "--sun 0,30,1000 --sky clear --turbidity 20");
    EXPECT_EQ(hazy.run.exitCode, 1);
    EXPECT_NE(hazy.run.output.find("turbidity"), std::string::npos) << hazy.run.output;
    auto below = bake("below", "--sun 0,-10,1000");
    EXPECT_EQ(below.run.exitCode, 1);
    EXPECT_NE(below.run.output.find("elevation"), std::string::npos) << below.run.output;
}

}  // namespace
}  // namespace penumbra

namespace penumbra {
namespace {

using testing::Execute;
using testing::ProcessResult;

// Issues 18 and 61: a diverged solution is never written, and never the answer. The paper's
// symmetric scheme diverges on a row of ten boxes 2 cm apart; bake says which scene and
// iteration, goes on with the light-field solver (FallbackSettings) and writes its answer,
// its stats naming the solver it came from.
TEST(BakeCli, DivergedSolutionGoesOnWithTheFallbackSolver) {
    const auto dir = testing::TempDir("bake-diverged");
    const std::string scene = (dir / "row.gltf").string(), out = (dir / "row.json").string();
    scenes::BoxRow(10, 0.02f).WriteGltf(scene);
    ProcessResult r = Execute(
        "bake " + scene + " -o " + out +
        " --solver antiradiance --scheme symmetric --bins 64 --element-size 0.12 --iterations 40 "
        "--gather off --device cpu -q");
    EXPECT_EQ(r.exitCode, 0) << r.output;
    EXPECT_NE(r.output.find(scene + ": the antiradiance solution diverged at iteration "),
              std::string::npos)
        << r.output;
    EXPECT_NE(r.output.find("going on with the lightfield solver"), std::string::npos) << r.output;
    ASSERT_TRUE(std::filesystem::exists(out));
    const nlohmann::json j = nlohmann::json::parse(std::ifstream(out));
    EXPECT_EQ(j["solver"], "lightfield") << j["stats"].dump();
    EXPECT_EQ(j["stats"]["fallback"]["from"], "antiradiance") << j["stats"].dump();
    EXPECT_FALSE(j["stats"].contains("divergence")) << j["stats"].dump();
    std::filesystem::remove(out);
    // The adaptive scheme settles the same scene.
    ProcessResult ok = Execute(
        "bake " + scene + " -o " + out +
        " --solver antiradiance --scheme adaptive --bins 64 --element-size 0.12 --iterations 60 "
        "--device cpu -q");
    EXPECT_EQ(ok.exitCode, 0) << ok.output;
    EXPECT_TRUE(std::filesystem::exists(out));
}

}  // namespace
}  // namespace penumbra
