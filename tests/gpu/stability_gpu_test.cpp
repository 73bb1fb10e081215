// Issue 18 on lavapipe with validation on: the clutter scenes converge within their furnace
// bounds as on the CPU back end (tests/solver/stability_test.cpp has the whole suite).
#include <gtest/gtest.h>

#include "clutter_scenes.h"
#include "solver/stability_util.h"

namespace penumbra {
namespace {

using testing::ExpectConverges;

// Kept small for CI (one scene, 500 iterations, about 2,500 passes): the deepest row of
// boxes, where the unbounded and the symmetric iterations diverge, with validation on. The
// bounds of the local pass (shaders/local.comp, Blocked) are what keeps it finite.
TEST(Stability, ClutterScenesConvergeOnLavapipe) {
    ExpectConverges("box-row-15-5mm", scenes::BoxRow(15, 0.005f).Build(), DeviceChoice::kLavapipe);
}

}  // namespace
}  // namespace penumbra
