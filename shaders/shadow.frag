// Shadow pass, fragment stage: keeps the nearest NDC depth per texel with atomicMin on the
// float's bits (non-negative floats order as their bits do). The map is a storage buffer,
// not a depth attachment, so the direct pass and the CPU twin read the same layout.
#version 450

layout(std430, binding = 1) buffer Maps { uint maps[]; };

layout(push_constant) uniform Push {
    mat4 viewProj;
    uint mapOffset;
    uint size;
} pc;

void main() {
    uvec2 texel = uvec2(gl_FragCoord.xy);
    atomicMin(maps[pc.mapOffset + texel.y * pc.size + texel.x], floatBitsToUint(gl_FragCoord.z));
}
