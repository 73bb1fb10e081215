// The implicit solver's compositing on a Vulkan device (Dong et al. 2007, Sec. 4.2.3-4.2.4,
// RefineHierarchicalLinks and PushdownLinks as front-to-back coverage): the links' ends
// ordered by (node, bin) slot and depth, then each leaf's front bins filled nearest first from
// the slots of the leaf and its ancestors. The device twin of ImplicitLinker::Build's
// compositing (solvers/implicit/implicit_links.cpp: the ends by slot, the per-leaf loop with
// its SolidCover rules, the partial fill, the far faces' fronts and the shares' travel):
// keep the arithmetic and the order of the shares in step with it.
//   mode 0: per end, count it in its slot;
//   modes 1-3: an exclusive scan of counts[scanFirst, scanFirst + scanCount), the total after
//     it (1: per block of kBlock entries, its sum; 2: one invocation scans the blocks' sums;
//     3: per block, its entries scanned from its sum's offset);
//   mode 4: per end, copied to its slot in `scattered` (the slot's start, advanced: after it
//     counts[s] is where slot s ends, and slot s starts where slot s - 1 ends);
//   mode 5: per end, its rank in its slot nearest first (the sender, then its place, break
//     ties): `ends` rewritten in slot order, each slot sorted;
//   mode 6: per (leaf, bin), the merge counted: its shares, the solid angle they cover (-1:
//     not a front bin) and whether the bin is left partly uncovered;
//   mode 7: per (leaf, bin), whether it shows the environment (partly covered and not
//     filled: the partial fill reads the bins next to it);
//   mode 8: per (leaf, bin), the merge again, its shares written where the scans put them
//     (each leaf's bins in order, then its bins that show the environment);
//   mode 9: per leaf, its first share;
//   mode 10: per share, a far face's share given the front met in the nearest bin, and its
//     travel.
// No invocation loops long: lavapipe (llvmpipe) ends a shader's loops after 65,535
// iterations in all, counted over the invocations it runs side by side. No workgroup
// barriers either: with one, llvmpipe runs every invocation of the shader as a coroutine.
// Each invocation walks its mode's items with the grid's stride.
#version 450
#extension GL_GOOGLE_include_directive : require

layout(local_size_x = 64) in;

// ImplicitLinker::End.
struct End {
    uint slot;
    uint sender;
    float dist;
    float omega;
};
// solvers/implicit/vulkan_composite.cpp: struct CompositeNode (48 bytes).
struct CompositeNode {
    vec3 center;
    float coneCos;
    vec3 normal;
    uint right;  // the second child (the first is the node after it); 0 for a leaf
    uint solid;  // the closed solid all its members bound, or kNoSolid
    uint pad0, pad1, pad2;
};
// Per leaf (hierarchy leaf order): its centre, Directions::CosineNorm of its normal, its
// normal and its node.
struct Leaf {
    vec3 center;
    float norm;
    vec3 normal;
    uint node;
};
// A share of a leaf's front bin (ImplicitLinks' bin, sender and weight) and its mark: kFront
// | solid for the first facing face of a closed solid met in the bin, kFarOnly | solid for a
// solid's far face where none of its near faces were met.
struct Share {
    uint bin;
    uint sender;
    float weight;
    uint mark;
};

// The ends as the rounds made them, then (mode 5) in slot order, each slot nearest first.
// The ends as the rounds made them, then (mode 5) in slot order, each slot nearest first; and
// the ends scattered to their slots (mode 4). Each field its own array: a list of 4-byte
// entries fits the storage-buffer range four times as long (lavapipe's is 128 MiB).
layout(std430, binding = 0) buffer EndSlot { uint endSlot[]; };
layout(std430, binding = 1) buffer EndSender { uint endSender[]; };
layout(std430, binding = 2) buffer EndDist { float endDist[]; };
layout(std430, binding = 3) buffer EndOmega { float endOmega[]; };
layout(std430, binding = 4) buffer ScatteredSlot { uint scatteredSlot[]; };
layout(std430, binding = 5) buffer ScatteredSender { uint scatteredSender[]; };
layout(std430, binding = 6) buffer ScatteredDist { float scatteredDist[]; };
layout(std430, binding = 7) buffer ScatteredOmega { float scatteredOmega[]; };
// The slots' counts (nodes × bins + 1), then per (leaf, bin) the shares merged and the
// environment's (leaves × bins + 1 each), each scanned in place.
layout(std430, binding = 8) buffer Counts { uint counts[]; };
layout(std430, binding = 9) buffer BlockSums { uint blockSums[]; };
layout(std430, binding = 10) readonly buffer Nodes { CompositeNode nodes[]; };
layout(std430, binding = 11) readonly buffer Leaves { Leaf leaves[]; };
// Per (leaf, bin): the solid angle covered (-1: not a front bin), and 1 where partly covered.
layout(std430, binding = 12) buffer Cover { float cover[]; };
layout(std430, binding = 13) buffer Partial { uint partial[]; };
// Per closed solid the box of its leaves (ImplicitLinker's SolidBoxes): lo, then hi.
layout(std430, binding = 14) readonly buffer Boxes { vec4 boxes[]; };
layout(std430, binding = 15) readonly buffer Dirs { vec4 dirs[]; };
layout(std430, binding = 16) readonly buffer Cube { uint cube[]; };
layout(std430, binding = 17) readonly buffer Adjacent { uint adjacent[]; };
layout(std430, binding = 18) readonly buffer Opposite { uint opposite[]; };
// The shares, a field an array.
layout(std430, binding = 19) buffer ShareBin { uint shareBin[]; };
layout(std430, binding = 20) buffer ShareSender { uint shareSender[]; };
layout(std430, binding = 21) buffer ShareWeight { float shareWeight[]; };
layout(std430, binding = 22) buffer ShareMark { uint shareMark[]; };
layout(std430, binding = 23) writeonly buffer Travel { uint travel[]; };
// Per leaf its first share, then the shares' count.
layout(std430, binding = 24) buffer Offsets { uint offsets[]; };
// [1]: 1 where a bin met more solids than kMaxSolids; [2]: 1 where a slot held more ends than
// kMostInSlot; [3]: 1 where a bin's merge wrote another count of shares than it counted.
layout(std430, binding = 25) buffer Status { uint status[]; };
// Per node and bin the front-facing projected area Σ A cos⁺(n, ω_b) (ImplicitLinker::Build's
// frontArea): a cluster of a closed solid mostly turned away from the leaf stands as its far
// faces.
layout(std430, binding = 26) readonly buffer FrontArea { float frontArea[]; };

layout(push_constant) uniform Push {
    uint mode;
    uint bins;
    uint leafCount;
    uint endCount;
    uint slots;      // nodes × bins
    uint scanFirst;  // modes 1-3: the scanned entries in `counts`
    uint scanCount;
    uint mergedAt;  // the first (leaf, bin)'s merged count in `counts`
    uint environmentAt;  // the first (leaf, bin)'s environment count in `counts`
    uint cubeRes;
    uint adjacentWidth;
    uint hasSolids;
    float binSolidAngle;  // ω_bin
    float thin;           // ImplicitLinker::Build's `thin`
    float cosBinRadius;   // cos and sin of the radius of a disc of a bin's solid angle
    float sinBinRadius;
    float aboveHorizon;  // sin of the bins' spacing
} pc;

#include "directions.glsl"

const uint kNoSolid = 0xffffffffu;  // implicit_links.h
const uint kNoSender = 0xffffffffu;
const uint kFacing = 0xfffffffeu;
const uint kAway = 0xfffffffdu;
const float kFlatCone = 0.9;
const float kFillCoverage = 0.25;  // implicit_links.cpp
const float kEdgeCoverage = 0.1;
const uint kFront = 0x40000000u;
const uint kFarOnly = 0x80000000u;
const uint kSolidBits = 0x3fffffffu;
// The deepest chain a leaf may have (the host composites deeper hierarchies itself), and the
// most closed solids one bin may meet (a bin that meets more sets status[1]; the host sets it).
const uint kMaxDepth = 64u;
layout(constant_id = 0) const uint kMaxSolids = 32u;
// The most ends one slot may hold (mode 5 ranks each against all of them; a slot with more
// sets status[2]).
const uint kMostInSlot = 4096u;
const uint kBlock = 4096u;  // the scan's blocks
const float kFloatMax = 3.402823466e38;

uint SlotBegin(uint s) { return s == 0u ? 0u : counts[s - 1u]; }

End LoadEnd(uint k) { return End(endSlot[k], endSender[k], endDist[k], endOmega[k]); }
void StoreEnd(uint k, End e) {
    endSlot[k] = e.slot;
    endSender[k] = e.sender;
    endDist[k] = e.dist;
    endOmega[k] = e.omega;
}
End LoadScattered(uint k) {
    return End(scatteredSlot[k], scatteredSender[k], scatteredDist[k], scatteredOmega[k]);
}
void StoreScattered(uint k, End e) {
    scatteredSlot[k] = e.slot;
    scatteredSender[k] = e.sender;
    scatteredDist[k] = e.dist;
    scatteredOmega[k] = e.omega;
}
Share LoadShare(uint k) { return Share(shareBin[k], shareSender[k], shareWeight[k], shareMark[k]); }
void StoreShare(uint k, Share s) {
    shareBin[k] = s.bin;
    shareSender[k] = s.sender;
    shareWeight[k] = s.weight;
    shareMark[k] = s.mark;
}

// SolidBox::Meets: whether the ray from `from` along `dir` meets the box ahead.
bool Meets(vec3 lo, vec3 hi, vec3 from, vec3 dir) {
    float near = 0.0, far = kFloatMax;
    for (int a = 0; a < 3; ++a) {
        if (abs(dir[a]) < 1e-12) {
            if (from[a] < lo[a] || from[a] > hi[a]) return false;
            continue;
        }
        float t0 = (lo[a] - from[a]) / dir[a], t1 = (hi[a] - from[a]) / dir[a];
        if (t0 > t1) {
            float t = t0;
            t0 = t1;
            t1 = t;
        }
        near = max(near, t0);
        far = min(far, t1);
    }
    return near <= far;
}

// rays/sampling.h Basis: two unit vectors completing `n` to an orthonormal basis.
void Basis(vec3 n, out vec3 t, out vec3 s) {
    float sign = (floatBitsToUint(n.z) & 0x80000000u) != 0u ? -1.0 : 1.0;
    float p = -1.0 / (sign + n.z), q = n.x * n.y * p;
    t = vec3(1.0 + sign * n.x * n.x * p, sign * q, -sign * n.x);
    s = vec3(q, sign + n.y * n.y * p, -n.y);
}

// SolidBox::Holds: whether a bin's cone about `dir` lies inside solid `of`'s outline seen from
// `from`, a receiver with `normal`.
bool Holds(uint of, vec3 from, vec3 dir, vec3 normal) {
    vec3 lo = boxes[2u * of].xyz, hi = boxes[2u * of + 1u].xyz;
    if (!Meets(lo, hi, from, dir)) return false;
    vec3 t, s;
    Basis(dir, t, s);
    float c = pc.cosBinRadius, r = pc.sinBinRadius;
    vec3 sides[4] = vec3[4](t, -t, s, -s);
    for (int k = 0; k < 4; ++k) {
        vec3 ray = c * dir + r * sides[k];
        if (dot(ray, normal) > 0.0 && !Meets(lo, hi, from, ray)) return false;
    }
    return true;
}

// Leaf i's bin b merged from its chain's slots nearest first (Build's per-leaf loop): returns
// its shares' count, `cover` the solid angle they cover (-1: not a front bin) and `part`
// whether it is left partly uncovered. With `write`, the shares go to at, at + 1, ...
uint Merge(uint i, uint b, bool write, uint at, out float coverOut, out bool part) {
    Leaf L = leaves[i];
    vec3 w = dirs[b].xyz;
    float c = dot(L.normal, w);
    coverOut = -1.0;
    part = false;
    if (!(c > 0.0)) return 0u;
    // The chain's slots for this bin, root first.
    uint headAt[kMaxDepth], headEnd[kMaxDepth];
    uint heads = 0u;
    for (uint n = 0u;;) {
        uint s = n * pc.bins + b;
        uint s0 = SlotBegin(s), s1 = counts[s];
        if (s1 > s0) {
            headAt[heads] = s0;
            headEnd[heads] = s1;
            ++heads;
        }
        if (n == L.node) break;
        uint right = nodes[n].right;
        n = L.node < right ? n + 1u : right;
    }
    float omegaBin = pc.binSolidAngle;
    float left = omegaBin;
    uint solidOf[kMaxSolids];
    float facingOf[kMaxSolids], awayOf[kMaxSolids], nearOf[kMaxSolids];
    uint frontOf[kMaxSolids];
    uint solids = 0u;
    uint count = 0u;
    while (left > 1e-4 * omegaBin) {
        // The leaf's own slot first: of two ends at one depth, the nearer node's is taken.
        int next = -1;
        float nextDist = 0.0;
        for (int j = int(heads) - 1; j >= 0; --j)
            if (headAt[j] != headEnd[j] && (next < 0 || endDist[headAt[j]] < nextDist)) {
                next = j;
                nextDist = endDist[headAt[j]];
            }
        if (next < 0) break;
        End e = LoadEnd(headAt[next]);
        headAt[next] += 1u;
        float omega = e.omega;
        uint sender = e.sender;
        uint mark = 0u;
        bool farOnly = false;
        uint of = pc.hasSolids != 0u ? nodes[e.sender].solid : kNoSolid;
        bool flatSender = nodes[e.sender].coneCos >= kFlatCone;
        if (of != kNoSolid &&
            (flatSender || frontArea[e.sender * pc.bins + b] >
                         2.0 * frontArea[e.sender * pc.bins + opposite[b]])) {
            CompositeNode s = nodes[e.sender];
            bool facing = flatSender && dot(s.normal, L.center - s.center) > 0.0;
            uint k = 0u;
            while (k < solids && solidOf[k] != of) ++k;
            if (k == solids) {
                if (solids == kMaxSolids) {
                    status[1] = 1u;
                    return count;
                }
                solidOf[k] = of;
                facingOf[k] = 0.0;
                awayOf[k] = 0.0;
                nearOf[k] = e.dist;
                frontOf[k] = e.sender;
                ++solids;
            }
            if (facing) {
                if (facingOf[k] == 0.0) {
                    nearOf[k] = e.dist;
                    frontOf[k] = e.sender;
                    mark = kFront | of;
                }
                facingOf[k] += omega;
            } else if (facingOf[k] > 0.0) {
                if ((e.dist - nearOf[k]) * abs(dot(s.normal, w)) >= pc.thin ||
                    !Holds(of, L.center, w, L.normal)) {
                    float before = max(facingOf[k], awayOf[k]);
                    awayOf[k] += omega;
                    omega = max(facingOf[k], awayOf[k]) - before;
                }
                sender = frontOf[k];
            } else {
                farOnly = true;
            }
        }
        float take = min(left, omega);
        if (!(take > 0.0)) continue;
        if (farOnly) mark = kFarOnly | of;
        if (write) StoreShare(at + count, Share(b, sender, c * L.norm * take, mark));
        ++count;
        left -= take;
    }
    coverOut = omegaBin - left;
    part = left > 1e-4 * omegaBin;
    return count;
}

// Whether leaf i's partly covered bin b is filled by its shares (Build's partial fill).
bool Fills(uint i, uint b) {
    float omegaBin = pc.binSolidAngle;
    uint row = i * pc.bins;
    float covered = cover[row + b];
    if (!(covered >= kFillCoverage * omegaBin)) return false;
    vec3 normal = leaves[i].normal;
    for (uint k = 0u; k < pc.adjacentWidth; ++k) {
        uint j = adjacent[b * pc.adjacentWidth + k];
        if (j == b) continue;  // the padding
        float cj = cover[row + j];
        if (cj >= 0.0 && cj < kEdgeCoverage * omegaBin && dot(normal, dirs[j].xyz) > pc.aboveHorizon)
            return false;
    }
    return true;
}

// Where leaf i's shares start (its bins' merged shares, then its environment shares).
uint LeafStart(uint i) {
    return counts[pc.mergedAt + i * pc.bins] + counts[pc.environmentAt + i * pc.bins];
}

void main() {
    const uint stride = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    const uint id = gl_GlobalInvocationID.x;
    const uint lid = gl_LocalInvocationID.x;
    if (pc.mode == 0u) {
        for (uint k = id; k < pc.endCount; k += stride) atomicAdd(counts[endSlot[k]], 1u);
    } else if (pc.mode == 1u) {
        uint blocks = (pc.scanCount + kBlock - 1u) / kBlock;
        for (uint block = id; block < blocks; block += stride) {
            uint first = pc.scanFirst + block * kBlock;
            uint last = min(first + kBlock, pc.scanFirst + pc.scanCount);
            uint sum = 0u;
            for (uint j = first; j < last; ++j) sum += counts[j];
            blockSums[block] = sum;
        }
    } else if (pc.mode == 2u) {
        if (id == 0u) {
            uint blocks = (pc.scanCount + kBlock - 1u) / kBlock;
            uint run = 0u;
            for (uint j = 0u; j < blocks; ++j) {
                uint v = blockSums[j];
                blockSums[j] = run;
                run += v;
            }
            counts[pc.scanFirst + pc.scanCount] = run;
        }
    } else if (pc.mode == 3u) {
        uint blocks = (pc.scanCount + kBlock - 1u) / kBlock;
        for (uint block = id; block < blocks; block += stride) {
            uint first = pc.scanFirst + block * kBlock;
            uint last = min(first + kBlock, pc.scanFirst + pc.scanCount);
            uint run = blockSums[block];
            for (uint j = first; j < last; ++j) {
                uint v = counts[j];
                counts[j] = run;
                run += v;
            }
        }
    } else if (pc.mode == 4u) {
        for (uint k = id; k < pc.endCount; k += stride) {
            End e = LoadEnd(k);
            StoreScattered(atomicAdd(counts[e.slot], 1u), e);
        }
    } else if (pc.mode == 5u) {
        for (uint k = id; k < pc.endCount; k += stride) {
            End e = LoadScattered(k);
            uint lo = SlotBegin(e.slot), hi = counts[e.slot];
            if (hi - lo > kMostInSlot) {
                status[2] = 1u;
                continue;
            }
            uint rank = 0u;
            for (uint j = lo; j < hi; ++j) {
                float d = scatteredDist[j];
                uint sender = scatteredSender[j];
                if (d < e.dist || (d == e.dist && (sender < e.sender || (sender == e.sender && j < k))))
                    ++rank;
            }
            StoreEnd(lo + rank, e);
        }
    } else if (pc.mode == 6u) {
        for (uint k = id; k < pc.leafCount * pc.bins; k += stride) {
            float covered;
            bool part;
            counts[pc.mergedAt + k] = Merge(k / pc.bins, k % pc.bins, false, 0u, covered, part);
            cover[k] = covered;
            partial[k] = part ? 1u : 0u;
        }
    } else if (pc.mode == 7u) {
        for (uint k = id; k < pc.leafCount * pc.bins; k += stride) {
            uint shows = 0u;
            if (partial[k] != 0u) {
                uint i = k / pc.bins, b = k % pc.bins;
                float left = pc.binSolidAngle - cover[k];
                if (!Fills(i, b) && left > 1e-4 * pc.binSolidAngle) shows = 1u;
            }
            counts[pc.environmentAt + k] = shows;
        }
    } else if (pc.mode == 8u) {
        for (uint k = id; k < pc.leafCount * pc.bins; k += stride) {
            uint i = k / pc.bins, b = k % pc.bins;
            uint row = i * pc.bins;
            uint start = LeafStart(i);
            uint merged = counts[pc.mergedAt + row + pc.bins] - counts[pc.mergedAt + row];
            uint at = start + counts[pc.mergedAt + k] - counts[pc.mergedAt + row];
            float covered;
            bool part;
            uint n = Merge(i, b, true, at, covered, part);
            // The count pass made as many (a loop cut short on lavapipe would not).
            if (n != counts[pc.mergedAt + k + 1u] - counts[pc.mergedAt + k]) status[3] = 1u;
            if (!part) continue;
            if (Fills(i, b)) {
                float scale = pc.binSolidAngle / covered;
                for (uint j = 0u; j < n; ++j) shareWeight[at + j] *= scale;
                continue;
            }
            float left = pc.binSolidAngle - covered;
            if (left > 1e-4 * pc.binSolidAngle) {
                float rise = dot(leaves[i].normal, dirs[b].xyz);
                uint env = start + merged + counts[pc.environmentAt + k] -
                           counts[pc.environmentAt + row];
                StoreShare(env, Share(b, kNoSender, rise * leaves[i].norm * left, 0u));
            }
        }
    } else if (pc.mode == 9u) {
        for (uint i = id; i <= pc.leafCount; i += stride) offsets[i] = LeafStart(i);
    } else {
        uint total = offsets[pc.leafCount];
        for (uint k = id; k < total; k += stride) {
            // The leaf: the last whose first share is at or before k.
            uint lo = 0u, hi = pc.leafCount;
            while (hi - lo > 1u) {
                uint mid = (lo + hi) / 2u;
                if (offsets[mid] <= k) lo = mid; else hi = mid;
            }
            uint i = lo, first = offsets[i], end = offsets[i + 1u];
            Share sh = LoadShare(k);
            if ((sh.mark & kFarOnly) != 0u) {
                // A solid's far face where none of its near faces were met: the near face met
                // in the closest bin stands for it (Build's `unseen`).
                uint of = sh.mark & kSolidBits;
                vec3 w = dirs[sh.bin].xyz;
                float best = -2.0;
                for (uint j = first; j < end; ++j) {
                    uint mark = shareMark[j];
                    if ((mark & kFront) == 0u || (mark & kSolidBits) != of) continue;
                    float cw = dot(w, dirs[shareBin[j]].xyz);
                    if (cw > best) {
                        best = cw;
                        sh.sender = shareSender[j];
                    }
                }
                shareSender[k] = sh.sender;
            }
            uint t;
            if (sh.sender == kNoSender) {
                t = opposite[sh.bin];
            } else {
                CompositeNode from = nodes[sh.sender];
                vec3 toLeaf = leaves[i].center - from.center;
                if (from.coneCos >= kFlatCone)
                    t = dot(from.normal, toLeaf) > 0.0 ? kFacing : kAway;
                else
                    t = dot(toLeaf, toLeaf) > 0.0
                            ? LookupBin(normalize(toLeaf), pc.cubeRes, pc.adjacentWidth)
                            : opposite[sh.bin];
            }
            travel[k] = t;
        }
    }
}
