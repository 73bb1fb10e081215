// Fibonacci-sphere bins, cube-map accelerated nearest-bin lookup and the Gaussian
// spreading tables of Sec. 3.1 ("Global pass", filtering).
#include "hierarchy/directions.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>

#include "base/check.h"

namespace penumbra {
namespace {

// The unit direction through face coordinates s, t ∈ [−1, 1] of cube face `face`.
glm::vec3 CubePoint(int face, float s, float t) {
    glm::vec3 d;
    switch (face) {
        case 0:
            d = {1, s, t};
            break;
        case 1:
            d = {-1, s, t};
            break;
        case 2:
            d = {s, 1, t};
            break;
        case 3:
            d = {s, -1, t};
            break;
        case 4:
            d = {s, t, 1};
            break;
        default:
            d = {s, t, -1};
            break;
    }
    return glm::normalize(d);
}

glm::vec3 CubeTexelCentre(int face, int u, int v, int res) {
    return CubePoint(face, ((u + 0.5f) / res) * 2.0f - 1.0f, ((v + 0.5f) / res) * 2.0f - 1.0f);
}

float AngleBetween(const glm::vec3& a, const glm::vec3& b) {
    return std::acos(std::clamp(glm::dot(a, b), -1.0f, 1.0f));
}

}  // namespace

void Directions::Check(int count) {
    if (count < kMinBins || count > kMaxBins || count % 4 != 0)
        throw Error("bin count " + std::to_string(count) + " must be a multiple of 4 in " +
                    std::to_string(kMinBins) + "…" + std::to_string(kMaxBins) +
                    " (table rows are read as whole vec4s on the device)");
}

Directions::Directions(int count) : count_(count) {
    Check(count);
    const float pi = std::numbers::pi_v<float>;
    solidAngle_ = 4.0f * pi / count;
    spacing_ = std::sqrt(solidAngle_);

    // Fibonacci sphere: equal-area latitude bands, golden-angle longitudes.
    const double golden = std::numbers::pi * (3.0 - std::sqrt(5.0));
    dirs_.resize(count);
    for (int i = 0; i < count; ++i) {
        double z = 1.0 - (2.0 * i + 1.0) / count;
        double r = std::sqrt(std::max(0.0, 1.0 - z * z));
        double phi = golden * i;
        dirs_[i] = glm::normalize(glm::vec3(r * std::cos(phi), r * std::sin(phi), z));
    }

    for (const auto& d : dirs_) x_.push_back(d.x), y_.push_back(d.y), z_.push_back(d.z);
    BuildAdjacency();
    BuildCubeTable();
    BuildLookupTable();
    opposite_.resize(count);
    for (int b = 0; b < count; ++b) opposite_[b] = Lookup(-dirs_[b]);
    BuildGroups();
    BuildSpreading();
}

void Directions::BuildAdjacency() {
    const int count = count_;
    // Adjacency: bins within 2 spacings (enough for the greedy walk to reach the nearest).
    adjacent_.resize(count);
    for (int i = 0; i < count; ++i)
        for (int j = 0; j < count; ++j)
            if (i != j && AngleBetween(dirs_[i], dirs_[j]) < AdjacentAngle())
                adjacent_[i].push_back(j);
    byAngle_.resize(count);
    for (int i = 0; i < count; ++i) {
        for (uint32_t j : adjacent_[i]) byAngle_[i].push_back({j, glm::dot(dirs_[i], dirs_[j])});
        std::stable_sort(byAngle_[i].begin(), byAngle_[i].end(),
                         [](const Near& a, const Near& b) { return a.cos > b.cos; });
    }
}

void Directions::BuildCubeTable() {
    const int count = count_;
    // Cube-map table, brute force at build time (≤ 6·64²·1024 dot products).
    cubeRes_ = std::max(8, static_cast<int>(std::ceil(std::sqrt(count / 6.0f) * 2.0f)));
    cube_.resize(6 * cubeRes_ * cubeRes_);
    for (int f = 0; f < 6; ++f)
        for (int v = 0; v < cubeRes_; ++v)
            for (int u = 0; u < cubeRes_; ++u) {
                glm::vec3 d = CubeTexelCentre(f, u, v, cubeRes_);
                uint32_t best = 0;
                float bestDot = -2.0f;
                for (int b = 0; b < count; ++b) {
                    float dd = glm::dot(d, dirs_[b]);
                    if (dd > bestDot) bestDot = dd, best = b;
                }
                cube_[(f * cubeRes_ + v) * cubeRes_ + u] = best;
            }
}

void Directions::BuildLookupTable() {
    // Lookup's own table: a cube map twice as fine (finer tables miss the cache more), each texel
    // listing every bin that is the nearest somewhere in it. For p in a texel, |p − c| ≤ ρ (c its
    // centre, ρ the chord to its farthest corner), so |p·x − c·x| ≤ ρ |x| for any x: a bin b
    // nearest at some p has p·(ω_b − ω_best) ≥ 0, so c·(ω_b − ω_best) ≥ −ρ |ω_b − ω_best|. Those
    // lie next to the centre's nearest bin (within its adjacency). The lookup is then the best
    // of one to a few dot products (the bound c·ω_b ≥ c·ω_best − 2ρ took the whole adjacency).
    lookupRes_ = 2 * cubeRes_;
    const int res = lookupRes_;
    candidateFirst_.assign(size_t(6) * res * res + 1, 0);
    for (int f = 0; f < 6; ++f)
        for (int v = 0; v < res; ++v)
            for (int u = 0; u < res; ++u) {
                const glm::vec3 c = CubeTexelCentre(f, u, v, res);
                float rho = 0.0f;
                for (const float du : {0.0f, 1.0f})
                    for (const float dv : {0.0f, 1.0f}) {
                        const glm::vec3 corner = CubePoint(f, 2.0f * (u + du) / res - 1.0f,
                                                           2.0f * (v + dv) / res - 1.0f);
                        rho = std::max(rho, glm::length(corner - c));
                    }
                rho *= 1.05f;  // float rounding's margin
                const uint32_t best = Walk(c);
                candidates_.push_back(uint16_t(best));
                for (uint32_t j : adjacent_[best]) {
                    const glm::vec3 apart = dirs_[j] - dirs_[best];
                    if (glm::dot(c, apart) >= -rho * glm::length(apart))
                        candidates_.push_back(uint16_t(j));
                }
                candidateFirst_[size_t(f * res + v) * res + u + 1] = uint32_t(candidates_.size());
            }
}

void Directions::BuildGroups() {
    const int count = count_;
    // ForEachWithin's groups: the cells of a cube map of 4² cells a face (about nine bins a
    // group at 864 bins), each bin in the cell its direction falls in.
    constexpr int kCells = 4;
    std::vector<std::vector<uint32_t>> members(6 * kCells * kCells);
    for (int b = 0; b < count; ++b) {
        int face, u, v;
        CubeCoords(dirs_[b], kCells, face, u, v);
        members[(face * kCells + v) * kCells + u].push_back(uint32_t(b));
    }
    groupFirst_.push_back(0);
    for (const auto& m : members) {
        if (m.empty()) continue;
        glm::vec3 sum(0.0f);
        for (uint32_t b : m) sum += dirs_[b];
        const glm::vec3 centre = glm::normalize(sum);
        float radius = 0.0f;
        for (uint32_t b : m) radius = std::max(radius, AngleBetween(centre, dirs_[b]));
        radius += 2e-3f;  // the rounding of the caller's cosines
        groups_.push_back({centre, radius, std::cos(radius), std::sin(radius)});
        groupBins_.insert(groupBins_.end(), m.begin(), m.end());
        groupFirst_.push_back(uint32_t(groupBins_.size()));
    }
    const size_t groups = groups_.size();
    PENUMBRA_CHECK(groups <= 256);  // groupOrder_ holds them as bytes
    groupOrder_.resize(size_t(count) * groups);
    groupLower_.resize(size_t(count) * groups);
    std::vector<std::pair<float, uint8_t>> byLower(groups);
    for (int b = 0; b < count; ++b) {
        for (size_t g = 0; g < groups; ++g)
            byLower[g] = {
                std::max(0.0f, AngleBetween(dirs_[b], groups_[g].centre) - groups_[g].radius),
                uint8_t(g)};
        std::sort(byLower.begin(), byLower.end());
        for (size_t g = 0; g < groups; ++g) {
            groupLower_[size_t(b) * groups + g] = byLower[g].first;
            groupOrder_[size_t(b) * groups + g] = byLower[g].second;
        }
    }
}

void Directions::BuildSpreading() {
    const int count = count_;
    const float pi = std::numbers::pi_v<float>;
    // Spreading tables: for each level, bins within 2.5σ with Gaussian weights, Σ = 1.
    offsets_.assign(kLevels * (count + 1), 0);
    for (int k = 0; k < kLevels; ++k) {
        float sigma = LevelSigma(k);
        float radius = std::min(2.5f * sigma, pi);
        for (int b = 0; b < count; ++b) {
            offsets_[k * (count + 1) + b] = static_cast<uint32_t>(weights_.size());
            double sum = 0.0;
            size_t first = weights_.size();
            for (int j = 0; j < count; ++j) {
                float ang = AngleBetween(dirs_[b], dirs_[j]);
                if (j != b && ang > radius) continue;
                float w = std::exp(-0.5f * ang * ang / (sigma * sigma));
                weights_.push_back({static_cast<uint32_t>(j), w});
                sum += w;
            }
            for (size_t i = first; i < weights_.size(); ++i)
                weights_[i].weight = static_cast<float>(weights_[i].weight / sum);
            // Heaviest first: the bin itself leads its list.
            std::sort(weights_.begin() + first, weights_.end(),
                      [](const BinWeight& a, const BinWeight& c) { return a.weight > c.weight; });
        }
        offsets_[k * (count + 1) + count] = static_cast<uint32_t>(weights_.size());
    }
    for (int k = 0; k < kLevels; ++k) {
        int width = 0;
        for (int b = 0; b < count; ++b)
            width = std::max(width, static_cast<int>(Neighbours(k, b).size()));
        paddedWidth_[k] = width;
        paddedStart_[k] = padded_.size();
        for (int b = 0; b < count; ++b) {
            auto list = Neighbours(k, b);
            padded_.insert(padded_.end(), list.begin(), list.end());
            padded_.resize(padded_.size() + width - list.size(),
                           BinWeight{static_cast<uint32_t>(b), 0.0f});
        }
    }
}

uint32_t Directions::Walk(const glm::vec3& d) const {
    int face, u, v;
    CubeCoords(d, cubeRes_, face, u, v);
    uint32_t best = cube_[(face * cubeRes_ + v) * cubeRes_ + u];
    float bestDot = glm::dot(d, dirs_[best]);
    for (bool moved = true; moved;) {
        moved = false;
        for (uint32_t j : adjacent_[best]) {
            float dd = glm::dot(d, dirs_[j]);
            if (dd > bestDot) bestDot = dd, best = j, moved = true;
        }
    }
    return best;
}

std::vector<uint32_t> Directions::PaddedAdjacency(uint32_t& width) const {
    width = 0;
    for (const auto& a : adjacent_) width = std::max(width, static_cast<uint32_t>(a.size()));
    std::vector<uint32_t> out;
    out.reserve(size_t(count_) * width);
    for (uint32_t b = 0; b < static_cast<uint32_t>(count_); ++b) {
        out.insert(out.end(), adjacent_[b].begin(), adjacent_[b].end());
        out.resize(out.size() + width - adjacent_[b].size(), b);
    }
    return out;
}

uint32_t Directions::LookupWithin(const glm::vec3& d, const glm::vec3& a,
                                  const glm::vec3& b) const {
    uint32_t nearest = Lookup(d);
    const glm::vec3 none(0.0f);
    auto valid = [&](uint32_t j) {
        return (a == none || glm::dot(dirs_[j], a) > 0.0f) &&
               (b == none || glm::dot(dirs_[j], b) > 0.0f);
    };
    if (valid(nearest)) return nearest;
    uint32_t best = nearest;
    float bestDot = -2.0f;
    for (uint32_t j : adjacent_[nearest]) {
        float dd = glm::dot(d, dirs_[j]);
        if (valid(j) && dd > bestDot) bestDot = dd, best = j;
    }
    return best;
}

float Directions::CosineNorm(const glm::vec3& n) const {
    double sum = 0.0;
    for (const auto& d : dirs_) sum += std::max(0.0f, glm::dot(n, d));
    return CosineNormOfSum(sum);
}

float Directions::CosineNormOfSum(double cosineSum) const {
    const double sum = cosineSum * solidAngle_;
    return sum > 0.0 ? static_cast<float>(std::numbers::pi / sum) : 0.0f;
}

// σ_0 = half the bin spacing (pre-filter against aliasing on the bin grid); each level
// widens by √2 to follow larger senders.
float Directions::LevelSigma(int level) const {
    return 0.5f * spacing_ * std::pow(2.0f, 0.5f * level);
}

// A disc of angular radius α has per-axis standard deviation α/2; combined with the
// pre-filter σ_0 this gives the Gaussian that stands in for the sender's cone.
int Directions::LevelFor(float alpha) const {
    float s0 = LevelSigma(0);
    float s = std::sqrt(0.25f * alpha * alpha + s0 * s0);
    int k = static_cast<int>(std::lround(2.0f * std::log2(s / s0)));
    return std::clamp(k, 0, kLevels - 1);
}

}  // namespace penumbra
