// The gather of operator U (Eqs. 15–17 with the σ spreading of Sec. 3.1) into one
// receiver's L_in row, shared by the cluster pass (global.comp) and the leaf pass
// (local.comp). The row starts from the parent's L_in, already complete: the push of
// Sec. 3.2 ("Maintenance of the hierarchy") is folded into the gather, clusters being
// gathered depth by depth from the root down. The root starts from the environment row
// (Sec. 3.3), kept as an extra row after the nodes' rows of the L_in table.
//
// Links, spread lists, I_ex and L_in are read through texel buffers: random per-lane reads
// that lavapipe gathers in vector registers where it loads storage buffers lane by lane
// (gpu/pipeline.h, Slot). Bindings 0–5 are the same in both passes.

layout(std430, binding = 0) readonly buffer LinkOffsets { uint linkOffsets[]; };
// Link (common.glsl) as three uints: sender, binLevel, formFactor bits.
layout(binding = 1) uniform usamplerBuffer links;
// Directions::Padded*: level k's list for bin b starts at spread[2k] + b·spread[2k+1] and
// has spread[2k+1] entries.
layout(binding = 2) uniform usamplerBuffer spread;
// BinWeight (common.glsl) as two uints: bin, weight bits.
layout(binding = 3) uniform usamplerBuffer neighbours;
// I_ex of the previous iteration (the table the local pass reads as "old").
layout(binding = 4) uniform samplerBuffer iex;
// L_in rows (BINS·3 floats) as the cluster pass left them, plus the environment row.
layout(binding = 5) uniform samplerBuffer linIn;

float acc[BINS * 3u];

// acc = L_in row `row` of linIn (a parent's, or the environment row).
void StartFrom(uint row) {
    int at = int(row * BINS * 3u);
    for (uint k = 0u; k < BINS * 3u; ++k) acc[k] = texelFetch(linIn, at + int(k)).x;
}

// acc += Σ over the links of receiver r of F · w · I_ex[sender][bin]. Links come sorted by
// (level, bin): a run of equal (level, bin) is summed and spread once.
void Gather(uint r) {
    uint end = linkOffsets[r + 1];
    uint key = 0xffffffffu;
    vec3 v = vec3(0.0);
    for (uint l = linkOffsets[r]; l <= end; ++l) {
        uint sender = 0u, binLevel = 0u;
        float formFactor = 0.0;
        if (l < end) {
            sender = texelFetch(links, int(3u * l)).x;
            binLevel = texelFetch(links, int(3u * l + 1u)).x;
            formFactor = uintBitsToFloat(texelFetch(links, int(3u * l + 2u)).x);
        }
        if (l == end || binLevel != key) {
            if (key != 0xffffffffu) {
                uint level = key >> 16;
                uint width = texelFetch(spread, int(2u * level + 1u)).x;
                uint first = texelFetch(spread, int(2u * level)).x + (key & 0xffffu) * width;
                for (uint j = first; j < first + width; ++j) {
                    uint a = texelFetch(neighbours, int(2u * j)).x * 3u;
                    float weight = uintBitsToFloat(texelFetch(neighbours, int(2u * j + 1u)).x);
                    acc[a] += weight * v.x;
                    acc[a + 1u] += weight * v.y;
                    acc[a + 2u] += weight * v.z;
                }
            }
            if (l == end) break;
            key = binLevel;
            v = vec3(0.0);
        }
        int s = int((sender * BINS + (binLevel & 0xffffu)) * 3u);
        v += formFactor * vec3(texelFetch(iex, s).x, texelFetch(iex, s + 1).x, texelFetch(iex, s + 2).x);
    }
}
