// Scene files written back (gltf_loader.h, WriteGltfModel): a tinygltf model as .glb or
// .gltf, its external buffers and images embedded.
#include <tiny_gltf.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <sstream>

#include "base/check.h"
#include "scene/gltf_loader.h"

namespace penumbra {

namespace {

// Appends `bytes` to `buffer`, 4-byte aligned; returns where they start.
size_t Append(std::vector<unsigned char>& buffer, const unsigned char* bytes, size_t size) {
    const size_t at = (buffer.size() + 3) & ~size_t(3);
    buffer.resize(at + size);
    if (size) std::memcpy(buffer.data() + at, bytes, size);
    return at;
}

std::string MimeOf(const std::string& uri) {
    auto ends = [&](const char* e) {
        const size_t n = std::strlen(e);
        return uri.size() >= n && uri.compare(uri.size() - n, n, e) == 0;
    };
    if (ends(".png")) return "image/png";
    if (ends(".jpg") || ends(".jpeg")) return "image/jpeg";
    if (ends(".ktx2")) return "image/ktx2";
    if (ends(".webp")) return "image/webp";
    return "application/octet-stream";
}

// The percent-decoded form of a relative URI.
std::string DecodeUri(const std::string& uri) {
    std::string out;
    for (size_t i = 0; i < uri.size(); ++i) {
        if (uri[i] == '%' && i + 2 < uri.size() && std::isxdigit(uri[i + 1]) &&
            std::isxdigit(uri[i + 2])) {
            out.push_back(static_cast<char>(std::stoi(uri.substr(i + 1, 2), nullptr, 16)));
            i += 2;
        } else {
            out.push_back(uri[i]);
        }
    }
    return out;
}

}  // namespace

void WriteGltfModel(tinygltf::Model model, const std::string& path, const std::string& inputDir) {
    const bool binary = IsGlbPath(path);
    // One buffer, the others' bytes appended to it.
    if (!model.buffers.empty()) {
        std::vector<size_t> start(model.buffers.size(), 0);
        std::vector<unsigned char> data;
        for (size_t b = 0; b < model.buffers.size(); ++b)
            start[b] = Append(data, model.buffers[b].data.data(), model.buffers[b].data.size());
        for (tinygltf::BufferView& v : model.bufferViews) {
            v.byteOffset += start.at(static_cast<size_t>(v.buffer));
            v.buffer = 0;
        }
        model.buffers.resize(1);
        model.buffers[0].data = std::move(data);
        model.buffers[0].uri.clear();
    }
    // Images in buffer views, as they were encoded (the decoded pixels are dropped): a .glb
    // holds them in its BIN chunk, a .gltf in its one embedded buffer, so that a file written
    // to another folder than its input's has every image it names.
    {
        for (tinygltf::Image& image : model.images) {
            if (image.bufferView >= 0 || image.uri.empty()) continue;
            std::vector<unsigned char> bytes;
            std::string mime = image.mimeType;
            if (tinygltf::IsDataURI(image.uri)) {
                if (!tinygltf::DecodeDataURI(&bytes, mime, image.uri, 0, false))
                    throw Error(path + ": image '" + image.name + "' has an unreadable data URI");
            } else {
                const std::string file = inputDir + "/" + DecodeUri(image.uri);
                std::ifstream in(file, std::ios::binary);
                if (!in) throw Error(path + ": cannot read image " + file);
                bytes.assign(std::istreambuf_iterator<char>(in), {});
                if (mime.empty()) mime = MimeOf(image.uri);
            }
            if (model.buffers.empty()) model.buffers.emplace_back();
            tinygltf::BufferView view;
            view.buffer = 0;
            view.byteOffset = Append(model.buffers[0].data, bytes.data(), bytes.size());
            view.byteLength = bytes.size();
            model.bufferViews.push_back(view);
            image.bufferView = static_cast<int>(model.bufferViews.size()) - 1;
            image.mimeType = mime.empty() ? MimeOf(image.uri) : mime;
            image.uri.clear();
            image.image.clear();
        }
    }
    std::ostringstream out;
    tinygltf::TinyGLTF io;
    if (!io.WriteGltfSceneToStream(&model, out, !binary, binary))
        throw Error(path + ": cannot write glTF");
    std::string bytes = out.str();
    // "zfar": 0 (tinygltf's infinite projection) is not glTF: the key is left out instead.
    auto dropZeroZfar = [](nlohmann::json& j) {
        bool changed = false;
        if (!j.contains("cameras")) return false;
        for (auto& camera : j["cameras"])
            if (camera.contains("perspective") && camera["perspective"].contains("zfar") &&
                camera["perspective"]["zfar"].get<double>() == 0.0) {
                camera["perspective"].erase("zfar");
                changed = true;
            }
        return changed;
    };
    if (!binary) {
        nlohmann::json j = nlohmann::json::parse(bytes);
        if (dropZeroZfar(j)) bytes = j.dump(2);
    } else if (bytes.size() >= 20) {
        // GLB: a 12-byte header, then the JSON chunk (length, type, text padded with spaces
        // to 4 bytes), then the BIN chunk.
        uint32_t jsonLength = 0;
        std::memcpy(&jsonLength, bytes.data() + 12, 4);
        nlohmann::json j = nlohmann::json::parse(bytes.substr(20, jsonLength));
        if (dropZeroZfar(j)) {
            std::string text = j.dump();
            text.resize((text.size() + 3) & ~size_t(3), ' ');
            const uint32_t length = static_cast<uint32_t>(text.size());
            std::string rest = bytes.substr(20 + jsonLength);
            bytes.resize(12);
            bytes.append(reinterpret_cast<const char*>(&length), 4);
            bytes.append(reinterpret_cast<const char*>("JSON"), 4);
            bytes += text;
            bytes += rest;
            const uint32_t total = static_cast<uint32_t>(bytes.size());
            std::memcpy(bytes.data() + 8, &total, 4);
        }
    }
    std::ofstream file(path, std::ios::binary);
    if (!file || !file.write(bytes.data(), static_cast<std::streamsize>(bytes.size())))
        throw Error(path + ": cannot write");
}

}  // namespace penumbra
