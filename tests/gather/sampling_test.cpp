// The gather's sampling patterns (rays/sampling.h): the cheap R2 fraction equals fmod, and
// CosineCone lets through every pattern point whose direction lies in its cone.
#include "rays/sampling.h"

#include <gtest/gtest.h>

#include <random>

namespace penumbra {
namespace {

TEST(Sampling, R2PointIsTheFractionOfTheSequence) {
    const glm::vec2 s(0.3141f, 0.9265f);
    for (int i : {0, 1, 2, 255, 256, 4097, 65535}) {
        const double x = std::fmod(s.x + i * 0.7548776662466927, 1.0);
        const double y = std::fmod(s.y + i * 0.5698402909980532, 1.0);
        EXPECT_EQ(R2Point(s, i), glm::vec2(static_cast<float>(x), static_cast<float>(y))) << i;
    }
}

// Random normals (axis-aligned ones included, with −0 components: they turn the basis), cone
// axes and half-angles from tiny to nearly a hemisphere: no point whose direction is in the
// cone is turned away, and a narrow cone turns away most of the others.
TEST(Sampling, CosineConeLetsThroughEveryDirectionInItsCone) {
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> uniform(0.0f, 1.0f);
    auto direction = [&] {
        glm::vec3 v;
        do v = 2.0f * glm::vec3(uniform(rng), uniform(rng), uniform(rng)) - 1.0f;
        while (glm::dot(v, v) > 1.0f || glm::dot(v, v) < 1e-4f);
        return glm::normalize(v);
    };
    const glm::vec3 axes[] = {{0, 0, 1}, {0, 0, -1}, {1, 0, -0.0f}, {1, 0, 0}, {0, -1, 0}};
    size_t inside = 0, passed = 0, narrowOutside = 0, narrowPassed = 0;
    for (int c = 0; c < 4000; ++c) {
        const glm::vec3 n = c % 3 == 0 ? axes[(c / 3) % 5] : direction();
        const glm::vec3 axis = direction();
        const float sinHalf = c % 4 == 0 ? 0.05f * uniform(rng)
                                         : (c % 4 == 1 ? 0.9f + 0.1f * uniform(rng) : uniform(rng));
        const float cosHalf = std::sqrt(1.0f - sinHalf * sinHalf);
        const CosineCone cone(n, axis, sinHalf);
        for (int k = 0; k < 1000; ++k) {
            const glm::vec2 u(uniform(rng), uniform(rng));
            const bool in = glm::dot(CosineDirection(n, u), axis) >= cosHalf;
            const bool may = cone.MayContain(u);
            inside += in;
            passed += in && may;
            if (c % 4 == 0 && !in) ++narrowOutside, narrowPassed += may;
        }
    }
    EXPECT_GT(inside, 100000u);
    EXPECT_EQ(passed, inside);
    EXPECT_LT(narrowPassed, narrowOutside / 20);
}

}  // namespace
}  // namespace penumbra
