// Cluttered test scenes (issue 18): rows and stacks of boxes, bookshelves, chairs under desks
// and random boxes, in a closed room under an emissive ceiling panel. Built in memory by the
// stability tests and written as glTF by make_scenes for the command line.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "scene/scene_builder.h"

namespace penumbra::scenes {

// A closed 2 × 2 × 2 m room (albedo `albedo`, one-sided walls facing in) lit by a 0.6 m
// square ceiling panel emitting `emission` nits, 1 cm under the ceiling, facing down: what
// every clutter scene stands in.
void AddClutterRoom(SceneBuilder& b, float emission = 30.0f, float albedo = 0.7f);

// `count` boxes 0.27 × 0.25 × 0.08 m (albedo 0.6) standing on the floor in a row along z,
// their 8 cm-apart faces parallel with `gap` metres between neighbours (0: faces in contact).
SceneBuilder BoxRow(int count, float gap);
// Stacks of flat boxes on top of each other (in contact, or `gap` apart on thin spacers):
// `stacks` columns of `height` boxes 0.3 × 0.04 × 0.25 m.
SceneBuilder BoxStacks(int stacks, int height, float gap);
// A bookshelf of `boards` boards 0.8 m wide, each carrying a row of books 2–3 cm thick and
// 18–24 cm tall, `gap` metres apart (books of seed-picked sizes). `faceNodes`: every face of
// every box a node of its own, as many exporters write boxes (SceneBuilder::SetBoxFacesAsNodes).
SceneBuilder Bookshelf(int boards, float gap, uint32_t seed, bool faceNodes = false);
// Two desks (a top on four legs) with a chair pushed under each, seat under the top.
SceneBuilder ChairsUnderDesks();
// `count` boxes of random sizes (2–40 cm) placed at random on the floor or on each other,
// some touching, some interpenetrating, on seed `seed`.
SceneBuilder RandomBoxes(int count, uint32_t seed);

// A sunlit maze (issue 61): a closed 4 × 2.5 × 4 m room of one-sided quads facing in, its
// roof open over x, z ∈ [0.5, 1] (SunlitMazeHole), three hollow inner walls 6 cm thick from
// floor to roof (four sides each facing out, no top or bottom; SunlitMazeWalls), and a sun
// (directional light "sun", 1,000 lux) travelling along SunlitMazeSun. Straight lines from
// the sun reach through the hole only the floor west of the first inner wall and that wall's
// west side; everything else gets no direct sun.
SceneBuilder SunlitMaze();
glm::vec3 SunlitMazeSun();
// The inner walls' boxes (lo, hi), and the hole's x and z range [lo, hi] at the roof, y = 2.5.
std::vector<std::pair<glm::vec3, glm::vec3>> SunlitMazeWalls();
constexpr float kSunlitMazeHoleLo = 0.5f, kSunlitMazeHoleHi = 1.0f, kSunlitMazeHeight = 2.5f;

// The furnace bound of a scene lit only by its emitters: no surface can receive more than
// π · max(L_e) / (1 − max ρ) lux (radiance never exceeds max(L_e) / (1 − max ρ)).
float FurnaceBound(const Scene& scene);

struct ClutterScene {
    std::string name;  // file name under the output folder, "box-row-10-2cm.gltf"
    SceneBuilder builder;
};
// The stability suite (tests/solver/stability_test.cpp uses the same list): the box rows of
// issue 18 at every gap, stacks, shelves, desks and random boxes on several seeds.
std::vector<ClutterScene> ClutterSuite();

}  // namespace penumbra::scenes
