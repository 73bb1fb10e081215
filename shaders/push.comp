// Push (Sec. 3.2, "Maintenance of the hierarchy"): L_in of each node at one depth +=
// L_in of its parent. Dispatched depth by depth from the root down; one invocation per
// float of the row.
#version 450
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"

layout(local_size_x_id = 0) in;

layout(std430, binding = 0) buffer Lin { float lin[]; };
layout(std430, binding = 1) readonly buffer Parents { uint parents[]; };
layout(std430, binding = 2) readonly buffer NodesByDepth { uint nodesByDepth[]; };

layout(push_constant) uniform Push { uint first; uint count; } pc;

void main() {
    uint i = gl_GlobalInvocationID.x;
    uint row = BINS * 3u;
    if (i >= pc.count * row) return;
    uint node = nodesByDepth[pc.first + i / row];
    uint k = i % row;
    lin[node * row + k] += lin[parents[node] * row + k];
}
