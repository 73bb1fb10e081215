// Writes the fuzz targets' seed corpora (scripts/fuzz.sh runs it before the fuzzers): a frame
// of each request the server reads, a sky map with a sun, the bundled scenes as .glb, and the
// CLI's script lines. Usage: fuzz_seeds SOURCE_DIR CORPUS_DIR.
#include <tiny_gltf.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "base/check.h"
#include "base/image.h"
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
        b.Finish(fb::CreateStepDirect(b, "s", 3));
        add("step", protocol::MessageType::kStep, b);
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
        Scripts(source, corpus / "script");
    } catch (const std::exception& e) {
        std::fprintf(stderr, "fuzz_seeds: %s\n", e.what());
        return 1;
    }
    return 0;
}
