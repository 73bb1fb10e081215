// Global pass over the clusters (operator U, Eqs. 15–17, with the push of Sec. 3.2 folded
// in; gather.glsl): dispatched depth by depth from the root down, one invocation per
// cluster: its L_in row = its parent's row + its own links. Clusters of one depth come
// sorted by link count so the lanes of a workgroup finish together. Leaves gather in the
// local pass (local.comp), which reads their parents' rows.
#version 450
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "gather.glsl"

layout(local_size_x_id = 0) in;

layout(std430, binding = 6) writeonly buffer Lin { vec4 lin[]; };  // rows of BINS·3/4 vec4
// Per cluster: (node, row its L_in starts from: the parent's, or the environment row).
layout(std430, binding = 7) readonly buffer Order { uvec2 order[]; };

layout(push_constant) uniform Push { uint first; uint count; } pc;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= pc.count) return;
    uvec2 o = order[pc.first + i];
    StartFrom(o.y);
    Gather(o.x);
    uint row = o.x * (BINS * 3u / 4u);
    for (uint q = 0u; q < BINS * 3u / 4u; ++q)
        lin[row + q] = vec4(acc[4u * q], acc[4u * q + 1u], acc[4u * q + 2u], acc[4u * q + 3u]);
}
