// Quad/box geometry with flat normals, and its glTF serialisation through tinygltf.
#include "scene/scene_builder.h"

#include <tiny_gltf.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <glm/gtc/matrix_transform.hpp>
#include <numbers>
#define GLM_ENABLE_EXPERIMENTAL
#include <glm/gtx/quaternion.hpp>

#include "base/check.h"
#include "scene/gltf_loader.h"

namespace penumbra {

uint32_t SceneBuilder::AddMaterial(const std::string& name, glm::vec3 albedo, glm::vec3 emission) {
    materials_.push_back(DiffuseMaterial(name, albedo, emission));
    return static_cast<uint32_t>(materials_.size() - 1);
}

uint32_t SceneBuilder::AddPbrMaterial(const std::string& name, glm::vec3 baseColor, float metallic,
                                      float roughness, glm::vec3 emission) {
    materials_.push_back(PbrMaterial(name, baseColor, metallic, roughness, emission));
    return static_cast<uint32_t>(materials_.size() - 1);
}

void SceneBuilder::AddQuad(const std::string& node, uint32_t material, glm::vec3 p0, glm::vec3 p1,
                           glm::vec3 p2, glm::vec3 p3, glm::vec3 towards, int tiles) {
    if (std::find(nodeOrder_.begin(), nodeOrder_.end(), node) == nodeOrder_.end())
        nodeOrder_.push_back(node);
    Part& part = nodes_[node][material];
    glm::vec3 n = glm::normalize(glm::cross(p1 - p0, p3 - p0));
    glm::vec3 centre = 0.25f * (p0 + p1 + p2 + p3);
    bool flip = glm::dot(n, towards - centre) < 0.0f;
    if (flip) {
        std::swap(p1, p3);
        n = -n;
    }
    // A (tiles+1)² grid of shared vertices, bilinear between the corners (planar quads
    // stay planar), two triangles per tile.
    PENUMBRA_CHECK_LE(1, tiles);
    uint32_t base = static_cast<uint32_t>(part.positions.size());
    if (tiles == 1) {  // p0..p3 in order
        for (const auto& p : {p0, p1, p2, p3}) {
            part.positions.push_back(p);
            part.normals.push_back(n);
        }
        part.indices.insert(part.indices.end(),
                            {base, base + 1, base + 2, base, base + 2, base + 3});
        return;
    }
    for (int j = 0; j <= tiles; ++j)
        for (int i = 0; i <= tiles; ++i) {
            float u = float(i) / tiles, v = float(j) / tiles;
            part.positions.push_back((1 - u) * (1 - v) * p0 + u * (1 - v) * p1 + u * v * p2 +
                                     (1 - u) * v * p3);
            part.normals.push_back(n);
        }
    auto at = [&](int i, int j) { return base + uint32_t(j * (tiles + 1) + i); };
    for (int j = 0; j < tiles; ++j)
        for (int i = 0; i < tiles; ++i)
            part.indices.insert(part.indices.end(), {at(i, j), at(i + 1, j), at(i + 1, j + 1),
                                                     at(i, j), at(i + 1, j + 1), at(i, j + 1)});
}

void SceneBuilder::AddSphere(const std::string& node, uint32_t material, glm::vec3 centre,
                             float radius, int rings, int segments) {
    PENUMBRA_CHECK_LE(2, rings);
    PENUMBRA_CHECK_LE(3, segments);
    if (std::find(nodeOrder_.begin(), nodeOrder_.end(), node) == nodeOrder_.end())
        nodeOrder_.push_back(node);
    Part& part = nodes_[node][material];
    const uint32_t base = static_cast<uint32_t>(part.positions.size());
    auto add = [&](glm::vec3 n) {
        part.positions.push_back(centre + radius * n);
        part.normals.push_back(n);
    };
    add({0.0f, 1.0f, 0.0f});  // north pole: base
    for (int r = 1; r < rings; ++r) {
        const float theta = std::numbers::pi_v<float> * float(r) / float(rings);
        for (int s = 0; s < segments; ++s) {
            const float phi = 2.0f * std::numbers::pi_v<float> * float(s) / float(segments);
            add({std::sin(theta) * std::cos(phi), std::cos(theta),
                 std::sin(theta) * std::sin(phi)});
        }
    }
    add({0.0f, -1.0f, 0.0f});  // south pole
    const uint32_t south = static_cast<uint32_t>(part.positions.size() - 1);
    auto ring = [&](int r, int s) {
        return base + 1 + uint32_t((r - 1) * segments + s % segments);
    };
    // Wound counter-clockwise seen from outside (normal = (b − a) × (c − a) points out).
    for (int s = 0; s < segments; ++s) {
        part.indices.insert(part.indices.end(), {base, ring(1, s + 1), ring(1, s)});
        part.indices.insert(part.indices.end(),
                            {south, ring(rings - 1, s), ring(rings - 1, s + 1)});
    }
    for (int r = 1; r + 1 < rings; ++r)
        for (int s = 0; s < segments; ++s)
            part.indices.insert(part.indices.end(),
                                {ring(r, s), ring(r, s + 1), ring(r + 1, s + 1), ring(r, s),
                                 ring(r + 1, s + 1), ring(r + 1, s)});
}

void SceneBuilder::AddMorphTarget(const std::string& node,
                                  const std::function<glm::vec3(glm::vec3)>& displacement) {
    auto it = nodes_.find(node);
    if (it == nodes_.end() || it->second.size() != 1)
        throw Error("a morph target needs a node with one material: '" + node + "'");
    Part& part = it->second.begin()->second;
    std::vector<glm::vec3> d;
    for (const glm::vec3& p : part.positions) d.push_back(displacement(p));
    part.targets.push_back(std::move(d));
}

void SceneBuilder::AddTiledQuad(const std::string& node, uint32_t material, glm::vec3 origin,
                                glm::vec3 u, glm::vec3 v, int nu, int nv, glm::vec3 towards) {
    glm::vec3 du = u / float(nu), dv = v / float(nv);
    glm::vec3 normalSide = towards - (origin + 0.5f * (u + v));
    for (int j = 0; j < nv; ++j)
        for (int i = 0; i < nu; ++i) {
            glm::vec3 p = origin + float(i) * du + float(j) * dv;
            glm::vec3 c = p + 0.5f * (du + dv);
            AddQuad(node, material, p, p + du, p + du + dv, p + dv, c + normalSide);
        }
}

void SceneBuilder::AddBox(const std::string& node, uint32_t material, glm::vec3 centre,
                          glm::vec3 size, float yawDegrees, bool bottom) {
    glm::mat4 rot = glm::rotate(glm::mat4(1.0f), glm::radians(yawDegrees), glm::vec3(0, 1, 0));
    glm::vec3 h = 0.5f * size;
    auto corner = [&](float sx, float sy, float sz) {
        return centre + glm::vec3(rot * glm::vec4(sx * h.x, sy * h.y, sz * h.z, 0.0f));
    };
    // Each face: 4 corners and a point outside it.
    const std::string box = node + "." + std::to_string(boxes_++) + ".";
    for (int axis = 0; axis < 3; ++axis)
        for (int sign = -1; sign <= 1; sign += 2) {
            if (axis == 1 && sign < 0 && !bottom) continue;
            glm::vec3 c[4];
            const float a[4][2] = {{-1, -1}, {1, -1}, {1, 1}, {-1, 1}};
            for (int k = 0; k < 4; ++k) {
                float s[3];
                s[axis] = float(sign);
                s[(axis + 1) % 3] = a[k][0];
                s[(axis + 2) % 3] = a[k][1];
                c[k] = corner(s[0], s[1], s[2]);
            }
            glm::vec3 faceCentre = 0.25f * (c[0] + c[1] + c[2] + c[3]);
            const std::string face = box + (sign > 0 ? "+" : "-") + "xyz"[axis];
            AddQuad(boxFacesAsNodes_ ? face : node, material, c[0], c[1], c[2], c[3],
                    2.0f * faceCentre - centre);
        }
}

void SceneBuilder::AddBoxWithBottom(const std::string& node, uint32_t material,
                                    uint32_t bottomMaterial, glm::vec3 centre, glm::vec3 size) {
    AddBox(node, material, centre, size, 0.0f, false);
    glm::vec3 h = 0.5f * size;
    float y = centre.y - h.y;
    AddQuad(node, bottomMaterial, {centre.x - h.x, y, centre.z - h.z},
            {centre.x + h.x, y, centre.z - h.z}, {centre.x + h.x, y, centre.z + h.z},
            {centre.x - h.x, y, centre.z + h.z}, {centre.x, y - 1.0f, centre.z});
}

void SceneBuilder::SetDynamic(const std::string& node, glm::vec3 origin) {
    dynamic_[node] = Motion{origin};
}

void SceneBuilder::SetDynamic(const std::string& node, glm::vec3 origin, glm::vec3 boundsMin,
                              glm::vec3 boundsMax) {
    dynamic_[node] = Motion{origin, true, boundsMin, boundsMax};
}

void SceneBuilder::AddLight(const PunctualLight& light) {
    if (light.name.empty() || nodes_.count(light.name))
        throw Error("a light needs a name that no other node has");
    lights_.push_back(light);
    lights_.back().direction = glm::normalize(light.direction);
}

void SceneBuilder::AddCamera(const std::string& name, glm::vec3 eye, glm::vec3 target, float yfov) {
    if (name.empty() || nodes_.count(name)) throw Error("a camera needs a name no other node has");
    Camera c;
    c.name = name;
    c.eye = eye;
    c.forward = glm::normalize(target - eye);
    glm::vec3 up(0.0f, 1.0f, 0.0f);
    c.up = glm::normalize(up - glm::dot(up, c.forward) * c.forward);
    c.yfov = yfov;
    cameras_.push_back(c);
}

namespace {
// The rotation of a camera node: −Z to `forward`, +Y to `up`.
glm::quat CameraRotation(const Camera& c) {
    return glm::quat_cast(glm::mat3(glm::cross(c.forward, c.up), c.up, -c.forward));
}

// The rotation that turns −Z into `direction` (unit).
glm::quat LightRotation(const glm::vec3& direction) {
    return glm::rotation(glm::vec3(0.0f, 0.0f, -1.0f), direction);
}
}  // namespace

Scene SceneBuilder::Build() const {
    Scene scene;
    scene.source = "(built in memory)";
    scene.materials = materials_;
    int nodeIndex = 0;
    for (const auto& name : nodeOrder_) {
        SceneNode node;
        node.name = name;
        glm::vec3 origin(0.0f);
        if (auto it = dynamic_.find(name); it != dynamic_.end()) {
            node.dynamic = true;
            origin = it->second.origin;
            node.hasMotionBounds = it->second.hasBounds;
            node.boundsMin = it->second.boundsMin;
            node.boundsMax = it->second.boundsMax;
        }
        node.local = node.world = glm::translate(glm::mat4(1.0f), origin);
        int primIndex = 0;
        for (const auto& [material, part] : nodes_.at(name)) {
            Primitive p;
            p.node = name;
            p.nodeIndex = nodeIndex;
            p.mesh = nodeIndex;
            p.primitive = primIndex++;
            p.material = material;
            p.positions = part.positions;
            p.normals = part.normals;
            p.indices = part.indices;
            for (const auto& v : part.positions) p.objectPositions.push_back(v - origin);
            p.objectNormals = part.normals;
            p.morphPositions = part.targets;
            p.morphNormals.assign(part.targets.size(), {});
            if (!part.targets.empty()) node.morphWeights.assign(part.targets.size(), 0.0f);
            node.primitives.push_back(static_cast<uint32_t>(scene.primitives.size()));
            scene.primitives.push_back(std::move(p));
        }
        scene.nodes.push_back(std::move(node));
        ++nodeIndex;
    }
    for (const PunctualLight& light : lights_) {
        SceneNode node;
        node.name = light.name;
        node.local = node.world = glm::translate(glm::mat4(1.0f), light.position) *
                                  glm::mat4_cast(LightRotation(light.direction));
        PunctualLight placed = light;
        placed.node = nodeIndex++;
        PlaceLight(placed, node.world);
        scene.nodes.push_back(std::move(node));
        scene.lights.push_back(placed);
    }
    for (const Camera& c : cameras_) {
        SceneNode node;
        node.name = c.name;
        node.local = node.world =
            glm::translate(glm::mat4(1.0f), c.eye) * glm::mat4_cast(CameraRotation(c));
        scene.nodes.push_back(std::move(node));
        scene.cameras.push_back(c);
    }
    return scene;
}

namespace {

// The model's materials: base colour, metallic and roughness factors, and emission as
// emissiveFactor times KHR_materials_emissive_strength past 1.
void WriteMaterials(const std::vector<Material>& materials, tinygltf::Model& model) {
    bool usesStrength = false;
    for (const auto& m : materials) {
        tinygltf::Material mat;
        mat.name = m.name;
        mat.pbrMetallicRoughness.baseColorFactor = {m.baseColor.x, m.baseColor.y, m.baseColor.z,
                                                    1.0};
        mat.pbrMetallicRoughness.metallicFactor = m.metallic;
        mat.pbrMetallicRoughness.roughnessFactor = m.roughness;
        float peak = std::max(m.emission.x, std::max(m.emission.y, m.emission.z));
        if (peak > 0.0f) {
            // emissiveFactor is clamped to [0,1] by the spec: the rest goes to the strength.
            glm::vec3 factor = m.emission / std::max(peak, 1.0f);
            mat.emissiveFactor = {factor.x, factor.y, factor.z};
            if (peak > 1.0f) {
                tinygltf::Value::Object strength;
                strength["emissiveStrength"] = tinygltf::Value(double(peak));
                mat.extensions["KHR_materials_emissive_strength"] = tinygltf::Value(strength);
                usesStrength = true;
            }
        }
        model.materials.push_back(mat);
    }
    if (usesStrength) model.extensionsUsed.push_back("KHR_materials_emissive_strength");
}

// The model's one buffer, each view 4-byte aligned.
struct BufferWriter {
    tinygltf::Model& model;
    tinygltf::Buffer buffer;
    int AddView(const void* data, size_t bytes, int target) {
        tinygltf::BufferView view;
        view.buffer = 0;
        view.byteOffset = buffer.data.size();
        view.byteLength = bytes;
        view.target = target;
        buffer.data.resize(buffer.data.size() + ((bytes + 3) & ~size_t(3)));
        std::memcpy(buffer.data.data() + view.byteOffset, data, bytes);
        model.bufferViews.push_back(view);
        return static_cast<int>(model.bufferViews.size() - 1);
    }
};

// The extras of a dynamic node: {"penumbra": {"dynamic": true, "bounds": ...}}.
tinygltf::Value DynamicExtras(bool hasBounds, const glm::vec3& boundsMin,
                              const glm::vec3& boundsMax) {
    tinygltf::Value::Object pen;
    pen["dynamic"] = tinygltf::Value(true);
    if (hasBounds) {
        auto array = [](glm::vec3 v) {
            return tinygltf::Value(tinygltf::Value::Array{tinygltf::Value(double(v.x)),
                                                          tinygltf::Value(double(v.y)),
                                                          tinygltf::Value(double(v.z))});
        };
        tinygltf::Value::Object bounds;
        bounds["min"] = array(boundsMin);
        bounds["max"] = array(boundsMax);
        pen["bounds"] = tinygltf::Value(bounds);
    }
    tinygltf::Value::Object extras;
    extras["penumbra"] = tinygltf::Value(pen);
    return tinygltf::Value(extras);
}

// The punctual lights, each a node with KHR_lights_punctual.
void WriteLights(const std::vector<PunctualLight>& lights, tinygltf::Model& model,
                 tinygltf::Scene& scene) {
    for (const PunctualLight& light : lights) {
        tinygltf::Light out;
        out.name = light.name;
        out.type = light.type == LightType::kPoint  ? "point"
                   : light.type == LightType::kSpot ? "spot"
                                                    : "directional";
        out.color = {light.color.x, light.color.y, light.color.z};
        out.intensity = light.intensity;
        out.range = light.range;
        out.spot.innerConeAngle = light.innerCone;
        out.spot.outerConeAngle = light.outerCone;
        model.lights.push_back(out);
        tinygltf::Node node;
        node.name = light.name;
        glm::quat q = LightRotation(light.direction);
        node.translation = {light.position.x, light.position.y, light.position.z};
        node.rotation = {q.x, q.y, q.z, q.w};
        tinygltf::Value::Object ext;
        ext["light"] = tinygltf::Value(static_cast<int>(model.lights.size() - 1));
        node.extensions["KHR_lights_punctual"] = tinygltf::Value(ext);
        model.nodes.push_back(node);
        scene.nodes.push_back(static_cast<int>(model.nodes.size() - 1));
    }
}

// The perspective cameras, each a node.
void WriteCameras(const std::vector<Camera>& cameras, tinygltf::Model& model,
                  tinygltf::Scene& scene) {
    for (const Camera& c : cameras) {
        tinygltf::Camera out;
        out.name = c.name;
        out.type = "perspective";
        out.perspective.yfov = c.yfov;
        out.perspective.znear = 0.01;
        out.perspective.aspectRatio = 1.0;
        model.cameras.push_back(out);
        tinygltf::Node node;
        node.name = c.name;
        node.camera = static_cast<int>(model.cameras.size() - 1);
        glm::quat q = CameraRotation(c);
        node.translation = {c.eye.x, c.eye.y, c.eye.z};
        node.rotation = {q.x, q.y, q.z, q.w};
        model.nodes.push_back(node);
        scene.nodes.push_back(static_cast<int>(model.nodes.size() - 1));
    }
}

// One part's primitive: its positions (less `origin`), normals, indices and morph targets.
// `positions` are moved by `origin` first. A morph target adds a weight to `mesh`.
tinygltf::Primitive WritePart(std::vector<glm::vec3> positions,
                              const std::vector<glm::vec3>& normals,
                              const std::vector<uint32_t>& indices,
                              const std::vector<std::vector<glm::vec3>>& targets, uint32_t material,
                              const glm::vec3& origin, BufferWriter& writer, tinygltf::Mesh& mesh) {
    tinygltf::Model& model = writer.model;
    for (auto& v : positions) v -= origin;
    tinygltf::Primitive prim;
    prim.material = static_cast<int>(material);
    prim.mode = TINYGLTF_MODE_TRIANGLES;
    glm::vec3 lo(1e30f), hi(-1e30f);
    for (const auto& p : positions) lo = glm::min(lo, p), hi = glm::max(hi, p);
    tinygltf::Accessor pos;
    pos.bufferView =
        writer.AddView(positions.data(), positions.size() * 12, TINYGLTF_TARGET_ARRAY_BUFFER);
    pos.componentType = TINYGLTF_COMPONENT_TYPE_FLOAT;
    pos.type = TINYGLTF_TYPE_VEC3;
    pos.count = positions.size();
    pos.minValues = {lo.x, lo.y, lo.z};
    pos.maxValues = {hi.x, hi.y, hi.z};
    model.accessors.push_back(pos);
    prim.attributes["POSITION"] = static_cast<int>(model.accessors.size() - 1);
    tinygltf::Accessor nrm = pos;
    nrm.bufferView =
        writer.AddView(normals.data(), normals.size() * 12, TINYGLTF_TARGET_ARRAY_BUFFER);
    nrm.minValues.clear();
    nrm.maxValues.clear();
    model.accessors.push_back(nrm);
    prim.attributes["NORMAL"] = static_cast<int>(model.accessors.size() - 1);
    tinygltf::Accessor idx;
    idx.bufferView =
        writer.AddView(indices.data(), indices.size() * 4, TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER);
    idx.componentType = TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT;
    idx.type = TINYGLTF_TYPE_SCALAR;
    idx.count = indices.size();
    model.accessors.push_back(idx);
    prim.indices = static_cast<int>(model.accessors.size() - 1);
    for (const auto& target : targets) {
        glm::vec3 dlo(1e30f), dhi(-1e30f);
        for (const auto& d : target) dlo = glm::min(dlo, d), dhi = glm::max(dhi, d);
        tinygltf::Accessor t = pos;
        t.bufferView =
            writer.AddView(target.data(), target.size() * 12, TINYGLTF_TARGET_ARRAY_BUFFER);
        t.minValues = {dlo.x, dlo.y, dlo.z};
        t.maxValues = {dhi.x, dhi.y, dhi.z};
        model.accessors.push_back(t);
        prim.targets.push_back({{"POSITION", int(model.accessors.size() - 1)}});
        mesh.weights.push_back(0.0);
    }
    return prim;
}

}  // namespace

void SceneBuilder::WriteGltf(const std::string& path) const {
    tinygltf::Model model;
    model.asset.version = "2.0";
    model.asset.generator = "penumbra make_scenes";
    WriteMaterials(materials_, model);
    BufferWriter writer{model, {}};
    tinygltf::Scene scene;
    for (const auto& name : nodeOrder_) {
        tinygltf::Mesh mesh;
        mesh.name = name;
        auto motion = dynamic_.find(name);
        glm::vec3 origin = motion != dynamic_.end() ? motion->second.origin : glm::vec3(0.0f);
        for (const auto& [material, shared] : nodes_.at(name))
            mesh.primitives.push_back(WritePart(shared.positions, shared.normals, shared.indices,
                                                shared.targets, material, origin, writer, mesh));
        model.meshes.push_back(mesh);
        tinygltf::Node node;
        node.name = name;
        node.mesh = static_cast<int>(model.meshes.size() - 1);
        if (motion != dynamic_.end()) {
            node.translation = {origin.x, origin.y, origin.z};
            node.extras = DynamicExtras(motion->second.hasBounds, motion->second.boundsMin,
                                        motion->second.boundsMax);
        }
        model.nodes.push_back(node);
        scene.nodes.push_back(static_cast<int>(model.nodes.size() - 1));
    }
    WriteLights(lights_, model, scene);
    WriteCameras(cameras_, model, scene);
    model.buffers.push_back(writer.buffer);
    model.scenes.push_back(scene);
    model.defaultScene = 0;
    WriteGltfModel(std::move(model), path);
}

}  // namespace penumbra
