// `penumbra render`, fragment stage: the interpolated vertex colour, linear; the back of a
// one-sided surface (seen against its normal) is black, as the solvers treat it.
#version 450

layout(location = 0) in vec3 color;
layout(location = 1) in vec3 normal;
layout(location = 2) in vec3 toEye;
layout(location = 0) out vec4 outColor;

void main() { outColor = dot(normal, toEye) > 0.0 ? vec4(color, 1.0) : vec4(0.0, 0.0, 0.0, 1.0); }
