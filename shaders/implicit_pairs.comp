// One round of the implicit solver's link creation, each link end appended for the closest
// layer's compositing: implicit_pairs.glsl.
#version 450
#extension GL_GOOGLE_include_directive : require

#include "implicit_pairs.glsl"
