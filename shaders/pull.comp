// Pull (Sec. 3.2): a cluster's exitant intensity is the sum of its children's.
// Dispatched depth by depth from the deepest clusters up; one invocation per cluster.
#version 450
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"

layout(local_size_x_id = 0) in;

layout(std430, binding = 0) buffer Iex { vec4 iex[]; };  // rows of BINS·3/4 vec4
layout(std430, binding = 1) readonly buffer Children { uvec2 children[]; };
layout(std430, binding = 2) readonly buffer NodesByDepth { uint nodesByDepth[]; };

layout(push_constant) uniform Push { uint first; uint count; } pc;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= pc.count) return;
    uint row = BINS * 3u / 4u;
    uint node = nodesByDepth[pc.first + i];
    uvec2 c = children[node];
    uint dst = node * row, a = c.x * row, b = c.y * row;
    for (uint k = 0u; k < row; ++k) iex[dst + k] = iex[a + k] + iex[b + k];
}
