// Builds scenes from quads and boxes, in memory (for tests) or as glTF files (for the
// bundled scenes). Every object is one glTF node; each material one primitive of it.
#pragma once

#include <functional>
#include <map>
#include <string>
#include <vector>

#include "scene/scene.h"

namespace penumbra {

class SceneBuilder {
  public:
    // A diffuse material (metallic 0, roughness 1): albedo = base colour.
    uint32_t AddMaterial(const std::string& name, glm::vec3 albedo, glm::vec3 emission = {});
    // A glTF metallic-roughness material (DeriveReflectance gives its diffuse and lobe).
    uint32_t AddPbrMaterial(const std::string& name, glm::vec3 baseColor, float metallic,
                            float roughness, glm::vec3 emission = {});

    // A planar quad p0..p3 whose normal points to the side of `towards`, as a grid of
    // tiles × tiles (more input vertices where per-vertex output should resolve detail).
    void AddQuad(const std::string& node, uint32_t material, glm::vec3 p0, glm::vec3 p1,
                 glm::vec3 p2, glm::vec3 p3, glm::vec3 towards, int tiles = 1);
    // An axis-aligned quad grid of nx × ny tiles (more input triangles, same surface).
    void AddTiledQuad(const std::string& node, uint32_t material, glm::vec3 origin, glm::vec3 u,
                      glm::vec3 v, int nu, int nv, glm::vec3 towards);
    // A closed box (6 outward faces) centred at `centre`, rotated by `yawDegrees` about +y.
    // `bottom == false` leaves out the face at −y (a box standing on a floor).
    void AddBox(const std::string& node, uint32_t material, glm::vec3 centre, glm::vec3 size,
                float yawDegrees = 0.0f, bool bottom = true);
    // From now on, AddBox writes each face of a box as a node of its own, called
    // `node.N.face` (N counts the boxes, face is +x, -x, +y, -y, +z or -z), as many exporters
    // write boxes: the six nodes close a solid together, none alone (scene/solids.h).
    void SetBoxFacesAsNodes(bool on) { boxFacesAsNodes_ = on; }
    // Box with a different material on its −y face (a light fixture).
    void AddBoxWithBottom(const std::string& node, uint32_t material, uint32_t bottomMaterial,
                          glm::vec3 centre, glm::vec3 size);

    // Marks `node` movable (extras.penumbra.dynamic): its glTF translation is `origin`, so
    // moves rotate about it, and `boundsMin/Max` (world space) bound its motion when given.
    void SetDynamic(const std::string& node, glm::vec3 origin);
    void SetDynamic(const std::string& node, glm::vec3 origin, glm::vec3 boundsMin,
                    glm::vec3 boundsMax);

    // A closed sphere of `rings` latitude bands × `segments` longitudes with shared vertices
    // (one at each pole) and outward normals: 2 + (rings − 1) × segments vertices.
    void AddSphere(const std::string& node, uint32_t material, glm::vec3 centre, float radius,
                   int rings, int segments);
    // A morph target (glTF `targets`) for `node`, which must have one material: each of its
    // vertices displaced by `displacement(position)` (world space, of the vertex as added).
    // The targets carry positions only: a posed mesh gets area-weighted normals.
    void AddMorphTarget(const std::string& node,
                        const std::function<glm::vec3(glm::vec3)>& displacement);

    // A KHR_lights_punctual light on its own node called `light.name`, placed at
    // `light.position` and turned so that its −Z axis is `light.direction`.
    void AddLight(const PunctualLight& light);

    // A perspective camera on its own node: at `eye`, looking at `target`, +Y up, vertical
    // field of view `yfov` (radians).
    void AddCamera(const std::string& name, glm::vec3 eye, glm::vec3 target, float yfov);

    Scene Build() const;
    // Writes .gltf (buffers embedded as base64) or .glb. Throws penumbra::Error.
    void WriteGltf(const std::string& path) const;

  private:
    struct Part {
        std::vector<glm::vec3> positions, normals;
        std::vector<uint32_t> indices;
        std::vector<std::vector<glm::vec3>> targets;  // morph targets: per vertex displacement
    };
    struct Motion {
        glm::vec3 origin{0.0f};
        bool hasBounds = false;
        glm::vec3 boundsMin{0.0f}, boundsMax{0.0f};
    };
    std::map<std::string, Motion> dynamic_;
    std::vector<PunctualLight> lights_;
    std::vector<Camera> cameras_;
    std::vector<Material> materials_;
    std::vector<std::string> nodeOrder_;
    std::map<std::string, std::map<uint32_t, Part>> nodes_;
    bool boxFacesAsNodes_ = false;
    int boxes_ = 0;  // AddBox calls, naming face nodes
};

}  // namespace penumbra
