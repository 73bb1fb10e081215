// A sun and an analytic clear sky from a position, for scenes whose file has neither: the sun
// a directional light on a node of its own (so that light edits turn it like any other), the
// sky an equirectangular map of Preetham, Shirley and Smits' clear-sky model ("A Practical
// Analytic Model for Daylight", SIGGRAPH 1999) with the turbidity it is given.
//
// Directions: glTF has no north, so the scene's −Z is north and +X east (the way the
// equirectangular map's centre column looks, scene/environment.h); azimuth counts degrees
// from north towards east, elevation degrees above the horizon (the XZ plane).
#pragma once

#include <glm/glm.hpp>
#include <string>

#include "scene/environment.h"
#include "scene/scene.h"

namespace penumbra {

struct SunPosition {
    float azimuth = 0.0f;    // degrees from north (−Z) towards east (+X)
    float elevation = 0.0f;  // degrees above the horizon, 0 … 90
};

// The unit direction towards the sun.
glm::vec3 SunDirection(const SunPosition& sun);
// Throws penumbra::Error unless the azimuth is finite and the elevation within 0 … 90.
void ValidateSunPosition(const SunPosition& sun);

// The name of the node and light AddSun makes.
inline constexpr const char* kSunName = "sun";
// Adds a node called "sun" (no parent, no geometry) placing a white directional light of
// `illuminance` lux (on a surface facing it) that shines from `sun`; returns the light's
// index. Throws penumbra::Error for a position ValidateSunPosition refuses, an illuminance
// that is not a finite number ≥ 0, or a scene that already has a node or light called "sun".
int AddSun(Scene& scene, const SunPosition& sun, float illuminance);
// Where a directional light shines from (the inverse of SunDirection; below the horizon, a
// negative elevation).
SunPosition SunPositionOf(const PunctualLight& sun);
// The local transform of the sun's node: its −Z (where the light travels) away from `sun`.
glm::mat4 SunTransform(const SunPosition& sun);

// Preetham's fit holds for turbidities of about 2 (very clear) to 10 (hazy); 3 is a clear day.
inline constexpr float kMinTurbidity = 1.7f, kMaxTurbidity = 10.0f, kDefaultTurbidity = 3.0f;
// The clear sky for a sun at `sun` as an equirectangular map of `width` × width/2 pixels:
// per pixel Preetham's luminance (Eq. 1, 3: the Perez distribution scaled by the zenith
// luminance of the appendix's fit, kcd/m² → nits) and chromaticity (the appendix's x and y
// fits) turned into linear sRGB (Rec. 709 primaries, D65; a colour outside that gamut loses
// its negative part); black below the horizon (the scene's own ground takes that part).
// `source` names the model, the turbidity and the sun. Throws penumbra::Error for a sun
// ValidateSunPosition refuses or a turbidity outside kMinTurbidity … kMaxTurbidity.
Environment ClearSky(const SunPosition& sun, float turbidity, int width = 256);
// The luminance (nits) Preetham's fit gives at the zenith: the map's scale, for tests.
float ClearSkyZenithLuminance(const SunPosition& sun, float turbidity);

}  // namespace penumbra
