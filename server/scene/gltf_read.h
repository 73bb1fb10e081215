// The glTF loader's reading of accessors and nodes (gltf_loader.cpp, gltf_accessors.cpp): a
// file's bytes checked against what its accessors claim before they are read.
#pragma once

#include <tiny_gltf.h>

#include <cstdint>
#include <glm/glm.hpp>
#include <string>
#include <vector>

#include "base/check.h"
#include "scene/gltf_loader.h"

namespace penumbra::gltf {

// What the reading of one file shares: the file, its model, where its external files may lie,
// and the warnings it gathers.
struct Context {
    const std::string& path;
    const tinygltf::Model& model;
    const GltfFiles& files;
    std::vector<std::string>* notes;  // warnings: input left out or approximated

    [[noreturn]] void Fail(const std::string& where, const std::string& why) const {
        throw Error(path + ": " + where + ": " + why);
    }
};

// A binary glTF (its bytes) with EXT_meshopt_compression: every compressed buffer view decoded
// (Debian's libmeshoptimizer: its mode and filter) into the bytes of a .glb without the
// extension, which tinygltf then reads; false, `glb` untouched, for a file without it. Throws
// penumbra::Error naming the view for data that does not decode or does not fit, and for
// decoded buffers past `most` bytes (gltf_meshopt.cpp).
bool DecodeMeshopt(std::vector<unsigned char>& glb, const std::string& path, uint64_t most);
// Why `filepath`, a file a glTF names, may not be read under `files` ("" when it may):
// outside the scene root, or any external file of an uploaded .glb (gltf_files.cpp).
std::string FileRefusal(const GltfFiles& files, const std::string& filepath);
// "node N 'name'", as messages name a node.
std::string NodeLabel(const tinygltf::Model& model, int node);
// A node's local transform: its matrix, else translation × rotation × scale.
glm::mat4 LocalTransform(const tinygltf::Node& node);
// Reads a VEC3 accessor (POSITION, NORMAL, morph targets), honouring byteStride: floats, or
// the bytes and shorts KHR_mesh_quantization allows.
std::vector<glm::vec3> ReadVec3(const Context& ctx, const std::string& where, int accessorIndex,
                                const char* attribute);
// Reads a TEXCOORD_n accessor: VEC2 of floats, or of bytes or shorts (normalised, or with
// KHR_mesh_quantization not).
std::vector<glm::vec2> ReadTexcoords(const Context& ctx, const std::string& where,
                                     int accessorIndex, const std::string& attribute);
// Reads an index accessor: unsigned byte, short or int SCALAR.
std::vector<uint32_t> ReadIndices(const Context& ctx, const std::string& where, int accessorIndex);
// Triangle list from a TRIANGLES / TRIANGLE_STRIP / TRIANGLE_FAN index sequence.
std::vector<uint32_t> ToTriangleList(const Context& ctx, const std::string& where, int mode,
                                     const std::vector<uint32_t>& seq);

// Node `ni`'s mesh (model.nodes[ni].mesh, ≥ 0): each primitive read and checked, given flat
// normals where it has none, placed at `world` (scene.primitives and the node's list; material
// −1 is `defaultMaterial`), then the mesh posed at its morph weights. Warnings go to ctx.notes.
void ReadNodeMeshes(const Context& ctx, int ni, const glm::mat4& world, uint32_t defaultMaterial,
                    Scene& scene);

}  // namespace penumbra::gltf
