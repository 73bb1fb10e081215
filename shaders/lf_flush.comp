// The light field's walk, second pass (solvers/lightfield/vulkan_walk.h; TravelSums::Flush in
// lines.cpp is the CPU twin): per surfel, per column of the group its lines met it along, the
// global-lines share A_cell Σ φ L_I with its weight A_cell Σ φ, or where the hat's projected
// area P_s spans two cells or more P_s Σ φ L_I / Σ φ with P_s, added to `weighted` (RGB, w);
// a glossy surfel records the mean radiance that arrived. The sums go back to 0 for the next
// group.
#version 450

layout(local_size_x = 64) in;

layout(std430, binding = 0) buffer Sums { float sums[]; };
layout(std430, binding = 1) readonly buffer FacetOffsets { uint facetOffsets[]; };  // surfels + 1
layout(std430, binding = 2) readonly buffer Facets { vec4 facets[]; };  // normal × area / 3
layout(std430, binding = 3) readonly buffer Directions { vec4 directions[]; };
layout(std430, binding = 4) buffer Weighted { vec4 weighted[]; };  // per surfel
layout(std430, binding = 5) readonly buffer Slots { int slot[]; };
layout(std430, binding = 6) buffer Incoming { vec4 incoming[]; };  // slot × columns

layout(push_constant) uniform Push {
    uint surfels;
    uint directions;
    uint firstDirection;
    uint group;
    float cellArea;
    float ratioCells;  // kRatioCells
    uint glossy;
} pc;

void main() {
    const uint s = gl_GlobalInvocationID.x;
    if (s >= pc.surfels) return;
    vec4 sum = vec4(0.0);
    for (uint c = 0u; c < 2u * pc.group; ++c) {
        const uint base = (c * pc.surfels + s) * 4u;
        const float w = sums[base + 3u];
        if (w == 0.0) continue;
        const vec3 light = vec3(sums[base], sums[base + 1u], sums[base + 2u]);
        const bool back = c >= pc.group;
        const uint k = pc.firstDirection + (back ? c - pc.group : c);
        const vec3 travel = back ? -directions[k].xyz : directions[k].xyz;
        float p = 0.0;
        for (uint f = facetOffsets[s]; f < facetOffsets[s + 1u]; ++f)
            p += max(0.0, -dot(facets[f].xyz, travel));
        const bool ratio = p >= pc.ratioCells * pc.cellArea;
        if (pc.glossy != 0u && slot[s] >= 0 && p > 0.0)
            incoming[uint(slot[s]) * 2u * pc.directions + (back ? pc.directions + k : k)] =
                vec4(ratio ? light / w : (pc.cellArea / p) * light, 0.0);
        sum += ratio ? vec4((p / w) * light, p) : pc.cellArea * vec4(light, w);
        sums[base] = 0.0, sums[base + 1u] = 0.0, sums[base + 2u] = 0.0, sums[base + 3u] = 0.0;
    }
    weighted[s] += sum;
}
