// glTF 2.0 → Scene: node transforms, triangle primitives, materials (docs/ARCHITECTURE.md).
// Unsupported features fail loudly rather than being silently ignored.
#include "scene/gltf_loader.h"

#include <stb/stb_image.h>
#include <tiny_gltf.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <functional>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>
#include <glm/gtc/type_ptr.hpp>
#include <iterator>
#include <nlohmann/json.hpp>
#include <numbers>
#include <sstream>

#include "base/check.h"
#include "base/numeric.h"

namespace penumbra {
namespace {

struct Context {
    const std::string& path;
    const tinygltf::Model& model;
    const GltfFiles& files;
    std::vector<std::string>* notes;  // warnings: input left out or approximated

    [[noreturn]] void Fail(const std::string& where, const std::string& why) const {
        throw Error(path + ": " + where + ": " + why);
    }
};

std::string NodeLabel(const tinygltf::Model& model, int node) {
    const auto& n = model.nodes[node];
    std::ostringstream s;
    s << "node " << node;
    if (!n.name.empty()) s << " '" << n.name << "'";
    return s.str();
}

glm::mat4 LocalTransform(const tinygltf::Node& node) {
    if (node.matrix.size() == 16) {
        glm::mat4 m;
        for (int i = 0; i < 16; ++i) glm::value_ptr(m)[i] = static_cast<float>(node.matrix[i]);
        return m;  // glTF matrices are column-major, as GLM's
    }
    glm::mat4 m(1.0f);
    if (node.translation.size() == 3)
        m = glm::translate(
            m, glm::vec3(node.translation[0], node.translation[1], node.translation[2]));
    if (node.rotation.size() == 4) {
        glm::quat q(static_cast<float>(node.rotation[3]), static_cast<float>(node.rotation[0]),
                    static_cast<float>(node.rotation[1]), static_cast<float>(node.rotation[2]));
        m = m * glm::mat4_cast(q);
    }
    if (node.scale.size() == 3)
        m = glm::scale(m, glm::vec3(node.scale[0], node.scale[1], node.scale[2]));
    return m;
}

// The first byte an accessor reads, for `acc.count` elements of `size` bytes each, `stride`
// (set here: the view's byteStride, or `size`) apart: fails unless its view and buffer exist
// and every element lies inside both. Overflow-safe: counts and offsets come from the file.
const unsigned char* AccessorBytes(const Context& ctx, const std::string& where,
                                   const tinygltf::Accessor& acc, size_t size, size_t& stride,
                                   const std::string& what) {
    const auto& model = ctx.model;
    if (acc.bufferView < 0 || acc.bufferView >= static_cast<int>(model.bufferViews.size()))
        ctx.Fail(where, what + " accessor has no buffer view");
    const auto& view = model.bufferViews[acc.bufferView];
    if (view.buffer < 0 || view.buffer >= static_cast<int>(model.buffers.size()))
        ctx.Fail(where, what + " accessor's buffer view names buffer " +
                            std::to_string(view.buffer) + ", which does not exist");
    const auto& buffer = model.buffers[view.buffer];
    stride = view.byteStride ? view.byteStride : size;
    // The bytes the view may give: its length, cut to what its buffer holds.
    const size_t held = buffer.data.size();
    if (view.byteOffset > held) ctx.Fail(where, what + " buffer view starts past its buffer");
    const size_t limit = std::min<size_t>(view.byteLength, held - view.byteOffset);
    if (acc.count > 0 && (acc.byteOffset > limit || size > limit - acc.byteOffset ||
                          (acc.count - 1) > (limit - acc.byteOffset - size) / stride))
        ctx.Fail(where, what + " accessor reads past the end of its buffer");
    return buffer.data.data() + view.byteOffset + acc.byteOffset;
}

// Reads a float VEC3 accessor (POSITION, NORMAL), honouring byteStride.
std::vector<glm::vec3> ReadVec3(const Context& ctx, const std::string& where, int accessorIndex,
                                const char* attribute) {
    const auto& model = ctx.model;
    if (accessorIndex < 0 || accessorIndex >= static_cast<int>(model.accessors.size()))
        ctx.Fail(where, std::string(attribute) + " names accessor " +
                            std::to_string(accessorIndex) + ", which does not exist");
    const auto& acc = model.accessors[accessorIndex];
    if (acc.sparse.isSparse)
        ctx.Fail(where, std::string(attribute) + " uses a sparse accessor (not supported)");
    if (acc.type != TINYGLTF_TYPE_VEC3 || acc.componentType != TINYGLTF_COMPONENT_TYPE_FLOAT ||
        acc.normalized)
        ctx.Fail(where, std::string(attribute) +
                            " must be float VEC3 (quantized attributes are not supported)");
    size_t stride = 0;
    const unsigned char* bytes =
        AccessorBytes(ctx, where, acc, sizeof(float) * 3, stride, attribute);
    std::vector<glm::vec3> out(acc.count);
    for (size_t i = 0; i < acc.count; ++i) {
        float v[3];
        std::memcpy(v, bytes + stride * i, sizeof(v));
        out[i] = glm::vec3(v[0], v[1], v[2]);
    }
    return out;
}

// Reads a TEXCOORD_n accessor: float, or normalised unsigned byte or short VEC2.
std::vector<glm::vec2> ReadTexcoords(const Context& ctx, const std::string& where,
                                     int accessorIndex, const std::string& attribute) {
    const auto& model = ctx.model;
    if (accessorIndex < 0 || accessorIndex >= static_cast<int>(model.accessors.size()))
        ctx.Fail(where, attribute + " names accessor " + std::to_string(accessorIndex) +
                            ", which does not exist");
    const auto& acc = model.accessors[accessorIndex];
    if (acc.sparse.isSparse) ctx.Fail(where, attribute + " uses a sparse accessor (not supported)");
    const int type = acc.componentType;
    const size_t size = type == TINYGLTF_COMPONENT_TYPE_FLOAT            ? 4
                        : type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT ? 2
                        : type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE  ? 1
                                                                         : 0;
    if (acc.type != TINYGLTF_TYPE_VEC2 || size == 0 || (size < 4 && !acc.normalized))
        ctx.Fail(where,
                 attribute + " must be VEC2 of floats or normalised unsigned bytes or shorts");
    size_t stride = 0;
    const unsigned char* bytes = AccessorBytes(ctx, where, acc, size * 2, stride, attribute);
    std::vector<glm::vec2> out(acc.count);
    for (size_t i = 0; i < acc.count; ++i) {
        const unsigned char* p = bytes + stride * i;
        for (int c = 0; c < 2; ++c) {
            if (size == 4) {
                std::memcpy(&out[i][c], p + 4 * c, 4);
            } else if (size == 2) {
                uint16_t v;
                std::memcpy(&v, p + 2 * c, 2);
                out[i][c] = static_cast<float>(v) / 65535.0f;
            } else {
                out[i][c] = static_cast<float>(p[c]) / 255.0f;
            }
        }
        if (!std::isfinite(out[i].x) || !std::isfinite(out[i].y))
            ctx.Fail(where, attribute + " has NaN or infinity");
    }
    return out;
}

std::vector<uint32_t> ReadIndices(const Context& ctx, const std::string& where, int accessorIndex) {
    const auto& model = ctx.model;
    if (accessorIndex < 0 || accessorIndex >= static_cast<int>(model.accessors.size()))
        ctx.Fail(where, "indices name accessor " + std::to_string(accessorIndex) +
                            ", which does not exist");
    const auto& acc = model.accessors[accessorIndex];
    if (acc.sparse.isSparse) ctx.Fail(where, "indices use a sparse accessor (not supported)");
    if (acc.type != TINYGLTF_TYPE_SCALAR) ctx.Fail(where, "indices accessor must be SCALAR");
    size_t size = 0;
    switch (acc.componentType) {
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
            size = 1;
            break;
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
            size = 2;
            break;
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT:
            size = 4;
            break;
        default:
            ctx.Fail(where, "indices must be unsigned byte, short or int");
    }
    size_t stride = 0;
    const unsigned char* bytes = AccessorBytes(ctx, where, acc, size, stride, "indices");
    std::vector<uint32_t> out(acc.count);
    for (size_t i = 0; i < acc.count; ++i) {
        const unsigned char* p = bytes + stride * i;
        if (size == 1) {
            out[i] = p[0];
        } else if (size == 2) {
            uint16_t v;
            std::memcpy(&v, p, 2);
            out[i] = v;
        } else {
            std::memcpy(&out[i], p, 4);
        }
    }
    return out;
}

// Triangle list from a TRIANGLES / TRIANGLE_STRIP / TRIANGLE_FAN index sequence.
std::vector<uint32_t> ToTriangleList(const Context& ctx, const std::string& where, int mode,
                                     const std::vector<uint32_t>& seq) {
    if (mode == TINYGLTF_MODE_TRIANGLES) {
        if (seq.size() % 3 != 0)
            ctx.Fail(where, "triangle list has " + std::to_string(seq.size()) +
                                " indices, not a multiple of 3");
        return seq;
    }
    std::vector<uint32_t> out;
    if (mode == TINYGLTF_MODE_TRIANGLE_STRIP) {
        for (size_t i = 2; i < seq.size(); ++i) {
            if (i % 2 == 0)
                out.insert(out.end(), {seq[i - 2], seq[i - 1], seq[i]});
            else
                out.insert(out.end(), {seq[i - 1], seq[i - 2], seq[i]});
        }
        return out;
    }
    if (mode == TINYGLTF_MODE_TRIANGLE_FAN) {
        for (size_t i = 2; i < seq.size(); ++i) out.insert(out.end(), {seq[0], seq[i - 1], seq[i]});
        return out;
    }
    ctx.Fail(where, "primitive mode " + std::to_string(mode) +
                        " (points/lines) has no surface to light; only triangles are supported");
}

std::string Refusal(const GltfFiles& files, const std::string& filepath);

// The colour map of glTF texture `textureIndex` as Scene::maps[returned index], decoded on
// first use (ReadGltfModel keeps images encoded) and shared by every material that uses it;
// -1, with a warning, for an image that is missing or cannot be decoded.
int ReadMap(const Context& ctx, const std::string& where, const char* what, int textureIndex,
            Scene& scene, std::vector<int>& mapOfTexture) {
    if (textureIndex < 0 || textureIndex >= static_cast<int>(ctx.model.textures.size()))
        ctx.Fail(where, std::string(what) + " names texture " + std::to_string(textureIndex) +
                            ", which does not exist");
    mapOfTexture.resize(ctx.model.textures.size(), -1);
    if (mapOfTexture[textureIndex] >= 0) return mapOfTexture[textureIndex];
    const auto& tex = ctx.model.textures[textureIndex];
    if (tex.source < 0 || tex.source >= static_cast<int>(ctx.model.images.size()))
        ctx.Fail(where, std::string(what) + " has no image");
    const auto& img = ctx.model.images[tex.source];
    int w = 0, h = 0;
    std::vector<glm::vec3> linear;
    const char* why = "";
    if (!DecodeSrgbImage(img.image, w, h, linear, why)) {
        const std::string image = std::string(what) + " image " + std::to_string(tex.source) +
                                  (img.uri.empty() ? "" : " '" + img.uri + "'");
        // A file the loader may not read is an error; one missing or broken is what a
        // renderer would warn about and draw with the factor alone.
        if (!img.uri.empty() && img.uri.rfind("data:", 0) != 0) {
            const std::string file =
                (std::filesystem::path(ctx.path).parent_path() / img.uri).string();
            if (const std::string refused = Refusal(ctx.files, file); !refused.empty())
                ctx.Fail(where, image + ": " + refused);
        }
        if (ctx.notes)
            ctx.notes->push_back(where + ": " + image + " could not be decoded (" + why +
                                 "): its factor is used alone");
        return -1;
    }
    Wrap wrap[2] = {Wrap::kRepeat, Wrap::kRepeat};
    if (tex.sampler >= 0 && tex.sampler < static_cast<int>(ctx.model.samplers.size())) {
        const auto& sampler = ctx.model.samplers[tex.sampler];
        const int modes[2] = {sampler.wrapS, sampler.wrapT};
        for (int i = 0; i < 2; ++i)
            wrap[i] = modes[i] == TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE     ? Wrap::kClamp
                      : modes[i] == TINYGLTF_TEXTURE_WRAP_MIRRORED_REPEAT ? Wrap::kMirror
                                                                          : Wrap::kRepeat;
    }
    scene.maps.emplace_back(w, h, std::move(linear), wrap[0], wrap[1]);
    return mapOfTexture[textureIndex] = static_cast<int>(scene.maps.size() - 1);
}

// `extras.penumbra` of a node: {"dynamic": bool, "bounds": {"min": [x,y,z], "max": [x,y,z]}}.
void ReadPenumbraExtras(const Context& ctx, const std::string& where, const tinygltf::Value& extras,
                        SceneNode& out) {
    if (!extras.IsObject() || !extras.Has("penumbra")) return;
    const tinygltf::Value& pen = extras.Get("penumbra");
    if (!pen.IsObject()) ctx.Fail(where, "extras.penumbra must be an object");
    if (pen.Has("dynamic")) {
        if (!pen.Get("dynamic").IsBool())
            ctx.Fail(where, "extras.penumbra.dynamic must be true or false");
        out.dynamic = pen.Get("dynamic").Get<bool>();
    }
    if (!pen.Has("bounds")) return;
    const tinygltf::Value& b = pen.Get("bounds");
    auto corner = [&](const char* key) {
        if (!b.IsObject() || !b.Has(key) || !b.Get(key).IsArray() || b.Get(key).ArrayLen() != 3)
            ctx.Fail(where, std::string("extras.penumbra.bounds.") + key +
                                " must be an array of 3 numbers");
        glm::vec3 v;
        for (int i = 0; i < 3; ++i) {
            const tinygltf::Value& c = b.Get(key).Get(i);
            if (!c.IsNumber() || !std::isfinite(c.GetNumberAsDouble()))
                ctx.Fail(where, std::string("extras.penumbra.bounds.") + key +
                                    " must hold finite numbers");
            v[i] = static_cast<float>(c.GetNumberAsDouble());
        }
        return v;
    };
    out.boundsMin = corner("min");
    out.boundsMax = corner("max");
    if (glm::any(glm::greaterThan(out.boundsMin, out.boundsMax)))
        ctx.Fail(where, "extras.penumbra.bounds.min exceeds max");
    out.hasMotionBounds = true;
}

Material ReadMaterial(const Context& ctx, int index, Scene& scene, std::vector<int>& mapOfTexture) {
    const auto& m = ctx.model.materials[index];
    std::string where = "material " + std::to_string(index) + " '" + m.name + "'";
    const auto& pbr = m.pbrMetallicRoughness;
    for (int set : {pbr.baseColorTexture.texCoord, m.emissiveTexture.texCoord})
        if (set < 0 || set > 7) ctx.Fail(where, "a texture's texCoord must be 0 to 7");
    glm::vec3 base(1.0f);
    if (pbr.baseColorFactor.size() >= 3)
        base = glm::vec3(pbr.baseColorFactor[0], pbr.baseColorFactor[1], pbr.baseColorFactor[2]);
    int baseMap = -1, emissionMap = -1;
    if (pbr.baseColorTexture.index >= 0) {
        baseMap = ReadMap(ctx, where, "baseColorTexture", pbr.baseColorTexture.index, scene,
                          mapOfTexture);
        if (baseMap >= 0) base *= scene.maps[baseMap].Mean();
    }
    float metallic = static_cast<float>(pbr.metallicFactor);
    float roughness = static_cast<float>(pbr.roughnessFactor);
    glm::vec3 emissive(0.0f);
    if (m.emissiveFactor.size() == 3)
        emissive = glm::vec3(m.emissiveFactor[0], m.emissiveFactor[1], m.emissiveFactor[2]);
    float strength = 1.0f;
    auto ext = m.extensions.find("KHR_materials_emissive_strength");
    if (ext != m.extensions.end() && ext->second.Has("emissiveStrength"))
        strength = static_cast<float>(ext->second.Get("emissiveStrength").GetNumberAsDouble());
    glm::vec3 emission = emissive * strength;
    if (m.emissiveTexture.index >= 0 && glm::any(glm::greaterThan(emission, glm::vec3(0.0f)))) {
        emissionMap =
            ReadMap(ctx, where, "emissiveTexture", m.emissiveTexture.index, scene, mapOfTexture);
        if (emissionMap >= 0) emission *= scene.maps[emissionMap].Mean();
    }
    for (int c = 0; c < 3; ++c) {
        if (!std::isfinite(base[c]) || base[c] < 0.0f)
            ctx.Fail(where, "base colour is not a finite non-negative number");
        if (!std::isfinite(emission[c]) || emission[c] < 0.0f)
            ctx.Fail(where, "emission is not a finite non-negative number");
    }
    if (glm::any(glm::greaterThan(base, glm::vec3(1.0f))))
        ctx.Fail(where, "base colour exceeds 1 (the surface would create light)");
    if (!(metallic >= 0.0f && metallic <= 1.0f))
        ctx.Fail(where, "metallicFactor is not a number in [0, 1]");
    if (!(roughness >= 0.0f && roughness <= 1.0f))
        ctx.Fail(where, "roughnessFactor is not a number in [0, 1]");
    Material out = PbrMaterial(m.name, base, metallic, roughness, emission);
    out.baseColorMap = baseMap, out.baseColorSet = pbr.baseColorTexture.texCoord;
    out.emissionMap = emissionMap, out.emissionSet = m.emissiveTexture.texCoord;
    return out;
}

// KHR_lights_punctual light `index`, checked; placed by the caller.
PunctualLight ReadLight(const Context& ctx, int index) {
    if (index < 0 || index >= static_cast<int>(ctx.model.lights.size()))
        ctx.Fail("KHR_lights_punctual", "light " + std::to_string(index) + " does not exist");
    const tinygltf::Light& in = ctx.model.lights[index];
    std::string where = "light " + std::to_string(index);
    if (!in.name.empty()) where += " '" + in.name + "'";
    PunctualLight light;
    light.name = in.name;
    if (in.type == "point")
        light.type = LightType::kPoint;
    else if (in.type == "spot")
        light.type = LightType::kSpot;
    else if (in.type == "directional")
        light.type = LightType::kDirectional;
    else
        ctx.Fail(where, "type '" + in.type + "' is not point, spot or directional");
    if (!in.color.empty()) {
        if (in.color.size() != 3) ctx.Fail(where, "color needs 3 numbers");
        for (int c = 0; c < 3; ++c) {
            if (!std::isfinite(in.color[c]) || in.color[c] < 0.0)
                ctx.Fail(where, "color must be finite and not negative");
            light.color[c] = static_cast<float>(in.color[c]);
        }
    }
    if (!std::isfinite(in.intensity) || in.intensity < 0.0)
        ctx.Fail(where, "intensity must be finite and not negative");
    light.intensity = static_cast<float>(in.intensity);
    if (!std::isfinite(in.range) || in.range < 0.0)
        ctx.Fail(where, "range must be a positive number of metres");
    light.range = light.type == LightType::kDirectional ? 0.0f : static_cast<float>(in.range);
    if (light.type == LightType::kSpot) {
        double inner = in.spot.innerConeAngle, outer = in.spot.outerConeAngle;
        if (!(inner >= 0.0 && inner < outer && outer <= std::numbers::pi / 2 + 1e-6))
            ctx.Fail(where, "spot cone angles need 0 <= innerConeAngle < outerConeAngle <= pi/2");
        light.innerCone = static_cast<float>(inner);
        light.outerCone = static_cast<float>(outer);
    }
    return light;
}

}  // namespace

float SrgbToLinear(float c) {
    return c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
}

bool IsGlbPath(const std::string& path) {
    return path.size() >= 4 && path.compare(path.size() - 4, 4, ".glb") == 0;
}

namespace {

// What tinygltf's file reading may read: the glTF itself, and its external files as `files`
// confines them.
struct Confinement {
    const GltfFiles* files;
    std::filesystem::path self;  // the glTF, canonical
};

// Why `filepath`, a file a glTF names, may not be read under `files` ("" when it may).
std::string Refusal(const GltfFiles& files, const std::string& filepath) {
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

// tinygltf's file reading (the glTF itself goes through it too), refused outside
// GltfFiles::root.
bool ReadConfinedFile(std::vector<unsigned char>* out, std::string* err,
                      const std::string& filepath, void* user) {
    const Confinement& c = *static_cast<const Confinement*>(user);
    std::error_code ec;
    const std::filesystem::path file = std::filesystem::weakly_canonical(filepath, ec);
    if (ec || file != c.self) {
        const std::string why = Refusal(*c.files, filepath);
        if (!why.empty()) {
            if (err) *err += why;
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

void ReadGltfModel(const std::string& path, tinygltf::Model* model, const GltfFiles& files) {
    if (std::ifstream probe(path); !probe) throw Error(path + ": cannot open (no such file?)");
    tinygltf::TinyGLTF loader;
    std::error_code ec;
    Confinement confinement{&files, std::filesystem::weakly_canonical(path, ec)};
    tinygltf::FsCallbacks fs{&tinygltf::FileExists, &tinygltf::ExpandFilePath, &ReadConfinedFile,
                             &RefuseWrite, &confinement};
    loader.SetFsCallbacks(fs);
    loader.SetImageLoader(&KeepEncoded, model);
    std::string err, warn;
    bool ok = IsGlbPath(path) ? loader.LoadBinaryFromFile(model, &err, &warn, path)
                              : loader.LoadASCIIFromFile(model, &err, &warn, path);
    if (!ok) {
        if (err.empty()) err = "unreadable glTF";
        while (!err.empty() && (err.back() == '\n' || err.back() == ' ')) err.pop_back();
        throw Error(path + ": " + err);
    }
}

// A primitive's morph targets (POSITION and NORMAL displacements, float VEC3 like the
// attributes; TANGENT is not used). Throws penumbra::Error (through ctx.Fail) for what it
// cannot read; the caller then ignores the targets.
void ReadMorphTargets(const Context& ctx, const std::string& where, const tinygltf::Primitive& prim,
                      Primitive& out) {
    for (size_t t = 0; t < prim.targets.size(); ++t) {
        const std::string label = where + " morph target " + std::to_string(t);
        const auto& target = prim.targets[t];
        std::vector<glm::vec3> dp(out.positions.size(), glm::vec3(0.0f)), dn;
        if (auto it = target.find("POSITION"); it != target.end())
            dp = ReadVec3(ctx, label, it->second, "POSITION");
        if (auto it = target.find("NORMAL"); it != target.end())
            dn = ReadVec3(ctx, label, it->second, "NORMAL");
        if (dp.size() != out.positions.size() || (!dn.empty() && dn.size() != dp.size()))
            ctx.Fail(label, "has another vertex count than its primitive");
        for (const auto* list : {&dp, &dn})
            for (const glm::vec3& v : *list)
                if (!std::isfinite(v.x) || !std::isfinite(v.y) || !std::isfinite(v.z))
                    ctx.Fail(label, "has NaN or infinity");
        out.morphPositions.push_back(std::move(dp));
        out.morphNormals.push_back(std::move(dn));
    }
}

// Poses node `ni`'s mesh at its morph weights (the node's `weights`, else the mesh's, else
// zeros), once its primitives are read. glTF asks every primitive of a mesh for the same
// number of targets; a mesh that breaks that keeps its rest pose, with a warning.
void PoseMorphTargets(const Context& ctx, const std::string& where, const tinygltf::Node& node,
                      Scene& scene, int ni, std::vector<std::string>& warnings) {
    const size_t targets = NodeMorphTargets(scene, ni);
    SceneNode& sn = scene.nodes[ni];
    bool even = true;
    for (uint32_t p : sn.primitives)
        even = even && scene.primitives[p].morphPositions.size() == targets;
    if (targets == 0 || !even) {
        for (uint32_t p : sn.primitives) {
            scene.primitives[p].morphPositions.clear();
            scene.primitives[p].morphNormals.clear();
        }
        if (!even)
            warnings.push_back(where +
                               ": its primitives have different numbers of morph "
                               "targets: they are ignored (rest pose)");
        return;
    }
    const auto& given = !node.weights.empty() ? node.weights : ctx.model.meshes[node.mesh].weights;
    std::vector<float> weights(targets, 0.0f);
    if (!given.empty()) {
        if (given.size() != targets)
            ctx.Fail(where, "has " + std::to_string(given.size()) + " morph weights for " +
                                std::to_string(targets) + " targets");
        for (size_t t = 0; t < targets; ++t) weights[t] = static_cast<float>(given[t]);
    }
    sn.morphWeights = weights;
    bool posed = false;
    for (float w : weights) posed = posed || w != 0.0f;
    if (!posed) return;
    try {
        SetNodeMorphWeights(scene, ni, weights);
    } catch (const Error& e) {
        ctx.Fail(where, e.what());
    }
    for (uint32_t p : sn.primitives) scene.primitives[p].shape = 0;  // as loaded
}

// What LoadGltf read but ignored or approximated, one sentence each (Scene::warnings).
std::vector<std::string> IgnoredInput(const tinygltf::Model& model, const Scene& scene) {
    std::vector<std::string> out;
    auto named = [](const std::string& what, size_t index, const std::string& name) {
        return what + " " + std::to_string(index) + (name.empty() ? "" : " '" + name + "'");
    };
    for (size_t i = 0; i < model.materials.size(); ++i) {
        const auto& m = model.materials[i];
        const std::string where = named("material", i, m.name);
        if (m.pbrMetallicRoughness.baseColorTexture.index >= 0 && scene.materials[i].Glossy())
            out.push_back(where +
                          ": baseColorTexture tints the diffuse albedo only; the glossy lobe "
                          "takes the texture's mean colour");
        std::vector<std::string> maps;
        if (m.normalTexture.index >= 0) maps.push_back("normalTexture");
        if (m.occlusionTexture.index >= 0) maps.push_back("occlusionTexture");
        if (m.pbrMetallicRoughness.metallicRoughnessTexture.index >= 0)
            maps.push_back("metallicRoughnessTexture");
        if (!maps.empty()) {
            std::string list;
            for (const auto& t : maps) list += (list.empty() ? "" : ", ") + t;
            out.push_back(where + ": " + list +
                          " ignored (geometric normals and the factors are used)");
        }
        if (m.alphaMode == "BLEND" || m.alphaMode == "MASK")
            out.push_back(where + ": alphaMode " + m.alphaMode + " ignored (surfaces are opaque)");
    }
    if (!model.skins.empty())
        out.push_back(std::to_string(model.skins.size()) +
                      " skin(s) ignored: skinned meshes are lit in their rest pose");
    if (!model.animations.empty())
        out.push_back(std::to_string(model.animations.size()) +
                      " animation(s) ignored: nodes keep their rest transforms");
    for (const auto& ext : model.extensionsUsed)
        if (ext != "KHR_materials_emissive_strength" && ext != "KHR_lights_punctual")
            out.push_back("extension '" + ext + "' ignored (not supported)");
    size_t unnamed = 0;
    for (const auto& n : model.nodes) unnamed += n.name.empty() && n.mesh >= 0 ? 1 : 0;
    if (unnamed > 0)
        out.push_back(std::to_string(unnamed) +
                      " node(s) with a mesh but no name: called \"node\" and their index");
    size_t cameras = 0;
    for (const auto& n : model.nodes)
        if (n.camera >= 0 && n.camera < static_cast<int>(model.cameras.size()) &&
            model.cameras[n.camera].type != "perspective")
            ++cameras;
    if (cameras > 0)
        out.push_back(std::to_string(cameras) +
                      " orthographic camera(s) skipped (`render` uses perspective ones)");
    return out;
}

Scene LoadGltf(const std::string& path, const GltfFiles& files) {
    tinygltf::Model model;
    ReadGltfModel(path, &model, files);
    std::vector<std::string> readNotes;  // warnings: coordinates, targets or images left out
    Context ctx{path, model, files, &readNotes};

    for (const auto& ext : model.extensionsRequired) {
        if (ext != "KHR_materials_emissive_strength" && ext != "KHR_lights_punctual")
            ctx.Fail("extensionsRequired", "extension '" + ext + "' is not supported");
    }

    Scene scene;
    scene.source = path;
    scene.materials.reserve(model.materials.size() + 1);
    std::vector<int> mapOfTexture;
    for (size_t i = 0; i < model.materials.size(); ++i)
        scene.materials.push_back(ReadMaterial(ctx, static_cast<int>(i), scene, mapOfTexture));
    // glTF's default material: baseColor 1, metallic 1, hence black diffuse.
    uint32_t defaultMaterial = static_cast<uint32_t>(scene.materials.size());
    // Kept black (no light reflected) rather than glTF's rough white metal, so that
    // geometry without a material does not light the scene up.
    scene.materials.push_back(DiffuseMaterial("(default)", glm::vec3(0.0f)));

    std::vector<int> roots;
    if (!model.scenes.empty()) {
        int s = model.defaultScene >= 0 ? model.defaultScene : 0;
        if (s >= static_cast<int>(model.scenes.size()))
            ctx.Fail("scene", "default scene " + std::to_string(s) + " does not exist");
        roots = model.scenes[s].nodes;
    } else {
        std::vector<bool> isChild(model.nodes.size(), false);
        for (const auto& n : model.nodes)
            for (int c : n.children)
                if (c >= 0 && c < static_cast<int>(isChild.size())) isChild[c] = true;
        for (size_t i = 0; i < model.nodes.size(); ++i)
            if (!isChild[i]) roots.push_back(static_cast<int>(i));
    }

    std::vector<int> visits(model.nodes.size(), 0);
    scene.nodes.resize(model.nodes.size());
    for (size_t i = 0; i < model.nodes.size(); ++i)
        scene.nodes[i].name =
            model.nodes[i].name.empty() ? "node" + std::to_string(i) : model.nodes[i].name;
    std::function<void(int, int, int)> visit = [&](int ni, int parentIndex, int depth) {
        if (ni < 0 || ni >= static_cast<int>(model.nodes.size()))
            ctx.Fail("scene graph",
                     "reference to node " + std::to_string(ni) + ", which does not exist");
        if (depth > 256 || ++visits[ni] > 1)
            ctx.Fail(NodeLabel(model, ni),
                     "node appears twice in the hierarchy (cycle or "
                     "shared child)");
        const auto& node = model.nodes[ni];
        if (!node.matrix.empty() && node.matrix.size() != 16)
            ctx.Fail(NodeLabel(model, ni),
                     "matrix has " + std::to_string(node.matrix.size()) + " numbers, not 16");
        SceneNode& sn = scene.nodes[ni];
        sn.parent = parentIndex;
        sn.local = LocalTransform(node);
        glm::mat4 parent = parentIndex >= 0 ? scene.nodes[parentIndex].world : glm::mat4(1.0f);
        glm::mat4 world = parent * sn.local;
        if (!Finite(world)) ctx.Fail(NodeLabel(model, ni), "transform has NaN or infinity");
        sn.world = world;
        ReadPenumbraExtras(ctx, NodeLabel(model, ni), node.extras, sn);
        if (auto ext = node.extensions.find("KHR_lights_punctual"); ext != node.extensions.end()) {
            const tinygltf::Value& index = ext->second.Get("light");
            if (!index.IsInt())
                ctx.Fail(NodeLabel(model, ni), "KHR_lights_punctual needs an integer 'light'");
            PunctualLight light = ReadLight(ctx, index.Get<int>());
            light.node = ni;
            if (light.name.empty()) light.name = sn.name;
            try {
                PlaceLight(light, world);
            } catch (const Error& e) {
                ctx.Fail(NodeLabel(model, ni),
                         "transform is singular (the light has no direction)");
            }
            scene.lights.push_back(light);
        }
        if (node.camera >= 0) {
            // Only perspective cameras matter (`penumbra render`); others are skipped.
            if (node.camera >= static_cast<int>(model.cameras.size()))
                ctx.Fail(NodeLabel(model, ni),
                         "camera " + std::to_string(node.camera) + " does not exist");
            const tinygltf::Camera& cam = model.cameras[node.camera];
            if (cam.type == "perspective") {
                Camera c;
                c.name = cam.name.empty() ? sn.name : cam.name;
                c.yfov = static_cast<float>(cam.perspective.yfov);
                if (!(c.yfov > 0.0f && c.yfov < 3.14f))
                    ctx.Fail(NodeLabel(model, ni), "camera yfov must be in (0, π)");
                c.eye = glm::vec3(world[3]);
                glm::vec3 f = -glm::vec3(world[2]), u = glm::vec3(world[1]);
                if (glm::length(f) < 1e-12f || glm::length(u) < 1e-12f)
                    ctx.Fail(NodeLabel(model, ni), "camera transform is singular");
                c.forward = glm::normalize(f);
                c.up = glm::normalize(u - glm::dot(u, c.forward) * c.forward);
                scene.cameras.push_back(c);
            }
        }
        if (parentIndex >= 0) {
            scene.nodes[parentIndex].children.push_back(ni);
            sn.dynamic = sn.dynamic || scene.nodes[parentIndex].dynamic;
        }
        if (node.mesh >= 0) {
            if (node.mesh >= static_cast<int>(model.meshes.size()))
                ctx.Fail(NodeLabel(model, ni),
                         "mesh " + std::to_string(node.mesh) + " does not exist");
            if (std::abs(glm::determinant(glm::mat3(world))) < 1e-20f)
                ctx.Fail(NodeLabel(model, ni), "transform is singular (zero scale)");
            glm::mat3 normalMatrix = glm::transpose(glm::inverse(glm::mat3(world)));
            bool flips = glm::determinant(glm::mat3(world)) < 0.0f;
            const auto& mesh = model.meshes[node.mesh];
            for (size_t pi = 0; pi < mesh.primitives.size(); ++pi) {
                const auto& prim = mesh.primitives[pi];
                std::string where = NodeLabel(model, ni) + " mesh " + std::to_string(node.mesh) +
                                    " primitive " + std::to_string(pi);
                auto pos = prim.attributes.find("POSITION");
                if (pos == prim.attributes.end()) ctx.Fail(where, "has no POSITION attribute");
                Primitive out;
                out.node = sn.name;
                out.nodeIndex = ni;
                out.mesh = node.mesh;
                out.primitive = static_cast<int>(pi);
                if (prim.material >= static_cast<int>(model.materials.size()))
                    ctx.Fail(where,
                             "material " + std::to_string(prim.material) + " does not exist");
                out.material =
                    prim.material >= 0 ? static_cast<uint32_t>(prim.material) : defaultMaterial;
                out.positions = ReadVec3(ctx, where, pos->second, "POSITION");
                std::vector<uint32_t> seq;
                if (prim.indices >= 0) {
                    seq = ReadIndices(ctx, where, prim.indices);
                } else {
                    seq.resize(out.positions.size());
                    for (size_t i = 0; i < seq.size(); ++i) seq[i] = static_cast<uint32_t>(i);
                }
                out.indices = ToTriangleList(ctx, where, prim.mode, seq);
                for (uint32_t idx : out.indices)
                    if (idx >= out.positions.size())
                        ctx.Fail(where, "index " + std::to_string(idx) + " is past the " +
                                            std::to_string(out.positions.size()) + " vertices");
                for (const auto& p : out.positions)
                    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
                        ctx.Fail(where, "POSITION has NaN or infinity");
                auto nrm = prim.attributes.find("NORMAL");
                if (nrm != prim.attributes.end()) {
                    out.normals = ReadVec3(ctx, where, nrm->second, "NORMAL");
                    if (out.normals.size() != out.positions.size())
                        ctx.Fail(where, "NORMAL and POSITION counts differ");
                    for (const auto& n : out.normals) {
                        float len = glm::length(normalMatrix * n);
                        if (!std::isfinite(len) || len == 0.0f)
                            ctx.Fail(where, "NORMAL has a zero, NaN or infinite vector");
                    }
                }
                // The texture coordinates the material's maps read.
                const Material& material = scene.materials[out.material];
                for (auto [map, set] : {std::pair{material.baseColorMap, material.baseColorSet},
                                        {material.emissionMap, material.emissionSet}}) {
                    if (map < 0) continue;
                    const std::string name = "TEXCOORD_" + std::to_string(set);
                    auto uv = prim.attributes.find(name);
                    if (uv == prim.attributes.end()) {
                        readNotes.push_back(where + ": no " + name +
                                            " for its material's texture: the texture's mean "
                                            "colour is used over it");
                        continue;
                    }
                    if (static_cast<int>(out.texcoords.size()) <= set)
                        out.texcoords.resize(set + 1);
                    if (!out.texcoords[set].empty()) continue;
                    out.texcoords[set] = ReadTexcoords(ctx, where, uv->second, name);
                    if (out.texcoords[set].size() != out.positions.size())
                        ctx.Fail(where, name + " and POSITION counts differ");
                }
                // Morph targets: displacements in the mesh's own space (posed below).
                if (!prim.targets.empty()) {
                    try {
                        ReadMorphTargets(ctx, where, prim, out);
                    } catch (const Error& e) {
                        out.morphPositions.clear();
                        out.morphNormals.clear();
                        readNotes.push_back(std::string(e.what()) +
                                            ": its morph targets are ignored (rest pose)");
                    }
                }
                // No normals: flat ones, as glTF draws such a mesh (in the mesh's own space).
                if (out.normals.empty()) SplitForFlatNormals(out);
                // Keep the mesh-space vertices (moves re-place them), then go to world space.
                out.objectPositions = out.positions;
                out.objectNormals = out.normals;
                for (auto& p : out.positions) p = glm::vec3(world * glm::vec4(p, 1.0f));
                for (auto& n : out.normals) n = glm::normalize(normalMatrix * n);
                if (flips)
                    for (size_t t = 0; t + 2 < out.indices.size(); t += 3)
                        std::swap(out.indices[t + 1], out.indices[t + 2]);
                scene.nodes[ni].primitives.push_back(
                    static_cast<uint32_t>(scene.primitives.size()));
                scene.primitives.push_back(std::move(out));
            }
        }
        if (node.mesh >= 0) PoseMorphTargets(ctx, NodeLabel(model, ni), node, scene, ni, readNotes);
        for (int c : node.children) visit(c, ni, depth + 1);
    };
    for (int r : roots) visit(r, -1, 0);

    if (scene.TriangleCount() == 0) throw Error(path + ": the scene has no triangles to light");
    scene.warnings = IgnoredInput(model, scene);
    scene.warnings.insert(scene.warnings.end(), readNotes.begin(), readNotes.end());
    return scene;
}

}  // namespace penumbra
