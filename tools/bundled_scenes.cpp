// Geometry of the bundled scenes.
#include "bundled_scenes.h"

#include <algorithm>
#include <cmath>

#include "clutter_scenes.h"

namespace penumbra::scenes {
namespace {

constexpr float kMm = 0.001f;
glm::vec3 Mm(float x, float y, float z) { return {x * kMm, y * kMm, z * kMm}; }

}  // namespace

SceneBuilder CornellBox() {
    SceneBuilder b;
    // Albedos and light radiance as in the widely used pbrt/Mitsuba rendition.
    uint32_t white = b.AddMaterial("white", {0.725f, 0.71f, 0.68f});
    uint32_t red = b.AddMaterial("red", {0.63f, 0.065f, 0.05f});
    uint32_t green = b.AddMaterial("green", {0.14f, 0.45f, 0.091f});
    uint32_t light = b.AddMaterial("light", {0.78f, 0.78f, 0.78f}, {17.0f, 12.0f, 4.0f});
    glm::vec3 inside = Mm(278.0f, 274.4f, 279.6f);

    // Walls as grids of input vertices (per-vertex output resolves their gradients).
    constexpr int kWall = 8, kStrip = 6, kSide = 3, kLight = 2, kBlock = 4;
    b.AddQuad("floor", white, Mm(552.8f, 0, 0), Mm(0, 0, 0), Mm(0, 0, 559.2f),
              Mm(549.6f, 0, 559.2f), inside, kWall);
    // Ceiling around the light's opening (x 213..343, z 227..332).
    const float y = 548.8f;
    b.AddQuad("ceiling", white, Mm(0, y, 0), Mm(556, y, 0), Mm(556, y, 227), Mm(0, y, 227), inside,
              kStrip);
    b.AddQuad("ceiling", white, Mm(0, y, 332), Mm(556, y, 332), Mm(556, y, 559.2f),
              Mm(0, y, 559.2f), inside, kStrip);
    b.AddQuad("ceiling", white, Mm(0, y, 227), Mm(213, y, 227), Mm(213, y, 332), Mm(0, y, 332),
              inside, kSide);
    b.AddQuad("ceiling", white, Mm(343, y, 227), Mm(556, y, 227), Mm(556, y, 332), Mm(343, y, 332),
              inside, kSide);
    b.AddQuad("ceiling_light", light, Mm(343, y, 227), Mm(343, y, 332), Mm(213, y, 332),
              Mm(213, y, 227), inside, kLight);
    b.AddQuad("back_wall", white, Mm(549.6f, 0, 559.2f), Mm(0, 0, 559.2f), Mm(0, y, 559.2f),
              Mm(556, y, 559.2f), inside, kWall);
    b.AddQuad("right_wall", green, Mm(0, 0, 559.2f), Mm(0, 0, 0), Mm(0, y, 0), Mm(0, y, 559.2f),
              inside, kWall);
    b.AddQuad("left_wall", red, Mm(552.8f, 0, 0), Mm(549.6f, 0, 559.2f), Mm(556, y, 559.2f),
              Mm(556, y, 0), inside, kWall);

    // Blocks: four sides and a top each, faces pointing away from the block's centre.
    auto block = [&](const std::string& name, const glm::vec3(&top)[4], float h) {
        glm::vec3 c(0.0f);
        for (const auto& p : top) c += p;
        c = 0.25f * c;
        glm::vec3 centre(c.x, 0.5f * h, c.z);
        b.AddQuad(name, white, Mm(top[0].x, h, top[0].z), Mm(top[1].x, h, top[1].z),
                  Mm(top[2].x, h, top[2].z), Mm(top[3].x, h, top[3].z), Mm(c.x, 2 * h, c.z),
                  kBlock);
        for (int i = 0; i < 4; ++i) {
            glm::vec3 a = top[i], d = top[(i + 1) % 4];
            glm::vec3 faceCentre(0.5f * (a.x + d.x), 0.5f * h, 0.5f * (a.z + d.z));
            glm::vec3 out = 2.0f * faceCentre - centre;
            b.AddQuad(name, white, Mm(a.x, 0, a.z), Mm(a.x, h, a.z), Mm(d.x, h, d.z),
                      Mm(d.x, 0, d.z), Mm(out.x, out.y, out.z), kBlock);
        }
        // Movable by the service, about the centre of its base, within 16 cm of where it
        // stands (inside the box): the service links it for that region (Sec. 3.3), and
        // tighter bounds mean fewer links than "anywhere on the floor" would.
        glm::vec3 lo = top[0], hi = top[0];
        for (const auto& p : top) lo = glm::min(lo, p), hi = glm::max(hi, p);
        constexpr float kReach = 160.0f;
        b.SetDynamic(
            name, Mm(c.x, 0, c.z),
            Mm(std::max(0.0f, lo.x - kReach), 0, std::max(0.0f, lo.z - kReach)),
            Mm(std::min(556.0f, hi.x + kReach), h + 1.0f, std::min(559.2f, hi.z + kReach)));
    };
    const glm::vec3 shortTop[4] = {{130, 0, 65}, {82, 0, 225}, {240, 0, 272}, {290, 0, 114}};
    const glm::vec3 tallTop[4] = {{423, 0, 247}, {265, 0, 296}, {314, 0, 456}, {472, 0, 406}};
    block("short_block", shortTop, 165.0f);
    block("tall_block", tallTop, 330.0f);
    // The published camera: 800 mm in front of the opening, 39.3° field of view.
    b.AddCamera("camera", Mm(278, 273, -800), Mm(278, 273, 0), glm::radians(39.3f));
    return b;
}

SceneBuilder Blocker(bool withBlocker) {
    SceneBuilder b;
    uint32_t grey = b.AddMaterial("grey", {0.5f, 0.5f, 0.5f});
    uint32_t light = b.AddMaterial("light", {0.0f, 0.0f, 0.0f}, {10.0f, 10.0f, 10.0f});
    b.AddQuad("floor", grey, {-1, 0, -1}, {1, 0, -1}, {1, 0, 1}, {-1, 0, 1}, {0, 1, 0}, 16);
    b.AddQuad("emitter", light, {-0.25f, 1, -0.25f}, {0.25f, 1, -0.25f}, {0.25f, 1, 0.25f},
              {-0.25f, 1, 0.25f}, {0, 0, 0});
    if (withBlocker) {
        b.AddBox("blocker", grey, {0, 0.5f, 0}, {0.4f, 0.05f, 0.4f});
        b.SetDynamic("blocker", {0, 0.5f, 0});  // no bounds given: anywhere in the scene
    }
    return b;
}

SceneBuilder Office() {
    SceneBuilder b;
    uint32_t wall = b.AddMaterial("wall", {0.7f, 0.68f, 0.64f});
    uint32_t floorMat = b.AddMaterial("carpet", {0.35f, 0.3f, 0.28f});
    uint32_t ceiling = b.AddMaterial("ceiling", {0.8f, 0.8f, 0.8f});
    uint32_t wood = b.AddMaterial("wood", {0.55f, 0.38f, 0.22f});
    uint32_t metal = b.AddMaterial("metal_paint", {0.3f, 0.32f, 0.35f});
    uint32_t fabric = b.AddMaterial("fabric", {0.2f, 0.25f, 0.5f});
    uint32_t screen = b.AddMaterial("screen", {0.05f, 0.05f, 0.05f});
    uint32_t fixture = b.AddMaterial("fixture", {0.8f, 0.8f, 0.8f});
    uint32_t lamp = b.AddMaterial("lamp", {0.8f, 0.8f, 0.8f}, {40.0f, 38.0f, 34.0f});
    const float W = 12.0f, D = 8.0f, H = 3.0f;
    glm::vec3 inside(W / 2, H / 2, D / 2);
    // Room shell in 0.5 m tiles.
    b.AddTiledQuad("floor", floorMat, {0, 0, 0}, {W, 0, 0}, {0, 0, D}, 24, 16, inside);
    b.AddTiledQuad("ceiling", ceiling, {0, H, 0}, {W, 0, 0}, {0, 0, D}, 24, 16, inside);
    b.AddTiledQuad("wall_south", wall, {0, 0, 0}, {W, 0, 0}, {0, H, 0}, 24, 6, inside);
    b.AddTiledQuad("wall_north", wall, {0, 0, D}, {W, 0, 0}, {0, H, 0}, 24, 6, inside);
    b.AddTiledQuad("wall_west", wall, {0, 0, 0}, {0, 0, D}, {0, H, 0}, 16, 6, inside);
    b.AddTiledQuad("wall_east", wall, {W, 0, 0}, {0, 0, D}, {0, H, 0}, 16, 6, inside);
    // Ceiling fixtures: closed boxes whose underside emits.
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 2; ++j)
            b.AddBoxWithBottom("fixture_" + std::to_string(i * 2 + j), fixture, lamp,
                               {1.5f + 3.0f * i, H - 0.05f, 2.0f + 4.0f * j}, {1.2f, 0.06f, 0.6f});
    // Workstations: desk, chair, monitor, computer.
    int n = 0;
    for (int row = 0; row < 4 && n < 16; ++row)
        for (int col = 0; col < 6 && n < 16; ++col, ++n) {
            std::string id = std::to_string(n);
            float x = 1.3f + 1.9f * col, z = 1.2f + 1.8f * row;
            float yaw = (row % 2) ? 180.0f : 0.0f;
            float dz = (row % 2) ? -1.0f : 1.0f;
            b.AddBox("desk_" + id, wood, {x, 0.73f, z}, {1.4f, 0.04f, 0.7f}, 0, true);
            for (int lx = -1; lx <= 1; lx += 2)
                for (int lz = -1; lz <= 1; lz += 2)
                    b.AddBox("desk_" + id, metal, {x + lx * 0.65f, 0.355f, z + lz * 0.3f},
                             {0.05f, 0.71f, 0.05f}, 0, false);
            float cz = z - dz * 0.6f;
            b.AddBox("chair_" + id, fabric, {x, 0.45f, cz}, {0.45f, 0.06f, 0.45f}, yaw, true);
            b.AddBox("chair_" + id, fabric, {x, 0.75f, cz - dz * 0.22f}, {0.45f, 0.55f, 0.05f}, yaw,
                     true);
            for (int lx = -1; lx <= 1; lx += 2)
                for (int lz = -1; lz <= 1; lz += 2)
                    b.AddBox("chair_" + id, metal, {x + lx * 0.19f, 0.21f, cz + lz * 0.19f},
                             {0.03f, 0.42f, 0.03f}, 0, false);
            b.AddBox("monitor_" + id, screen, {x, 1.0f, z + dz * 0.2f}, {0.55f, 0.35f, 0.03f}, yaw,
                     true);
            b.AddBox("monitor_" + id, metal, {x, 0.8f, z + dz * 0.22f}, {0.06f, 0.1f, 0.06f}, 0,
                     true);
            b.AddBox("computer_" + id, metal, {x + 0.5f, 0.22f, z}, {0.2f, 0.44f, 0.45f}, 0, false);
        }
    // The first chair can be pushed about in front of its desk (Sec. 3.3 moving objects):
    // the service links it for this box.
    b.SetDynamic("chair_0", {1.3f, 0.0f, 0.6f}, {0.6f, 0.0f, 0.05f}, {2.0f, 1.1f, 1.0f});
    // Shelves along the west and east walls.
    for (int s = 0; s < 6; ++s) {
        std::string id = std::to_string(s);
        float x = (s < 3) ? 0.25f : W - 0.25f;
        float z = 1.5f + 2.5f * (s % 3);
        b.AddBox("shelf_" + id, wood, {x, 1.0f, z - 0.45f}, {0.4f, 2.0f, 0.03f}, 0, false);
        b.AddBox("shelf_" + id, wood, {x, 1.0f, z + 0.45f}, {0.4f, 2.0f, 0.03f}, 0, false);
        for (int k = 0; k < 5; ++k)
            b.AddBox("shelf_" + id, wood, {x, 0.1f + 0.45f * k, z}, {0.4f, 0.03f, 0.87f});
    }
    // Filing cabinets by the south wall.
    for (int c = 0; c < 8; ++c)
        for (int k = 0; k < 3; ++k)
            b.AddBox("cabinet_" + std::to_string(c), metal,
                     {1.0f + 1.4f * c, 0.22f + 0.44f * k, 7.7f}, {0.5f, 0.42f, 0.5f}, 0,
                     k == 0 ? false : true);
    return b;
}

SceneBuilder Maze() {
    SceneBuilder b;
    uint32_t wall = b.AddMaterial("wall", {0.8f, 0.8f, 0.8f});
    uint32_t floorMat = b.AddMaterial("floor", {0.6f, 0.55f, 0.5f});
    uint32_t housing = b.AddMaterial("housing", {0.2f, 0.2f, 0.2f});
    uint32_t light = b.AddMaterial("light", {0.0f, 0.0f, 0.0f}, {40.0f, 38.0f, 34.0f});
    const float W = 4.0f, D = 4.0f, H = 1.0f;
    const glm::vec3 inside(W / 2, H / 2, D / 2);
    b.AddQuad("floor", floorMat, {0, 0, 0}, {W, 0, 0}, {W, 0, D}, {0, 0, D}, inside, 16);
    b.AddQuad("ceiling", wall, {0, H, 0}, {W, H, 0}, {W, H, D}, {0, H, D}, inside, 16);
    b.AddQuad("wall_south", wall, {0, 0, 0}, {W, 0, 0}, {W, H, 0}, {0, H, 0}, inside, 16);
    b.AddQuad("wall_north", wall, {0, 0, D}, {W, 0, D}, {W, H, D}, {0, H, D}, inside, 16);
    b.AddQuad("wall_west", wall, {0, 0, 0}, {0, 0, D}, {0, H, D}, {0, H, 0}, inside, 16);
    b.AddQuad("wall_east", wall, {W, 0, 0}, {W, 0, D}, {W, H, D}, {W, H, 0}, inside, 16);
    // Three partitions, 0.1 m thick, floor to ceiling, leaving a 1 m gap at alternate
    // ends: a serpentine of four corridors along x.
    const float t = 0.1f, gap = 1.0f;
    b.AddBox("partition_1", wall, {(W - gap) / 2, H / 2, 1.0f}, {W - gap, H, t}, 0, false);
    b.AddBox("partition_2", wall, {gap + (W - gap) / 2, H / 2, 2.0f}, {W - gap, H, t}, 0, false);
    b.AddBox("partition_3", wall, {(W - gap) / 2, H / 2, 3.0f}, {W - gap, H, t}, 0, false);
    // The lamp: a closed box in the first corridor's dead end whose only emitting face looks
    // at the end wall (x = 0), away from the maze; all else is lit by bounces.
    const glm::vec3 c(0.35f, 0.5f, 0.5f), size(0.1f, 0.3f, 0.4f);
    b.AddBox("lamp_housing", housing, c, size);
    const float x = c.x - size.x / 2 - 0.002f;
    b.AddQuad("lamp", light, {x, c.y - size.y / 2, c.z - size.z / 2},
              {x, c.y - size.y / 2, c.z + size.z / 2}, {x, c.y + size.y / 2, c.z + size.z / 2},
              {x, c.y + size.y / 2, c.z - size.z / 2}, {0, c.y, c.z}, 2);
    return b;
}

SceneBuilder GlossyBox() {
    SceneBuilder b;
    uint32_t white = b.AddMaterial("white", {0.75f, 0.75f, 0.75f});
    uint32_t floorMat = b.AddMaterial("floor", {0.55f, 0.5f, 0.45f});
    uint32_t green = b.AddMaterial("green", {0.3f, 0.55f, 0.3f});
    // Blue metal, roughness 0.35 (Phong exponent ≈ 33), and a rougher gold.
    uint32_t blue = b.AddPbrMaterial("blue_metal", {0.25f, 0.4f, 0.9f}, 1.0f, 0.35f);
    uint32_t gold = b.AddPbrMaterial("gold", {1.0f, 0.78f, 0.34f}, 1.0f, 0.5f);
    const float W = 4.0f, D = 4.0f, H = 3.0f;
    const glm::vec3 inside(W / 2, H / 2, D / 2);
    b.AddQuad("floor", floorMat, {0, 0, 0}, {W, 0, 0}, {W, 0, D}, {0, 0, D}, inside, 12);
    b.AddQuad("ceiling", white, {0, H, 0}, {W, H, 0}, {W, H, D}, {0, H, D}, inside, 12);
    b.AddQuad("wall_south", white, {0, 0, 0}, {W, 0, 0}, {W, H, 0}, {0, H, 0}, inside, 12);
    b.AddQuad("wall_north", white, {0, 0, D}, {W, 0, D}, {W, H, D}, {0, H, D}, inside, 12);
    b.AddQuad("wall_west", green, {0, 0, 0}, {0, 0, D}, {0, H, D}, {0, H, 0}, inside, 12);
    b.AddQuad("wall_east", white, {W, 0, 0}, {W, 0, D}, {W, H, D}, {W, H, 0}, inside, 12);
    // The glossy cube, standing on the floor, movable anywhere in the room.
    b.AddBox("glossy_cube", blue, {2.1f, 0.6f, 2.2f}, {1.2f, 1.2f, 1.2f}, 30.0f, false);
    b.SetDynamic("glossy_cube", {2.1f, 0.6f, 2.2f}, {0.6f, 0.0f, 0.6f}, {3.4f, 1.2f, 3.4f});
    b.AddBox("gold_column", gold, {0.8f, 0.8f, 3.1f}, {0.5f, 1.6f, 0.5f}, 0.0f, false);
    // A spot from a top corner aimed at the cube: the room is lit by what the cube and the
    // column reflect, directionally (the paper's Fig. 15 idea).
    PunctualLight spot;
    spot.name = "spot";
    spot.type = LightType::kSpot;
    spot.color = {1.0f, 0.95f, 0.85f};
    spot.intensity = 60.0f;
    spot.innerCone = 0.25f;
    spot.outerCone = 0.45f;
    spot.position = {3.6f, 2.8f, 0.4f};
    spot.direction = glm::normalize(glm::vec3(2.1f, 0.9f, 2.2f) - spot.position);
    b.AddLight(spot);
    b.AddCamera("camera", {0.3f, 1.9f, 0.3f}, {2.3f, 0.7f, 2.6f}, 1.1f);
    return b;
}

SceneBuilder MorphRoom() {
    SceneBuilder b;
    AddClutterRoom(b);
    const uint32_t clay = b.AddMaterial("clay", {0.75f, 0.45f, 0.35f});
    const uint32_t grey = b.AddMaterial("plinth", glm::vec3(0.6f));
    b.AddBox("plinth", grey, {1.0f, 0.1f, 1.0f}, {0.5f, 0.2f, 0.5f}, 20.0f, false);
    const glm::vec3 centre(1.0f, 0.55f, 1.0f);
    const float radius = 0.3f;
    b.AddSphere("blob", clay, centre, radius, 34, 33);
    b.SetDynamic("blob", centre, {0.4f, 0.2f, 0.4f}, {1.6f, 1.2f, 1.6f});
    // squash: y × 0.55 about the base (its lowest point stays), x and z × 1.3.
    const float base = centre.y - radius;
    b.AddMorphTarget("blob", [&](glm::vec3 p) {
        const glm::vec3 q(centre.x + 1.3f * (p.x - centre.x), base + 0.55f * (p.y - base),
                          centre.z + 1.3f * (p.z - centre.z));
        return q - p;
    });
    // ripple: radial, 6 cm × sin 4φ × sin 3θ.
    b.AddMorphTarget("blob", [&](glm::vec3 p) {
        const glm::vec3 n = (p - centre) / radius;
        const float theta = std::acos(std::clamp(n.y, -1.0f, 1.0f));
        const float phi = std::atan2(n.z, n.x);
        return 0.06f * std::sin(4.0f * phi) * std::sin(3.0f * theta) * n;
    });
    b.AddCamera("camera", {1.9f, 1.3f, 0.15f}, {1.0f, 0.5f, 1.0f}, 1.0f);
    return b;
}

std::vector<Bundled> All() {
    return {{"cornell-box.gltf", &CornellBox},
            {"blocker.gltf", [] { return Blocker(true); }},
            {"maze.gltf", &Maze},
            {"office.gltf", &Office},
            {"glossy-box.gltf", &GlossyBox},
            {"morph-room.gltf", &MorphRoom}};
}

}  // namespace penumbra::scenes
