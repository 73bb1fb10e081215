// Geometry of the cluttered stability scenes (clutter_scenes.h).
#include "clutter_scenes.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>

namespace penumbra::scenes {
namespace {

constexpr float kRoom = 2.0f;

// A uniform number in [lo, hi) from the generator's raw 32-bit output (std::mt19937 is the
// same everywhere; the standard distributions are not).
float Uniform(std::mt19937& rng, float lo, float hi) {
    return lo + (hi - lo) * static_cast<float>(rng() >> 8) * (1.0f / 16777216.0f);
}

std::string Cm(float metres) {
    char buf[32];
    if (metres < 0.01f && metres > 0.0f)
        std::snprintf(buf, sizeof buf, "%dmm", static_cast<int>(std::lround(metres * 1000.0f)));
    else
        std::snprintf(buf, sizeof buf, "%dcm", static_cast<int>(std::lround(metres * 100.0f)));
    return buf;
}

}  // namespace

void AddClutterRoom(SceneBuilder& b, float emission, float albedo) {
    const uint32_t wall = b.AddMaterial("room", glm::vec3(albedo));
    const uint32_t lamp = b.AddMaterial("panel", glm::vec3(0.0f), glm::vec3(emission));
    const float R = kRoom;
    const glm::vec3 inside(R / 2, R / 2, R / 2);
    b.AddQuad("floor", wall, {0, 0, 0}, {R, 0, 0}, {R, 0, R}, {0, 0, R}, inside, 4);
    b.AddQuad("ceiling", wall, {0, R, 0}, {R, R, 0}, {R, R, R}, {0, R, R}, inside, 4);
    b.AddQuad("wall_south", wall, {0, 0, 0}, {R, 0, 0}, {R, R, 0}, {0, R, 0}, inside, 4);
    b.AddQuad("wall_north", wall, {0, 0, R}, {R, 0, R}, {R, R, R}, {0, R, R}, inside, 4);
    b.AddQuad("wall_west", wall, {0, 0, 0}, {0, 0, R}, {0, R, R}, {0, R, 0}, inside, 4);
    b.AddQuad("wall_east", wall, {R, 0, 0}, {R, 0, R}, {R, R, R}, {R, R, 0}, inside, 4);
    // The panel hangs 1 cm under the ceiling, facing down.
    const float y = R - 0.01f, lo = R / 2 - 0.3f, hi = R / 2 + 0.3f;
    b.AddQuad("panel", lamp, {lo, y, lo}, {hi, y, lo}, {hi, y, hi}, {lo, y, hi}, inside, 2);
}

glm::vec3 SunlitMazeSun() { return glm::normalize(glm::vec3(0.3f, -1.0f, 0.2f)); }

std::vector<std::pair<glm::vec3, glm::vec3>> SunlitMazeWalls() {
    const float h = kSunlitMazeHeight;
    return {{{1.47f, 0.0f, 0.0f}, {1.53f, h, 2.5f}},
            {{2.47f, 0.0f, 1.5f}, {2.53f, h, 4.0f}},
            {{0.3f, 0.0f, 3.0f}, {1.0f, h, 3.06f}}};
}

SceneBuilder SunlitMaze() {
    SceneBuilder b;
    const uint32_t plaster = b.AddMaterial("plaster", glm::vec3(0.6f));
    const float W = 4.0f, H = kSunlitMazeHeight, lo = kSunlitMazeHoleLo, hi = kSunlitMazeHoleHi;
    const glm::vec3 inside(W / 2, H / 2, W / 2);
    b.AddQuad("floor", plaster, {0, 0, 0}, {W, 0, 0}, {W, 0, W}, {0, 0, W}, inside, 16);
    b.AddQuad("wall_south", plaster, {0, 0, 0}, {W, 0, 0}, {W, H, 0}, {0, H, 0}, inside, 8);
    b.AddQuad("wall_north", plaster, {0, 0, W}, {W, 0, W}, {W, H, W}, {0, H, W}, inside, 8);
    b.AddQuad("wall_west", plaster, {0, 0, 0}, {0, 0, W}, {0, H, W}, {0, H, 0}, inside, 8);
    b.AddQuad("wall_east", plaster, {W, 0, 0}, {W, 0, W}, {W, H, W}, {W, H, 0}, inside, 8);
    // The roof in four quads about the hole, facing down into the room.
    const glm::vec3 below(W / 2, 0.0f, W / 2);
    b.AddQuad("roof", plaster, {0, H, 0}, {W, H, 0}, {W, H, lo}, {0, H, lo}, below, 4);
    b.AddQuad("roof", plaster, {0, H, hi}, {W, H, hi}, {W, H, W}, {0, H, W}, below, 8);
    b.AddQuad("roof", plaster, {0, H, lo}, {lo, H, lo}, {lo, H, hi}, {0, H, hi}, below, 1);
    b.AddQuad("roof", plaster, {hi, H, lo}, {W, H, lo}, {W, H, hi}, {hi, H, hi}, below, 4);
    // Hollow inner walls: four sides facing out, open at floor and roof.
    int k = 0;
    for (const auto& [a, c] : SunlitMazeWalls()) {
        const std::string name = "inner_" + std::to_string(k++);
        const glm::vec3 mid = 0.5f * (a + c);
        b.AddQuad(name, plaster, {a.x, 0, a.z}, {a.x, 0, c.z}, {a.x, H, c.z}, {a.x, H, a.z},
                  mid - glm::vec3(1, 0, 0), 8);
        b.AddQuad(name, plaster, {c.x, 0, a.z}, {c.x, 0, c.z}, {c.x, H, c.z}, {c.x, H, a.z},
                  mid + glm::vec3(1, 0, 0), 8);
        b.AddQuad(name, plaster, {a.x, 0, a.z}, {c.x, 0, a.z}, {c.x, H, a.z}, {a.x, H, a.z},
                  mid - glm::vec3(0, 0, 1), 8);
        b.AddQuad(name, plaster, {a.x, 0, c.z}, {c.x, 0, c.z}, {c.x, H, c.z}, {a.x, H, c.z},
                  mid + glm::vec3(0, 0, 1), 8);
    }
    PunctualLight sun;
    sun.name = "sun";
    sun.type = LightType::kDirectional;
    sun.intensity = 1000.0f;
    sun.position = {W / 2, H + 1.0f, W / 2};
    sun.direction = SunlitMazeSun();
    b.AddLight(sun);
    return b;
}

SceneBuilder BoxRow(int count, float gap) {
    SceneBuilder b;
    AddClutterRoom(b);
    const uint32_t grey = b.AddMaterial("box", glm::vec3(0.6f));
    const glm::vec3 size(0.27f, 0.25f, 0.08f);
    const float length = count * size.z + (count - 1) * gap;
    for (int i = 0; i < count; ++i) {
        const float z = kRoom / 2 - length / 2 + size.z / 2 + i * (size.z + gap);
        b.AddBox("box_" + std::to_string(i), grey, {kRoom / 2, size.y / 2, z}, size, 0.0f, false);
    }
    return b;
}

SceneBuilder BoxStacks(int stacks, int height, float gap) {
    SceneBuilder b;
    AddClutterRoom(b);
    const uint32_t grey = b.AddMaterial("box", glm::vec3(0.6f));
    const glm::vec3 size(0.3f, 0.04f, 0.25f);
    // With a gap the boxes float that far above each other (as on thin spacers, left out).
    for (int s = 0; s < stacks; ++s)
        for (int k = 0; k < height; ++k) {
            const float x = 0.4f + s * 0.45f;
            const float y = size.y / 2 + k * (size.y + gap);
            b.AddBox("stack_" + std::to_string(s), grey, {x, y, 1.0f}, size, 0.0f, k > 0);
        }
    return b;
}

SceneBuilder Bookshelf(int boards, float gap, uint32_t seed, bool faceNodes) {
    SceneBuilder b;
    AddClutterRoom(b);
    b.SetBoxFacesAsNodes(faceNodes);
    const uint32_t wood = b.AddMaterial("wood", {0.55f, 0.4f, 0.25f});
    const uint32_t paper[3] = {b.AddMaterial("book_red", {0.6f, 0.2f, 0.15f}),
                               b.AddMaterial("book_cream", {0.75f, 0.7f, 0.6f}),
                               b.AddMaterial("book_blue", {0.2f, 0.3f, 0.55f})};
    std::mt19937 rng(seed);
    const float x0 = 0.6f, width = 0.8f, depth = 0.25f, z = kRoom - 0.02f - depth / 2;
    const float pitch = 0.32f, board = 0.02f;
    const float top = boards * pitch + board;
    // Sides, back and boards: the back stands 2 cm off the north wall.
    b.AddBox("shelf", wood, {x0 - board / 2, top / 2, z}, {board, top, depth}, 0.0f, false);
    b.AddBox("shelf", wood, {x0 + width + board / 2, top / 2, z}, {board, top, depth}, 0.0f, false);
    b.AddBox("shelf", wood, {x0 + width / 2, top / 2, z + depth / 2 + 0.005f}, {width, top, 0.01f},
             0.0f, false);
    for (int k = 0; k <= boards; ++k)
        b.AddBox("shelf", wood, {x0 + width / 2, k * pitch + board / 2, z}, {width, board, depth},
                 0.0f, k > 0);
    // Books standing on each board, `gap` apart, until the board is full.
    int n = 0;
    for (int k = 0; k < boards; ++k) {
        float x = x0 + gap;
        while (true) {
            const float t = Uniform(rng, 0.02f, 0.03f), h = Uniform(rng, 0.18f, 0.24f);
            const float d = Uniform(rng, 0.17f, 0.21f);
            if (x + t > x0 + width - 0.005f) break;
            const uint32_t m = paper[rng() % 3];
            const float y = k * pitch + board + h / 2;
            b.AddBox("book_" + std::to_string(n++), m, {x + t / 2, y, z - (depth - d) / 2},
                     {t, h, d}, 0.0f, false);
            x += t + gap;
        }
    }
    return b;
}

SceneBuilder ChairsUnderDesks() {
    SceneBuilder b;
    AddClutterRoom(b);
    const uint32_t wood = b.AddMaterial("wood", {0.55f, 0.4f, 0.25f});
    const uint32_t metal = b.AddMaterial("metal_paint", {0.3f, 0.32f, 0.35f});
    const uint32_t fabric = b.AddMaterial("fabric", {0.2f, 0.25f, 0.5f});
    for (int d = 0; d < 2; ++d) {
        const std::string id = std::to_string(d);
        const float x = 0.55f + d * 0.9f, z = 1.45f;
        b.AddBox("desk_" + id, wood, {x, 0.715f, z}, {0.8f, 0.03f, 0.55f});
        for (int lx = -1; lx <= 1; lx += 2)
            for (int lz = -1; lz <= 1; lz += 2)
                b.AddBox("desk_" + id, metal, {x + lx * 0.37f, 0.35f, z + lz * 0.24f},
                         {0.04f, 0.7f, 0.04f}, 0.0f, false);
        // The chair's seat reaches 15 cm under the desk top, its back 7 cm below its edge.
        const float cz = z - 0.275f - 0.21f + 0.15f;
        b.AddBox("chair_" + id, fabric, {x, 0.45f, cz}, {0.42f, 0.05f, 0.42f});
        b.AddBox("chair_" + id, fabric, {x, 0.6f, cz - 0.2f}, {0.42f, 0.25f, 0.03f});
        for (int lx = -1; lx <= 1; lx += 2)
            for (int lz = -1; lz <= 1; lz += 2)
                b.AddBox("chair_" + id, metal, {x + lx * 0.18f, 0.2125f, cz + lz * 0.18f},
                         {0.03f, 0.425f, 0.03f}, 0.0f, false);
    }
    return b;
}

SceneBuilder RandomBoxes(int count, uint32_t seed) {
    SceneBuilder b;
    AddClutterRoom(b);
    const uint32_t mats[2] = {b.AddMaterial("box_light", glm::vec3(0.65f)),
                              b.AddMaterial("box_dark", {0.3f, 0.25f, 0.2f})};
    std::mt19937 rng(seed);
    struct Placed {
        glm::vec3 centre, size;
    };
    std::vector<Placed> placed;
    for (int i = 0; i < count; ++i) {
        glm::vec3 size(Uniform(rng, 0.02f, 0.4f), Uniform(rng, 0.02f, 0.4f),
                       Uniform(rng, 0.02f, 0.4f));
        glm::vec3 c(Uniform(rng, 0.3f, 1.7f), 0.0f, Uniform(rng, 0.3f, 1.7f));
        // On the floor, or on top of the highest box it overlaps (contact faces); boxes may
        // interpenetrate sideways.
        float base = 0.0f;
        for (const Placed& p : placed)
            if (std::abs(p.centre.x - c.x) < (p.size.x + size.x) / 2 &&
                std::abs(p.centre.z - c.z) < (p.size.z + size.z) / 2)
                base = std::max(base, p.centre.y + p.size.y / 2);
        c.y = base + size.y / 2;
        const float yaw = (rng() % 4 == 0) ? Uniform(rng, 0.0f, 90.0f) : 0.0f;
        b.AddBox("box_" + std::to_string(i), mats[rng() % 2], c, size, yaw, base > 0.0f);
        placed.push_back({c, size});
    }
    return b;
}

float FurnaceBound(const Scene& scene) {
    float emission = 0.0f, albedo = 0.0f;
    for (const Material& m : scene.materials) {
        emission = std::max({emission, m.emission.x, m.emission.y, m.emission.z});
        const glm::vec3 r = m.albedo + m.specular;
        albedo = std::max({albedo, r.x, r.y, r.z});
    }
    if (albedo >= 1.0f) return std::numeric_limits<float>::infinity();
    return 3.14159265f * emission / (1.0f - albedo);
}

std::vector<ClutterScene> ClutterSuite() {
    std::vector<ClutterScene> suite;
    for (int count : {3, 5, 10})
        for (float gap : {0.0f, 0.005f, 0.02f, 0.05f})
            suite.push_back(
                {"box-row-" + std::to_string(count) + "-" + Cm(gap) + ".gltf", BoxRow(count, gap)});
    suite.push_back({"box-row-15-5mm.gltf", BoxRow(15, 0.005f)});
    suite.push_back({"box-row-10-10cm.gltf", BoxRow(10, 0.1f)});
    suite.push_back({"box-stacks-0cm.gltf", BoxStacks(3, 8, 0.0f)});
    suite.push_back({"box-stacks-1cm.gltf", BoxStacks(3, 8, 0.01f)});
    suite.push_back({"bookshelf-5mm.gltf", Bookshelf(2, 0.005f, 7)});
    suite.push_back({"bookshelf-0mm.gltf", Bookshelf(2, 0.0f, 11)});
    suite.push_back({"bookshelf-5mm-faces.gltf", Bookshelf(2, 0.005f, 7, true)});
    suite.push_back({"chairs-under-desks.gltf", ChairsUnderDesks()});
    for (uint32_t seed : {1u, 2u, 3u, 4u})
        suite.push_back({"random-boxes-" + std::to_string(seed) + ".gltf", RandomBoxes(40, seed)});
    return suite;
}

}  // namespace penumbra::scenes
