// The m world-space direction bins of Sec. 3.1: near-uniform centres on the sphere,
// a direction→bin lookup, and per-bin Gaussian neighbour lists for several cone sizes σ.
#pragma once

#include <algorithm>
#include <cstdint>
#include <glm/glm.hpp>
#include <numbers>
#include <span>
#include <vector>

#include "gpu/layout.h"

namespace penumbra {

struct BinWeight {
    uint32_t bin;
    float weight;
};
PENUMBRA_GPU_WORDS(BinWeight, 2);

class Directions {
  public:
    static constexpr int kMinBins = 32;
    static constexpr int kMaxBins = 1024;
    static constexpr int kLevels = 6;  // cone sizes σ_k = σ_0 · 2^(k/2)

    // `count` in [kMinBins, kMaxBins]; throws penumbra::Error otherwise.
    explicit Directions(int count);
    // penumbra::Error unless `count` is a bin count the tables can hold (kMinBins…kMaxBins,
    // a multiple of 4).
    static void Check(int count);

    int Count() const { return count_; }
    float BinSolidAngle() const { return solidAngle_; }  // ω_bin = 4π/m
    float Spacing() const { return spacing_; }           // √(4π/m), angle to the nearest bin
    const glm::vec3& Direction(uint32_t bin) const { return dirs_[bin]; }
    const std::vector<glm::vec3>& All() const { return dirs_; }
    // The same directions as three arrays (for vectorised loops over bins).
    const float* X() const { return x_.data(); }
    const float* Y() const { return y_.data(); }
    const float* Z() const { return z_.data(); }

    // Nearest bin centre to unit direction `d` (inline: the link creation's pair loop makes
    // two a pair).
    uint32_t Lookup(const glm::vec3& d) const {
        int face, u, v;
        CubeCoords(d, lookupRes_, face, u, v);
        const size_t texel = size_t(face * lookupRes_ + v) * lookupRes_ + u;
        const uint16_t* c = candidates_.data() + candidateFirst_[texel];
        const uint16_t* end = candidates_.data() + candidateFirst_[texel + 1];
        uint32_t best = *c;
        float bestDot = glm::dot(d, dirs_[best]);
        for (++c; c != end; ++c) {
            const float dd = glm::dot(d, dirs_[*c]);
            if (dd > bestDot) bestDot = dd, best = *c;
        }
        return best;
    }
    // Cube face (±x, ±y, ±z: 0…5) and texel coordinates of direction `d` on a cube of res²
    // texels a face.
    static void CubeCoords(const glm::vec3& d, int res, int& face, int& u, int& v) {
        const glm::vec3 a = glm::abs(d);
        float s, t, m;
        if (a.x >= a.y && a.x >= a.z) {
            face = d.x > 0 ? 0 : 1;
            m = a.x, s = d.y, t = d.z;
        } else if (a.y >= a.z) {
            face = d.y > 0 ? 2 : 3;
            m = a.y, s = d.x, t = d.z;
        } else {
            face = d.z > 0 ? 4 : 5;
            m = a.z, s = d.x, t = d.y;
        }
        u = std::clamp(static_cast<int>((s / m * 0.5f + 0.5f) * res), 0, res - 1);
        v = std::clamp(static_cast<int>((t / m * 0.5f + 0.5f) * res), 0, res - 1);
    }
    // Calls f(b, ω_b, c) for exactly the bins b with c = ⟨d, ω_b⟩ ≥ cos `reach` (in no set
    // order), for unit `d` within angle `offset` of bin `bin`'s direction (its nearest bin,
    // say). A cap inside the bin's adjacency walks that nearest first, stopping at the first
    // bin outside the cap; a wider one walks groups of bins (a cube-map cell's) nearest `bin`
    // first, stopping at the first group that lies farther than reach + offset from it.
    template <typename F>
    void ForEachWithin(uint32_t bin, float offset, const glm::vec3& d, float reach, F&& f) const {
        constexpr float pi = std::numbers::pi_v<float>;
        constexpr float margin = 1e-3f;  // the rounding of the angles compared
        const float cosReach = std::cos(std::min(reach, pi));
        auto visit = [&](uint32_t b) {
            const glm::vec3& w = dirs_[b];
            const float c = glm::dot(d, w);
            if (c >= cosReach) f(b, w, c);
        };
        if (offset + reach <= AdjacentAngle() - margin) {
            // A bin farther than offset + reach from `bin` lies farther than reach from `d`,
            // as does every one after it.
            const float cosStop = std::cos(offset + reach + margin);
            visit(bin);
            for (const Near& n : byAngle_[bin]) {
                if (n.cos < cosStop) break;
                visit(n.bin);
            }
            return;
        }
        const float sinReach = std::sin(std::min(reach, pi));
        const size_t groups = groups_.size();
        const uint8_t* order = groupOrder_.data() + size_t(bin) * groups;
        const float* lower = groupLower_.data() + size_t(bin) * groups;
        const float stop = reach + offset + margin;
        for (size_t k = 0; k < groups && lower[k] <= stop; ++k) {
            const uint8_t g = order[k];
            const Group& G = groups_[g];
            if (reach + G.radius < pi &&
                glm::dot(d, G.centre) < cosReach * G.cosRadius - sinReach * G.sinRadius)
                continue;
            for (uint32_t j = groupFirst_[g]; j < groupFirst_[g + 1]; ++j) visit(groupBins_[j]);
        }
    }
    // The other bins within AdjacentAngle() of bin `bin`'s direction, in bin order.
    std::span<const uint32_t> Adjacent(uint32_t bin) const { return adjacent_[bin]; }
    // The same bins nearest first, each with the cosine of its angle to bin `bin`: a walk
    // over a cap about `bin` stops at the first one outside it.
    struct Near {
        uint32_t bin;
        float cos;
    };
    std::span<const Near> AdjacentByAngle(uint32_t bin) const { return byAngle_[bin]; }
    float AdjacentAngle() const { return 2.0f * spacing_; }
    // Nearest bin to `d` among those with dot(ω_b, a) > 0 and dot(ω_b, b) > 0 (a zero
    // vector imposes nothing), searched around the nearest bin; the nearest bin if none.
    uint32_t LookupWithin(const glm::vec3& d, const glm::vec3& a, const glm::vec3& b) const;
    // π / Σ_b ω_bin max(0, n·ω_b): corrects the discrete cosine integral over one side.
    float CosineNorm(const glm::vec3& n) const;
    // The same from `cosineSum` = Σ_b max(0, n·ω_b), for a caller that has the cosines.
    float CosineNormOfSum(double cosineSum) const;
    // The bin of bin `bin`'s opposite direction (Lookup(−ω_bin): the bins need not come in
    // opposite pairs).
    uint32_t Opposite(uint32_t bin) const { return opposite_[bin]; }

    // Gaussian width (radians) of spread level k.
    float LevelSigma(int level) const;
    // Spread level for a sender of angular radius `alpha` (radians) seen from the receiver.
    int LevelFor(float alpha) const;
    // Receiver bins and normalised weights (Σ = 1) that a link through `bin` spreads into.
    std::span<const BinWeight> Neighbours(int level, uint32_t bin) const {
        const uint32_t* o = offsets_.data() + level * (count_ + 1) + bin;
        return {weights_.data() + o[0], o[1] - o[0]};
    }
    // All levels in one table: level k's bin b spreads into
    // Weights()[Offsets()[k·(m+1) + b] .. Offsets()[k·(m+1) + b + 1]).
    const std::vector<uint32_t>& Offsets() const { return offsets_; }
    const std::vector<BinWeight>& Weights() const { return weights_; }
    // The same lists padded with zero weights to one width per level (the longest list of
    // that level), so a loop over them has a trip count that does not change from bin to
    // bin (the CPU gather and the global shader read these): PaddedWidth(k) entries from
    // PaddedWeights()[PaddedStart(k) + bin · PaddedWidth(k)].
    int PaddedWidth(int level) const { return paddedWidth_[level]; }
    size_t PaddedStart(int level) const { return paddedStart_[level]; }
    const BinWeight* Padded(int level, uint32_t bin) const {
        return padded_.data() + paddedStart_[level] + size_t(bin) * paddedWidth_[level];
    }
    const std::vector<BinWeight>& PaddedWeights() const { return padded_; }

    // The tables of Lookup's device twin (LookupBin in shaders/directions.glsl, the same
    // nearest bin by a walk): a cube map of CubeRes()² texels a face, each holding a bin near
    // the texel centre (face-major, then v, then u), and every bin's neighbours within two
    // spacings, padded with the bin itself to `width` entries a bin.
    int CubeRes() const { return cubeRes_; }
    const std::vector<uint32_t>& CubeTable() const { return cube_; }
    std::vector<uint32_t> PaddedAdjacency(uint32_t& width) const;

  private:
    // The constructor's tables, in order: each bin's neighbours (adjacent_, byAngle_), the
    // nearest-bin cube map Walk starts from (cube_), Lookup's finer map of candidates, the
    // groups ForEachWithin prunes by, and the spreading levels' Gaussian weights.
    void BuildAdjacency();
    void BuildCubeTable();
    void BuildLookupTable();
    void BuildGroups();
    void BuildSpreading();
    int count_;
    float solidAngle_;
    float spacing_;
    std::vector<glm::vec3> dirs_;
    std::vector<float> x_, y_, z_;
    // Cube-map table: face*res*res texels → a bin near the texel centre, refined by a
    // greedy walk over `adjacent_` to the exact nearest bin.
    int cubeRes_;
    std::vector<uint32_t> cube_;
    // Lookup's table on the CPU: a cube map of lookupRes_² texels a face, texel t's
    // candidate bins candidates_[candidateFirst_[t], candidateFirst_[t + 1]) (the constructor
    // says why they hold the nearest bin of every direction in the texel).
    int lookupRes_;
    std::vector<uint32_t> candidateFirst_;
    std::vector<uint16_t> candidates_;
    static_assert(kMaxBins <= 65536, "candidates_ holds bins as 16 bits");
    // The nearest bin by the device's way: the coarse table's bin, then a greedy walk over
    // `adjacent_` (builds the candidate lists).
    uint32_t Walk(const glm::vec3& d) const;
    std::vector<uint32_t> opposite_;
    std::vector<std::vector<uint32_t>> adjacent_;
    std::vector<std::vector<Near>> byAngle_;  // AdjacentByAngle
    // ForEachWithin's groups: the bins of group g are groupBins_[groupFirst_[g],
    // groupFirst_[g + 1]), around `centre` within `radius` (with a margin for rounding).
    struct Group {
        glm::vec3 centre;
        float radius, cosRadius, sinRadius;
    };
    std::vector<Group> groups_;
    std::vector<uint32_t> groupFirst_, groupBins_;
    // Per bin, every group by how near it comes to the bin's direction (the angle to the
    // group's centre less its radius, at least 0), ascending: ForEachWithin.
    std::vector<uint8_t> groupOrder_;
    std::vector<float> groupLower_;
    std::vector<uint32_t> offsets_;
    std::vector<BinWeight> weights_;
    std::vector<BinWeight> padded_;
    int paddedWidth_[kLevels];
    size_t paddedStart_[kLevels];
};

}  // namespace penumbra
