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
};

struct Scene {
    std::string source;  // file it came from, for messages
    std::vector<Material> materials;
    std::vector<Primitive> primitives;

    glm::vec3 BoundsMin() const;
    glm::vec3 BoundsMax() const;
    float Diameter() const;  // length of the bounding box diagonal
    size_t VertexCount() const;
    size_t TriangleCount() const;
};

// Fills `normals` with area-weighted vertex normals of the triangles.
void ComputeVertexNormals(Primitive& primitive);

}  // namespace penumbra
