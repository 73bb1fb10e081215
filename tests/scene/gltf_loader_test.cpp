// glTF loading: the bundled files, and broken files that must fail naming the file,
// the offending object and the reason.
#include "scene/gltf_loader.h"

#include <gtest/gtest.h>
#include <tiny_gltf.h>

#include <algorithm>
#include <cstring>
#include <fstream>
#include <glm/gtc/matrix_transform.hpp>
#include <iterator>
#include <limits>
#include <nlohmann/json.hpp>

#include "base/check.h"
#include "base/image.h"
#include "scene/solids.h"
#include "scene/surfels.h"
#include "test_util.h"

namespace penumbra {
namespace {

const std::string kCornell = std::string(PENUMBRA_SOURCE_DIR) + "/scenes/cornell-box.gltf";

TEST(GltfLoader, LoadsBundledCornellBox) {
    Scene scene = LoadGltf(kCornell);
    // Walls 8×8 tiles, ceiling pieces 6×6 and 3×3, the light 2×2, block faces 4×4.
    EXPECT_EQ(scene.TriangleCount(), 1020u);
    bool sawLight = false, sawTall = false;
    for (const auto& p : scene.primitives) {
        const Material& m = scene.materials[p.material];
        if (p.node == "ceiling_light") {
            sawLight = true;
            // emissiveFactor (1, 12/17, 4/17) × KHR_materials_emissive_strength 17.
            EXPECT_NEAR(m.emission.x, 17.0f, 1e-4f);
            EXPECT_NEAR(m.emission.y, 12.0f, 1e-4f);
            EXPECT_NEAR(m.emission.z, 4.0f, 1e-4f);
        }
        if (p.node == "tall_block") {
            sawTall = true;
            EXPECT_NEAR(m.albedo.x, 0.725f, 1e-6f);  // baseColor × (1 − metallic 0)
        }
        ASSERT_EQ(p.normals.size(), p.positions.size());
    }
    EXPECT_TRUE(sawLight);
    EXPECT_TRUE(sawTall);
    // Bounds 0.556 × 0.5488 × 0.5592 m: diagonal √0.9230 = 0.9607 m.
    EXPECT_NEAR(scene.Diameter(), 0.9607f, 1e-3f);
}

TEST(GltfLoader, RefinementKeepsInputVerticesAndArea) {
    Scene scene = LoadGltf(kCornell);
    Surfels s = RefineScene(scene, 0.05f);
    double area = 0.0, input = 0.0;
    for (float a : s.areas) area += a;
    for (const auto& p : scene.primitives)
        for (size_t t = 0; t < p.indices.size(); t += 3)
            input += 0.5 * glm::length(glm::cross(
                               p.positions[p.indices[t + 1]] - p.positions[p.indices[t]],
                               p.positions[p.indices[t + 2]] - p.positions[p.indices[t]]));
    EXPECT_NEAR(area, input, 1e-4 * input);
    for (size_t p = 0; p < scene.primitives.size(); ++p)
        for (size_t i = 0; i < scene.primitives[p].positions.size(); ++i)
            EXPECT_EQ(s.positions[s.firstSurfel[p] + i], scene.primitives[p].positions[i]);
    for (size_t t = 0; t < s.refinedTriangles.size(); t += 3)
        for (int k = 0; k < 3; ++k) {
            glm::vec3 e = s.positions[s.refinedTriangles[t + k]] -
                          s.positions[s.refinedTriangles[t + (k + 1) % 3]];
            ASSERT_LE(glm::length(e), 0.05f * 1.0001f);
        }
}

// Writes `doc` to a temp file and returns the message LoadGltf throws.
std::string LoadError(const nlohmann::json& doc, const std::string& name) {
    auto path = testing::TempDir("gltf") / name;
    std::ofstream(path) << doc.dump();
    try {
        LoadGltf(path.string());
    } catch (const Error& e) {
        return e.what();
    }
    return "(loaded without error)";
}

nlohmann::json Cornell() {
    std::ifstream in(kCornell);
    return nlohmann::json::parse(in);
}

// Appends to `doc` a float VEC2 accessor over `uv` (two floats a vertex), its bytes in the
// file DIR/NAME; returns the accessor's index.
size_t AddUvAccessor(nlohmann::json& doc, const std::filesystem::path& dir, const std::string& name,
                     const std::vector<float>& uv) {
    std::ofstream(dir / name, std::ios::binary)
        .write(reinterpret_cast<const char*>(uv.data()), uv.size() * sizeof(float));
    const size_t buffer = doc["buffers"].size();
    doc["buffers"].push_back({{"uri", name}, {"byteLength", uv.size() * sizeof(float)}});
    doc["bufferViews"].push_back({{"buffer", buffer}, {"byteLength", uv.size() * sizeof(float)}});
    doc["accessors"].push_back({{"bufferView", doc["bufferViews"].size() - 1},
                                {"componentType", 5126},
                                {"count", uv.size() / 2},
                                {"type", "VEC2"}});
    return doc["accessors"].size() - 1;
}

TEST(GltfLoader, MissingFileNamesThePath) {
    try {
        LoadGltf("/nonexistent/scene.gltf");
        FAIL() << "no error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("/nonexistent/scene.gltf"), std::string::npos)
            << e.what();
    }
}

TEST(GltfLoader, MalformedJsonIsAnError) {
    auto path = testing::TempDir("gltf-bad") / "broken.gltf";
    std::ofstream(path) << "{\"asset\": {\"version\": \"2.0\"}, \"nodes\": [";
    EXPECT_THROW(LoadGltf(path.string()), Error);
}

TEST(GltfLoader, NonFiniteMatrixNamesTheNode) {
    // JSON has no NaN; 1e39 overflows a float to infinity.
    auto doc = Cornell();
    doc["nodes"][0]["matrix"] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 1e39, 0, 0, 1};
    std::string msg = LoadError(doc, "inf.gltf");
    EXPECT_NE(msg.find("inf.gltf: node 0 'floor'"), std::string::npos) << msg;
    EXPECT_NE(msg.find("NaN or infinity"), std::string::npos) << msg;
}

TEST(GltfLoader, MalformedMatrixIsRefused) {
    auto doc = Cornell();
    doc["nodes"][0]["matrix"] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, nullptr, 0, 0, 1};
    std::string msg = LoadError(doc, "matrix.gltf");
    EXPECT_NE(msg.find("matrix.gltf"), std::string::npos) << msg;
    EXPECT_EQ(msg.find("loaded without error"), std::string::npos) << msg;
}

TEST(GltfLoader, SingularTransformNamesTheNode) {
    auto doc = Cornell();
    doc["nodes"][1]["scale"] = {0.0, 1.0, 1.0};
    std::string msg = LoadError(doc, "singular.gltf");
    EXPECT_NE(msg.find("'ceiling'"), std::string::npos) << msg;
    EXPECT_NE(msg.find("singular"), std::string::npos) << msg;
}

TEST(GltfLoader, IndexPastTheVerticesIsRefused) {
    auto doc = Cornell();
    int acc = doc["meshes"][0]["primitives"][0]["indices"];
    // Point the index accessor of the floor at the position data (floats as uint32).
    doc["accessors"][acc]["bufferView"] = doc["accessors"][0]["bufferView"];
    std::string msg = LoadError(doc, "index.gltf");
    EXPECT_NE(msg.find("node 0 'floor'"), std::string::npos) << msg;
    EXPECT_NE(msg.find("past the"), std::string::npos) << msg;
}

// Found by the glTF fuzz target (issue 24): a buffer view naming a buffer that does not exist
// was read; counts and offsets large enough to wrap the bounds check around must not pass it.
TEST(GltfLoader, AccessorsOutsideTheirBuffersAreRefused) {
    int acc = Cornell()["meshes"][0]["primitives"][0]["attributes"]["POSITION"];
    auto noBuffer = Cornell();
    int view = noBuffer["accessors"][acc]["bufferView"];
    noBuffer["bufferViews"][view]["buffer"] = 7;
    std::string msg = LoadError(noBuffer, "nobuffer.gltf");
    EXPECT_NE(msg.find("buffer 7"), std::string::npos) << msg;
    for (const char* field : {"count", "byteOffset"}) {
        auto huge = Cornell();
        huge["accessors"][acc][field] = uint64_t{1} << 62;
        msg = LoadError(huge, std::string("huge-") + field + ".gltf");
        EXPECT_NE(msg.find("past the end"), std::string::npos) << field << ": " << msg;
    }
}

// Issue 24: a glTF's external files stay inside the folder the caller names (the service's
// scene root): a URI with "..", an absolute one or a symlink leading out fails the load with
// the file named; a file inside loads; with an empty root (an upload) none is read.
TEST(GltfLoader, ExternalFilesStayInsideTheirRoot) {
    const auto dir = testing::TempDir("gltf-confined");
    const auto root = dir / "root";
    std::filesystem::create_directories(root / "sub");
    // The Cornell box with its one buffer moved out of its data URI into files.
    nlohmann::json doc = Cornell();
    tinygltf::Model model;
    ReadGltfModel(kCornell, &model);
    const std::string bytes(model.buffers[0].data.begin(), model.buffers[0].data.end());
    for (const auto& file : {dir / "outside.bin", root / "inside.bin"})
        std::ofstream(file, std::ios::binary) << bytes;
    std::filesystem::create_symlink(dir / "outside.bin", root / "link.bin");
    auto load = [&](const std::string& bufferUri, const GltfFiles& files) -> std::string {
        nlohmann::json d = doc;
        d["buffers"][0]["uri"] = bufferUri;
        const auto path = root / "sub" / "scene.gltf";
        std::ofstream(path) << d.dump();
        try {
            LoadGltf(path.string(), files);
        } catch (const Error& e) {
            return e.what();
        }
        return "";
    };
    const GltfFiles confined{root};
    EXPECT_EQ(load("../inside.bin", confined), "");
    for (const std::string& out : {std::string("../../outside.bin"), std::string("../link.bin")}) {
        const std::string msg = load(out, confined);
        EXPECT_NE(msg.find("outside the scene root"), std::string::npos) << out << ": " << msg;
    }
    // tinygltf looks for an absolute URI under the glTF's own folder: not found there.
    EXPECT_NE(load((dir / "outside.bin").string(), confined), "");
    // Unconfined (the CLI's own files), everything is read.
    EXPECT_EQ(load("../../outside.bin", {}), "");
    // An upload: no external file at all.
    const std::string msg = load("../inside.bin", GltfFiles{std::filesystem::path()});
    EXPECT_NE(msg.find("external file '" + (root / "sub" / "../inside.bin").string() +
                       "' refused: an uploaded .glb must hold its buffers"),
              std::string::npos)
        << msg;
}

// Issue 62: a glTF 1.0 file, text or binary, with or without its asset's version, is refused
// as such, with the command that converts it, not as an empty or invalid 2.0 scene.
TEST(GltfLoader, GltfOneIsNamedWithItsConverter) {
    const auto dir = testing::TempDir("gltf-one");
    auto expectRefused = [](const std::filesystem::path& path) {
        try {
            LoadGltf(path.string());
            ADD_FAILURE() << path << " loaded";
        } catch (const Error& e) {
            const std::string what = e.what();
            EXPECT_NE(what.find("a glTF 1.0 file"), std::string::npos) << what;
            EXPECT_NE(what.find("assimp export"), std::string::npos) << what;
        }
    };
    // 1.0's lists are objects keyed by id; its asset (when it has one) says 1.0.
    const std::string meshes = R"("meshes": {"box": {"primitives": []}}, "nodes": {}, )";
    std::ofstream(dir / "versioned.gltf")
        << "{" << meshes << R"("asset": {"version": "1.0"}, "scene": "s", "scenes": {}})";
    std::ofstream(dir / "unversioned.gltf") << "{" << meshes << R"("scene": "s", "scenes": {}})";
    // A 1.0 binary: magic, version 1, length, then its content (JSON) chunk.
    const std::string json = R"({"asset": {"version": "1.0"}})";
    std::ofstream glb(dir / "binary.glb", std::ios::binary);
    const uint32_t header[5] = {0x46546C67u, 1u, uint32_t(20 + json.size()), uint32_t(json.size()),
                                0u};
    glb.write(reinterpret_cast<const char*>(header), sizeof header);
    glb << json;
    glb.close();
    for (const char* name : {"versioned.gltf", "unversioned.gltf", "binary.glb"})
        expectRefused(dir / name);
}

// What the loader ignores or approximates is said, one warning each (issue 23): averaged
// and ignored textures, skins, morph targets, animations, unsupported extensions, unnamed
// nodes; the bundled Cornell box has none, and a scene without light gets SceneWarnings'.
TEST(GltfLoader, IgnoredInputIsWarnedAbout) {
    EXPECT_TRUE(SceneWarnings(LoadGltf(kCornell)).empty());
    const auto dir = testing::TempDir("gltf-warnings");
    WritePng((dir / "tex.png").string(), 2, 2, std::vector<uint8_t>(12, 200));
    nlohmann::json doc = Cornell();
    std::ofstream(dir / "broken.png") << "not a PNG at all";
    doc["images"] = {{{"uri", "tex.png"}}, {{"uri", "broken.png"}}};
    doc["textures"] = {{{"source", 0}}, {{"source", 1}}};
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = {{"index", 0}};
    doc["materials"][0]["emissiveTexture"] = {{"index", 0}};
    // A texture the answer does not read (a normal map) cannot fail the load, broken or not.
    doc["materials"][1]["normalTexture"] = {{"index", 1}};
    doc["skins"] = {{{"joints", {0}}}};
    doc["animations"] = nlohmann::json::array(
        {{{"channels", nlohmann::json::array()}, {"samplers", nlohmann::json::array()}}});
    auto& prim = doc["meshes"][0]["primitives"][0];
    prim["targets"] = {{{"POSITION", prim["attributes"]["POSITION"]}}};
    doc["extensionsUsed"] = {"KHR_materials_clearcoat"};
    doc["nodes"][0].erase("name");
    std::ofstream(dir / "ignored.gltf") << doc.dump();
    const Scene scene = LoadGltf((dir / "ignored.gltf").string());
    std::string all;
    for (const auto& w : SceneWarnings(scene)) all += w + "\n";
    for (const char* expected :
         {"no TEXCOORD_0 for its material's texture: the texture's mean colour is used",
          "normalTexture ignored", "1 skin(s) ignored", "1 animation(s) ignored",
          "extension 'KHR_materials_clearcoat' ignored", "1 node(s) with a mesh but no name"})
        EXPECT_NE(all.find(expected), std::string::npos) << expected << " in:\n" << all;
    EXPECT_EQ(all.find("no light"), std::string::npos) << all;
    EXPECT_EQ(scene.nodes[0].name, "node0");
    // Morph targets are read (and posed at weight 0), not ignored.
    EXPECT_EQ(NodeMorphTargets(scene, 0), 1u);
    EXPECT_EQ(all.find("morph"), std::string::npos) << all;
    // One the answer reads, broken (issue 62: as a renderer would): a warning naming the
    // image, and the material's factor alone.
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = {{"index", 1}};
    std::ofstream(dir / "broken-base.gltf") << doc.dump();
    const Scene broken = LoadGltf((dir / "broken-base.gltf").string());
    std::string brokenWarnings;
    for (const auto& w : SceneWarnings(broken)) brokenWarnings += w + "\n";
    EXPECT_NE(brokenWarnings.find("image 1 'broken.png' could not be decoded"), std::string::npos)
        << brokenWarnings;
    EXPECT_NE(brokenWarnings.find("its factor is used alone"), std::string::npos) << brokenWarnings;
    EXPECT_EQ(broken.materials[0].baseColorMap, -1);
    // One outside the scene root stays an error, and says so.
    doc["images"][1]["uri"] = "../../elsewhere.png";
    std::ofstream(dir / "outside-base.gltf") << doc.dump();
    try {
        LoadGltf((dir / "outside-base.gltf").string(), GltfFiles{dir});
        ADD_FAILURE() << "an image outside the scene root loaded";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("lies outside the scene root"), std::string::npos)
            << e.what();
    }

    Scene dark = LoadGltf(kCornell);
    for (auto& m : dark.materials) m.emission = glm::vec3(0.0f);
    ASSERT_EQ(SceneWarnings(dark).size(), 1u);
    EXPECT_NE(SceneWarnings(dark)[0].find("no light"), std::string::npos);
}

// Base colour and emissive textures are read as colour maps (one per texture, shared by
// the materials that use it) with the texture coordinates their primitives give; the
// material's colour holds the factor times the texture's mean.
TEST(GltfLoader, ReadsColourMapsAndTheirCoordinates) {
    const auto dir = testing::TempDir("gltf-maps");
    // 64 × 1 texels: white on the left half, black on the right.
    std::vector<uint8_t> rgb(64 * 3, 0);
    std::fill(rgb.begin(), rgb.begin() + 32 * 3, 255);
    WritePng((dir / "halves.png").string(), 64, 1, rgb);
    nlohmann::json doc = Cornell();
    const int count = doc["accessors"][0]["count"];  // the floor's POSITION
    // TEXCOORD_0 of the floor: u = ¼ for its first half of vertices, ¾ for the rest.
    std::vector<float> uv;
    for (int i = 0; i < count; ++i) uv.insert(uv.end(), {i < count / 2 ? 0.25f : 0.75f, 0.5f});
    doc["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_0"] =
        AddUvAccessor(doc, dir, "uv.bin", uv);
    doc["images"] = {{{"uri", "halves.png"}}};
    doc["textures"] = {{{"source", 0}, {"sampler", 0}}};
    doc["samplers"] = {{{"wrapS", 33071}, {"wrapT", 33071}}};  // clamp to edge
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = {{"index", 0}};
    doc["materials"][0]["emissiveTexture"] = {{"index", 0}};
    doc["materials"][0]["emissiveFactor"] = {2.0, 2.0, 2.0};
    std::ofstream(dir / "maps.gltf") << doc.dump();
    const Scene scene = LoadGltf((dir / "maps.gltf").string());
    ASSERT_EQ(scene.maps.size(), 1u);  // one texture, read once
    const Material& white = scene.materials[0];
    EXPECT_EQ(white.baseColorMap, 0);
    EXPECT_EQ(white.emissionMap, 0);
    EXPECT_NEAR(scene.maps[0].Mean().x, 0.5f, 1e-6f);
    EXPECT_NEAR(white.baseColor.x, 0.725f * 0.5f, 1e-5f);
    EXPECT_NEAR(white.emission.x, 2.0f * 0.5f, 1e-5f);
    const int floor = FindNode(scene, "floor");
    const uint32_t p = scene.nodes[floor].primitives[0];
    ASSERT_EQ(scene.primitives[p].texcoords.size(), 1u);
    ASSERT_EQ(scene.primitives[p].texcoords[0].size(), static_cast<size_t>(count));
    // At a vertex of the first half the texture is white: twice its mean; at the last, black.
    const Tints first = TintsAt(scene, p, glm::uvec3(0), 0.0f, 0.0f);
    const Tints last = TintsAt(scene, p, glm::uvec3(count - 1), 0.0f, 0.0f);
    EXPECT_NEAR(first.albedo.x, 2.0f, 1e-5f);
    EXPECT_NEAR(first.emission.x, 2.0f, 1e-5f);
    EXPECT_NEAR(last.albedo.x, 0.0f, 1e-6f);
    // The other primitives with the material have no coordinates: warned, the mean used.
    std::string all;
    for (const auto& w : scene.warnings) all += w + "\n";
    EXPECT_NE(all.find("no TEXCOORD_0"), std::string::npos) << all;
    EXPECT_EQ(all.find("'floor' mesh 0"), std::string::npos) << all;
    const uint32_t wall = scene.nodes[FindNode(scene, "back_wall")].primitives[0];
    EXPECT_EQ(TintsAt(scene, wall, glm::uvec3(0), 0.0f, 0.0f).albedo, glm::vec3(1.0f));

    // A texCoord out of range is refused.
    doc["materials"][0]["emissiveTexture"]["texCoord"] = 9;
    std::ofstream(dir / "texcoord.gltf") << doc.dump();
    EXPECT_THROW(
        {
            try {
                LoadGltf((dir / "texcoord.gltf").string());
            } catch (const Error& e) {
                EXPECT_NE(std::string(e.what()).find("texCoord must be 0 to 7"), std::string::npos)
                    << e.what();
                throw;
            }
        },
        Error);
}

// Issue 62: KHR_texture_transform on a colour map's textureInfo (offset, rotation, scale,
// texCoord) as the extension defines it, for that map only; the texels are not copied.
TEST(GltfLoader, ColourMapsReadThroughTheirTextureTransforms) {
    const auto dir = testing::TempDir("gltf-texture-transform");
    // 2 × 2 texels: white at the top left (u, v < ½), black elsewhere; clamped.
    std::vector<uint8_t> rgb(2 * 2 * 3, 0);
    std::fill(rgb.begin(), rgb.begin() + 3, 255);
    WritePng((dir / "corner.png").string(), 2, 2, rgb);
    nlohmann::json doc = Cornell();
    const int count = doc["accessors"][0]["count"];  // the floor's POSITION
    std::vector<float> uv;  // every floor vertex at (¼, ¾): a black texel
    for (int i = 0; i < count; ++i) uv.insert(uv.end(), {0.25f, 0.75f});
    auto& attributes = doc["meshes"][0]["primitives"][0]["attributes"];
    attributes["TEXCOORD_0"] = AddUvAccessor(doc, dir, "uv.bin", uv);
    doc["images"] = {{{"uri", "corner.png"}}};
    doc["textures"] = {{{"source", 0}, {"sampler", 0}}};
    doc["samplers"] = {{{"wrapS", 33071}, {"wrapT", 33071}}};
    doc["materials"][0]["emissiveTexture"] = {{"index", 0}};
    doc["materials"][0]["emissiveFactor"] = {1.0, 1.0, 1.0};
    doc["extensionsUsed"] = {"KHR_texture_transform"};
    // The floor's first vertex's tints with `transform` on the base colour map.
    auto tints = [&](const nlohmann::json& transform) {
        doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = {
            {"index", 0}, {"extensions", {{"KHR_texture_transform", transform}}}};
        std::ofstream(dir / "transformed.gltf") << doc.dump();
        const Scene scene = LoadGltf((dir / "transformed.gltf").string());
        for (const auto& w : scene.warnings)
            EXPECT_EQ(w.find("KHR_texture_transform"), std::string::npos) << w;
        const uint32_t p = scene.nodes[FindNode(scene, "floor")].primitives[0];
        return TintsAt(scene, p, glm::uvec3(0), 0.0f, 0.0f);
    };
    // The texture's mean is ¼ white: its white texel is a tint of 4, a black one 0.
    const Tints none = tints(nlohmann::json::object());
    EXPECT_NEAR(none.albedo.x, 0.0f, 1e-5f);
    EXPECT_NEAR(tints({{"offset", {0.0, -0.5}}}).albedo.x, 4.0f, 1e-5f);
    EXPECT_NEAR(tints({{"scale", {1.0, 1.0 / 3.0}}}).albedo.x, 4.0f, 1e-5f);
    // A quarter turn, counter-clockwise as the extension's matrix has it: (¼, ¾) → (−¾, ¼),
    // then the offset: (¼, ¼), white. Turned the other way it would read (1, 0), black.
    const Tints turned = tints({{"rotation", 1.5707963267948966}, {"offset", {1.0, 0.0}}});
    EXPECT_NEAR(turned.albedo.x, 4.0f, 1e-4f);
    EXPECT_NEAR(turned.emission.x, 0.0f, 1e-5f) << "the emissive map has no transform";
    // texCoord overrides the textureInfo's set: set 1 is at (¼, ¼).
    for (float& x : uv) x = 0.25f;
    attributes["TEXCOORD_1"] = AddUvAccessor(doc, dir, "uv1.bin", uv);
    EXPECT_NEAR(tints({{"texCoord", 1}}).albedo.x, 4.0f, 1e-5f);
    // A transform that is not numbers is refused, naming the material and the map.
    try {
        tints({{"scale", {1.0, "two"}}});
        ADD_FAILURE() << "a bad scale loaded";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("baseColorTexture's KHR_texture_transform"),
                  std::string::npos)
            << e.what();
    }
}

// An image in a buffer view that reaches past its buffer is refused with why: tinygltf hands
// the view's bytes over unchecked (the fuzzer read past a .glb's buffer that way).
TEST(GltfLoader, AnImageOutsideItsBufferIsRefused) {
    const auto dir = testing::TempDir("gltf-image-view");
    std::ofstream(dir / "img.bin", std::ios::binary) << std::string(16, 'x');
    nlohmann::json doc = Cornell();
    const int buffer = static_cast<int>(doc["buffers"].size());
    doc["buffers"].push_back({{"uri", "img.bin"}, {"byteLength", 16}});
    doc["bufferViews"].push_back({{"buffer", buffer}, {"byteOffset", 8}, {"byteLength", 4096}});
    doc["images"] = {{{"bufferView", doc["bufferViews"].size() - 1}, {"mimeType", "image/png"}}};
    doc["textures"] = {{{"source", 0}}};
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = {{"index", 0}};
    std::ofstream(dir / "view.gltf") << doc.dump();
    try {
        LoadGltf((dir / "view.gltf").string());
        FAIL() << "no error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("image 0's buffer view"), std::string::npos)
            << e.what();
        EXPECT_NE(std::string(e.what()).find("lies outside its buffer"), std::string::npos)
            << e.what();
    }
}

TEST(GltfLoader, MissingPositionIsRefused) {
    auto doc = Cornell();
    doc["meshes"][0]["primitives"][0]["attributes"].erase("POSITION");
    std::string msg = LoadError(doc, "nopos.gltf");
    EXPECT_NE(msg.find("has no POSITION"), std::string::npos) << msg;
}

TEST(GltfLoader, PointsAreRefused) {
    auto doc = Cornell();
    doc["meshes"][0]["primitives"][0]["mode"] = 0;
    std::string msg = LoadError(doc, "points.gltf");
    EXPECT_NE(msg.find("only triangles are supported"), std::string::npos) << msg;
}

TEST(GltfLoader, UnsupportedRequiredExtensionIsRefused) {
    auto doc = Cornell();
    doc["extensionsRequired"] = {"EXT_texture_webp"};
    doc["extensionsUsed"] = {"EXT_texture_webp"};
    std::string msg = LoadError(doc, "webp.gltf");
    EXPECT_NE(msg.find("EXT_texture_webp"), std::string::npos) << msg;
}

// Issue 62: quantised attributes (KHR_mesh_quantization) read as the floats they stand for: the
// Cornell box packed by Debian's gltfpack (positions as unsigned shorts under a dequantising
// node transform, normals as normalised bytes) is the same geometry as the file it came from,
// up to 14-bit positions.
TEST(GltfLoader, AQuantizedFileReadsAsItsSource) {
    const auto dir = testing::TempDir("quantized");
    const std::string packed = (dir / "cornell-q.glb").string();
    const auto run = testing::Shell("gltfpack -i " + kCornell + " -o " + packed + " -kn -km");
    ASSERT_EQ(run.exitCode, 0) << run.output;
    const Scene q = LoadGltf(packed);
    const Scene plain = LoadGltf(kCornell);
    EXPECT_EQ(q.TriangleCount(), plain.TriangleCount());
    auto area = [](const Scene& s) {
        double a = 0.0;
        for (const Primitive& p : s.primitives)
            for (size_t t = 0; t + 2 < p.indices.size(); t += 3)
                a += 0.5 * glm::length(glm::cross(
                               p.positions[p.indices[t + 1]] - p.positions[p.indices[t]],
                               p.positions[p.indices[t + 2]] - p.positions[p.indices[t]]));
        return a;
    };
    EXPECT_NEAR(area(q), area(plain), 1e-3 * area(plain));
    EXPECT_NEAR(q.Diameter(), plain.Diameter(), 1e-3f * plain.Diameter());
    for (const Primitive& p : q.primitives)
        for (const glm::vec3& n : p.normals) EXPECT_NEAR(glm::length(n), 1.0f, 1e-4f);
}

// Issue 62: meshopt-compressed buffers (EXT_meshopt_compression, gltfpack -c) decode to the
// very bytes of the uncompressed packing; compressed data that does not decode is refused by
// view, and the extension in a text .gltf is named as not read.
TEST(GltfLoader, AMeshoptFileReadsAsItsUncompressedTwin) {
    const auto dir = testing::TempDir("meshopt");
    const std::string packed = (dir / "cornell-q.glb").string(),
                      compressed = (dir / "cornell-c.glb").string();
    for (const auto& [out, flags] : {std::pair{packed, ""}, {compressed, " -c"}}) {
        const auto run =
            testing::Shell("gltfpack -i " + kCornell + " -o " + out + " -kn -km" + flags);
        ASSERT_EQ(run.exitCode, 0) << run.output;
    }
    const Scene q = LoadGltf(packed), c = LoadGltf(compressed);
    ASSERT_EQ(c.primitives.size(), q.primitives.size());
    // The index codec keeps each triangle and its winding, not which corner comes first.
    auto rotated = [](std::vector<uint32_t> indices) {
        for (size_t t = 0; t + 2 < indices.size(); t += 3)
            std::rotate(indices.begin() + t,
                        std::min_element(indices.begin() + t, indices.begin() + t + 3),
                        indices.begin() + t + 3);
        return indices;
    };
    for (size_t p = 0; p < q.primitives.size(); ++p) {
        EXPECT_EQ(rotated(c.primitives[p].indices), rotated(q.primitives[p].indices)) << p;
        EXPECT_EQ(c.primitives[p].positions, q.primitives[p].positions) << p;
        EXPECT_EQ(c.primitives[p].normals, q.primitives[p].normals) << p;
    }
    for (const std::string& w : c.warnings) EXPECT_EQ(w.find("meshopt"), std::string::npos) << w;

    // Zeros over the start of the binary chunk: the first compressed view's header is gone.
    std::vector<char> bytes;
    {
        std::ifstream in(compressed, std::ios::binary);
        bytes.assign(std::istreambuf_iterator<char>(in), {});
    }
    uint32_t jsonLength;
    std::memcpy(&jsonLength, bytes.data() + 12, 4);
    std::fill_n(bytes.begin() + 20 + jsonLength + 8, 16, '\0');
    const std::string broken = (dir / "broken.glb").string();
    std::ofstream(broken, std::ios::binary).write(bytes.data(), std::streamsize(bytes.size()));
    std::string what;
    try {
        LoadGltf(broken);
    } catch (const Error& e) {
        what = e.what();
    }
    EXPECT_NE(what.find("does not decode"), std::string::npos) << what;
    EXPECT_NE(what.find("buffer view"), std::string::npos) << what;

    auto doc = Cornell();
    doc["extensionsUsed"] = {"EXT_meshopt_compression"};
    std::string msg = LoadError(doc, "meshopt.gltf");
    EXPECT_NE(msg.find("binary glTF (.glb) only"), std::string::npos) << msg;
}

// Issue 62: a Draco-compressed file (KHR_draco_mesh_compression; Khronos' 2CylinderEngine as
// Debian's assimp-testmodels has it both ways) reads as the same geometry as the plain one:
// the same triangles, the same area, the same bounds, up to Draco's quantisation.
TEST(GltfLoader, ADracoFileReadsAsItsPlainTwin) {
    const std::string models = "/usr/share/assimp/models/glTF2/";
    const Scene draco = LoadGltf(models + "draco/2CylinderEngine.gltf");
    const Scene plain = LoadGltf(models + "2CylinderEngine-glTF-Binary/2CylinderEngine.glb");
    ASSERT_EQ(draco.primitives.size(), plain.primitives.size());
    // Draco's encoder drops degenerate triangles (two corners at one vertex), and a few whose
    // corners its quantisation welds: the rest match.
    auto proper = [](const Scene& s) {
        size_t n = 0;
        for (const Primitive& p : s.primitives)
            for (size_t t = 0; t + 2 < p.indices.size(); t += 3)
                n += p.indices[t] != p.indices[t + 1] && p.indices[t + 1] != p.indices[t + 2] &&
                     p.indices[t] != p.indices[t + 2];
        return n;
    };
    EXPECT_EQ(proper(draco), draco.TriangleCount());
    EXPECT_NEAR(double(proper(draco)), double(proper(plain)), 1e-4 * double(proper(plain)));
    for (const std::string& w : draco.warnings) EXPECT_EQ(w.find("draco"), std::string::npos) << w;
    auto area = [](const Scene& s) {
        double a = 0.0;
        for (const Primitive& p : s.primitives)
            for (size_t t = 0; t + 2 < p.indices.size(); t += 3) {
                const glm::vec3 x = p.positions[p.indices[t]], y = p.positions[p.indices[t + 1]],
                                z = p.positions[p.indices[t + 2]];
                a += 0.5 * glm::length(glm::cross(y - x, z - x));
            }
        return a;
    };
    EXPECT_NEAR(area(draco), area(plain), 5e-3 * area(plain));
    const float diameter = plain.Diameter();
    EXPECT_NEAR(draco.Diameter(), diameter, 1e-3f * diameter);
}

TEST(GltfLoader, AlbedoAboveOneIsRefused) {
    auto doc = Cornell();
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorFactor"] = {1.5, 0.5, 0.5, 1.0};
    std::string msg = LoadError(doc, "albedo.gltf");
    EXPECT_NE(msg.find("material 0 'white'"), std::string::npos) << msg;
}

TEST(GltfLoader, UnknownMeshIsRefused) {
    auto doc = Cornell();
    doc["nodes"][2]["mesh"] = 99;
    std::string msg = LoadError(doc, "mesh.gltf");
    EXPECT_NE(msg.find("99"), std::string::npos) << msg;
}

// --- Dynamic nodes and moves (extras.penumbra, SetNodeTransform) ------------------------------

TEST(GltfLoader, ReadsDynamicNodesAndMotionBounds) {
    Scene scene = LoadGltf(kCornell);
    int tall = FindNode(scene, "tall_block"), floor = FindNode(scene, "floor");
    ASSERT_GE(tall, 0);
    ASSERT_GE(floor, 0);
    EXPECT_TRUE(scene.nodes[tall].dynamic);
    EXPECT_TRUE(scene.nodes[tall].hasMotionBounds);
    EXPECT_NEAR(scene.nodes[tall].boundsMax.y, 0.331f, 1e-4f);  // its height + 1 mm
    EXPECT_FALSE(scene.nodes[floor].dynamic);
    EXPECT_EQ(scene.nodes[tall].primitives.size(), 1u);
    EXPECT_EQ(FindNode(scene, "no_such_node"), -1);
}

TEST(GltfLoader, BadMotionBoundsAreRefused) {
    auto doc = Cornell();
    doc["nodes"][0]["extras"] = {{"penumbra", {{"dynamic", "yes"}}}};
    std::string msg = LoadError(doc, "dyn.gltf");
    EXPECT_NE(msg.find("extras.penumbra.dynamic must be true or false"), std::string::npos) << msg;
    doc["nodes"][0]["extras"] = {
        {"penumbra", {{"dynamic", true}, {"bounds", {{"min", {0, 0}}, {"max", {1, 1, 1}}}}}}};
    msg = LoadError(doc, "bounds.gltf");
    EXPECT_NE(msg.find("bounds.min must be an array of 3 numbers"), std::string::npos) << msg;
}

// Issue 61: glTF draws a mesh without NORMAL with flat normals. A cube of 8 shared vertices
// becomes a vertex a face at each corner (24), each with its face's normal; outputs, frames
// and deformations still count the file's 8, a corner reporting the mean of its three faces.
TEST(GltfLoader, AMeshWithoutNormalsGetsFlatOnes) {
    const auto dir = testing::TempDir("flat-cube");
    std::vector<float> corners;
    for (int i = 0; i < 8; ++i)
        for (int axis = 0; axis < 3; ++axis) corners.push_back((i >> axis) & 1 ? 1.0f : -1.0f);
    // Two triangles a face, wound outwards.
    const std::vector<uint16_t> indices{0, 2, 3, 0, 3, 1, 4, 5, 7, 4, 7, 6, 0, 1, 5, 0, 5, 4,
                                        2, 6, 7, 2, 7, 3, 0, 4, 6, 0, 6, 2, 1, 3, 7, 1, 7, 5};
    std::ofstream bin(dir / "cube.bin", std::ios::binary);
    bin.write(reinterpret_cast<const char*>(corners.data()), corners.size() * 4);
    bin.write(reinterpret_cast<const char*>(indices.data()), indices.size() * 2);
    bin.close();
    nlohmann::json doc = {
        {"asset", {{"version", "2.0"}}},
        {"scene", 0},
        {"scenes", {{{"nodes", {0}}}}},
        {"nodes",
         {{{"name", "cube"}, {"mesh", 0}, {"extras", {{"penumbra", {{"dynamic", true}}}}}}}},
        {"meshes", {{{"primitives", {{{"attributes", {{"POSITION", 0}}}, {"indices", 1}}}}}}},
        {"buffers", {{{"uri", "cube.bin"}, {"byteLength", 96 + 72}}}},
        {"bufferViews",
         {{{"buffer", 0}, {"byteOffset", 0}, {"byteLength", 96}},
          {{"buffer", 0}, {"byteOffset", 96}, {"byteLength", 72}}}},
        {"accessors",
         {{{"bufferView", 0},
           {"componentType", 5126},
           {"count", 8},
           {"type", "VEC3"},
           {"min", {-1, -1, -1}},
           {"max", {1, 1, 1}}},
          {{"bufferView", 1}, {"componentType", 5123}, {"count", 36}, {"type", "SCALAR"}}}}};
    std::ofstream(dir / "cube.gltf") << doc.dump();
    Scene scene = LoadGltf((dir / "cube.gltf").string());
    ASSERT_EQ(scene.primitives.size(), 1u);
    const Primitive& p = scene.primitives[0];
    EXPECT_EQ(p.InputVertexCount(), 8u);
    ASSERT_EQ(p.positions.size(), 24u);
    ASSERT_EQ(p.copyOf.size(), 16u);
    for (size_t k = 0; k < p.positions.size(); ++k) {
        EXPECT_EQ(p.positions[k], p.positions[p.InputVertex(k)]);
        const glm::vec3 n = p.normals[k];
        EXPECT_NEAR(glm::length(glm::abs(n) - glm::vec3(std::round(std::abs(n.x)),
                                                        std::round(std::abs(n.y)),
                                                        std::round(std::abs(n.z)))),
                    0.0f, 1e-6f)
            << "vertex " << k << ": not a face's normal";
        EXPECT_GT(glm::dot(n, p.positions[k]), 0.0f) << "vertex " << k << " faces inwards";
    }
    for (size_t t = 0; t < p.indices.size(); t += 3) {  // each triangle's corners share one
        EXPECT_EQ(p.normals[p.indices[t]], p.normals[p.indices[t + 1]]);
        EXPECT_EQ(p.normals[p.indices[t]], p.normals[p.indices[t + 2]]);
    }
    // A value per copy (here its normal) merges to the mean over the corner's three faces,
    // each weighted by its triangles' area there: two triangles of a face meet at corners 0
    // and 7, one or two elsewhere.
    const std::vector<glm::vec3> merged = ToInputVertices(p, p.normals);
    ASSERT_EQ(merged.size(), 8u);
    for (size_t i : {0, 7}) {
        const glm::vec3 want = p.positions[i] / 3.0f;  // corners are (±1, ±1, ±1)
        EXPECT_NEAR(glm::length(merged[i] - want), 0.0f, 1e-5f) << "corner " << i;
    }
    for (size_t i = 0; i < 8; ++i)
        for (int axis = 0; axis < 3; ++axis) {
            const float share = merged[i][axis] * p.positions[i][axis];
            EXPECT_GE(share, 0.25f - 1e-5f) << "corner " << i;
            EXPECT_LE(share, 0.5f + 1e-5f) << "corner " << i;
        }
    // Deformations give the file's 8 vertices; the copies follow and the faces stay flat.
    ASSERT_EQ(NodeVertexCount(scene, 0), 8u);
    const std::vector<glm::vec3> flat = p.normals;
    std::vector<glm::vec3> twice;
    for (size_t i = 0; i < 8; ++i) twice.push_back(2.0f * p.positions[i]);
    SetNodeVertices(scene, 0, twice, {});
    const Primitive& q = scene.primitives[0];
    ASSERT_EQ(q.positions.size(), 24u);
    for (size_t k = 0; k < q.positions.size(); ++k) {
        EXPECT_EQ(q.positions[k], twice[q.InputVertex(k)]);
        EXPECT_NEAR(glm::length(q.normals[k] - flat[k]), 0.0f, 1e-6f);
    }
}

TEST(SceneTransform, MovingANodeMovesItsGeometryExactly) {
    Scene scene = LoadGltf(kCornell);
    int tall = FindNode(scene, "tall_block");
    const Primitive& p = scene.primitives[scene.nodes[tall].primitives[0]];
    std::vector<glm::vec3> before = p.positions, normalsBefore = p.normals;
    glm::mat4 local = scene.nodes[tall].local;
    glm::mat4 moved = glm::translate(glm::mat4(1.0f), glm::vec3(0.05f, 0.0f, 0.0f)) * local;
    SetNodeTransform(scene, tall, moved);
    for (size_t i = 0; i < before.size(); ++i) {
        EXPECT_NEAR(p.positions[i].x, before[i].x + 0.05f, 1e-6f);
        EXPECT_NEAR(p.positions[i].y, before[i].y, 1e-6f);
        EXPECT_NEAR(glm::dot(p.normals[i], normalsBefore[i]), 1.0f, 1e-6f);
    }
    // Back to where it was: the original vertices, not an accumulated drift.
    SetNodeTransform(scene, tall, local);
    for (size_t i = 0; i < before.size(); ++i)
        EXPECT_NEAR(glm::length(p.positions[i] - before[i]), 0.0f, 1e-6f);
}

TEST(SceneTransform, BadMatricesAreRefusedAndChangeNothing) {
    Scene scene = LoadGltf(kCornell);
    int tall = FindNode(scene, "tall_block");
    const Primitive& p = scene.primitives[scene.nodes[tall].primitives[0]];
    std::vector<glm::vec3> before = p.positions;
    auto message = [&](const glm::mat4& m) {
        try {
            SetNodeTransform(scene, tall, m);
        } catch (const Error& e) {
            return std::string(e.what());
        }
        return std::string("(accepted)");
    };
    glm::mat4 nan(1.0f);
    nan[3][0] = std::numeric_limits<float>::quiet_NaN();
    EXPECT_NE(message(nan).find("NaN"), std::string::npos) << message(nan);
    const glm::mat4 flat = glm::scale(glm::mat4(1.0f), glm::vec3(0.0f, 1.0f, 1.0f));
    EXPECT_NE(message(flat).find("singular"), std::string::npos) << message(flat);
    EXPECT_NE(message(glm::mat4(0.0f)).find("not affine"), std::string::npos);
    glm::mat4 projective(1.0f);
    projective[1][3] = 0.5f;  // a w row of (0, 0.5, 0, 1)
    EXPECT_NE(message(projective).find("not affine"), std::string::npos) << message(projective);
    glm::mat4 mirror = glm::scale(glm::mat4(1.0f), glm::vec3(-1.0f, 1.0f, 1.0f));
    EXPECT_NE(message(mirror).find("mirror"), std::string::npos) << message(mirror);
    EXPECT_EQ(p.positions, before);
}

const std::string kMorph = std::string(PENUMBRA_SOURCE_DIR) + "/scenes/morph-room.gltf";

// The bundled morphing blob: its two targets are read, posed exactly (rest + Σ w·target), and
// the refinement keeps its elements through any pose (it splits by the rest pose).
TEST(Deform, MorphTargetsPoseTheMeshAndKeepItsElements) {
    Scene scene = LoadGltf(kMorph);
    const int blob = FindNode(scene, "blob");
    ASSERT_GE(blob, 0);
    ASSERT_EQ(NodeMorphTargets(scene, blob), 2u);
    EXPECT_EQ(scene.nodes[blob].morphWeights, std::vector<float>({0.0f, 0.0f}));
    for (const std::string& w : scene.warnings) EXPECT_EQ(w.find("morph"), std::string::npos) << w;
    EXPECT_TRUE(ClosedNodes(scene)[blob]) << "the sphere must close a solid";
    const Primitive& p = scene.primitives[scene.nodes[blob].primitives[0]];
    const std::vector<glm::vec3> rest = p.positions;
    const Surfels before = RefineScene(scene, 0.1f);

    SetNodeMorphWeights(scene, blob, {0.7f, -0.4f});
    const glm::mat4& world = scene.nodes[blob].world;
    float lowest = 1e9f, lowestRest = 1e9f;
    for (size_t i = 0; i < rest.size(); ++i) {
        const glm::vec3 own =
            p.RestPositions()[i] + 0.7f * p.morphPositions[0][i] - 0.4f * p.morphPositions[1][i];
        EXPECT_NEAR(glm::length(p.positions[i] - glm::vec3(world * glm::vec4(own, 1.0f))), 0.0f,
                    1e-6f);
        EXPECT_NEAR(glm::length(p.normals[i]), 1.0f, 1e-5f);
        lowest = std::min(lowest, p.positions[i].y);
        lowestRest = std::min(lowestRest, rest[i].y);
    }
    EXPECT_EQ(p.shape, 1u);
    EXPECT_EQ(scene.nodes[blob].morphWeights, std::vector<float>({0.7f, -0.4f}));
    EXPECT_GT(lowest, lowestRest - 0.05f);  // squash keeps its base (ripple moves it a little)
    const Surfels after = RefineScene(scene, 0.1f);
    EXPECT_EQ(after.size(), before.size());
    EXPECT_EQ(after.refinedTriangles, before.refinedTriangles);
    EXPECT_NE(after.positions, before.positions);
    // Back to weights 0: the rest pose again, not an accumulated drift.
    SetNodeMorphWeights(scene, blob, {0.0f, 0.0f});
    for (size_t i = 0; i < rest.size(); ++i)
        EXPECT_NEAR(glm::length(p.positions[i] - rest[i]), 0.0f, 1e-6f);
}

// Vertices given directly: normals computed from the deformed triangles when none are given,
// taken (normalised) when they are; bad input is refused and changes nothing.
TEST(Deform, VerticesReplaceTheMeshAndBadOnesChangeNothing) {
    Scene scene = LoadGltf(kMorph);
    const int blob = FindNode(scene, "blob");
    const Primitive& p = scene.primitives[scene.nodes[blob].primitives[0]];
    const size_t n = NodeVertexCount(scene, blob);
    ASSERT_EQ(n, p.positions.size());
    // Stretch the sphere 2× along its own x: the normals tilt towards ±x.
    std::vector<glm::vec3> stretched = p.objectPositions;
    for (glm::vec3& v : stretched) v.x *= 2.0f;
    SetNodeVertices(scene, blob, stretched);
    size_t tilted = 0;
    for (size_t i = 0; i < n; ++i) {
        const glm::vec3 own = p.objectPositions[i];
        EXPECT_EQ(own, stretched[i]);
        // An ellipsoid x²/4 + y² + z² = r²: its normal is along (x/4, y, z), outwards.
        const glm::vec3 want = glm::normalize(glm::vec3(own.x / 4.0f, own.y, own.z));
        if (glm::dot(p.normals[i], want) > 0.98f) ++tilted;
    }
    EXPECT_GT(tilted, n * 95 / 100) << "computed normals must follow the deformed surface";
    std::vector<glm::vec3> up(n, glm::vec3(0.0f, 2.0f, 0.0f));
    SetNodeVertices(scene, blob, stretched, up);
    EXPECT_EQ(p.normals[7], glm::vec3(0.0f, 1.0f, 0.0f));
    EXPECT_EQ(p.shape, 2u);

    const std::vector<glm::vec3> before = p.positions;
    auto refused = [&](const std::vector<glm::vec3>& pos, const std::vector<glm::vec3>& nrm) {
        try {
            SetNodeVertices(scene, blob, pos, nrm);
        } catch (const Error& e) {
            return std::string(e.what());
        }
        return std::string("(accepted)");
    };
    std::vector<glm::vec3> fewer(stretched.begin(), stretched.end() - 1);
    EXPECT_NE(refused(fewer, {}).find("positions were given"), std::string::npos);
    std::vector<glm::vec3> nan = stretched;
    nan[5].y = std::numeric_limits<float>::quiet_NaN();
    EXPECT_NE(refused(nan, {}).find("NaN"), std::string::npos) << refused(nan, {});
    std::vector<glm::vec3> zero = up;
    zero[3] = glm::vec3(0.0f);
    EXPECT_NE(refused(stretched, zero).find("normal 3"), std::string::npos);
    EXPECT_NE(refused(stretched, fewer).find("normals were given"), std::string::npos);
    EXPECT_EQ(p.positions, before);
    EXPECT_EQ(p.shape, 2u);
    for (const std::vector<float>& w : {std::vector<float>{1.0f}, {1.0f, NAN}}) {
        EXPECT_THROW(SetNodeMorphWeights(scene, blob, w), Error);
    }
    EXPECT_EQ(p.positions, before);
    const int floor = FindNode(scene, "floor");
    EXPECT_THROW(SetNodeMorphWeights(scene, floor, {}), Error);  // no targets
}

// A file's own weights (the node's, else the mesh's) pose the mesh at load; the rest pose is
// still the base mesh, so the refinement is the one of weights 0.
TEST(Deform, TheFilesWeightsPoseTheLoadedMesh) {
    const auto dir = testing::TempDir("morph-weights");
    nlohmann::json j;
    std::ifstream(kMorph) >> j;
    int blobNode = -1;
    for (size_t i = 0; i < j["nodes"].size(); ++i)
        if (j["nodes"][i]["name"] == "blob") blobNode = int(i);
    ASSERT_GE(blobNode, 0);
    j["nodes"][blobNode]["weights"] = {1.0, 0.0};
    const std::string posed = (dir / "posed.gltf").string();
    std::ofstream(posed) << j.dump();
    Scene a = LoadGltf(posed), rest = LoadGltf(kMorph);
    const int blob = FindNode(a, "blob");
    EXPECT_EQ(a.nodes[blob].morphWeights, std::vector<float>({1.0f, 0.0f}));
    SetNodeMorphWeights(rest, blob, {1.0f, 0.0f});
    const uint32_t p = a.nodes[blob].primitives[0];
    EXPECT_EQ(a.primitives[p].positions, rest.primitives[p].positions);
    EXPECT_EQ(a.primitives[p].shape, 0u);  // as loaded
    EXPECT_EQ(RefineScene(a, 0.1f).refinedTriangles,
              RefineScene(LoadGltf(kMorph), 0.1f).refinedTriangles);
    // A weight count that does not match the targets fails the load, naming the node.
    j["nodes"][blobNode]["weights"] = {1.0};
    std::ofstream(posed) << j.dump();
    try {
        LoadGltf(posed);
        ADD_FAILURE() << "a wrong weight count was accepted";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("morph weights"), std::string::npos) << e.what();
    }
}

// WriteGltfModel: a .glb holds its buffers and images in its one BIN chunk (the image's bytes
// as they were in its file), and an infinite camera has no zfar, in either form.
TEST(GltfWriter, GlbHoldsImagesAndBuffersInItsBinChunk) {
    const auto dir = testing::TempDir("gltf-writer");
    WritePng((dir / "tex.png").string(), 2, 2, std::vector<uint8_t>(12, 200));
    std::ifstream png(dir / "tex.png", std::ios::binary);
    const std::vector<unsigned char> pngBytes(std::istreambuf_iterator<char>(png), {});
    tinygltf::Model model;
    ReadGltfModel(kCornell, &model);
    tinygltf::Buffer extra;
    extra.data = {1, 2, 3, 4, 5};
    model.buffers.push_back(extra);
    tinygltf::BufferView view;
    view.buffer = 1;
    view.byteLength = 5;
    model.bufferViews.push_back(view);
    tinygltf::Image image;
    image.uri = "tex.png";
    model.images.push_back(image);
    ASSERT_FALSE(model.cameras.empty());
    model.cameras[0].perspective.zfar = 0.0;  // infinite
    const std::string glb = (dir / "out.glb").string(), gltf = (dir / "out.gltf").string();
    WriteGltfModel(model, glb, dir.string());
    WriteGltfModel(model, gltf, dir.string());

    tinygltf::Model back;
    ReadGltfModel(glb, &back);
    ASSERT_EQ(back.buffers.size(), 1u);
    EXPECT_TRUE(back.buffers[0].uri.empty());
    ASSERT_EQ(back.images.size(), 1u);
    ASSERT_GE(back.images[0].bufferView, 0);
    EXPECT_EQ(back.images[0].mimeType, "image/png");
    const tinygltf::BufferView& iv = back.bufferViews[back.images[0].bufferView];
    ASSERT_EQ(iv.byteLength, pngBytes.size());
    EXPECT_TRUE(
        std::equal(pngBytes.begin(), pngBytes.end(), back.buffers[0].data.begin() + iv.byteOffset));
    const tinygltf::BufferView& ev = back.bufferViews[model.bufferViews.size() - 1];
    EXPECT_EQ(back.buffers[0].data[ev.byteOffset + 4], 5);
    // No "zfar": 0 in either file.
    for (const std::string& f : {glb, gltf}) {
        std::ifstream in(f, std::ios::binary);
        const std::string text(std::istreambuf_iterator<char>(in), {});
        EXPECT_EQ(text.find("\"zfar\""), std::string::npos) << f;
    }
    EXPECT_THROW(WriteGltfModel(model, glb, "/nonexistent"), Error);
}

}  // namespace
}  // namespace penumbra
