// Pull (Sec. 3.2): a cluster's exitant intensity is the sum of its children's.
// Dispatched depth by depth from the deepest clusters up; one invocation per float.
#version 450
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"

layout(local_size_x_id = 0) in;

layout(std430, binding = 0) buffer Iex { float iex[]; };
layout(std430, binding = 1) readonly buffer Children { uvec2 children[]; };
layout(std430, binding = 2) readonly buffer NodesByDepth { uint nodesByDepth[]; };

layout(push_constant) uniform Push { uint first; uint count; } pc;

void main() {
    uint i = gl_GlobalInvocationID.x;
    uint row = BINS * 3u;
    if (i >= pc.count * row) return;
    uint node = nodesByDepth[pc.first + i / row];
    uint k = i % row;
    uvec2 c = children[node];
    iex[node * row + k] = iex[c.x * row + k] + iex[c.y * row + k];
}
