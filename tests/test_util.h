// Helpers shared by the tests: nearest-surfel lookup and scene files in a temp folder.
#pragma once

#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <glm/glm.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "scene/scene_builder.h"
#include "scene/surfels.h"
#include "solver/solver.h"

namespace penumbra::testing {

// Index of the surfel closest to `p` whose normal is within 30° of `normal`.
inline size_t NearestSurfel(const Surfels& s, glm::vec3 p, glm::vec3 normal) {
    size_t best = 0;
    float bestD = 1e30f;
    for (size_t i = 0; i < s.size(); ++i) {
        if (s.areas[i] <= 0.0f || glm::dot(s.normals[i], normal) < 0.866f) continue;
        float d = glm::length(s.positions[i] - p);
        if (d < bestD) bestD = d, best = i;
    }
    return best;
}

// Solver settings for tests: the CPU back end, `bins` bins, elements of `elementSize` metres.
inline SolverSettings CpuSettings(int bins, float elementSize) {
    SolverSettings s;
    s.solver = "antiradiance";
    s.device = DeviceChoice::kCpu;
    SetOption(s.options, "bins", bins);
    s.elementSize = elementSize;
    return s;
}

// Per-vertex irradiance of every primitive in `channel`, one array (what bake and the
// service output).
inline std::vector<glm::vec3> AllVertices(Solver& solver, const Scene& scene, Channel channel) {
    std::vector<glm::vec3> surfels = solver.SurfelIrradiance(channel), out;
    for (size_t p = 0; p < scene.primitives.size(); ++p) {
        auto v = PrimitiveIrradiance(solver.GetSurfels(), surfels, scene, p);
        out.insert(out.end(), v.begin(), v.end());
    }
    return out;
}

inline float Mean(glm::vec3 v) { return (v.x + v.y + v.z) / 3.0f; }

// √(Σ|a−b|²) / √(Σ|b|²) over two equally long arrays (NaN when b is all zero).
inline double RelativeRms(const std::vector<glm::vec3>& a, const std::vector<glm::vec3>& b) {
    double num = 0, den = 0;
    for (size_t i = 0; i < a.size() && i < b.size(); ++i) {
        glm::dvec3 d = glm::dvec3(a[i]) - glm::dvec3(b[i]);
        num += glm::dot(d, d);
        den += glm::dot(glm::dvec3(b[i]), glm::dvec3(b[i]));
    }
    return std::sqrt(num / den);
}

// A white (ρ 0.8) floor 2 m square at y = 0 (floorTiles² tiles) and a 1 m high wall on its
// +x edge facing it (wallTiles² tiles): a corner that a light can reach only one side of.
inline uint32_t AddWhiteCorner(SceneBuilder& b, int floorTiles, int wallTiles) {
    uint32_t white = b.AddMaterial("white", glm::vec3(0.8f));
    b.AddTiledQuad("floor", white, {-1, 0, -1}, {2, 0, 0}, {0, 0, 2}, floorTiles, floorTiles,
                   {0, 1, 0});
    b.AddQuad("wall", white, {1, 0, -1}, {1, 0, 1}, {1, 1, 1}, {1, 1, -1}, {0, 0.5f, 0}, wallTiles);
    return white;
}

// The floor and four walls of a unit room, facing in, each a grid of tiles²; all in node
// `name`, or each in its own node (floor, w0…w3) when `name` is empty.
inline void AddRoomSides(SceneBuilder& b, uint32_t material, const std::string& name = "",
                         int tiles = 1) {
    const glm::vec3 inside(0.5f, 0.5f, 0.5f);
    auto node = [&](const char* own) { return name.empty() ? std::string(own) : name; };
    b.AddQuad(node("floor"), material, {0, 0, 0}, {1, 0, 0}, {1, 0, 1}, {0, 0, 1}, inside, tiles);
    b.AddQuad(node("w0"), material, {0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, inside, tiles);
    b.AddQuad(node("w1"), material, {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}, inside, tiles);
    b.AddQuad(node("w2"), material, {0, 0, 0}, {0, 0, 1}, {0, 1, 1}, {0, 1, 0}, inside, tiles);
    b.AddQuad(node("w3"), material, {1, 0, 0}, {1, 0, 1}, {1, 1, 1}, {1, 1, 0}, inside, tiles);
}

// The unit room with half a ceiling (the opening is x ∈ [0.5, 1]) under a constant sky of
// radiance 1: the sky furnace (radiance inside can nowhere exceed the sky's).
inline Scene SkyFurnaceRoom(SceneBuilder& b, uint32_t material, int tiles = 1) {
    AddRoomSides(b, material, "", tiles);
    b.AddQuad("ceiling", material, {0, 1, 0}, {0.5f, 1, 0}, {0.5f, 1, 1}, {0, 1, 1},
              {0.5f, 0.5f, 0.5f});
    Scene scene = b.Build();
    scene.environment = ConstantEnvironment(glm::vec3(1.0f));
    return scene;
}

// A punctual light for SceneBuilder::AddLight; a spot's inner cone is half its outer one
// (other types keep the glTF default cone, which they do not use).
inline PunctualLight MakeLight(const std::string& name, LightType type, glm::vec3 position,
                               glm::vec3 direction, float intensity, float outerCone = 0.8f) {
    PunctualLight l;
    l.name = name;
    l.type = type;
    l.position = position;
    l.direction = direction;
    l.intensity = intensity;
    if (type == LightType::kSpot) {
        l.innerCone = 0.5f * outerCone;
        l.outerCone = outerCone;
    }
    return l;
}

inline std::string ReadFile(const std::filesystem::path& path) {
    std::ifstream in(path, std::ios::binary);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
}
inline void WriteFile(const std::filesystem::path& path, const std::string& text) {
    std::ofstream(path, std::ios::binary) << text;
}

// A fresh temporary folder for one test. Named by the process too: ctest runs the tests of
// one executable as parallel processes, which must not share (and delete) a folder.
inline std::filesystem::path TempDir(const std::string& name) {
    auto dir = std::filesystem::temp_directory_path() /
               ("penumbra-test-" + name + "-" + std::to_string(::getpid()));
    std::filesystem::remove_all(dir);
    std::filesystem::create_directories(dir);
    return dir;
}

// A closed 1 m room, every face pointing in: `walls` on floor and sides, `ceiling` above.
inline void AddUnitRoom(SceneBuilder& b, uint32_t walls, uint32_t ceiling, int tiles = 1) {
    const glm::vec3 inside(0.5f, 0.5f, 0.5f);
    b.AddQuad("floor", walls, {0, 0, 0}, {1, 0, 0}, {1, 0, 1}, {0, 0, 1}, inside, tiles);
    b.AddQuad("ceiling", ceiling, {0, 1, 0}, {1, 1, 0}, {1, 1, 1}, {0, 1, 1}, inside, tiles);
    b.AddQuad("w0", walls, {0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, inside, tiles);
    b.AddQuad("w1", walls, {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}, inside, tiles);
    b.AddQuad("w2", walls, {0, 0, 0}, {0, 0, 1}, {0, 1, 1}, {0, 1, 0}, inside, tiles);
    b.AddQuad("w3", walls, {1, 0, 0}, {1, 0, 1}, {1, 1, 1}, {1, 1, 0}, inside, tiles);
}

// Two 1 m rooms side by side (a 2 × 1 × 1 m box, faces in, floors "floor_lit" and
// "floor_dark"), split at x = 1 by a closed wall `wall` thick, a 20-nit lamp under the lit
// room's ceiling: what the dark floor gets is what leaks through the wall.
inline Scene ThinWallRooms(float wall) {
    SceneBuilder b;
    uint32_t white = b.AddMaterial("white", glm::vec3(0.7f));
    uint32_t lamp = b.AddMaterial("lamp", glm::vec3(0.0f), glm::vec3(20.0f));
    const glm::vec3 inside(1.0f, 0.5f, 0.5f);
    b.AddQuad("floor_lit", white, {0, 0, 0}, {1, 0, 0}, {1, 0, 1}, {0, 0, 1}, inside, 4);
    b.AddQuad("floor_dark", white, {1, 0, 0}, {2, 0, 0}, {2, 0, 1}, {1, 0, 1}, inside, 4);
    b.AddQuad("ceiling", white, {0, 1, 0}, {2, 1, 0}, {2, 1, 1}, {0, 1, 1}, inside, 4);
    b.AddQuad("south", white, {0, 0, 0}, {2, 0, 0}, {2, 1, 0}, {0, 1, 0}, inside, 4);
    b.AddQuad("north", white, {0, 0, 1}, {2, 0, 1}, {2, 1, 1}, {0, 1, 1}, inside, 4);
    b.AddQuad("west", white, {0, 0, 0}, {0, 0, 1}, {0, 1, 1}, {0, 1, 0}, inside, 4);
    b.AddQuad("east", white, {2, 0, 0}, {2, 0, 1}, {2, 1, 1}, {2, 1, 0}, inside, 4);
    b.AddBox("wall", white, {1, 0.5f, 0.5f}, {wall, 1, 1});
    b.AddQuad("lamp", lamp, {0.4f, 0.99f, 0.4f}, {0.6f, 0.99f, 0.4f}, {0.6f, 0.99f, 0.6f},
              {0.4f, 0.99f, 0.6f}, {0.5f, 0, 0.5f});
    return b.Build();
}

// A square emitter of side `side` centred at (0, height, 0) whose normal is −y tilted by
// `tiltDegrees` about +z; returns that normal.
inline glm::vec3 AddTiltedEmitter(SceneBuilder& b, uint32_t material, float tiltDegrees, float side,
                                  float height) {
    float t = glm::radians(tiltDegrees);
    glm::vec3 n(std::sin(t), -std::cos(t), 0.0f);
    glm::vec3 u = glm::normalize(glm::cross(n, glm::vec3(0, 0, 1))) * (side / 2);
    glm::vec3 v(0, 0, side / 2);
    glm::vec3 o(0, height, 0);
    b.AddQuad("emitter", material, o - u - v, o + u - v, o + u + v, o - u + v, o + n);
    return n;
}

// The `penumbra` binary of this build, run as a real process.
struct ProcessResult {
    int exitCode;
    std::string output;  // stdout and stderr together
};
// Runs a shell command line, its standard error joined to its output.
inline ProcessResult Shell(const std::string& command) {
    const std::string cmd = command + " 2>&1";
    FILE* pipe = popen(cmd.c_str(), "r");
    ProcessResult r{-1, ""};
    std::array<char, 4096> buf;
    while (size_t n = fread(buf.data(), 1, buf.size(), pipe)) r.output.append(buf.data(), n);
    int status = pclose(pipe);
    r.exitCode = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    return r;
}
// Runs the penumbra CLI (or `program`, under the build folder) with `args` (and `env`,
// "NAME=value ..." before it, when given).
inline ProcessResult Execute(const std::string& args, const std::string& env = "",
                             const std::string& program = "penumbra") {
    return Shell((env.empty() ? "" : env + " ") + std::string(PENUMBRA_BINARY_DIR) + "/" + program +
                 " " + args);
}

// An equirectangular map of `w` × w/2 pixels holding f(direction at the pixel centre).
template <typename F>
Image MapOf(int w, F f) {
    Image im(w, w / 2);
    for (int y = 0; y < im.height; ++y)
        for (int x = 0; x < im.width; ++x)
            im.At(x, y) = f(EquirectDirection((x + 0.5f) / im.width, (y + 0.5f) / im.height));
    return im;
}

// A sky of `sky` nits with a sun of `sun` nits and angular radius `radius` (radians) around
// `toward` (unit, map space): the map sunny skies are.
inline Image SunnyMap(int w, glm::vec3 toward, float radius, float sun, float sky) {
    const float cosine = std::cos(radius);
    return MapOf(w,
                 [&](glm::vec3 d) { return glm::vec3(glm::dot(d, toward) >= cosine ? sun : sky); });
}

}  // namespace penumbra::testing
