// Writes the fuzz targets' seed corpora (scripts/fuzz.sh runs it before the fuzzers): a frame
// of each request the server reads, a sky map with a sun, the bundled scenes as .glb (one
// textured), and the CLI's script lines. Usage: fuzz_seeds SOURCE_DIR CORPUS_DIR.
#include <tiny_gltf.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "base/check.h"
#include "base/image.h"
#include "protocol/delta.h"
#include "protocol/frame.h"
#include "scene/environment.h"
#include "scene/gltf_loader.h"

using namespace penumbra;
namespace fb = protocol::fb;
namespace fs = std::filesystem;

namespace {

void Write(const fs::path& path, const std::vector<uint8_t>& bytes) {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(bytes.data()),
              static_cast<std::streamsize>(bytes.size()));
    if (!out) throw Error("cannot write " + path.string());
}

// The frame seeds: the first byte is fuzz_frame's piece size, then the frames.
void Frames(const fs::path& dir) {
    std::vector<std::pair<std::string, std::vector<uint8_t>>> seeds;
    auto add = [&](const std::string& name, protocol::MessageType type,
                   flatbuffers::FlatBufferBuilder& b) {
        std::vector<uint8_t> bytes{16};
        const std::vector<uint8_t> frame = protocol::EncodeFrame(type, 1, b);
        bytes.insert(bytes.end(), frame.begin(), frame.end());
        seeds.emplace_back(name, bytes);
    };
    const fb::Vec3 grey(0.5f, 0.5f, 0.5f);
    {
        flatbuffers::FlatBufferBuilder b;
        b.Finish(fb::CreateHelloDirect(b, "seed", 1, 1, "token"));
        add("hello", protocol::MessageType::kHello, b);
    }
    {
        flatbuffers::FlatBufferBuilder b;
        std::vector<flatbuffers::Offset<fb::SolverOption>> options{
            fb::CreateSolverOptionDirect(b, "bins", "64")};
        b.Finish(fb::CreateLoadSceneDirect(b, "cornell-box.gltf", nullptr, nullptr, "antiradiance",
                                           0, 2, 0.1f, "cpu", false, nullptr, 1.0f, 0.001f, nullptr,
                                           &grey, 1.0f, 0.0f, 64, 64, &options));
        add("load", protocol::MessageType::kLoadScene, b);
    }
    {
        flatbuffers::FlatBufferBuilder b;
        std::vector<float> m(16, 0.0f);
        m[0] = m[5] = m[10] = m[15] = 1.0f;
        b.Finish(fb::CreateSetTransformDirect(b, "s", "box", &m));
        add("transform", protocol::MessageType::kSetTransform, b);
    }
    {
        flatbuffers::FlatBufferBuilder b;
        fb::SetLightBuilder l(b);
        l.add_color(&grey);
        l.add_intensity(3.0f);
        b.Finish(l.Finish());
        add("light", protocol::MessageType::kSetLight, b);
    }
    {
        flatbuffers::FlatBufferBuilder b;
        b.Finish(fb::CreateSetMaterialDirect(b, "s", "white", &grey, nullptr, 0.5f, 0.0f));
        add("material", protocol::MessageType::kSetMaterial, b);
    }
    {
        flatbuffers::FlatBufferBuilder b;
        b.Finish(fb::CreateSetEnvironmentDirect(b, "s", nullptr, &grey, false, 2.0f, 1.0f, true));
        add("sky", protocol::MessageType::kSetEnvironment, b);
    }
    {
        flatbuffers::FlatBufferBuilder b;
        std::vector<float> p = {0, 0, 0, 1, 0, 0, 0, 1, 0};
        b.Finish(fb::CreateSetVerticesDirect(b, "s", "blob", &p));
        add("vertices", protocol::MessageType::kSetVertices, b);
    }
    {
        flatbuffers::FlatBufferBuilder b;
        std::vector<float> w = {0.25f, 0.75f};
        b.Finish(fb::CreateSetVerticesDirect(b, "s", "blob", nullptr, nullptr, &w));
        add("morph", protocol::MessageType::kSetVertices, b);
    }
    {
        flatbuffers::FlatBufferBuilder b;
        b.Finish(fb::CreateStepDirect(b, "s", 3));
        add("step", protocol::MessageType::kStep, b);
    }
    {
        // A delta frame of four vertices (SPEC.md's example), as a server sends it.
        std::vector<uint16_t> base(12, 0x3c00), next = base;
        next[8] = 0x3800;
        const protocol::DeltaRun run{2, 1};
        size_t raw = 0;
        const std::vector<uint8_t> data = protocol::EncodeDelta({&run, 1}, next, base, raw);
        flatbuffers::FlatBufferBuilder b;
        auto delta = fb::CreateDeltaIrradianceDirect(b, false, 1, 4, nullptr, protocol::kDeltaZstd,
                                                     uint32_t(raw), &data, 0.005f);
        fb::FrameBuilder f(b);
        f.add_frame(2);
        f.add_delta(delta);
        b.Finish(f.Finish());
        add("delta", protocol::MessageType::kFrame, b);
    }
    for (const auto& [name, bytes] : seeds) Write(dir / (name + ".bin"), bytes);
    // All of them in one stream.
    std::vector<uint8_t> all{7};
    for (const auto& seed : seeds)
        all.insert(all.end(), seed.second.begin() + 1, seed.second.end());
    Write(dir / "stream.bin", all);
}

void Sky(const fs::path& dir) {
    Image im(32, 16);
    for (int y = 0; y < im.height; ++y)
        for (int x = 0; x < im.width; ++x)
            im.At(x, y) = glm::vec3(x == 20 && y == 5 ? 500.0f : 0.5f, 0.6f, 0.7f);
    WriteExr((dir / "sunny.exr").string(), im);
}

void Scenes(const fs::path& source, const fs::path& dir) {
    for (const char* name : {"blocker", "cornell-box", "glossy-box"}) {
        tinygltf::TinyGLTF loader;
        tinygltf::Model model;
        std::string err, warn;
        const fs::path in = source / "scenes" / (std::string(name) + ".gltf");
        if (!loader.LoadASCIIFromFile(&model, &err, &warn, in.string()))
            throw Error(in.string() + ": " + err);
        WriteGltfModel(model, (dir / (std::string(name) + ".glb")).string(),
                       in.parent_path().string());
        fs::copy_file(in, dir / (std::string(name) + ".gltf"),
                      fs::copy_options::overwrite_existing);
    }
}

// The Cornell box with a base colour and an emissive texture on its first material (a 4 × 4
// checker PNG, clamped) and TEXCOORD_0 on its first mesh, as .glb: the colour maps' path.
void TexturedScene(const fs::path& source, const fs::path& dir) {
    tinygltf::TinyGLTF loader;
    tinygltf::Model model;
    std::string err, warn;
    const fs::path in = source / "scenes" / "cornell-box.gltf";
    if (!loader.LoadASCIIFromFile(&model, &err, &warn, in.string()))
        throw Error(in.string() + ": " + err);
    const fs::path images = dir / "images";
    fs::create_directories(images);
    std::vector<uint8_t> rgb(4 * 4 * 3);
    for (size_t i = 0; i < rgb.size(); ++i) rgb[i] = ((i / 3) % 4 + (i / 12)) % 2 ? 230 : 20;
    WritePng((images / "checker.png").string(), 4, 4, rgb);
    tinygltf::Primitive& prim = model.meshes.at(0).primitives.at(0);
    const size_t count = model.accessors.at(prim.attributes.at("POSITION")).count;
    std::vector<unsigned char>& data = model.buffers.at(0).data;
    tinygltf::BufferView view;
    view.buffer = 0;
    view.byteOffset = data.size();
    view.byteLength = count * 2 * sizeof(float);
    for (size_t i = 0; i < count; ++i) {
        const float uv[2] = {static_cast<float>(i % 5) * 0.25f, static_cast<float>(i % 3) * 0.5f};
        const auto* bytes = reinterpret_cast<const unsigned char*>(uv);
        data.insert(data.end(), bytes, bytes + sizeof(uv));
    }
    model.bufferViews.push_back(view);
    tinygltf::Accessor uv;
    uv.bufferView = static_cast<int>(model.bufferViews.size()) - 1;
    uv.componentType = TINYGLTF_COMPONENT_TYPE_FLOAT;
    uv.type = TINYGLTF_TYPE_VEC2;
    uv.count = count;
    model.accessors.push_back(uv);
    prim.attributes["TEXCOORD_0"] = static_cast<int>(model.accessors.size()) - 1;
    tinygltf::Image image;
    image.uri = "checker.png";
    model.images.push_back(image);
    tinygltf::Sampler sampler;
    sampler.wrapS = sampler.wrapT = TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE;
    model.samplers.push_back(sampler);
    tinygltf::Texture texture;
    texture.source = 0;
    texture.sampler = 0;
    model.textures.push_back(texture);
    tinygltf::Material& material =
        model.materials.at(static_cast<size_t>(std::max(prim.material, 0)));
    material.pbrMetallicRoughness.baseColorTexture.index = 0;
    material.emissiveTexture.index = 0;
    material.emissiveFactor = {1.0, 1.0, 1.0};
    WriteGltfModel(model, (dir / "textured-cornell-box.glb").string(), images.string());
    fs::remove_all(images);
}

void Scripts(const fs::path& source, const fs::path& dir) {
    fs::copy_file(source / "scenes" / "demo-edits.txt", dir / "demo-edits.txt",
                  fs::copy_options::overwrite_existing);
    std::ofstream out(dir / "edits.txt");
    out << "# a comment\n"
           "move tall_block --translate 0.1,0,0\n"
           "light ceiling --intensity 2 --color 1,0.9,0.8\n"
           "material white --albedo 0.5,0.5,0.5 --roughness 0.3\n"
           "sky --environment-color 1,1,1 --environment-intensity 2\n"
           "step 3\n"
           "wait --timeout 2\n"
           "sleep 0.1\n"
           "get -o out.json --channel total\n"
           "move box --matrix \"1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\"\n";
}

}  // namespace

int main(int argc, char** argv) {
    if (argc != 3) {
        std::fprintf(stderr, "usage: fuzz_seeds SOURCE_DIR CORPUS_DIR\n");
        return 2;
    }
    try {
        const fs::path source = argv[1], corpus = argv[2];
        for (const char* t : {"frame", "gltf", "exr", "script"}) fs::create_directories(corpus / t);
        Frames(corpus / "frame");
        Sky(corpus / "exr");
        Scenes(source, corpus / "gltf");
        TexturedScene(source, corpus / "gltf");
        Scripts(source, corpus / "script");
    } catch (const std::exception& e) {
        std::fprintf(stderr, "fuzz_seeds: %s\n", e.what());
        return 1;
    }
    return 0;
}
