// Longest-edge bisection refinement of a Scene into surfels with areas and normals.
#include "scene/surfels.h"

#include <cmath>
#include <unordered_map>

#include "base/check.h"
#include "scene/solids.h"

namespace penumbra {

namespace {

// RefineScene's work: the surfels so far and what they integrate, a primitive at a time.
class Refiner {
  public:
    Refiner(const Scene& scene, float elementSize)
        : scene_(scene), maxEdge2_(elementSize * elementSize), mapped_(AnyMapped(scene)) {}

    void Add(uint32_t pi) {
        const Primitive& prim = scene_.primitives[pi];
        StartPrimitive(prim);
        std::vector<glm::uvec3> stack;
        moments_.resize(out_.positions.size(), glm::vec3(0.0f));
        for (size_t t = 0; t + 2 < prim.indices.size(); t += 3)
            stack.emplace_back(base_ + prim.indices[t], base_ + prim.indices[t + 1],
                               base_ + prim.indices[t + 2]);
        while (!stack.empty()) {
            const glm::uvec3 tri = stack.back();
            stack.pop_back();
            float e[3];
            for (int k = 0; k < 3; ++k) e[k] = EdgeLength2(tri[k], tri[(k + 1) % 3]);
            const int longest = e[0] >= e[1] ? (e[0] >= e[2] ? 0 : 2) : (e[1] >= e[2] ? 1 : 2);
            if (e[longest] > maxEdge2_) {
                // Split edge (longest, longest+1) at its midpoint: two triangles.
                const uint32_t a = tri[longest], b = tri[(longest + 1) % 3],
                               c = tri[(longest + 2) % 3];
                const uint32_t m = Midpoint(a, b);
                stack.emplace_back(a, m, c);
                stack.emplace_back(m, b, c);
                continue;
            }
            Integrate(tri);
            out_.refinedTriangles.insert(out_.refinedTriangles.end(), {tri[0], tri[1], tri[2]});
        }
    }

    Surfels Finish() {
        if (anyOwn_) {
            out_.ownCentroids.resize(out_.size());
            out_.ownNormals = std::move(ownNormals_);
            for (size_t i = 0; i < out_.size(); ++i)
                out_.ownCentroids[i] =
                    ownAreas_[i] > 0.0f ? ownMoments_[i] / ownAreas_[i] : glm::vec3(0.0f);
        }
        if (mapped_) {
            albedoSums_.resize(out_.size(), glm::vec3(0.0f));
            emissionSums_.resize(out_.size(), glm::vec3(0.0f));
            out_.albedoTints.resize(out_.size());
            out_.emissionTints.resize(out_.size());
            for (size_t i = 0; i < out_.size(); ++i) {
                const bool some = out_.areas[i] > 0.0f;
                out_.albedoTints[i] = some ? albedoSums_[i] / out_.areas[i] : glm::vec3(1.0f);
                out_.emissionTints[i] = some ? emissionSums_[i] / out_.areas[i] : glm::vec3(1.0f);
            }
        }
        out_.centroids.resize(out_.size());
        for (size_t i = 0; i < out_.size(); ++i)
            out_.centroids[i] =
                out_.areas[i] > 0.0f ? moments_[i] / out_.areas[i] : out_.positions[i];
        return std::move(out_);
    }

  private:
    // The primitive's input vertices as surfels, and where its splits are measured.
    void StartPrimitive(const Primitive& prim) {
        prim_ = &prim;
        base_ = static_cast<uint32_t>(out_.positions.size());
        out_.firstSurfel.push_back(base_);
        // A dynamic node's primitives are split by their own-space edges in the rest pose
        // (Primitive::restPositions), measured with the metric AᵀA of the node's world matrix
        // rounded to 2⁻²⁰ of its trace: the same splits at every pose (world-space lengths of
        // equal edges differ by rounding noise from pose to pose, and ties would break
        // differently) and every deformation, so a move keeps the surfels (Sec. 3.3) and a
        // deformed mesh its elements (implicit visibility paper, Sec. 4: the hierarchy is
        // refitted, not rebuilt).
        own_ = prim.nodeIndex >= 0 && scene_.nodes[prim.nodeIndex].dynamic &&
               prim.objectPositions.size() == prim.positions.size();
        anyOwn_ = anyOwn_ || own_;
        material_ = &scene_.materials[prim.material];
        // The coordinates each tint reads here, if the primitive has them.
        baseSet_ = MapCoordinates(prim, material_->baseColorMap, material_->baseColorSet);
        emissionSet_ = MapCoordinates(prim, material_->emissionMap, material_->emissionSet);
        for (size_t i = 0; i < prim.positions.size(); ++i) {
            if (mapped_) {
                baseUv_.push_back(baseSet_ ? (*baseSet_)[i] : glm::vec2(0.0f));
                emissionUv_.push_back(emissionSet_ ? (*emissionSet_)[i] : glm::vec2(0.0f));
            }
            out_.positions.push_back(prim.positions[i]);
            out_.normals.push_back(prim.normals[i]);
            out_.areas.push_back(0.0f);
            out_.materials.push_back(prim.material);
            // The own-space arrays stay aligned with the surfels (zero where not dynamic).
            ownNormals_.push_back(own_ && i < prim.objectNormals.size() ? prim.objectNormals[i]
                                                                        : glm::vec3(0.0f));
            ownMoments_.emplace_back(0.0f);
            ownAreas_.push_back(0.0f);
        }
        object_.clear();
        rest_.clear();
        metric_ = glm::mat3(1.0f);
        if (own_) {
            object_ = prim.objectPositions;
            rest_ = prim.RestPositions();
            const glm::mat3 a(scene_.nodes[prim.nodeIndex].world);
            metric_ = glm::transpose(a) * a;
            const float q = (metric_[0][0] + metric_[1][1] + metric_[2][2]) / 1048576.0f;
            for (int i = 0; i < 3; ++i)
                for (int j = 0; j < 3; ++j) metric_[i][j] = std::round(metric_[i][j] / q) * q;
        }
        midpoints_.clear();
    }

    // The squared length of the edge between surfels a and b (own space in the rest pose for
    // a dynamic node).
    float EdgeLength2(uint32_t a, uint32_t b) const {
        if (own_) {
            const glm::vec3 d = rest_[b - base_] - rest_[a - base_];
            return glm::dot(d, metric_ * d);
        }
        const glm::vec3 d = out_.positions[b] - out_.positions[a];
        return glm::dot(d, d);
    }

    // The surfel at the midpoint of edge (a, b), made on its first use (keyed by the sorted
    // pair).
    uint32_t Midpoint(uint32_t a, uint32_t b) {
        const uint64_t key = a < b ? (uint64_t(a) << 32 | b) : (uint64_t(b) << 32 | a);
        auto it = midpoints_.find(key);
        if (it != midpoints_.end()) return it->second;
        const uint32_t m = static_cast<uint32_t>(out_.positions.size());
        moments_.emplace_back(0.0f);
        if (mapped_) {
            baseUv_.push_back(0.5f * (baseUv_[a] + baseUv_[b]));
            emissionUv_.push_back(0.5f * (emissionUv_[a] + emissionUv_[b]));
        }
        out_.positions.push_back(0.5f * (out_.positions[a] + out_.positions[b]));
        ownMoments_.emplace_back(0.0f);
        ownAreas_.push_back(0.0f);
        if (own_) {
            object_.push_back(0.5f * (object_[a - base_] + object_[b - base_]));
            rest_.push_back(0.5f * (rest_[a - base_] + rest_[b - base_]));
            const glm::vec3 on = ownNormals_[a] + ownNormals_[b];
            const float ol = glm::length(on);
            ownNormals_.push_back(ol > 1e-6f ? on / ol : ownNormals_[a]);
        } else {
            ownNormals_.emplace_back(0.0f);
        }
        const glm::vec3 n = out_.normals[a] + out_.normals[b];
        const float len = glm::length(n);
        out_.normals.push_back(len > 1e-6f ? n / len : out_.normals[a]);
        out_.areas.push_back(0.0f);
        out_.materials.push_back(prim_->material);
        midpoints_.emplace(key, m);
        return m;
    }

    // A final triangle's share of its corners' areas, moments (and own-space ones) and tints.
    void Integrate(const glm::uvec3& tri) {
        const glm::vec3 p[3] = {out_.positions[tri[0]], out_.positions[tri[1]],
                                out_.positions[tri[2]]};
        const float area = 0.5f * glm::length(glm::cross(p[1] - p[0], p[2] - p[0]));
        const glm::vec3 sum = p[0] + p[1] + p[2];
        if (mapped_) {
            // The tints over this triangle, a third of its area to each corner (the integral of
            // a corner's hat function over it, with the tint taken constant).
            albedoSums_.resize(out_.positions.size(), glm::vec3(0.0f));
            emissionSums_.resize(out_.positions.size(), glm::vec3(0.0f));
            glm::vec3 albedo(1.0f), emission(1.0f);
            if (baseSet_)
                albedo = scene_.maps[material_->baseColorMap].Over(baseUv_[tri[0]], baseUv_[tri[1]],
                                                                   baseUv_[tri[2]]);
            if (emissionSet_)
                emission = scene_.maps[material_->emissionMap].Over(
                    emissionUv_[tri[0]], emissionUv_[tri[1]], emissionUv_[tri[2]]);
            for (int k = 0; k < 3; ++k) {
                albedoSums_[tri[k]] += area / 3.0f * albedo;
                emissionSums_[tri[k]] += area / 3.0f * emission;
            }
        }
        for (int k = 0; k < 3; ++k) {
            out_.areas[tri[k]] += area / 3.0f;
            // ∫ φ_k x dA over the triangle = A (2 p_k + p_i + p_j) / 12.
            moments_[tri[k]] += area * (sum + p[k]) / 12.0f;
        }
        if (own_) {
            const glm::vec3 o[3] = {object_[tri[0] - base_], object_[tri[1] - base_],
                                    object_[tri[2] - base_]};
            const float oa = 0.5f * glm::length(glm::cross(o[1] - o[0], o[2] - o[0]));
            const glm::vec3 osum = o[0] + o[1] + o[2];
            for (int k = 0; k < 3; ++k) {
                ownAreas_[tri[k]] += oa / 3.0f;
                ownMoments_[tri[k]] += oa * (osum + o[k]) / 12.0f;
            }
        }
    }

    const Scene& scene_;
    const float maxEdge2_;
    // Colour maps: each surfel's texture coordinates in its base colour and emission maps'
    // sets (interpolated at midpoints like positions) and its tints' area integrals.
    const bool mapped_;
    Surfels out_;
    std::vector<glm::vec3> moments_;  // ∫ φ_s x dA per surfel
    // Dynamic primitives: own-space normals, moments and areas (Surfels::ownCentroids).
    std::vector<glm::vec3> ownNormals_, ownMoments_;
    std::vector<float> ownAreas_;
    bool anyOwn_ = false;
    std::vector<glm::vec2> baseUv_, emissionUv_;
    std::vector<glm::vec3> albedoSums_, emissionSums_;
    // The primitive being refined: its first surfel, whether it splits in its own space, its
    // material and maps' coordinates, its surfels' own-space and rest positions and metric.
    const Primitive* prim_ = nullptr;
    uint32_t base_ = 0;
    bool own_ = false;
    const Material* material_ = nullptr;
    const std::vector<glm::vec2>* baseSet_ = nullptr;
    const std::vector<glm::vec2>* emissionSet_ = nullptr;
    std::vector<glm::vec3> object_, rest_;
    glm::mat3 metric_{1.0f};
    std::unordered_map<uint64_t, uint32_t> midpoints_;  // edge midpoints by sorted surfel pair
};

}  // namespace

Surfels RefineScene(const Scene& scene, float elementSize) {
    if (!(elementSize > 0.0f)) throw Error("element size must be a positive number of metres");
    Refiner refiner(scene, elementSize);
    for (uint32_t pi = 0; pi < scene.primitives.size(); ++pi) refiner.Add(pi);
    return refiner.Finish();
}

bool BackOcclusionOn(BackOcclusion choice, const Environment& sky) {
    return choice == BackOcclusion::kOn || (choice == BackOcclusion::kAuto && sky.Present());
}

bool BackOcclusionChanges(BackOcclusion choice, const Environment& before,
                          const Environment& after) {
    return BackOcclusionOn(choice, before) != BackOcclusionOn(choice, after);
}

void MarkTwoSided(const Scene& scene, Surfels& s) {
    const std::vector<bool> closed = ClosedNodes(scene);
    s.twoSided.assign(s.size(), 0);
    for (size_t p = 0; p < scene.primitives.size(); ++p) {
        const int node = scene.primitives[p].nodeIndex;
        const bool open = node < 0 || !closed[node];
        for (size_t i = s.firstSurfel[p]; i < s.End(p); ++i) s.twoSided[i] = open;
    }
}

}  // namespace penumbra
