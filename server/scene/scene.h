// The scene as the solver sees it: world-space triangle primitives (one per glTF
// node × mesh primitive, input vertex order kept) and their materials.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <string>
#include <vector>

#include "scene/environment.h"
#include "scene/texture.h"

namespace penumbra {

// A glTF metallic-roughness material and the reflectance the solvers use, derived from it
// by DeriveReflectance (docs/MATERIALS.md):
//   diffuse BRDF ρ_d/π, plus for glossy materials a normalised Phong lobe about the mirror
//   direction, f_s = F0 · (n + 2)/(2π) · cosⁿ θ_r, with F0 = mix(0.04, baseColor, metallic),
//   α = roughness², n = 1/(2α²) − ½ (Blinn–Phong's 2/α² − 2 about the half vector is about
//   four times n about the mirror direction, since θ_r ≈ 2θ_h).
// Lobes with n < 1 (roughness > 0.76) are almost uniform: a metal's is folded into the
// diffuse albedo, a dielectric's 4% is left out (glTF's BRDF takes about that much from
// its diffuse layer by the (1 − F) weight), so rough materials stay on the diffuse path.
struct Material {
    std::string name;
    glm::vec3 baseColor{0.8f};   // as given (glTF baseColorFactor × mean texture colour)
    float metallic = 0.0f;       // as given
    float roughness = 1.0f;      // as given
    glm::vec3 albedo{0.8f};      // diffuse reflectance ρ_d (derived)
    glm::vec3 specular{0.0f};    // F0 of the glossy lobe; zero: no lobe (derived)
    float phongExponent = 0.0f;  // n of the lobe; 0 when there is none (derived)
    glm::vec3 emission{0.0f};    // emitted radiance (nits), emissiveFactor × strength × mean
    // Colour maps (indices into Scene::maps, −1: none) and the texture coordinate set each
    // reads (Primitive::texcoords): the base colour's tints the diffuse albedo, the emissive
    // one the emission, point by point (TintsAt); albedo and emission above hold the maps'
    // means. The glossy lobe's colour (specular) takes the base colour map's mean only.
    int baseColorMap = -1, baseColorSet = 0;
    int emissionMap = -1, emissionSet = 0;
    // Light passing straight through, per channel (a thin surface: glass, a cutout, a veil;
    // both ways, its direction kept): from alpha coverage c (alphaMode BLEND: the base colour
    // factor's alpha; MASK: 0 or 1 by the cutoff) and KHR_materials_transmission's factor t,
    // T = (1 − c) + c · t · base colour. Zero: opaque. The albedo and the lobe then hold only
    // the covered, untransmitted part (c · (1 − t)), the emission c of it (PassThrough).
    float coverage = 1.0f, transmission = 0.0f;  // c and t as given
    glm::vec3 transmittance{0.0f};               // derived

    bool Glossy() const { return phongExponent > 0.0f; }
    bool Passes() const { return transmittance != glm::vec3(0.0f); }
    bool Mapped() const { return baseColorMap >= 0 || emissionMap >= 0; }
};

// Whether any of `materials` is glossy.
inline bool AnyGlossy(const std::vector<Material>& materials) {
    for (const Material& m : materials)
        if (m.Glossy()) return true;
    return false;
}

// Roughness above this has a lobe exponent below 1 and is treated as diffuse.
inline constexpr float kGlossyRoughness = 0.7598357f;  // (1/3)^(1/4): n = 1
// The sharpest lobe kept (roughness ≈ 0.06): sharper ones are mirrors to every solver here.
inline constexpr float kMaxPhongExponent = 10000.0f;

// Fills albedo, specular and phongExponent from baseColor, metallic and roughness, and the
// transmittance from coverage and transmission (the albedo and lobe scaled by what passes).
void DeriveReflectance(Material& m);
// A material from glTF's factors (name, base colour, metallic, roughness, emission).
Material PbrMaterial(const std::string& name, glm::vec3 baseColor, float metallic, float roughness,
                     glm::vec3 emission = glm::vec3(0.0f));
// Gives `m` alpha coverage `coverage` and a transmission factor `transmission`, both in
// [0, 1]: its transmittance, and its albedo, lobe (DeriveReflectance keeps them so) and
// emission scaled to the part that neither passes nor is uncovered (Material::transmittance).
void PassThrough(Material& m, float coverage, float transmission);
// A purely diffuse material of albedo ρ (metallic 0, roughness 1).
Material DiffuseMaterial(const std::string& name, glm::vec3 albedo,
                         glm::vec3 emission = glm::vec3(0.0f));

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
    // TEXCOORD_n, one per position, for the sets its material's maps read (others empty).
    std::vector<std::vector<glm::vec2>> texcoords;
    // The rest pose: the own-space vertices and normals as loaded (glTF's base mesh, before
    // morph weights), kept when a deformation (SetNodeVertices) replaces objectPositions.
    // The refinement splits by restPositions (scene/surfels.h), so a deformed mesh keeps its
    // surfels. Empty: objectPositions and objectNormals are the rest pose.
    std::vector<glm::vec3> restPositions, restNormals;
    // Morph targets (glTF `targets`): per target, per vertex, the own-space displacement of
    // POSITION and of NORMAL (a target's NORMAL list is empty when it has none).
    std::vector<std::vector<glm::vec3>> morphPositions, morphNormals;
    uint32_t shape = 0;  // deformations taken so far (SetNodeVertices); 0: as loaded
    // Flat normals (SplitForFlatNormals: a glTF mesh without NORMAL, which glTF says is drawn
    // flat): a vertex whose triangles lie in more than one plane became one vertex a plane.
    // Input vertex i stays vertex i; the copies follow it, copy k of the primitive being
    // split from input vertex copyOf[k - InputVertexCount()]. Empty: no copies. Outputs stay
    // per input vertex (ToInputVertices).
    std::vector<uint32_t> copyOf;
    // Subdivided for output (RefineForOutput): its vertices and triangles are not the file's,
    // and outputs carry them; parentTriangles[t] is the file's triangle that triangle t lies in.
    bool refined = false;
    std::vector<uint32_t> parentTriangles;

    // The vertices the file has (what outputs, frames and deformations count).
    size_t InputVertexCount() const { return positions.size() - copyOf.size(); }
    // The input vertex vertex k stands for.
    uint32_t InputVertex(size_t k) const {
        const size_t n = InputVertexCount();
        return k < n ? static_cast<uint32_t>(k) : copyOf[k - n];
    }

    const std::vector<glm::vec3>& RestPositions() const {
        return restPositions.empty() ? objectPositions : restPositions;
    }
    const std::vector<glm::vec3>& RestNormals() const {
        return restNormals.empty() ? objectNormals : restNormals;
    }
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
    // The morph target weights its primitives are posed with (glTF node or mesh `weights`;
    // SetNodeMorphWeights); empty when its mesh has no targets.
    std::vector<float> morphWeights;
};

// A KHR_lights_punctual light placed by a node. Lights shine down the node's −Z axis.
enum class LightType { kPoint, kSpot, kDirectional };

struct PunctualLight {
    std::string name;  // the glTF light's name, else the node's
    int node = -1;     // the node that places it (its name is the object name in the protocol)
    LightType type = LightType::kPoint;
    glm::vec3 color{1.0f};
    float intensity = 1.0f;  // candela (point, spot) or lux (directional), as given
    float range = 0.0f;      // metres; 0 = infinite
    float innerCone = 0.0f;  // radians, spot only
    float outerCone = 0.7853982f;
    glm::vec3 position{0.0f};                // world space (point, spot)
    glm::vec3 direction{0.0f, 0.0f, -1.0f};  // world space, unit, where the light travels
};

// Intensity scale of a light towards a point at distance `d` along `toPoint` (unit, from the
// light), without the 1/d² and the receiver's cosine: the KHR_lights_punctual spot cone
// (smooth between the cone angles) and range window ((1 − (d/range)⁴)² clamped, the
// extension's recommended falloff). 1 for directional lights.
float LightAttenuation(const PunctualLight& light, const glm::vec3& toPoint, float d);

// How a punctual light reaches the point x of a surface facing n, without occlusion: the
// direction to it (unit), the segment a shadow ray covers (from x; a directional light from
// 4 scene diameters away), `scale` = attenuation / d² (1 for a directional light), the cosine
// at x and the irradiance color · intensity · scale · cosθ. `reaches`: cosθ > 0 (a
// directional light, or a point not at the light's place); it depends on where the light is
// only, not on its intensity, colour, cone or range.
struct LightArrival {
    bool reaches = false;
    glm::vec3 toLight{0.0f}, span{0.0f};
    float scale = 0.0f, cosine = 0.0f;
    glm::vec3 irradiance{0.0f};
};
LightArrival PunctualArrival(const PunctualLight& light, const glm::vec3& x, const glm::vec3& n,
                             float sceneDiameter);

// A glTF perspective camera placed by a node: it looks down the node's −Z axis, +Y up.
struct Camera {
    std::string name;  // the camera's name, else its node's
    glm::vec3 eye{0.0f};
    glm::vec3 forward{0.0f, 0.0f, -1.0f};  // unit
    glm::vec3 up{0.0f, 1.0f, 0.0f};        // unit, orthogonal to forward
    float yfov = 0.8f;                     // radians, vertical field of view
};

struct Scene {
    std::string source;  // file it came from, for messages
    std::vector<Material> materials;
    std::vector<Primitive> primitives;
    std::vector<SceneNode> nodes;       // indexed like the file's nodes (Primitive::nodeIndex)
    std::vector<PunctualLight> lights;  // KHR_lights_punctual, one per node that places one
    std::vector<Camera> cameras;        // perspective cameras of the file, in node order
    // The materials' colour maps (Material::baseColorMap, emissionMap).
    std::vector<TintMap> maps;
    // Light from infinity (not part of glTF: set by `--environment` or the protocol).
    Environment environment;
    // What the loader read but ignored or approximated (textures averaged, skins in rest pose,
    // unsupported extensions, ...), one sentence each; SceneWarnings adds the rest.
    std::vector<std::string> warnings;

    glm::vec3 BoundsMin() const;
    glm::vec3 BoundsMax() const;
    float Diameter() const;  // length of the bounding box diagonal
    size_t VertexCount() const;
    size_t TriangleCount() const;
};

// How a material's maps change its albedo and emission at a point: multiply by these.
struct Tints {
    glm::vec3 albedo{1.0f}, emission{1.0f};
};
// Whether any material of `scene` has a map (else every tint is 1).
bool AnyMapped(const Scene& scene);
// The texture coordinates by which primitive `prim` reads map `map` (a Material's
// baseColorMap or emissionMap) through set `set`: null where there is no map or the primitive
// lacks the coordinates (the map's mean then holds over it).
const std::vector<glm::vec2>* MapCoordinates(const Primitive& prim, int map, int set);
// The tints at the point a + u·(b − a) + v·(c − a) of primitive p's triangle with vertices
// a, b, c (indices into its positions), under its current material.
Tints TintsAt(const Scene& scene, uint32_t p, const glm::uvec3& abc, float u, float v);
// Everything a user should be told about `scene` before trusting its answer: the loader's
// warnings, and a scene with no light at all (no emission, punctual light or sky: its
// irradiance is zero everywhere). Shown by bake and reference (stderr and the JSON's
// `warnings`) and by the service (SceneInfo `warnings`, the server's log). Without
// `lightFromScene` (render --lighting: the light comes from a file) the second is left out.
std::vector<std::string> SceneWarnings(const Scene& scene, bool lightFromScene = true);

// Index of the node called `name`, or -1.
int FindNode(const Scene& scene, const std::string& name);

// Sets the light's world position and direction from its node's world matrix; throws
// penumbra::Error when the matrix has no direction (singular).
void PlaceLight(PunctualLight& light, const glm::mat4& world);

// Index of the light placed by the node called `name`, or -1.
int FindLight(const Scene& scene, const std::string& name);

// Replaces node `node`'s local transform and re-places the geometry and lights of its subtree.
// Throws penumbra::Error for a non-finite, non-affine or singular matrix (the scene is
// unchanged then).
void SetNodeTransform(Scene& scene, int node, const glm::mat4& local);

// Fills `normals` with area-weighted vertex normals of the triangles.
void ComputeVertexNormals(Primitive& primitive);

// glTF 2.0 (3.7.2.1): a mesh without normals is drawn with flat normals. Gives `primitive`
// (its positions, indices, texture coordinates and morph targets as read, in one space) a
// vertex per plane its triangles meet in at each vertex (Primitive::copyOf) and the normals of
// those planes. A vertex whose triangles are coplanar within ~0.8° stays one.
void SplitForFlatNormals(Primitive& primitive);

// Each vertex's share of its triangles' area (a third of each), the weight a split vertex's
// copies are merged with.
std::vector<float> VertexAreas(const Primitive& primitive);

// A value per vertex of `primitive` (copies included) as a value per input vertex: a vertex
// split for flat normals gets the area-weighted mean over its copies, the light over the
// faces that meet there (a value per face corner is what a vertex-coloured mesh cannot show).
std::vector<glm::vec3> ToInputVertices(const Primitive& primitive,
                                       std::vector<glm::vec3> perVertex);

// Deformations (a skinned or morphing mesh driven from outside: protocol/SPEC.md,
// SetVertices). The vertices of node `node`'s own primitives, one primitive after another
// in SceneNode::primitives order, each in its input order:
size_t NodeVertexCount(const Scene& scene, int node);
// Replaces them with `positions` (own space: the mesh's coordinates before the node's
// matrix) and `normals` (same layout; empty: area-weighted normals of the deformed
// triangles), re-placed in the world by the node's matrix. The triangles, the rest pose the
// refinement splits by, materials and texture coordinates stay. Throws penumbra::Error
// (the scene unchanged) for a node without triangles, a count other than NodeVertexCount,
// NaN or infinity, or a zero normal.
void SetNodeVertices(Scene& scene, int node, const std::vector<glm::vec3>& positions,
                     const std::vector<glm::vec3>& normals = {});
// The morph targets of node `node`'s mesh (0: none).
size_t NodeMorphTargets(const Scene& scene, int node);
// Poses the node's mesh at morph `weights` (glTF: position = rest + Σ wᵢ·targetᵢ, the same
// for normals, renormalised; a mesh whose targets carry no normals gets area-weighted ones)
// through SetNodeVertices. Throws penumbra::Error for a count other than NodeMorphTargets
// or a weight that is not finite.
void SetNodeMorphWeights(Scene& scene, int node, const std::vector<float>& weights);

}  // namespace penumbra
