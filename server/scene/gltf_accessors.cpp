// Accessors and node transforms of a glTF file (gltf_read.h).
#include <algorithm>
#include <cmath>
#include <cstring>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>
#include <glm/gtc/type_ptr.hpp>
#include <sstream>

#include "scene/gltf_read.h"

namespace penumbra::gltf {
namespace {

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

}  // namespace

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

namespace {

// The bytes of one component of `type` (0 for a type an attribute may not have).
size_t ComponentBytes(int type) {
    switch (type) {
        case TINYGLTF_COMPONENT_TYPE_FLOAT:
            return 4;
        case TINYGLTF_COMPONENT_TYPE_SHORT:
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
            return 2;
        case TINYGLTF_COMPONENT_TYPE_BYTE:
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
            return 1;
        default:
            return 0;
    }
}

// One component as a float: a float as it is, an integer as its value, or, normalised, as
// glTF 2.0 (3.11) maps it: c / 255 or c / 65535 unsigned, max(c / 127, −1) or max(c / 32767,
// −1) signed.
float Component(const unsigned char* p, int type, bool normalized) {
    switch (type) {
        case TINYGLTF_COMPONENT_TYPE_FLOAT: {
            float v;
            std::memcpy(&v, p, 4);
            return v;
        }
        case TINYGLTF_COMPONENT_TYPE_SHORT: {
            int16_t v;
            std::memcpy(&v, p, 2);
            return normalized ? std::max(float(v) / 32767.0f, -1.0f) : float(v);
        }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
            uint16_t v;
            std::memcpy(&v, p, 2);
            return normalized ? float(v) / 65535.0f : float(v);
        }
        case TINYGLTF_COMPONENT_TYPE_BYTE: {
            const int8_t v = static_cast<int8_t>(p[0]);
            return normalized ? std::max(float(v) / 127.0f, -1.0f) : float(v);
        }
        default:  // unsigned byte
            return normalized ? float(p[0]) / 255.0f : float(p[0]);
    }
}

// A VEC2 or VEC3 attribute's elements as floats: float components, or the integer ones
// KHR_mesh_quantization allows (signed or unsigned bytes and shorts, normalised or not; the
// node's transform or the texture transform takes them back to the model's units).
template <int N>
std::vector<glm::vec<N, float>> ReadFloats(const Context& ctx, const std::string& where,
                                           int accessorIndex, const std::string& attribute) {
    const auto& model = ctx.model;
    if (accessorIndex < 0 || accessorIndex >= static_cast<int>(model.accessors.size()))
        ctx.Fail(where, attribute + " names accessor " + std::to_string(accessorIndex) +
                            ", which does not exist");
    const auto& acc = model.accessors[accessorIndex];
    if (acc.sparse.isSparse) ctx.Fail(where, attribute + " uses a sparse accessor (not supported)");
    const size_t size = ComponentBytes(acc.componentType);
    const int type = N == 3 ? TINYGLTF_TYPE_VEC3 : TINYGLTF_TYPE_VEC2;
    if (acc.type != type || size == 0 || (size == 4 && acc.normalized))
        ctx.Fail(where, attribute + " must be VEC" + std::to_string(N) +
                            " of floats, or of bytes or shorts (KHR_mesh_quantization)");
    size_t stride = 0;
    const unsigned char* bytes = AccessorBytes(ctx, where, acc, size * N, stride, attribute);
    std::vector<glm::vec<N, float>> out(acc.count);
    for (size_t i = 0; i < acc.count; ++i) {
        const unsigned char* p = bytes + stride * i;
        for (int c = 0; c < N; ++c) {
            out[i][c] = Component(p + size * c, acc.componentType, acc.normalized);
            if (!std::isfinite(out[i][c])) ctx.Fail(where, attribute + " has NaN or infinity");
        }
    }
    return out;
}

}  // namespace

std::vector<glm::vec3> ReadVec3(const Context& ctx, const std::string& where, int accessorIndex,
                                const char* attribute) {
    return ReadFloats<3>(ctx, where, accessorIndex, attribute);
}

std::vector<glm::vec2> ReadTexcoords(const Context& ctx, const std::string& where,
                                     int accessorIndex, const std::string& attribute) {
    return ReadFloats<2>(ctx, where, accessorIndex, attribute);
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

}  // namespace penumbra::gltf
