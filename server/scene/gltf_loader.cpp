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
#include "scene/gltf_read.h"

namespace penumbra {
namespace {

using gltf::Context;
using gltf::LocalTransform;
using gltf::NodeLabel;

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
    // Its size decoded, from its header, before it is decoded: a small file can claim a
    // huge picture. Linear texels (12 bytes) and their smaller levels take about 16 a pixel.
    if (ctx.files.maxBufferBytes > 0 && EncodedImageSize(img.image, w, h) &&
        uint64_t(w) * uint64_t(h) * 16 > ctx.files.maxBufferBytes)
        throw GltfLimitError(
            ctx.path + ": " + where + ": " + what + " image " + std::to_string(tex.source) +
            " is " + std::to_string(w) + " × " + std::to_string(h) + " pixels, " +
            std::to_string(uint64_t(w) * uint64_t(h) * 16) + " bytes decoded; the limit is " +
            std::to_string(ctx.files.maxBufferBytes));
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
            if (const std::string refused = gltf::FileRefusal(ctx.files, file); !refused.empty())
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

// A textureInfo's KHR_texture_transform: `map` becomes a copy of itself (the texels shared)
// read through the transform, translation × rotation × scale as the extension defines them,
// and `set` its texCoord, if it overrides it.
void ReadTextureTransform(const Context& ctx, const std::string& where, const char* what,
                          const tinygltf::ExtensionMap& extensions, Scene& scene, int& map,
                          int& set) {
    auto it = extensions.find("KHR_texture_transform");
    if (it == extensions.end() || map < 0) return;
    const tinygltf::Value& t = it->second;
    const std::string at = where + ": " + what + "'s KHR_texture_transform";
    auto number = [&](const tinygltf::Value& v, const char* name) {
        const double x = v.IsNumber() ? v.GetNumberAsDouble() : NAN;
        if (!std::isfinite(x)) ctx.Fail(at, std::string(name) + " is not a finite number");
        return static_cast<float>(x);
    };
    auto pair = [&](const char* name, glm::vec2 value) {
        if (!t.Has(name)) return value;
        const tinygltf::Value& v = t.Get(name);
        if (!v.IsArray() || v.ArrayLen() != 2)
            ctx.Fail(at, std::string(name) + " is not 2 numbers");
        return glm::vec2(number(v.Get(0), name), number(v.Get(1), name));
    };
    const glm::vec2 offset = pair("offset", glm::vec2(0.0f)),
                    scale = pair("scale", glm::vec2(1.0f));
    const float rotation = t.Has("rotation") ? number(t.Get("rotation"), "rotation") : 0.0f;
    if (t.Has("texCoord")) {
        const float c = number(t.Get("texCoord"), "texCoord");
        if (!(c >= 0.0f && c <= 7.0f && c == std::floor(c)))
            ctx.Fail(at, "texCoord must be 0 to 7");
        set = static_cast<int>(c);
    }
    const float cs = std::cos(rotation), sn = std::sin(rotation);
    const glm::mat3 translate(1, 0, 0, 0, 1, 0, offset.x, offset.y, 1);  // columns, as GLSL's
    const glm::mat3 rotate(cs, sn, 0, -sn, cs, 0, 0, 0, 1);
    const glm::mat3 stretch(scale.x, 0, 0, 0, scale.y, 0, 0, 0, 1);
    scene.maps.push_back(scene.maps[map].Transformed(translate * rotate * stretch));
    map = static_cast<int>(scene.maps.size()) - 1;
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
    // Coverage (alphaMode) and thin transmission (KHR_materials_transmission).
    const float alpha =
        pbr.baseColorFactor.size() == 4 ? static_cast<float>(pbr.baseColorFactor[3]) : 1.0f;
    if (!(alpha >= 0.0f && alpha <= 1.0f)) ctx.Fail(where, "base colour alpha is not in [0, 1]");
    float coverage = 1.0f;
    if (m.alphaMode == "BLEND") coverage = alpha;
    if (m.alphaMode == "MASK") coverage = alpha >= static_cast<float>(m.alphaCutoff) ? 1.0f : 0.0f;
    float transmission = 0.0f;
    if (auto t = m.extensions.find("KHR_materials_transmission");
        t != m.extensions.end() && t->second.Has("transmissionFactor"))
        transmission = static_cast<float>(t->second.Get("transmissionFactor").GetNumberAsDouble());
    if (!(transmission >= 0.0f && transmission <= 1.0f))
        ctx.Fail(where, "KHR_materials_transmission's transmissionFactor is not in [0, 1]");
    if (coverage < 1.0f || transmission > 0.0f) PassThrough(out, coverage, transmission);
    int baseSet = pbr.baseColorTexture.texCoord, emissionSet = m.emissiveTexture.texCoord;
    ReadTextureTransform(ctx, where, "baseColorTexture", pbr.baseColorTexture.extensions, scene,
                         baseMap, baseSet);
    ReadTextureTransform(ctx, where, "emissiveTexture", m.emissiveTexture.extensions, scene,
                         emissionMap, emissionSet);
    out.baseColorMap = baseMap, out.baseColorSet = baseSet;
    out.emissionMap = emissionMap, out.emissionSet = emissionSet;
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

namespace {

// The extensions whose meaning the loader takes in: emissive strength, punctual lights,
// Draco-compressed meshes (decoded by tinygltf with Debian's libdraco as the file is read),
// quantised attributes (gltf_accessors.cpp), meshopt-compressed buffers (gltf_meshopt.cpp),
// thin transmission and texture-coordinate transforms of the colour maps.
bool Supported(const std::string& extension) {
    return extension == "KHR_materials_emissive_strength" || extension == "KHR_lights_punctual" ||
           extension == "KHR_draco_mesh_compression" || extension == "KHR_mesh_quantization" ||
           extension == "EXT_meshopt_compression" || extension == "KHR_materials_transmission" ||
           extension == "KHR_texture_transform";
}

}  // namespace

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
        if ((m.alphaMode == "BLEND" || m.alphaMode == "MASK") &&
            m.pbrMetallicRoughness.baseColorTexture.index >= 0)
            out.push_back(where + ": alphaMode " + m.alphaMode +
                          ": coverage from the base colour factor's alpha alone (the texture's "
                          "alpha, a cutout's shape, is not read)");
        if (m.extensions.count("KHR_materials_transmission") &&
            m.extensions.at("KHR_materials_transmission").Has("transmissionTexture"))
            out.push_back(where + ": transmissionTexture ignored (the factor is used)");
    }
    if (!model.skins.empty())
        out.push_back(std::to_string(model.skins.size()) +
                      " skin(s) ignored: skinned meshes are lit in their rest pose");
    if (!model.animations.empty())
        out.push_back(std::to_string(model.animations.size()) +
                      " animation(s) ignored: nodes keep their rest transforms");
    for (const auto& ext : model.extensionsUsed)
        if (!Supported(ext)) out.push_back("extension '" + ext + "' ignored (not supported)");
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

namespace {

// The nodes the scene starts from: the default scene's (the first's), or without scenes every
// node that is no node's child.
std::vector<int> SceneRoots(const Context& ctx) {
    const tinygltf::Model& model = ctx.model;
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
    return roots;
}

// Node `ni`'s KHR_lights_punctual light (if any), placed by its world transform.
void ReadNodeLight(const Context& ctx, int ni, Scene& scene) {
    const tinygltf::Model& model = ctx.model;
    const tinygltf::Node& node = model.nodes[ni];
    const SceneNode& sn = scene.nodes[ni];
    if (auto ext = node.extensions.find("KHR_lights_punctual"); ext != node.extensions.end()) {
        const tinygltf::Value& index = ext->second.Get("light");
        if (!index.IsInt())
            ctx.Fail(NodeLabel(model, ni), "KHR_lights_punctual needs an integer 'light'");
        PunctualLight light = ReadLight(ctx, index.Get<int>());
        light.node = ni;
        if (light.name.empty()) light.name = sn.name;
        try {
            PlaceLight(light, sn.world);
        } catch (const Error& e) {
            ctx.Fail(NodeLabel(model, ni), "transform is singular (the light has no direction)");
        }
        scene.lights.push_back(light);
    }
}

// Node `ni`'s camera (model.nodes[ni].camera, ≥ 0): a perspective one is kept (`penumbra
// render`), others are skipped.
void ReadNodeCamera(const Context& ctx, int ni, Scene& scene) {
    const tinygltf::Model& model = ctx.model;
    const tinygltf::Node& node = model.nodes[ni];
    const SceneNode& sn = scene.nodes[ni];
    const glm::mat4& world = sn.world;
    if (node.camera >= static_cast<int>(model.cameras.size()))
        ctx.Fail(NodeLabel(model, ni), "camera " + std::to_string(node.camera) + " does not exist");
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

}  // namespace

Scene LoadGltf(const std::string& path, const GltfFiles& files) {
    tinygltf::Model model;
    ReadGltfModel(path, &model, files);
    std::vector<std::string> readNotes;  // warnings: coordinates, targets or images left out
    Context ctx{path, model, files, &readNotes};

    for (const auto& ext : model.extensionsRequired) {
        if (!Supported(ext))
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

    const std::vector<int> roots = SceneRoots(ctx);

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
        ReadNodeLight(ctx, ni, scene);
        if (node.camera >= 0) ReadNodeCamera(ctx, ni, scene);
        if (parentIndex >= 0) {
            scene.nodes[parentIndex].children.push_back(ni);
            sn.dynamic = sn.dynamic || scene.nodes[parentIndex].dynamic;
        }
        if (node.mesh >= 0) gltf::ReadNodeMeshes(ctx, ni, world, defaultMaterial, scene);
        for (int c : node.children) visit(c, ni, depth + 1);
    };
    for (int r : roots) visit(r, -1, 0);

    if (scene.TriangleCount() == 0) throw Error(path + ": the scene has no triangles to light");
    scene.warnings = IgnoredInput(model, scene);
    scene.warnings.insert(scene.warnings.end(), readNotes.begin(), readNotes.end());
    return scene;
}

}  // namespace penumbra
