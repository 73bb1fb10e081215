// The scene as the solver sees it: world-space triangle primitives (one per glTF
// node × mesh primitive, input vertex order kept) and their diffuse materials.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <string>
#include <vector>

namespace penumbra {

struct Material {
    std::string name;
    glm::vec3 albedo{0.8f};    // diffuse reflectance, baseColor × (1 − metallic)
    glm::vec3 emission{0.0f};  // emitted radiance (nits), emissiveFactor × strength
};

// One glTF mesh primitive placed by one node, in world space.
struct Primitive {
    std::string node;  // glTF node name (the object name in the protocol)
    int nodeIndex = -1;
    int mesh = -1;
    int primitive = -1;
    uint32_t material = 0;
    std::vector<glm::vec3> positions;  // world space, in the input's vertex order
    std::vector<glm::vec3> normals;    // world space, unit length, one per position
    std::vector<uint32_t> indices;     // triangle list into positions
    // The same vertices in the node's own (mesh) space, so a move re-places them exactly.
    std::vector<glm::vec3> objectPositions;
    std::vector<glm::vec3> objectNormals;
};

// One glTF node: its transform, whether it may move, and the primitives it places.
struct SceneNode {
    std::string name;
    int parent = -1;
    std::vector<int> children;
    glm::mat4 local{1.0f};  // relative to the parent, as in the file
    glm::mat4 world{1.0f};
    // `extras.penumbra.dynamic` on the node or an ancestor: the node may be moved.
    bool dynamic = false;
    // `extras.penumbra.bounds` {min, max} (world space): where its geometry may go.
    bool hasMotionBounds = false;
    glm::vec3 boundsMin{0.0f}, boundsMax{0.0f};
    std::vector<uint32_t> primitives;  // indices into Scene::primitives
};

struct Scene {
    std::string source;  // file it came from, for messages
    std::vector<Material> materials;
    std::vector<Primitive> primitives;
    std::vector<SceneNode> nodes;  // indexed like the file's nodes (Primitive::nodeIndex)
    // KHR_lights_punctual lights in the file. Not lit yet (issue 5): their direct light is
    // missing from every channel, so services refuse the `direct` and `total` channels.
    int punctualLights = 0;

    glm::vec3 BoundsMin() const;
    glm::vec3 BoundsMax() const;
    float Diameter() const;  // length of the bounding box diagonal
    size_t VertexCount() const;
    size_t TriangleCount() const;
};

// Index of the node called `name`, or -1.
int FindNode(const Scene& scene, const std::string& name);

// Replaces node `node`'s local transform and re-places the geometry of its subtree.
// Throws penumbra::Error for a non-finite or singular matrix (the scene is unchanged then).
void SetNodeTransform(Scene& scene, int node, const glm::mat4& local);

// Fills `normals` with area-weighted vertex normals of the triangles.
void ComputeVertexNormals(Primitive& primitive);

}  // namespace penumbra
