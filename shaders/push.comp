// Push (Sec. 3.2, "Maintenance of the hierarchy"): L_in of each node at one depth +=
// L_in of its parent. Dispatched depth by depth from the root down; one invocation per
// node walks its row (per-float invocations cost more in launch than in work on a CPU).
#version 450
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"

layout(local_size_x_id = 0) in;

layout(std430, binding = 0) buffer Lin { vec4 lin[]; };  // rows of BINS·3/4 vec4
layout(std430, binding = 1) readonly buffer Parents { uint parents[]; };
layout(std430, binding = 2) readonly buffer NodesByDepth { uint nodesByDepth[]; };

layout(push_constant) uniform Push { uint first; uint count; } pc;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= pc.count) return;
    uint row = BINS * 3u / 4u;
    uint node = nodesByDepth[pc.first + i];
    uint dst = node * row, src = parents[node] * row;
    for (uint k = 0u; k < row; ++k) lin[dst + k] += lin[src + k];
}
