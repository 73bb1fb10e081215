// Directions::Lookup on the device: the cube-map texel, then a greedy walk over the bins'
// neighbours to the exact nearest bin. The including shader declares the buffers `dirs`
// (vec4 per bin), `cube` (Directions::CubeTable) and `adjacent` (Directions::PaddedAdjacency,
// `adjacentWidth` a bin) before including this file. Keep it in step with directions.cpp.
uint LookupBin(vec3 d, uint cubeRes, uint adjacentWidth) {
    vec3 a = abs(d);
    uint face;
    float s, t, m;
    if (a.x >= a.y && a.x >= a.z) {
        face = d.x > 0.0 ? 0u : 1u;
        m = a.x;
        s = d.y;
        t = d.z;
    } else if (a.y >= a.z) {
        face = d.y > 0.0 ? 2u : 3u;
        m = a.y;
        s = d.x;
        t = d.z;
    } else {
        face = d.z > 0.0 ? 4u : 5u;
        m = a.z;
        s = d.x;
        t = d.y;
    }
    int res = int(cubeRes);
    int u = clamp(int((s / m * 0.5 + 0.5) * float(res)), 0, res - 1);
    int v = clamp(int((t / m * 0.5 + 0.5) * float(res)), 0, res - 1);
    uint best = cube[(face * cubeRes + uint(v)) * cubeRes + uint(u)];
    float bestDot = dot(d, dirs[best].xyz);
    for (bool walked = true; walked;) {
        walked = false;
        uint row = best * adjacentWidth;
        for (uint k = 0u; k < adjacentWidth; ++k) {
            uint j = adjacent[row + k];
            float dd = dot(d, dirs[j].xyz);
            if (dd > bestDot) {
                bestDot = dd;
                best = j;
                walked = true;
            }
        }
    }
    return best;
}
