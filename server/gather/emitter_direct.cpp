// Emitter direct light with shadow rays (emitter_direct.h).
#include "gather/emitter_direct.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>

#include "base/check.h"
#include "base/numeric.h"
#include "base/pcg.h"
#include "rays/sampling.h"

namespace penumbra {
namespace {

// The power heuristic (Veach 1997) for a sample drawn na times with pdf pa against nb with pb.
float Power(float na, float pa, float nb, float pb) {
    const float a = na * pa, b = nb * pb;
    return a * a / (a * a + b * b);
}

// The share of a point's rays that sample the cosine-weighted hemisphere, the rest sampling
// the emitters by power (both joined by the power heuristic), from each technique's relative
// variance per ray, v = Var / mean², estimated by pilots of their own:
// - light sampling: kLightPilot points drawn on the emitters by power, nothing traced (the
//   emitters as if unoccluded): with g = L_e cosθx cosθy / (d² p), v_light = E[g²]/E[g]² − 1;
// - cosine sampling: kCosinePilot cosine rays traced, each giving π L_e of the emitter it
//   meets (0 where it meets none): v_cosine = E[L²]/E[L]² − 1, infinite when none met one.
// The share is v_light / (v_light + v_cosine) within [kLeastCosine, 1 − kLeastCosine], so
// that each technique still covers what the other misses. Emitters all round (a furnace)
// give v_cosine = 0: cosine rays are exact there and light rays only add noise (the white
// furnace's worst vertex was 1.15% at half each); a small or distant emitter gives
// v_cosine ≫ v_light. A light-sampling pilot alone judged the first badly: its own estimate
// of the emitters' coverage is noisiest exactly where they surround the point. The pilots
// draw streams of their own and are not part of the estimate, so the split does not depend
// on the samples the estimate uses: the estimate stays unbiased.
constexpr int kLightPilot = 32, kCosinePilot = 16;
constexpr float kLeastCosine = 0.125f;

int CosineShare(const RayScene& rays, int total, uint64_t seed, size_t point, const glm::vec3& x,
                const glm::vec3& nx) {
    if (total < 2) return 0;
    const int least = std::max(1, static_cast<int>(std::lround(kLeastCosine * total)));
    Pcg32 rng(seed ^ 0x9e3779b97f4a7c15ull, point);
    auto radiance = [&](uint32_t ti, float u, float v) {
        const glm::vec3 le = rays.MaterialOf(ti).emission * rays.TintsAt(ti, u, v).emission;
        return (le.x + le.y + le.z) / 3.0;
    };
    double g1 = 0.0, g2 = 0.0;
    for (int k = 0; k < kLightPilot; ++k) {
        const uint32_t ti = rays.Emitters()[rays.PickEmitter((k + rng.Uniform()) / kLightPilot)];
        const RayTriangle& t = rays.Triangles()[ti];
        glm::vec2 ab(rng.Uniform(), rng.Uniform());
        if (ab.x + ab.y > 1.0f) ab = glm::vec2(1.0f) - ab;
        const glm::vec3 d = t.p0 + ab.x * t.e1 + ab.y * t.e2 - x;
        const float d2 = glm::dot(d, d);
        if (!(d2 > 0.0f)) continue;
        const glm::vec3 w = d / std::sqrt(d2);
        const float cx = glm::dot(nx, w), cy = -glm::dot(t.normal, w);
        if (cx <= 0.0f || cy <= 0.0f) continue;
        const double g = radiance(ti, ab.x, ab.y) * cx * cy / (double(d2) * rays.AreaPdf(ti));
        g1 += g, g2 += g * g;
    }
    if (!(g1 > 0.0)) return least;  // no emitter in front: the split does not matter
    const double vl = std::max(0.0, g2 * kLightPilot / (g1 * g1) - 1.0);
    glm::vec3 dirs[kCosinePilot];
    RayHit hits[kCosinePilot];
    const glm::vec2 rotation(rng.Uniform(), rng.Uniform());
    for (int k = 0; k < kCosinePilot; ++k) dirs[k] = CosineDirection(nx, R2Point(rotation, k));
    rays.IntersectFrom(x + rays.Epsilon() * nx, dirs, kCosinePilot,
                       std::numeric_limits<float>::infinity(), hits);
    double l1 = 0.0, l2 = 0.0;
    for (int k = 0; k < kCosinePilot; ++k) {
        const uint32_t ti = hits[k].triangle;
        if (!hits[k].hit || !(rays.AreaPdf(ti) > 0.0f) ||
            glm::dot(rays.Triangles()[ti].normal, dirs[k]) >= 0.0f)
            continue;
        const glm::vec2 uv = rays.Mapped() ? rays.Barycentrics(ti, x + rays.Epsilon() * nx, dirs[k])
                                           : glm::vec2(0.0f);
        const double l = radiance(ti, uv.x, uv.y);
        l1 += l, l2 += l * l;
    }
    if (!(l1 > 0.0)) return least;
    const double vc = std::max(0.0, l2 * kCosinePilot / (l1 * l1) - 1.0);
    const double share = vl + vc > 0.0 ? vl / (vl + vc) : 0.5;
    return std::clamp(static_cast<int>(std::lround(share * total)), least, total - least);
}

}  // namespace

float EmitterHitWeight(const RayScene& rays, int lightRays, int cosineRays, const glm::vec3& n,
                       const glm::vec3& w, uint32_t triangle, float t) {
    const float pdfArea = rays.AreaPdf(triangle);
    if (!(pdfArea > 0.0f)) return 0.0f;
    const float cx = glm::dot(n, w), cy = -glm::dot(rays.Triangles()[triangle].normal, w);
    if (cx <= 0.0f || cy <= 0.0f) return 0.0f;
    return Power(cosineRays, cx / kPi, lightRays, pdfArea * t * t / cy) * kPi / cosineRays;
}

std::vector<uint16_t> EmitterCosineRays(const RayScene& rays, const std::vector<glm::vec3>& points,
                                        const std::vector<glm::vec3>& normals,
                                        const EmitterDirectSettings& settings) {
    if (points.size() != normals.size())
        throw Error("emitter direct light: " + std::to_string(points.size()) + " points, " +
                    std::to_string(normals.size()) + " normals");
    if (rays.Emitters().empty()) return {};
    std::vector<uint16_t> split(points.size());
    tbb::parallel_for(tbb::blocked_range<size_t>(0, points.size(), 256), [&](const auto& r) {
        for (size_t i = r.begin(); i != r.end(); ++i)
            split[i] = static_cast<uint16_t>(
                CosineShare(rays, settings.rays, settings.seed, i, points[i], normals[i]));
    });
    return split;
}

std::vector<glm::vec3> EmitterIrradiance(const RayScene& rays, const std::vector<glm::vec3>& points,
                                         const std::vector<glm::vec3>& normals,
                                         const EmitterDirectSettings& settings) {
    return EmitterDirect(settings).Trace(rays, points, normals);
}

EmitterDirect::EmitterDirect(const EmitterDirectSettings& settings) : settings_(settings) {
    if (settings.rays < 1) throw Error("emitter direct light needs at least one ray a point");
    words_ = (settings.rays + 63) / 64;
}

std::vector<glm::vec3> EmitterDirect::Trace(const RayScene& rays,
                                            const std::vector<glm::vec3>& points,
                                            const std::vector<glm::vec3>& normals,
                                            const std::vector<int>& extraCosine,
                                            const std::vector<uint16_t>& split) {
    Start(rays, points, normals, extraCosine, split);
    std::vector<glm::vec3> out(points.size(), glm::vec3(0.0f));
    TracePart(rays, points, normals, 0, points.size(), out);
    return out;
}

void EmitterDirect::Start(const RayScene& rays, const std::vector<glm::vec3>& points,
                          const std::vector<glm::vec3>& normals,
                          const std::vector<int>& extraCosine, const std::vector<uint16_t>& split) {
    if (points.size() != normals.size() ||
        (!extraCosine.empty() && extraCosine.size() != points.size()) ||
        (!split.empty() && split.size() != points.size()))
        throw Error("emitter direct light: " + std::to_string(points.size()) + " points, " +
                    std::to_string(normals.size()) + " normals");
    extra_ = extraCosine.empty() ? std::vector<int>(points.size(), settings_.extraCosineRays)
                                 : extraCosine;
    slots_ = rays.EmitterPrimitives().size() <= kMaxSlots ? rays.EmitterPrimitives().size() : 0;
    coef_.assign(points.size() * slots_, glm::vec3(0.0f));
    blocked_.assign(points.size() * words_, 0);
    // Each point's split, its cosine rays' outcomes from cosineFirst_[i] on.
    cosine_ = split.empty() ? EmitterCosineRays(rays, points, normals, settings_) : split;
    cosine_.resize(points.size(), 0);
    for (uint16_t c : cosine_)
        if (c > settings_.rays)
            throw Error("emitter direct light: a point's split of " + std::to_string(c) +
                        " cosine rays exceeds its " + std::to_string(settings_.rays) + " rays");
    cosineFirst_.assign(points.size() + 1, 0);
    for (size_t i = 0; i < points.size(); ++i) cosineFirst_[i + 1] = cosineFirst_[i] + cosine_[i];
    cosineT_.assign(cosineFirst_.back(), std::numeric_limits<float>::infinity());
    cosineTri_.assign(cosineFirst_.back(), ~0u);
}

void EmitterDirect::TracePart(const RayScene& rays, const std::vector<glm::vec3>& points,
                              const std::vector<glm::vec3>& normals, size_t first, size_t last,
                              std::vector<glm::vec3>& out) {
    PENUMBRA_CHECK_EQ(points.size(), extra_.size());
    PENUMBRA_CHECK(first <= last && last <= points.size() && out.size() == points.size());
    if (rays.Emitters().empty()) {
        std::fill(out.begin() + first, out.begin() + last, glm::vec3(0.0f));
        return;
    }
    tbb::parallel_for(tbb::blocked_range<size_t>(first, last, 16), [&](const auto& range) {
        size_t traced = 0;
        for (size_t i = range.begin(); i != range.end(); ++i)
            out[i] = Shoot(rays, i, points[i], normals[i], nullptr, traced);
    });
}

std::vector<glm::vec3> EmitterDirect::Retrace(const RayScene& rays,
                                              const std::vector<glm::vec3>& points,
                                              const std::vector<glm::vec3>& normals,
                                              const std::vector<uint8_t>& moved,
                                              const std::vector<Bounds>& boxes, size_t* traced) {
    PENUMBRA_CHECK_EQ(points.size(), extra_.size());
    PENUMBRA_CHECK_EQ(moved.size(), points.size());
    std::vector<glm::vec3> out(points.size(), glm::vec3(0.0f));
    std::atomic<size_t> total{0};
    if (rays.Emitters().empty()) {
        if (traced) *traced = 0;
        return out;
    }
    // With coefficients kept, a point whose rays cannot pass through a box keeps its E
    // (read from them) without making its rays again: its light rays when no box lies
    // between it and an emitting primitive, its cosine rays when no box lies above its
    // tangent plane. A point with a ray whose outcome changed sums its rays again.
    const bool kept = slots_ > 0 && rays.EmitterPrimitives().size() == slots_;
    std::vector<Ball> emitters, cutters;
    std::vector<Bounds> cut;  // the boxes that are not empty, a ball each in cutters
    for (const Bounds& b : boxes)
        if (!b.Empty()) cut.push_back(b), cutters.emplace_back(b);
    std::vector<glm::vec3> le(slots_);
    if (kept) {
        std::vector<Bounds> extent(slots_);
        for (uint32_t t : rays.Emitters()) {
            const RayTriangle& tri = rays.Triangles()[t];
            Bounds& b = extent[rays.EmitterSlot(tri.primitive)];
            for (const glm::vec3& p : {tri.p0, tri.p0 + tri.e1, tri.p0 + tri.e2}) b.Add(p);
        }
        for (const Bounds& b : extent) emitters.emplace_back(b);
        const Scene& scene = rays.GetScene();
        for (size_t k = 0; k < slots_; ++k)
            le[k] =
                scene.materials[scene.primitives[rays.EmitterPrimitives()[k]].material].emission;
    }
    const std::vector<Bounds> none;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, points.size(), 16), [&](const auto& range) {
        size_t n = 0;
        std::vector<BallCone> cones;
        for (size_t i = range.begin(); i != range.end(); ++i) {
            const glm::vec3& x = points[i];
            if (moved[i] || !kept) {
                out[i] = Shoot(rays, i, x, normals[i], moved[i] ? nullptr : &boxes, n);
                continue;
            }
            uint64_t slots = 0;
            bool cosine = false;
            for (const Ball& c : cutters) {
                cosine = cosine || glm::dot(normals[i], c.centre - x) > -c.radius;
                for (size_t k = 0; k < slots_; ++k)
                    if (CanCut(x, c, emitters[k])) slots |= uint64_t(1) << k;
            }
            cones.clear();
            for (const Ball& c : cutters) cones.emplace_back(x + rays.Epsilon() * normals[i], c);
            if ((slots != 0 || (cosine && cosine_[i] > 0)) &&
                Recheck(rays, i, x, normals[i], cut, cones, slots, cosine, moved, n)) {
                out[i] = Shoot(rays, i, x, normals[i], &none, n);
                continue;
            }
            const glm::vec3* coef = coef_.data() + i * slots_;
            for (size_t k = 0; k < slots_; ++k) out[i] += le[k] * coef[k];
        }
        total += n;
    });
    if (traced) *traced = total;
    return out;
}

bool EmitterDirect::Reevaluate(const RayScene& rays, std::vector<glm::vec3>& out) const {
    if (slots_ == 0 || rays.EmitterPrimitives().size() != slots_) return false;
    std::vector<glm::vec3> le(slots_);
    for (size_t k = 0; k < slots_; ++k) {
        const Scene& scene = rays.GetScene();
        le[k] = scene.materials[scene.primitives[rays.EmitterPrimitives()[k]].material].emission;
    }
    out.assign(extra_.size(), glm::vec3(0.0f));
    for (size_t i = 0; i < out.size(); ++i)
        for (size_t k = 0; k < slots_; ++k) out[i] += le[k] * coef_[i * slots_ + k];
    return true;
}

bool EmitterDirect::LightRay(const RayScene& rays, uint32_t ti, int r, const glm::vec2& sl,
                             const glm::vec3& x, const glm::vec3& nx, Sample& out) const {
    const RayTriangle& t = rays.Triangles()[ti];
    // A point on it: the r-th R2 point, folded into the triangle.
    glm::vec2 ab = R2Point(sl, r);
    if (ab.x + ab.y > 1.0f) ab = glm::vec2(1.0f) - ab;
    const glm::vec3 y = t.p0 + ab.x * t.e1 + ab.y * t.e2;
    out.uv = ab;
    const glm::vec3 d = y - x;
    out.dist2 = glm::dot(d, d);
    if (!(out.dist2 > 0.0f)) return false;
    const glm::vec3 w = d / std::sqrt(out.dist2);
    out.cx = glm::dot(nx, w), out.cy = -glm::dot(t.normal, w);
    if (out.cx <= 0.0f || out.cy <= 0.0f) return false;
    const float eps = rays.Epsilon();
    out.span = y + eps * t.normal - (x + eps * nx);
    return true;
}

glm::vec3 EmitterDirect::Shoot(const RayScene& rays, size_t i, const glm::vec3& x,
                               const glm::vec3& nx, const std::vector<Bounds>* boxes,
                               size_t& traced) {
    const auto& tris = rays.Triangles();
    const float eps = rays.Epsilon();
    const int own = cosine_[i], nl = settings_.rays - own, nb = own + extra_[i];
    float* const cosineT = cosineT_.data() + cosineFirst_[i];
    uint32_t* const cosineTri = cosineTri_.data() + cosineFirst_[i];
    // Each contribution is L_e of its triangle's material times a coefficient (the emission
    // map's tint at the point in it), kept per emitting primitive (Reevaluate).
    glm::vec3* coef = slots_ ? coef_.data() + i * slots_ : nullptr;
    if (coef) std::fill(coef, coef + slots_, glm::vec3(0.0f));
    glm::vec3 sum(0.0f);
    auto add = [&](uint32_t tri, float c, const glm::vec2& uv) {
        const glm::vec3 tinted = c * rays.TintsAt(tri, uv.x, uv.y).emission;
        sum += rays.MaterialOf(tri).emission * tinted;
        if (coef) coef[rays.EmitterSlot(tris[tri].primitive)] += tinted;
    };
    auto meets = [&](const glm::vec3& o, const glm::vec3& d, float tmax) {
        if (!boxes) return true;
        for (const Bounds& b : *boxes)
            if (b.Meets(o, d, tmax)) return true;
        return false;
    };
    Pcg32 rng(settings_.seed, i);
    // This point's rotations of the R2 sequence (Cranley–Patterson): emitter points,
    // hemisphere directions.
    glm::vec2 sl, sb;
    sl.x = rng.Uniform(), sl.y = rng.Uniform();
    sb.x = rng.Uniform(), sb.y = rng.Uniform();
    const glm::vec3 from = x + eps * nx;
    uint64_t* bits = blocked_.data() + i * words_;
    // The rays to trace go out in packets of 8 from the point (the same outcomes as one at a
    // time); what each adds is summed in ray order after.
    thread_local std::vector<Sample> samples;
    thread_local std::vector<uint32_t> picked;  // per light ray its triangle; ~0: adds nothing
    thread_local std::vector<int> batch;        // the rays to trace
    thread_local std::vector<glm::vec3> spans, dirs;
    thread_local std::vector<RayHit> hits;
    thread_local std::vector<uint8_t> blocked;
    samples.resize(size_t(nl));
    picked.assign(size_t(nl), ~0u);
    batch.clear(), spans.clear();
    for (int r = 0; r < nl; ++r) {
        // Emitter by power, from the r-th of nl strata of [0, 1): each emitter takes a run of
        // consecutive r, so its points below are consecutive R2 points.
        const float ut = (static_cast<float>(r) + rng.Uniform()) / nl;
        const uint32_t ti = rays.Emitters()[rays.PickEmitter(ut)];
        if (!LightRay(rays, ti, r, sl, x, nx, samples[r])) continue;
        picked[r] = ti;
        if (meets(from, samples[r].span, 1.0f))
            batch.push_back(r), spans.push_back(samples[r].span);
    }
    traced += batch.size();
    blocked.resize(batch.size());
    rays.OccludedFrom(from, spans.data(), spans.size(), blocked.data());
    for (size_t k = 0; k < batch.size(); ++k) {
        const int r = batch[k];
        const uint64_t bit = uint64_t(1) << (r % 64);
        if (blocked[k])
            bits[r / 64] |= bit;
        else
            bits[r / 64] &= ~bit;
    }
    for (int r = 0; r < nl; ++r) {
        const uint32_t ti = picked[r];
        if (ti == ~0u || (bits[r / 64] & (uint64_t(1) << (r % 64)))) continue;
        const Sample& s = samples[r];
        const float pdfArea = rays.AreaPdf(ti);
        const float weight = Power(nl, pdfArea * s.dist2 / s.cy, nb, s.cx / kPi);
        add(ti, weight * s.cx * s.cy / (s.dist2 * pdfArea * nl), s.uv);
    }
    dirs.resize(size_t(own));
    batch.clear(), spans.clear();
    for (int r = 0; r < own; ++r) {
        dirs[r] = CosineDirection(nx, R2Point(sb, r));
        if (meets(from, dirs[r], cosineT[r])) batch.push_back(r), spans.push_back(dirs[r]);
    }
    traced += batch.size();
    hits.resize(batch.size());
    rays.IntersectFrom(from, spans.data(), spans.size(), std::numeric_limits<float>::infinity(),
                       hits.data());
    for (size_t k = 0; k < batch.size(); ++k) {
        const int r = batch[k];
        cosineT[r] = hits[k].hit ? hits[k].t : std::numeric_limits<float>::infinity();
        cosineTri[r] = hits[k].hit ? hits[k].triangle : ~0u;
    }
    for (int r = 0; r < own; ++r) {
        const uint32_t tri = cosineTri[r];
        if (tri == ~0u || !(rays.AreaPdf(tri) > 0.0f)) continue;
        add(tri, EmitterHitWeight(rays, nl, nb, nx, dirs[r], tri, cosineT[r]),
            rays.Mapped() ? rays.Barycentrics(tri, from, dirs[r]) : glm::vec2(0.0f));
    }
    return sum;
}

bool EmitterDirect::Recheck(const RayScene& rays, size_t i, const glm::vec3& x, const glm::vec3& nx,
                            const std::vector<Bounds>& boxes, const std::vector<BallCone>& cones,
                            uint64_t slots, bool cosine, const std::vector<uint8_t>& moved,
                            size_t& traced) {
    const auto& tris = rays.Triangles();
    const int own = cosine_[i], nl = settings_.rays - own;
    const float inf = std::numeric_limits<float>::infinity();
    auto meets = [&](const glm::vec3& o, const glm::vec3& d, float tmax) {
        const bool endless = tmax == inf;
        const glm::vec3 span = endless ? d : d * tmax;
        for (size_t k = 0; k < boxes.size(); ++k)
            if (cones[k].MayMeet(span, endless) && boxes[k].Meets(o, d, tmax)) return true;
        return false;
    };
    auto emits = [&](uint32_t tri) { return tri != ~0u && rays.AreaPdf(tri) > 0.0f; };
    bool changed = false;
    // The same draws as Shoot's, in the same order.
    Pcg32 rng(settings_.seed, i);
    glm::vec2 sl, sb;
    sl.x = rng.Uniform(), sl.y = rng.Uniform();
    sb.x = rng.Uniform(), sb.y = rng.Uniform();
    const glm::vec3 from = x + rays.Epsilon() * nx;
    uint64_t* bits = blocked_.data() + i * words_;
    for (int r = 0; r < nl; ++r) {
        const float ut = (static_cast<float>(r) + rng.Uniform()) / nl;
        if (slots == 0) break;
        const uint32_t ti = rays.Emitters()[rays.PickEmitter(ut)];
        if (!(slots >> rays.EmitterSlot(tris[ti].primitive) & 1)) continue;
        Sample s;
        if (!LightRay(rays, ti, r, sl, x, nx, s) || !meets(from, s.span, 1.0f)) continue;
        ++traced;
        const uint64_t bit = uint64_t(1) << (r % 64);
        const bool blocked = rays.Occluded(from, s.span);
        if (blocked == ((bits[r / 64] & bit) != 0)) continue;
        bits[r / 64] ^= bit;
        changed = true;
    }
    // A cosine ray adds only where it first meets an emitter. Of those that did not, only
    // one that met a surface that moved can meet an emitter now (the emitters stayed, what
    // moved does not emit); one that met a surface that stayed, or nothing, adds nothing
    // whatever moved in front of it, and keeps its outcome.
    auto onMoved = [&](uint32_t t) {
        if (t == ~0u || !rays.HasCorners()) return t != ~0u;
        const glm::uvec3& c = rays.Corners(t);
        return moved[c.x] || moved[c.y] || moved[c.z];
    };
    for (int r = 0; cosine && r < own; ++r) {
        float& dist = cosineT_[cosineFirst_[i] + r];
        uint32_t& tri = cosineTri_[cosineFirst_[i] + r];
        const bool stale = onMoved(tri);
        if (!stale && !emits(tri)) continue;
        const glm::vec3 w = CosineDirection(nx, R2Point(sb, r));
        if (!stale && !meets(from, w, dist)) continue;
        ++traced;
        const RayHit hit = rays.Intersect(from, w, std::numeric_limits<float>::infinity());
        const uint32_t now = hit.hit ? hit.triangle : ~0u;
        changed = changed || (now != tri && (emits(now) || emits(tri)));
        dist = hit.hit ? hit.t : std::numeric_limits<float>::infinity();
        tri = now;
    }
    return changed;
}

}  // namespace penumbra
