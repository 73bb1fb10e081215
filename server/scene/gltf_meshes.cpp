// A glTF node's meshes: primitives read, checked, given flat normals where they have none,
// placed in world space and posed at their morph weights (gltf_read.h).
#include <cmath>
#include <utility>

#include "scene/gltf_read.h"

namespace penumbra::gltf {
namespace {

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

// The texture coordinates primitive `prim`'s material's maps read; a map without its set is
// warned about (its texture's mean colour is used over the primitive).
void ReadMapCoordinates(const Context& ctx, const std::string& where,
                        const tinygltf::Primitive& prim, const Material& material, Primitive& out) {
    for (auto [map, set] : {std::pair{material.baseColorMap, material.baseColorSet},
                            {material.emissionMap, material.emissionSet}}) {
        if (map < 0) continue;
        const std::string name = "TEXCOORD_" + std::to_string(set);
        auto uv = prim.attributes.find(name);
        if (uv == prim.attributes.end()) {
            ctx.notes->push_back(where + ": no " + name +
                                 " for its material's texture: the texture's mean colour is "
                                 "used over it");
            continue;
        }
        if (static_cast<int>(out.texcoords.size()) <= set) out.texcoords.resize(set + 1);
        if (!out.texcoords[set].empty()) continue;
        out.texcoords[set] = ReadTexcoords(ctx, where, uv->second, name);
        if (out.texcoords[set].size() != out.positions.size())
            ctx.Fail(where, name + " and POSITION counts differ");
    }
}

// Primitive `prim`'s triangles, vertices and attributes in the mesh's own space, checked.
// `normalMatrix`: the node's, for telling a normal that its transform makes zero.
Primitive ReadPrimitive(const Context& ctx, const std::string& where,
                        const tinygltf::Primitive& prim, const glm::mat3& normalMatrix,
                        uint32_t defaultMaterial, const Scene& scene) {
    const tinygltf::Model& model = ctx.model;
    auto pos = prim.attributes.find("POSITION");
    if (pos == prim.attributes.end()) ctx.Fail(where, "has no POSITION attribute");
    Primitive out;
    if (prim.material >= static_cast<int>(model.materials.size()))
        ctx.Fail(where, "material " + std::to_string(prim.material) + " does not exist");
    out.material = prim.material >= 0 ? static_cast<uint32_t>(prim.material) : defaultMaterial;
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
    ReadMapCoordinates(ctx, where, prim, scene.materials[out.material], out);
    // Morph targets: displacements in the mesh's own space (posed by the caller).
    if (!prim.targets.empty()) {
        try {
            ReadMorphTargets(ctx, where, prim, out);
        } catch (const Error& e) {
            out.morphPositions.clear();
            out.morphNormals.clear();
            ctx.notes->push_back(std::string(e.what()) +
                                 ": its morph targets are ignored (rest pose)");
        }
    }
    // No normals: flat ones, as glTF draws such a mesh (in the mesh's own space).
    if (out.normals.empty()) SplitForFlatNormals(out);
    return out;
}

// Keeps `out`'s mesh-space vertices (moves re-place them), then takes it to world space: a
// transform that mirrors turns its triangles' winding back.
void PlaceInWorld(Primitive& out, const glm::mat4& world, const glm::mat3& normalMatrix) {
    out.objectPositions = out.positions;
    out.objectNormals = out.normals;
    for (auto& p : out.positions) p = glm::vec3(world * glm::vec4(p, 1.0f));
    for (auto& n : out.normals) n = glm::normalize(normalMatrix * n);
    if (glm::determinant(glm::mat3(world)) < 0.0f)
        for (size_t t = 0; t + 2 < out.indices.size(); t += 3)
            std::swap(out.indices[t + 1], out.indices[t + 2]);
}

}  // namespace

void ReadNodeMeshes(const Context& ctx, int ni, const glm::mat4& world, uint32_t defaultMaterial,
                    Scene& scene) {
    const tinygltf::Model& model = ctx.model;
    const tinygltf::Node& node = model.nodes[ni];
    if (node.mesh >= static_cast<int>(model.meshes.size()))
        ctx.Fail(NodeLabel(model, ni), "mesh " + std::to_string(node.mesh) + " does not exist");
    if (std::abs(glm::determinant(glm::mat3(world))) < 1e-20f)
        ctx.Fail(NodeLabel(model, ni), "transform is singular (zero scale)");
    const glm::mat3 normalMatrix = glm::transpose(glm::inverse(glm::mat3(world)));
    const auto& mesh = model.meshes[node.mesh];
    for (size_t pi = 0; pi < mesh.primitives.size(); ++pi) {
        const std::string where = NodeLabel(model, ni) + " mesh " + std::to_string(node.mesh) +
                                  " primitive " + std::to_string(pi);
        Primitive out =
            ReadPrimitive(ctx, where, mesh.primitives[pi], normalMatrix, defaultMaterial, scene);
        out.node = scene.nodes[ni].name;
        out.nodeIndex = ni;
        out.mesh = node.mesh;
        out.primitive = static_cast<int>(pi);
        PlaceInWorld(out, world, normalMatrix);
        scene.nodes[ni].primitives.push_back(static_cast<uint32_t>(scene.primitives.size()));
        scene.primitives.push_back(std::move(out));
    }
    PoseMorphTargets(ctx, NodeLabel(model, ni), node, scene, ni, *ctx.notes);
}

}  // namespace penumbra::gltf
