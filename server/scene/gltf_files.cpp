// A glTF file's reading from disk (gltf_loader.h, ReadGltfModel): the external files it names
// confined to the scene root, its declared sizes checked before its buffers are read, glTF 1.0
// refused with the command that converts it, images kept encoded until a material uses them.
#include <tiny_gltf.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "base/check.h"
#include "scene/gltf_loader.h"
#include "scene/gltf_read.h"

namespace penumbra {

bool IsGlbPath(const std::string& path) {
    return path.size() >= 4 && path.compare(path.size() - 4, 4, ".glb") == 0;
}

namespace {

// What tinygltf's file reading may read: the glTF itself, and its external files as `files`
// confines them.
struct Confinement {
    const GltfFiles* files;
    std::filesystem::path self;  // the glTF, canonical
    std::string overLimit;       // an external file refused for its size (GltfLimitError)
};

}  // namespace

std::string gltf::FileRefusal(const GltfFiles& files, const std::string& filepath) {
    if (!files.root) return "";
    std::error_code ec;
    const std::filesystem::path file = std::filesystem::weakly_canonical(filepath, ec);
    bool inside = false;
    if (!ec && !files.root->empty()) {
        const std::filesystem::path root = std::filesystem::weakly_canonical(*files.root, ec);
        const std::filesystem::path rel = file.lexically_relative(root);
        inside = !ec && !rel.empty() && *rel.begin() != "..";
    }
    if (inside) return "";
    return files.root->empty() ? "external file '" + filepath +
                                     "' refused: an uploaded .glb must hold its buffers and images"
                               : "external file '" + filepath + "' lies outside the scene root " +
                                     files.root->string();
}

namespace {

// tinygltf's file reading (the glTF itself goes through it too), refused outside
// GltfFiles::root.
bool ReadConfinedFile(std::vector<unsigned char>* out, std::string* err,
                      const std::string& filepath, void* user) {
    Confinement& c = *static_cast<Confinement*>(user);
    std::error_code ec;
    const std::filesystem::path file = std::filesystem::weakly_canonical(filepath, ec);
    if (ec || file != c.self) {
        const std::string why = gltf::FileRefusal(*c.files, filepath);
        if (!why.empty()) {
            if (err) *err += why;
            return false;
        }
    }
    // An external file (a buffer or an image) is read whole: its size on disk against the
    // limit first, so that a huge image is refused before it is read.
    if (c.files->maxBufferBytes > 0 && !ec && file != c.self) {
        const uintmax_t bytes = std::filesystem::file_size(file, ec);
        if (!ec && bytes > c.files->maxBufferBytes) {
            c.overLimit = "external file '" + filepath + "' is " + std::to_string(bytes) +
                          " bytes; the limit is " + std::to_string(c.files->maxBufferBytes);
            if (err) *err += c.overLimit;
            return false;
        }
    }
    return tinygltf::ReadWholeFile(out, err, filepath, nullptr);
}

// tinygltf's image callback: keeps each image's encoded bytes (PNG, JPEG) as they are, with
// no size, instead of decoding every image while parsing. What the scene uses is decoded when
// it is read (ReadMap), so a texture nothing uses, or one that is only warned about (a normal
// map), cannot fail the load. `model` is the model being read: tinygltf hands over an image's
// buffer view as byteLength bytes from its byteOffset without checking that they lie inside
// the buffer (a fuzzed .glb read past it), so that is checked here.
bool KeepEncoded(tinygltf::Image* image, int index, std::string* err, std::string*, int, int,
                 const unsigned char* bytes, int size, void* model) {
    const auto& m = *static_cast<const tinygltf::Model*>(model);
    bool inside = size >= 0;
    if (image->bufferView >= 0) {
        // tinygltf checked both indices before calling.
        const auto& view = m.bufferViews.at(static_cast<size_t>(image->bufferView));
        const auto& buffer = m.buffers.at(static_cast<size_t>(view.buffer));
        inside = inside && view.byteOffset <= buffer.data.size() &&
                 view.byteLength <= buffer.data.size() - view.byteOffset &&
                 view.byteLength == static_cast<size_t>(size);
    }
    if (!inside) {
        if (err)
            *err += "image " + std::to_string(index) + "'s buffer view " +
                    std::to_string(image->bufferView) + " lies outside its buffer";
        return false;
    }
    image->image.assign(bytes, bytes + size);
    image->width = image->height = image->component = image->bits = 0;
    return true;
}

bool RefuseWrite(std::string* err, const std::string& path, const std::vector<unsigned char>&,
                 void*) {
    if (err) *err += "not writing " + path;
    return false;
}

}  // namespace

namespace {

// glTF 1.0 is another format (its materials are shader programs, its meshes keyed by name):
// tinygltf reads a 1.0 .gltf as an empty 2.0 scene and fails a 1.0 .glb as "invalid", so
// both are told apart here and sent to a converter.
[[noreturn]] void RefuseGltf1(const std::string& path) {
    throw Error(path +
                ": a glTF 1.0 file; penumbra reads glTF 2.0. Convert it first, e.g. with "
                "Debian's assimp-utils: assimp export " +
                path + " OUT.glb");
}

// Whether the .gltf at `path` is glTF 1.0 in a form tinygltf refuses outright: its top-level
// lists are objects keyed by id (2.0's are arrays), or its asset says 1.x.
bool LooksLikeGltf1(const std::string& path) {
    std::ifstream in(path);
    const nlohmann::json doc = nlohmann::json::parse(in, nullptr, false);
    if (!doc.is_object()) return false;
    if (doc.contains("asset") && doc["asset"].is_object() && doc["asset"].contains("version") &&
        doc["asset"]["version"].is_string())
        return doc["asset"]["version"].get<std::string>().rfind("1.", 0) == 0;
    for (const char* list : {"meshes", "nodes", "accessors"})
        if (doc.contains(list) && doc[list].is_object()) return true;
    return false;
}

// The JSON of a .gltf, or of a .glb's first chunk, read up to `most` bytes (null: longer, or
// not a glTF 2.0 container).
nlohmann::json DeclaredJson(const std::string& path, uint64_t most) {
    std::ifstream in(path, std::ios::binary);
    std::string text;
    if (IsGlbPath(path)) {
        uint32_t head[5] = {};  // magic, version, length; chunk length, chunk type
        in.read(reinterpret_cast<char*>(head), sizeof head);
        if (in.gcount() != sizeof head || head[0] != 0x46546C67u || head[4] != 0x4E4F534Au ||
            head[3] > most)
            return nullptr;
        text.resize(head[3]);
    } else {
        std::error_code ec;
        const uint64_t size = std::filesystem::file_size(path, ec);
        if (ec || size > most) return nullptr;
        text.resize(size);
    }
    in.read(text.data(), std::streamsize(text.size()));
    if (in.gcount() != std::streamsize(text.size())) return nullptr;
    return nlohmann::json::parse(text, nullptr, false);
}

// What the file declares, against files' limits, before tinygltf reads (and allocates) its
// buffers: the buffers' byteLength summed, and the triangles its primitives' accessor counts
// make times the nodes that place each mesh. Throws GltfLimitError.
void CheckDeclaredSize(const std::string& path, const GltfFiles& files) {
    if (files.maxTriangles == 0 && files.maxBufferBytes == 0) return;
    // The JSON itself: a .gltf may carry its buffers as data URIs (4/3 of their bytes).
    const uint64_t most =
        files.maxBufferBytes > 0 ? files.maxBufferBytes * 2 + (16u << 20) : uint64_t(1) << 40;
    const nlohmann::json doc = DeclaredJson(path, most);
    if (doc.is_discarded() || !doc.is_object()) return;  // tinygltf names what is wrong
    auto count = [](const nlohmann::json& j, const char* key) -> uint64_t {
        const auto it = j.find(key);
        return it != j.end() && it->is_number_unsigned() ? it->get<uint64_t>() : 0;
    };
    if (files.maxBufferBytes > 0 && doc.contains("buffers") && doc["buffers"].is_array()) {
        uint64_t bytes = 0;
        for (const auto& b : doc["buffers"])
            if (b.is_object()) bytes += count(b, "byteLength");
        if (bytes > files.maxBufferBytes)
            throw GltfLimitError(path + ": its buffers declare " + std::to_string(bytes) +
                                 " bytes; the limit is " + std::to_string(files.maxBufferBytes));
    }
    if (files.maxTriangles == 0 || !doc.contains("meshes") || !doc["meshes"].is_array() ||
        !doc.contains("nodes") || !doc["nodes"].is_array())
        return;
    const nlohmann::json& accessors = doc.contains("accessors") && doc["accessors"].is_array()
                                          ? doc["accessors"]
                                          : nlohmann::json();
    auto countOf = [&](const nlohmann::json& index) -> uint64_t {
        if (!index.is_number_unsigned() || index.get<uint64_t>() >= accessors.size()) return 0;
        const nlohmann::json& a = accessors[index.get<size_t>()];
        return a.is_object() ? count(a, "count") : 0;
    };
    std::vector<uint64_t> perMesh(doc["meshes"].size(), 0);
    for (size_t m = 0; m < perMesh.size(); ++m) {
        const nlohmann::json& mesh = doc["meshes"][m];
        if (!mesh.is_object() || !mesh.contains("primitives") || !mesh["primitives"].is_array())
            continue;
        for (const auto& prim : mesh["primitives"]) {
            if (!prim.is_object()) continue;
            const uint64_t mode = count(prim, "mode") + (prim.contains("mode") ? 0 : 4);
            uint64_t n = prim.contains("indices") ? countOf(prim["indices"]) : 0;
            if (!prim.contains("indices") && prim.contains("attributes") &&
                prim["attributes"].is_object() && prim["attributes"].contains("POSITION"))
                n = countOf(prim["attributes"]["POSITION"]);
            perMesh[m] += mode == 4 ? n / 3 : (mode == 5 || mode == 6) && n > 2 ? n - 2 : 0;
        }
    }
    uint64_t triangles = 0;
    for (const auto& node : doc["nodes"])
        if (node.is_object() && node.contains("mesh") && node["mesh"].is_number_unsigned() &&
            node["mesh"].get<uint64_t>() < perMesh.size())
            triangles += perMesh[node["mesh"].get<size_t>()];
    if (triangles > files.maxTriangles)
        throw GltfLimitError(path + ": its accessors declare " + std::to_string(triangles) +
                             " triangles; the limit is " + std::to_string(files.maxTriangles));
}

}  // namespace

void ReadGltfModel(const std::string& path, tinygltf::Model* model, const GltfFiles& files) {
    std::ifstream probe(path, std::ios::binary);
    if (!probe) throw Error(path + ": cannot open (no such file?)");
    if (IsGlbPath(path)) {  // the binary container's own version: 1 or 2
        unsigned char header[8] = {};
        probe.read(reinterpret_cast<char*>(header), sizeof header);
        if (probe.gcount() == 8 && std::memcmp(header, "glTF", 4) == 0 && header[4] == 1 &&
            header[5] == 0 && header[6] == 0 && header[7] == 0)
            RefuseGltf1(path);
    }
    CheckDeclaredSize(path, files);
    tinygltf::TinyGLTF loader;
    std::error_code ec;
    Confinement confinement{&files, std::filesystem::weakly_canonical(path, ec), {}};
    tinygltf::FsCallbacks fs{&tinygltf::FileExists, &tinygltf::ExpandFilePath, &ReadConfinedFile,
                             &RefuseWrite, &confinement};
    loader.SetFsCallbacks(fs);
    loader.SetImageLoader(&KeepEncoded, model);
    std::string err, warn;
    bool ok = false;
    if (IsGlbPath(path)) {
        // Read whole, so that EXT_meshopt_compression can be decoded before tinygltf parses.
        probe.clear();
        probe.seekg(0, std::ios::end);
        std::vector<unsigned char> glb(size_t(std::max<std::streamoff>(probe.tellg(), 0)));
        probe.seekg(0);
        probe.read(reinterpret_cast<char*>(glb.data()), std::streamsize(glb.size()));
        const uint64_t most = files.maxBufferBytes > 0 ? files.maxBufferBytes : uint64_t(1) << 32;
        gltf::DecodeMeshopt(glb, path, most);  // in place, when the file uses it
        ok = loader.LoadBinaryFromMemory(model, &err, &warn, glb.data(), unsigned(glb.size()),
                                         std::filesystem::path(path).parent_path().string());
    } else {
        ok = loader.LoadASCIIFromFile(model, &err, &warn, path);
    }
    // EXT_meshopt_compression in a text .gltf: its fallback buffers have no data to read.
    auto refuseMeshopt = [&path](const std::vector<std::string>& used) {
        if (std::find(used.begin(), used.end(), "EXT_meshopt_compression") != used.end())
            throw Error(path +
                        ": EXT_meshopt_compression is read from binary glTF (.glb) only: "
                        "`gltfpack -i FILE -o FILE.glb -c` packs one");
    };
    // tinygltf goes on without an image it could not read: one refused for its size fails.
    if (!confinement.overLimit.empty()) throw GltfLimitError(path + ": " + confinement.overLimit);
    if (ok && !IsGlbPath(path)) refuseMeshopt(model->extensionsUsed);
    if (!ok) {
        if (!IsGlbPath(path)) {
            if (LooksLikeGltf1(path)) RefuseGltf1(path);
            const nlohmann::json doc = DeclaredJson(path, uint64_t(1) << 32);
            std::vector<std::string> used;
            if (doc.is_object() && doc.contains("extensionsUsed") &&
                doc["extensionsUsed"].is_array())
                for (const auto& e : doc["extensionsUsed"])
                    if (e.is_string()) used.push_back(e.get<std::string>());
            refuseMeshopt(used);
        }
        if (err.empty()) err = "unreadable glTF";
        while (!err.empty() && (err.back() == '\n' || err.back() == ' ')) err.pop_back();
        throw Error(path + ": " + err);
    }
    if (model->asset.version.rfind("1.", 0) == 0) RefuseGltf1(path);
}

}  // namespace penumbra
