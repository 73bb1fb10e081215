// EXT_meshopt_compression in a binary glTF, decoded with Debian's libmeshoptimizer before
// tinygltf reads the file (gltf_read.h, DecodeMeshopt).
#include <meshoptimizer.h>

#include <algorithm>
#include <cstring>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "base/check.h"
#include "scene/gltf_read.h"

namespace penumbra::gltf {
namespace {

constexpr const char* kExtension = "EXT_meshopt_compression";
constexpr uint32_t kJson = 0x4E4F534Au, kBin = 0x004E4942u;

uint64_t Field(const nlohmann::json& j, const char* key, uint64_t otherwise = 0) {
    const auto it = j.find(key);
    return it != j.end() && it->is_number_unsigned() ? it->get<uint64_t>() : otherwise;
}

std::string Text(const nlohmann::json& j, const char* key, const char* otherwise) {
    const auto it = j.find(key);
    return it != j.end() && it->is_string() ? it->get<std::string>() : otherwise;
}

void Drop(nlohmann::json& doc, const char* list) {
    if (!doc.contains(list) || !doc[list].is_array()) return;
    nlohmann::json kept = nlohmann::json::array();
    for (const auto& e : doc[list])
        if (e != kExtension) kept.push_back(e);
    doc[list] = kept;
}

// A .glb of `json` and `bin` (each padded to 4 bytes), its header's magic as given.
std::vector<unsigned char> Glb(uint32_t magic, std::string json, std::vector<unsigned char> bin) {
    json.resize((json.size() + 3) & ~size_t(3), ' ');
    bin.resize((bin.size() + 3) & ~size_t(3), 0);
    std::vector<unsigned char> out(12 + 8 + json.size() + 8 + bin.size());
    const uint32_t header[3] = {magic, 2, uint32_t(out.size())};
    std::memcpy(out.data(), header, 12);
    const uint32_t jsonChunk[2] = {uint32_t(json.size()), kJson};
    std::memcpy(out.data() + 12, jsonChunk, 8);
    std::memcpy(out.data() + 20, json.data(), json.size());
    const uint32_t binChunk[2] = {uint32_t(bin.size()), kBin};
    std::memcpy(out.data() + 20 + json.size(), binChunk, 8);
    std::memcpy(out.data() + 28 + json.size(), bin.data(), bin.size());
    return out;
}

}  // namespace

bool DecodeMeshopt(std::vector<unsigned char>& glb, const std::string& path, uint64_t most) {
    auto fail = [&](const std::string& why) { throw Error(path + ": " + kExtension + ": " + why); };
    uint32_t head[3];
    if (glb.size() < 20) return false;
    std::memcpy(head, glb.data(), 12);
    // The chunks: JSON first, then an optional BIN (glTF 2.0, 4.4.3).
    std::string text;
    std::vector<unsigned char> bin;
    bool hasBin = false;
    for (size_t at = 12; at + 8 <= glb.size();) {
        uint32_t chunk[2];
        std::memcpy(chunk, glb.data() + at, 8);
        if (chunk[0] > glb.size() - at - 8) return false;  // tinygltf names what is wrong
        const unsigned char* data = glb.data() + at + 8;
        if (chunk[1] == kJson && text.empty())
            text.assign(reinterpret_cast<const char*>(data), chunk[0]);
        if (chunk[1] == kBin && !hasBin) bin.assign(data, data + chunk[0]), hasBin = true;
        at += 8 + size_t(chunk[0]);
    }
    if (text.find(kExtension) == std::string::npos) return false;  // most files: no parse
    nlohmann::json doc = nlohmann::json::parse(text, nullptr, false);
    if (!doc.is_object() || !doc.contains("extensionsUsed") || !doc["extensionsUsed"].is_array())
        return false;
    bool used = false;
    for (const auto& e : doc["extensionsUsed"]) used = used || e == kExtension;
    if (!used) return false;
    nlohmann::json& buffers = doc["buffers"];
    nlohmann::json& views = doc["bufferViews"];
    if (!buffers.is_array() || buffers.empty() || !views.is_array())
        fail("no buffers or buffer views");
    // What the decoded buffers may hold in all: `most`, and no more than the codec can make of
    // the compressed bytes (its densest encoding is a few bits a byte), so that a file cannot
    // have memory set aside for data it does not carry.
    const uint64_t reach = std::min<uint64_t>(most, 128 * uint64_t(bin.size()) + (1u << 20));
    uint64_t total = 0;

    // Each fallback buffer (no data of its own) gets its decoded bytes, appended to the BIN.
    std::vector<int> fallback(buffers.size(), -1);  // buffer → its index in `decoded`
    std::vector<std::vector<unsigned char>> decoded;
    for (size_t b = 0; b < buffers.size(); ++b) {
        const nlohmann::json& buffer = buffers[b];
        if (!buffer.is_object() || !buffer.contains("extensions") ||
            !buffer["extensions"].contains(kExtension))
            continue;
        const uint64_t length = Field(buffer, "byteLength");
        total += std::min<uint64_t>(length, uint64_t(1) << 62);
        if (total > reach)
            fail("buffer " + std::to_string(b) + " declares " + std::to_string(length) +
                 " decoded bytes, more than " + std::to_string(reach) +
                 " (the limit, or what its compressed data can hold)");
        fallback[b] = int(decoded.size());
        decoded.emplace_back(length, 0);
    }
    for (size_t v = 0; v < views.size(); ++v) {
        nlohmann::json& view = views[v];
        if (!view.is_object() || !view.contains("extensions") ||
            !view["extensions"].contains(kExtension))
            continue;
        const std::string where = "buffer view " + std::to_string(v);
        const nlohmann::json& e = view["extensions"][kExtension];
        const uint64_t source = Field(e, "buffer", ~0ull), offset = Field(e, "byteOffset"),
                       length = Field(e, "byteLength"), stride = Field(e, "byteStride"),
                       count = Field(e, "count");
        // The compressed bytes must be in the file's own BIN (buffer 0 without a URI).
        if (source != 0 || !hasBin || buffers[0].contains("uri"))
            fail(where + ": its compressed data must lie in the .glb's own binary chunk");
        if (offset > bin.size() || length > bin.size() - offset)
            fail(where + ": its compressed data reaches past the binary chunk");
        const uint64_t target = Field(view, "buffer", ~0ull);
        if (target >= fallback.size() || fallback[target] < 0)
            fail(where + ": it must sit in a fallback buffer (EXT_meshopt_compression fallback)");
        std::vector<unsigned char>& out = decoded[fallback[target]];
        const uint64_t at = Field(view, "byteOffset");
        if (stride == 0 || stride > 256 || count > (uint64_t(1) << 32) ||
            count * stride > Field(view, "byteLength") || at > out.size() ||
            count * stride > out.size() - at)
            fail(where + ": count × byteStride does not fit its view");
        unsigned char* dst = out.data() + at;
        const unsigned char* src = bin.data() + offset;
        const std::string mode = Text(e, "mode", ""), filter = Text(e, "filter", "NONE");
        int rc = -1;
        if (mode == "ATTRIBUTES" && stride % 4 == 0)
            rc = meshopt_decodeVertexBuffer(dst, count, stride, src, length);
        else if (mode == "TRIANGLES" && (stride == 2 || stride == 4) && count % 3 == 0)
            rc = meshopt_decodeIndexBuffer(dst, count, stride, src, length);
        else if (mode == "INDICES" && (stride == 2 || stride == 4))
            rc = meshopt_decodeIndexSequence(dst, count, stride, src, length);
        else
            fail(where + ": mode '" + mode + "' with byteStride " + std::to_string(stride) +
                 " and count " + std::to_string(count) + " is not one the extension defines");
        if (rc != 0)
            fail(where + ": its data does not decode (meshoptimizer error " + std::to_string(rc) +
                 ")");
        if (filter == "OCTAHEDRAL" && (stride == 4 || stride == 8))
            meshopt_decodeFilterOct(dst, count, stride);
        else if (filter == "QUATERNION" && stride == 8)
            meshopt_decodeFilterQuat(dst, count, stride);
        else if (filter == "EXPONENTIAL" && stride % 4 == 0)
            meshopt_decodeFilterExp(dst, count, stride);
        else if (filter != "NONE")
            fail(where + ": filter '" + filter + "' with byteStride " + std::to_string(stride) +
                 " is not one the extension defines");
        view["extensions"].erase(kExtension);
        if (view["extensions"].empty()) view.erase("extensions");
    }
    // The decoded buffers after the BIN's own bytes (4-byte aligned); the views that named
    // them name buffer 0 at the new offsets, the others keep theirs less the buffers gone.
    std::vector<uint64_t> base(decoded.size());
    for (size_t d = 0; d < decoded.size(); ++d) {
        bin.resize((bin.size() + 3) & ~size_t(3), 0);
        base[d] = bin.size();
        bin.insert(bin.end(), decoded[d].begin(), decoded[d].end());
    }
    if (fallback[0] >= 0) fail("buffer 0, the binary chunk, cannot be a fallback buffer");
    if (bin.size() + text.size() > (uint64_t(1) << 32) - 64)
        fail("the decoded file would pass 4 GiB, the most a .glb holds");
    std::vector<int64_t> renumber(buffers.size());
    nlohmann::json kept = nlohmann::json::array();
    for (size_t b = 0; b < buffers.size(); ++b) {
        renumber[b] = fallback[b] >= 0 ? -1 : int64_t(kept.size());
        if (fallback[b] < 0) kept.push_back(buffers[b]);
    }
    for (nlohmann::json& view : views) {
        const uint64_t b = Field(view, "buffer", ~0ull);
        if (b >= renumber.size()) continue;
        if (fallback[b] >= 0) {
            view["buffer"] = 0;
            view["byteOffset"] = Field(view, "byteOffset") + base[fallback[b]];
        } else {
            view["buffer"] = renumber[b];
        }
    }
    kept[0]["byteLength"] = bin.size();
    buffers = kept;
    Drop(doc, "extensionsUsed");
    Drop(doc, "extensionsRequired");

    glb = Glb(head[0], doc.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace), bin);
    return true;
}

}  // namespace penumbra::gltf
