// Issue 18 on lavapipe with validation on: the clutter scenes converge within their furnace
// bounds as on the CPU back end (tests/solver/stability_test.cpp has the whole suite).
#include <gtest/gtest.h>

#include "clutter_scenes.h"
#include "solver/stability_util.h"

namespace penumbra {
namespace {

using testing::ExpectConverges;

// Kept small for CI (about a minute each on two cores): the deepest row and random boxes,
// with validation on.
TEST(Stability, ClutterScenesConvergeOnLavapipe) {
    ExpectConverges("box-row-10-2cm", scenes::BoxRow(10, 0.02f).Build(), DeviceChoice::kLavapipe);
    ExpectConverges("random-boxes-1", scenes::RandomBoxes(40, 1).Build(), DeviceChoice::kLavapipe);
}

}  // namespace
}  // namespace penumbra
