// One bounce of the implicit solver on a Vulkan device (Dong et al. 2007, Sec. 4.4: each leaf
// gathers the light of what its bins see, then the new light is pulled up the hierarchy), the
// device twin of ImplicitSolver::ExitantTables and Bounce (solvers/implicit/
// implicit_solver.cpp): keep the arithmetic in step with them. One table holds every light a
// share reads: per node and bin the exitant intensity I(ω_b) = Σ A L cos⁺(n, ω_b) of its
// leaves, then per node Σ A L, then per bin the environment's radiance; a share reads one
// entry through its index and multiplies it by its factor (fixed at the relink).
//   mode 0: the leaves' rows and Σ A L from their radiance, and the environment's entries;
//   mode 1: one level of the pull: a cluster's row and Σ A L are its two children's sums;
//   mode 2: per leaf, E = Σ over its shares of factor · table[index].
// Each invocation walks its mode's items with the grid's stride (a dispatch holds at most
// 65,535 groups).
#version 450

layout(local_size_x = 64) in;

layout(std430, binding = 0) buffer Table { vec4 table[]; };
// Per leaf (hierarchy leaf order): its normal and area (w), and its node.
layout(std430, binding = 1) readonly buffer Leaves { vec4 leafNormalArea[]; };
layout(std430, binding = 2) readonly buffer LeafNodes { uint leafNode[]; };
// Per leaf its radiance, then per bin the environment's radiance travelling along it.
layout(std430, binding = 3) readonly buffer Radiance { vec4 radiance[]; };
// The pull's levels, deepest first: per cluster its node and its second child (the first is
// the node after it).
layout(std430, binding = 4) readonly buffer Levels { uvec2 levels[]; };
// Per leaf its shares [offsets[i], offsets[i + 1]), each with its index and factor.
layout(std430, binding = 5) readonly buffer Offsets { uint offsets[]; };
layout(std430, binding = 6) readonly buffer At { uint at[]; };
layout(std430, binding = 7) readonly buffer Factor { float factor[]; };
layout(std430, binding = 8) writeonly buffer Gathered { vec4 gathered[]; };
layout(std430, binding = 9) readonly buffer Dirs { vec4 dirs[]; };

layout(push_constant) uniform Push {
    uint mode;
    uint bins;
    uint leaves;
    uint first;  // mode 1: the level's first entry in `levels`
    uint count;  // mode 1: its clusters
    uint sumsAt;         // the first node's Σ A L in the table
    uint environmentAt;  // the first bin's environment entry
} pc;

void main() {
    const uint stride = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    const uint width = pc.bins + 1u;  // a node's row, then its Σ A L
    if (pc.mode == 0u) {
        const uint items = pc.leaves * width + pc.bins;
        for (uint k = gl_GlobalInvocationID.x; k < items; k += stride) {
            if (k >= pc.leaves * width) {
                const uint b = k - pc.leaves * width;
                table[pc.environmentAt + b] = radiance[pc.leaves + b];
                continue;
            }
            const uint i = k / width, b = k % width;
            const vec4 na = leafNormalArea[i];
            const vec3 sent = na.w * radiance[i].xyz;
            if (b == pc.bins)
                table[pc.sumsAt + leafNode[i]] = vec4(sent, 0.0);
            else
                table[leafNode[i] * pc.bins + b] = vec4(max(0.0, dot(na.xyz, dirs[b].xyz)) * sent, 0.0);
        }
    } else if (pc.mode == 1u) {
        const uint items = pc.count * width;
        for (uint k = gl_GlobalInvocationID.x; k < items; k += stride) {
            const uvec2 c = levels[pc.first + k / width];
            const uint b = k % width;
            if (b == pc.bins)
                table[pc.sumsAt + c.x] = table[pc.sumsAt + c.x + 1u] + table[pc.sumsAt + c.y];
            else
                table[c.x * pc.bins + b] =
                    table[(c.x + 1u) * pc.bins + b] + table[c.y * pc.bins + b];
        }
    } else {
        for (uint i = gl_GlobalInvocationID.x; i < pc.leaves; i += stride) {
            vec3 e = vec3(0.0);
            for (uint k = offsets[i]; k < offsets[i + 1u]; ++k) e += factor[k] * table[at[k]].xyz;
            gathered[i] = vec4(e, 0.0);
        }
    }
}
