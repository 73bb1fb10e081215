// Push (Sec. 3.2, "Maintenance of the hierarchy"): L_in of each node at one depth +=
// L_in of its parent. Dispatched depth by depth from the root down; one invocation per
// node walks its row (per-float invocations cost more in launch than in work on a CPU).
#version 450
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"

layout(local_size_x_id = 0) in;

// L_in written through a storage buffer and read through a texel buffer (lavapipe gathers
// texel fetches; gpu/pipeline.h, Slot): rows of BINS·3 floats.
layout(std430, binding = 0) writeonly buffer Lin { vec4 lin[]; };
layout(binding = 1) uniform samplerBuffer linIn;
layout(std430, binding = 2) readonly buffer Parents { uint parents[]; };
layout(std430, binding = 3) readonly buffer NodesByDepth { uint nodesByDepth[]; };

layout(push_constant) uniform Push { uint first; uint count; } pc;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= pc.count) return;
    uint row = BINS * 3u / 4u;
    uint node = nodesByDepth[pc.first + i];
    uint dst = node * row, src = parents[node] * row;
    for (uint k = 0u; k < row; ++k) {
        int a = int(4u * (dst + k)), b = int(4u * (src + k));
        lin[dst + k] = vec4(texelFetch(linIn, a).x + texelFetch(linIn, b).x,
                            texelFetch(linIn, a + 1).x + texelFetch(linIn, b + 1).x,
                            texelFetch(linIn, a + 2).x + texelFetch(linIn, b + 2).x,
                            texelFetch(linIn, a + 3).x + texelFetch(linIn, b + 3).x);
    }
}
