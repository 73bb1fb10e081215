// The gather stage: first shot and final gather (gather_stage.h).
#include "gather/gather_stage.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>

#include "base/check.h"
#include "base/image.h"
#include "base/pcg.h"
#include "gather/sampling.h"

namespace penumbra {
namespace {

constexpr float kPi = 3.14159265358979f;
// Streams of the gather's patterns, apart from the first shot's (which uses stream = surfel).
constexpr uint64_t kGatherStream = 0x9e3779b97f4a7c15ull;
constexpr uint64_t kSecondStream = 0x5851f42d4c957f2dull;
constexpr uint64_t kLobeStream = 0x2545f4914f6cdd1dull;
constexpr uint64_t kGlintStream = 0x6a09e667f3bcc909ull;

// A hit closer than this × the solver's element size is gathered again (GatherStage::kShort).
// Measured (bake at 0.1 m elements against the reference at 4,096 samples; 0, 0.25, 0.5, 1):
// the Cornell box 2.78, 2.15, 2.14, 2.13%; the office (0.37 m elements) 4.01, 3.90, 3.88,
// 3.88%, its tracing 0.44, 1.1, 1.2, 2.1 s; the white furnace's worst vertex 2.3% without.
constexpr float kShortHit = 0.5f;

double Ms(std::chrono::steady_clock::time_point since) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - since)
        .count();
}

bool SameEnvironment(const Environment& a, const Environment& b) {
    return a.source == b.source && a.image == b.image && a.constant == b.constant &&
           a.intensity == b.intensity && a.rotation == b.rotation;
}

}  // namespace

void CheckGatherRays(int rays, const std::string& what) {
    if (rays < 0 || rays > kMaxGatherRays)
        throw Error(what + " takes 0 (off) to " + std::to_string(kMaxGatherRays) +
                    " rays a surfel, not " + std::to_string(rays));
}

GatherStage::GatherStage(std::unique_ptr<Solver> inner, const Scene& scene,
                         const GatherSettings& settings)
    : inner_(std::move(inner)), scene_(scene), settings_(settings) {
    CheckGatherRays(settings.emitterRays, "the first shot");
    CheckGatherRays(settings.gatherRays, "the final gather");
    rays_ = std::make_unique<RayScene>(scene_, inner_->GetSurfels());
    glossy_ = AnyGlossy(scene_.materials);
    diameter_ = scene_.Diameter();
    Place();
    const Surfels& s = inner_->GetSurfels();
    if (settings_.gatherRays > 0) {
        if (settings_.allSurfels) {
            for (uint32_t i = 0; i < s.size(); ++i) targets_.push_back(i);
        } else {
            for (size_t p = 0; p < scene_.primitives.size(); ++p)
                for (uint32_t i = 0; i < scene_.primitives[p].positions.size(); ++i)
                    targets_.push_back(s.firstSurfel[p] + i);
        }
        rotation_.resize(targets_.size());
        for (size_t t = 0; t < targets_.size(); ++t) {
            Pcg32 rng(settings_.seed, kGatherStream + targets_[t]);
            rotation_[t].x = rng.Uniform();
            rotation_[t].y = rng.Uniform();
        }
        Trace();
        TraceLobes();
        PlaceGlints();
        TraceGlints();
        Sky();
    }
    Shoot();
}

void GatherStage::Shoot(const Moved* moved) {
    if (settings_.emitterRays <= 0) return;
    auto start = std::chrono::steady_clock::now();
    const Surfels& s = inner_->GetSurfels();
    ++traces_;
    if (!moved || !shooter_) {
        EmitterDirectSettings es;
        es.rays = settings_.emitterRays;
        es.seed = settings_.seed;
        shooter_ = std::make_unique<EmitterDirect>(es);
        // At the targets the gather's rays join the shot's own cosine rays (emitterHits_).
        std::vector<int> extra(s.size(), 0);
        for (uint32_t i : targets_) extra[i] = settings_.gatherRays;
        shot_ = shooter_->Trace(*rays_, points_, s.normals, extra);
    } else {
        size_t traced = 0;
        shot_ =
            shooter_->Retrace(*rays_, points_, s.normals, moved->surfels, moved->boxes, &traced);
        raysRetraced_ += traced;
    }
    for (size_t t = 0; t < targets_.size(); ++t) shot_[targets_[t]] += emitterHits_[t];
    if (HandsOver()) inner_->SetEmitterDirect(shot_);
    fresh_ = false;
    msShot_ = Ms(start);
}

void GatherStage::Place() {
    const Surfels& s = inner_->GetSurfels();
    // Surfels inside a primitive: at their position, or, on its boundary, moved as far towards
    // their centroid as the input vertices are (a point on the edge where a wall meets the
    // floor sees half its hemisphere behind that wall).
    points_ = s.positions;
    const float step = kVertexInset * scene_.Diameter();
    for (size_t i = 0; i < s.size(); ++i) {
        const glm::vec3 d = s.centroids[i] - s.positions[i];
        const float len = glm::length(d);
        if (len > 0.0f) points_[i] += std::min(len, step) * (d / len);
    }
    const auto inset = VertexEstimatePoints(scene_);
    surfelPrimitive_.assign(s.size(), 0);
    for (size_t p = 0; p < inset.size(); ++p) {
        std::copy(inset[p].begin(), inset[p].end(), points_.begin() + s.firstSurfel[p]);
        std::fill(surfelPrimitive_.begin() + s.firstSurfel[p], surfelPrimitive_.begin() + s.End(p),
                  static_cast<uint32_t>(p));
    }
}

glm::vec3 GatherStage::Direction(size_t target, int ray) const {
    return CosineDirection(inner_->GetSurfels().normals[targets_[target]],
                           R2Point(rotation_[target], ray));
}

glm::vec2 GatherStage::SecondRotation(size_t target, int ray) const {
    Pcg32 rng(settings_.seed, kSecondStream + target * settings_.gatherRays + ray);
    glm::vec2 rot;
    rot.x = rng.Uniform(), rot.y = rng.Uniform();
    return rot;
}

glm::vec3 GatherStage::SecondDirection(size_t target, int ray, uint32_t tri, int j) const {
    return CosineDirection(rays_->Triangles()[tri].normal, R2Point(SecondRotation(target, ray), j));
}

glm::vec3 GatherStage::HitPoint(const Hit& h) const {
    const RayTriangle& t = rays_->Triangles()[h.triangle & kIndex];
    return t.p0 + (h.u * (1.0f / 65535.0f)) * t.e1 + (h.v * (1.0f / 65535.0f)) * t.e2;
}

float GatherStage::Distance(const glm::vec3& origin, const Hit& h) const {
    if (h.triangle == kEscaped) return std::numeric_limits<float>::infinity();
    return glm::length(HitPoint(h) - origin);
}

GatherStage::Hit GatherStage::Cast(const glm::vec3& o, const glm::vec3& d, float* t) const {
    const float inf = std::numeric_limits<float>::infinity();
    const RayHit h = rays_->Intersect(o, d, inf);
    if (t) *t = h.hit ? h.t : inf;
    if (!h.hit) return Hit{kEscaped, 0, 0};
    const uint32_t back = glm::dot(rays_->Triangles()[h.triangle].normal, d) >= 0.0f ? kBack : 0u;
    return Hit{h.triangle | back, Quantise(h.u), Quantise(h.v)};
}

void GatherStage::Trace(const Moved* moved) {
    auto start = std::chrono::steady_clock::now();
    ++traces_;
    const int n = settings_.gatherRays, m = SecondRays();
    const float shortHit = kShortHit * inner_->Stats().elementSize;
    const auto& tris = rays_->Triangles();
    const Surfels& surfels = inner_->GetSurfels();
    const float inf = std::numeric_limits<float>::infinity();
    auto trace = [&](const glm::vec3& o, const glm::vec3& d, float& t) { return Cast(o, d, &t); };
    // After a move: whether a cached hit still holds (its ray starts on a surface that did not
    // move, ends on one that did not, and passes by where the moved ones were and are). The
    // segment is the one to the hit point (no direction needed, which costs more to make
    // again than the test), or the ray to infinity when it escaped; `cones` (one per box,
    // from the ray's origin) turn most segments away before the slab test.
    auto holds = [&](const glm::vec3& o, const std::vector<BallCone>& cones, const auto& direction,
                     const Hit& h) {
        const std::vector<Bounds>& boxes = moved->boxes;
        if (h.triangle == kEscaped) {
            const glm::vec3 d = direction();
            for (size_t k = 0; k < boxes.size(); ++k)
                if (cones[k].MayMeet(d, true) && boxes[k].Meets(o, d, inf)) return false;
            return true;
        }
        if (moved->Touches(*rays_, h.triangle & kIndex)) return false;
        const glm::vec3 span = HitPoint(h) - o;
        for (size_t k = 0; k < boxes.size(); ++k)
            if (cones[k].MayMeet(span) && boxes[k].Meets(o, span, 1.0f)) return false;
        return true;
    };
    // The cones from o towards the boxes (`grow`: each box's ball grown by that much), and
    // which points of a cosine pattern about `normal` can fall in one (CosineCone); false
    // when none can: no ray from o meets a box.
    auto conesAt = [&](const glm::vec3& o, const glm::vec3& normal, float grow,
                       std::vector<BallCone>& cones, std::vector<CosineCone>& pattern) {
        cones.clear(), pattern.clear();
        bool any = false;
        for (const Bounds& b : moved->boxes) {
            Ball ball(b);
            ball.radius += grow;
            cones.emplace_back(o, ball);
            const BallCone& c = cones.back();
            pattern.push_back(c.Inside() ? CosineCone()
                                         : CosineCone(normal, c.Axis(), c.SinHalf()));
            any = any || !pattern.back().Empty();
        }
        return any;
    };
    auto mayMeet = [](const std::vector<CosineCone>& pattern, const glm::vec2& u) {
        for (const CosineCone& c : pattern)
            if (c.MayContain(u)) return true;
        return false;
    };
    hits_.resize(targets_.size() * n);  // in place: a target's hits are read, then written
    second_.resize(targets_.size());
    // Per target: a gather ray was traced again (its emitter hits are weighed again).
    std::vector<uint8_t> touched(targets_.size(), moved ? 0 : 1);
    std::atomic<size_t> traced{0};
    tbb::parallel_for(tbb::blocked_range<size_t>(0, targets_.size(), 16), [&](const auto& range) {
        size_t count = 0;
        std::vector<BallCone> cones, wide, secondCones;
        std::vector<CosineCone> pattern, secondPattern;
        // Per normal met at this target's short hits, its secondaries' pattern.
        std::vector<std::pair<glm::vec3, std::vector<CosineCone>>> patterns;
        std::vector<uint8_t> kept(n), was(n);
        std::vector<Hit> relaid;
        for (size_t t = range.begin(); t != range.end(); ++t) {
            const uint32_t i = targets_[t];
            const glm::vec3 o = points_[i] + rays_->Epsilon() * surfels.normals[i];
            const bool all = !moved || moved->surfels[i];
            // Nothing moved in front of it: every hit holds, its secondaries are checked.
            const bool clear = !all && !conesAt(o, surfels.normals[i], 0.0f, cones, pattern);
            bool same = !all;  // its short hits are the rays they were
            for (int r = 0; r < n; ++r) {
                Hit& hit = hits_[t * n + r];
                const Hit before = all ? Hit{kEscaped, 0, 0} : hit;
                was[r] = Front(before) && (before.triangle & kShort);
                kept[r] = !all && (clear || !mayMeet(pattern, R2Point(rotation_[t], r)) ||
                                   holds(
                                       o, cones, [&] { return Direction(t, r); }, before));
                if (kept[r]) continue;
                float dist = inf;
                hit = trace(o, Direction(t, r), dist);
                ++count;
                touched[t] = 1;
                const bool isShort = Front(hit) && dist < shortHit;
                if (isShort) hit.triangle |= kShort;
                same = same && isShort == static_cast<bool>(was[r]);
            }
            // A secondary ray from a short hit y (within shortHit of o) that meets a ball runs
            // in a direction inside o's cone towards that ball grown by shortHit (the parallel
            // ray from o passes within shortHit of where it does): the pattern about y's normal
            // is made once per normal the target's short hits have, from o.
            patterns.clear();
            auto patternFor = [&](const glm::vec3& normal) -> const std::vector<CosineCone>& {
                // Bit for bit: a −0 in the normal turns the pattern's basis (CosineDirection).
                for (const auto& [nm, p] : patterns)
                    if (std::memcmp(&nm, &normal, sizeof(glm::vec3)) == 0) return p;
                if (wide.empty()) conesAt(o, normal, shortHit + rays_->Epsilon(), wide, pattern);
                patterns.emplace_back(normal, std::vector<CosineCone>());
                for (const BallCone& c : wide)
                    patterns.back().second.push_back(
                        c.Inside() ? CosineCone() : CosineCone(normal, c.Axis(), c.SinHalf()));
                return patterns.back().second;
            };
            wide.clear();
            // Ray r's secondary gather into `out`: the cached one (`old`, null where the hit
            // did not hold) where each ray holds, traced again where not (out may be old).
            auto gatherAgain = [&](int r, const Hit* old, Hit* out) {
                const Hit& hit = hits_[t * n + r];
                const uint32_t tri = hit.triangle & kIndex;
                const glm::vec3& normal = tris[tri].normal;
                const std::vector<CosineCone>* filter = old ? &patternFor(normal) : nullptr;
                if (filter && std::all_of(filter->begin(), filter->end(),
                                          [](const CosineCone& c) { return c.Empty(); })) {
                    if (out != old) std::copy(old, old + m, out);  // none can meet a box
                    return;
                }
                const glm::vec3 y = HitPoint(hit) + rays_->Epsilon() * normal;
                const glm::vec2 rot = SecondRotation(t, r);
                bool near = false;  // secondCones made at y
                for (int j = 0; j < m; ++j) {
                    const glm::vec2 u = R2Point(rot, j);
                    auto d2 = [&] { return CosineDirection(normal, u); };
                    bool holding = old && !mayMeet(*filter, u);
                    if (old && !holding) {
                        if (!near) conesAt(y, normal, 0.0f, secondCones, secondPattern);
                        near = true;
                        holding = holds(y, secondCones, d2, old[j]);
                    }
                    if (holding) {
                        out[j] = old[j];
                    } else {
                        float t2 = inf;
                        out[j] = trace(y, d2(), t2);
                        ++count;
                    }
                }
            };
            auto isShort = [&](int r) {
                return Front(hits_[t * n + r]) && (hits_[t * n + r].triangle & kShort);
            };
            // Its secondaries: in place where its short hits are the same rays as before.
            std::vector<Hit>& block = second_[t];
            if (same) {
                Hit* at = block.data();
                for (int r = 0; r < n; ++r)
                    if (isShort(r)) {
                        gatherAgain(r, kept[r] ? at : nullptr, at);
                        at += m;
                    }
                continue;
            }
            relaid.clear();
            size_t old = 0;  // its old secondaries (none when all are traced)
            for (int r = 0; r < n; ++r) {
                if (isShort(r)) {
                    relaid.resize(relaid.size() + m);
                    gatherAgain(r, kept[r] ? block.data() + old : nullptr,
                                relaid.data() + relaid.size() - m);
                }
                if (was[r]) old += m;
            }
            block.assign(relaid.begin(), relaid.end());
        }
        traced += count;
    });
    secondStart_.assign(targets_.size() + 1, 0);
    for (size_t t = 0; t < targets_.size(); ++t)
        secondStart_[t + 1] = secondStart_[t] + static_cast<uint32_t>(second_[t].size() / m);

    // The emitters the gather rays meet, weighted against the first shot's rays, as a
    // coefficient per emitting primitive: again at the targets with a ray traced again.
    const size_t slots = rays_->EmitterPrimitives().size();
    if (!moved) {
        emitterHits_.assign(targets_.size(), glm::vec3(0.0f));
        emitterCoef_.assign(slots <= EmitterDirect::kMaxSlots ? targets_.size() * slots : 0, 0.0f);
    }
    if (settings_.emitterRays > 0 && slots > 0) {
        EmitterDirectSettings es;  // the first shot's, for the weights of emitter hits
        es.rays = settings_.emitterRays;
        es.extraCosineRays = n;
        tbb::parallel_for(
            tbb::blocked_range<size_t>(0, targets_.size(), 64), [&](const auto& range) {
                for (size_t t = range.begin(); t != range.end(); ++t) {
                    if (!touched[t]) continue;
                    const uint32_t i = targets_[t];
                    const glm::vec3 o = points_[i] + rays_->Epsilon() * surfels.normals[i];
                    emitterHits_[t] = glm::vec3(0.0f);
                    float* coef = emitterCoef_.empty() ? nullptr : &emitterCoef_[t * slots];
                    if (coef) std::fill(coef, coef + slots, 0.0f);
                    for (int r = 0; r < n; ++r) {
                        const Hit& h = hits_[t * n + r];
                        if (!Front(h) || !(rays_->AreaPdf(h.triangle & kIndex) > 0.0f)) continue;
                        const uint32_t tri = h.triangle & kIndex;
                        const float c = EmitterHitWeight(*rays_, es, surfels.normals[i],
                                                         Direction(t, r), tri, Distance(o, h));
                        emitterHits_[t] += rays_->MaterialOf(tri).emission * c;
                        if (coef) coef[rays_->EmitterSlot(tris[tri].primitive)] += c;
                    }
                }
            });
    }
    raysRetraced_ += moved ? traced.load() : 0;
    fresh_ = false;
    lightsFresh_ = false;
    msTrace_ = Ms(start);
}

glm::vec3 GatherStage::LobeDirection(size_t target, int ray, const Hit& h, float& cosine) const {
    const uint32_t tri = h.triangle & kIndex;
    const glm::vec3& n = rays_->Triangles()[tri].normal;
    const float exponent = rays_->MaterialOf(tri).phongExponent;
    // The lobe's axis: the mirror image of the direction back along the ray (wo = −d).
    const glm::vec3 wo = -Direction(target, ray);
    const glm::vec3 mirror = 2.0f * glm::dot(n, wo) * n - wo;
    // Phong lobe sampling, pdf (n + 1)/(2π) cosⁿθ_r.
    Pcg32 rng(settings_.seed, kLobeStream + target * settings_.gatherRays + ray);
    const float u1 = rng.Uniform(), u2 = rng.Uniform();
    const float c = std::pow(u1, 1.0f / (exponent + 1.0f));
    const float r = std::sqrt(std::max(0.0f, 1.0f - c * c)), phi = 2.0f * kPi * u2;
    glm::vec3 t, b;
    Basis(mirror, t, b);
    const glm::vec3 wi = glm::normalize(r * std::cos(phi) * t + r * std::sin(phi) * b + c * mirror);
    cosine = glm::dot(n, wi);
    return wi;
}

void GatherStage::TraceLobes(const Moved* moved) {
    if (!glossy_) {
        lobes_.assign(targets_.size(), {});
        seen_.assign(targets_.size(), {});
        return;
    }
    auto start = std::chrono::steady_clock::now();
    const int n = settings_.gatherRays, words = LightWords();
    const auto& tris = rays_->Triangles();
    const float inf = std::numeric_limits<float>::infinity();
    lobes_.resize(targets_.size());
    seen_.resize(targets_.size());
    std::atomic<size_t> traced{0};
    tbb::parallel_for(tbb::blocked_range<size_t>(0, targets_.size(), 16), [&](const auto& range) {
        size_t count = 0;
        std::vector<LobeHit> lobes;
        std::vector<uint32_t> seen;
        for (size_t t = range.begin(); t != range.end(); ++t) {
            const std::vector<LobeHit>& old = lobes_[t];
            const std::vector<uint32_t>& oldSeen = seen_[t];
            lobes.clear(), seen.clear();
            size_t k = 0;  // the first old entry at or after ray r
            for (int r = 0; r < n; ++r) {
                const Hit& h = hits_[t * n + r];
                while (k < old.size() && old[k].ray < r) ++k;
                if (!Front(h) || !rays_->MaterialOf(h.triangle & kIndex).Glossy()) continue;
                const uint32_t tri = h.triangle & kIndex;
                const glm::vec3 y = HitPoint(h) + rays_->Epsilon() * tris[tri].normal;
                const bool reuse = moved && k < old.size() && old[k].ray == r &&
                                   Same(old[k].from, h) && !moved->Touches(*rays_, tri);
                LobeHit e =
                    reuse ? old[k]
                          : LobeHit{
                                static_cast<uint16_t>(r), h, {kNone, 0, 0}, 0.0f, glm::vec3(0.0f)};
                // The lobe ray: kept where it passes by what moved.
                bool again = !reuse;
                if (reuse && e.hit.triangle == kEscaped) {
                    float c;
                    again = moved->Meets(y, LobeDirection(t, r, h, c), inf);
                } else if (reuse && e.hit.triangle != kNone) {
                    again = moved->Touches(*rays_, e.hit.triangle & kIndex) ||
                            moved->Meets(y, HitPoint(e.hit) - y, 1.0f);
                }
                if (again) {
                    float cosine = 0.0f;
                    const glm::vec3 wi = LobeDirection(t, r, h, cosine);
                    e.hit = {kNone, 0, 0};
                    e.weight = 0.0f;
                    e.sky = glm::vec3(0.0f);
                    if (cosine > 0.0f) {
                        const float exponent = rays_->MaterialOf(tri).phongExponent;
                        e.weight = (exponent + 2.0f) / (exponent + 1.0f) * cosine;
                        e.hit = Cast(y, wi);
                        ++count;
                        if (e.hit.triangle == kEscaped && scene_.environment.Active())
                            e.sky = scene_.environment.Radiance(wi);
                    }
                }
                // The punctual lights it sees: kept where their segments pass by what moved.
                const size_t at = seen.size();
                seen.resize(at + words, 0u);
                count += See(y, tris[tri].normal, &seen[at], reuse ? &oldSeen[k * words] : nullptr,
                             moved);
                lobes.push_back(e);
            }
            lobes_[t].assign(lobes.begin(), lobes.end());
            seen_[t].assign(seen.begin(), seen.end());
        }
        traced += count;
    });
    raysRetraced_ += moved ? traced.load() : 0;
    fresh_ = false;
    lightsFresh_ = false;
    msTrace_ += Ms(start);
}

void GatherStage::PlaceGlints() {
    glossyTriangles_.clear();
    glossyCdf_.clear();
    const auto& tris = rays_->Triangles();
    glintDensity_.assign(tris.size(), 0.0f);
    if (!glossy_ || scene_.lights.empty()) return;
    double total = 0.0;
    for (uint32_t i = 0; i < tris.size(); ++i) {
        const Material& m = rays_->MaterialOf(i);
        if (!m.Glossy()) continue;
        const double w = double(tris[i].area) * Luminance(m.specular);
        if (!(w > 0.0)) continue;
        total += w;
        glossyTriangles_.push_back(i);
        glossyCdf_.push_back(total);
    }
    // Area density of a glint at a point of triangle i: (w_i / total) / area_i.
    for (uint32_t i : glossyTriangles_)
        glintDensity_[i] = static_cast<float>(Luminance(rays_->MaterialOf(i).specular) / total);
}

float GatherStage::GlintDensity(uint32_t tri) const {
    return tri < glintDensity_.size() ? glintDensity_[tri] : 0.0f;
}

void GatherStage::TraceGlints(const Moved* moved) {
    if (glossyTriangles_.empty() || targets_.empty()) {
        glints_.assign(targets_.size(), {});
        glintSeen_.assign(targets_.size(), {});
        return;
    }
    auto start = std::chrono::steady_clock::now();
    const int count = GlintCount(), words = LightWords();
    const auto& tris = rays_->Triangles();
    const Surfels& surfels = inner_->GetSurfels();
    glints_.resize(targets_.size());
    glintSeen_.resize(targets_.size());
    std::atomic<size_t> traced{0};
    tbb::parallel_for(tbb::blocked_range<size_t>(0, targets_.size(), 16), [&](const auto& range) {
        size_t rays = 0;
        for (size_t t = range.begin(); t != range.end(); ++t) {
            const uint32_t i = targets_[t];
            const glm::vec3 x = points_[i] + rays_->Epsilon() * surfels.normals[i];
            std::vector<Glint>& glints = glints_[t];
            std::vector<uint32_t>& seen = glintSeen_[t];
            const bool all = !moved || moved->surfels[i] || glints.size() != size_t(count);
            if (all) {
                // Stratified over the cumulative weights, uniform on each triangle.
                glints.resize(count);
                Pcg32 rng(settings_.seed, kGlintStream + t);
                for (int k = 0; k < count; ++k) {
                    const double pick = (k + rng.Uniform()) / count * glossyCdf_.back();
                    const size_t j = std::min<size_t>(
                        std::upper_bound(glossyCdf_.begin(), glossyCdf_.end(), pick) -
                            glossyCdf_.begin(),
                        glossyCdf_.size() - 1);
                    const float r1 = std::sqrt(rng.Uniform()), r2 = rng.Uniform();
                    glints[k] = {glossyTriangles_[j], Quantise(r1 * (1.0f - r2)), Quantise(r1 * r2),
                                 0u};
                }
                seen.assign(size_t(count) * words, 0u);
            }
            for (int k = 0; k < count; ++k) {
                Glint& g = glints[k];
                const RayTriangle& tri = tris[g.triangle];
                const glm::vec3 y =
                    HitPoint(Hit{g.triangle, g.u, g.v}) + rays_->Epsilon() * tri.normal;
                const bool moves = !all && moved->Touches(*rays_, g.triangle);
                // Whether the target sees the glint's front.
                if (all || moves || moved->Meets(x, y - x, 1.0f)) {
                    const glm::vec3 d = y - x;
                    g.seen = glm::dot(surfels.normals[i], d) > 0.0f &&
                             glm::dot(tri.normal, d) < 0.0f && !rays_->Occluded(x, d);
                    ++rays;
                }
                uint32_t* bits = &seen[k * words];
                rays += See(y, tri.normal, bits, all || moves ? nullptr : bits, moved);
            }
        }
        traced += rays;
    });
    raysRetraced_ += moved ? traced.load() : 0;
    fresh_ = false;
    lightsFresh_ = false;
    msTrace_ += Ms(start);
}

size_t GatherStage::See(const glm::vec3& y, const glm::vec3& n, uint32_t* bits, const uint32_t* old,
                        const Moved* moved, const std::vector<uint8_t>* which) const {
    size_t rays = 0;
    for (size_t l = 0; l < scene_.lights.size(); ++l) {
        const uint32_t bit = 1u << (l % 32);
        uint32_t& word = bits[l / 32];
        const LightArrival a = PunctualArrival(scene_.lights[l], y, n, diameter_);
        const bool again =
            !old || (which && (*which)[l]) || (moved && a.reaches && moved->Meets(y, a.span, 1.0f));
        if (!again) {
            word = (word & ~bit) | (old[l / 32] & bit);
            continue;
        }
        word &= ~bit;
        if (!a.reaches) continue;
        ++rays;
        if (!rays_->Occluded(y, a.span)) word |= bit;
    }
    return rays;
}

void GatherStage::SeeLights(const std::vector<uint8_t>& which) {
    if (!glossy_ || targets_.empty()) return;
    const int n = settings_.gatherRays, words = LightWords();
    const auto& tris = rays_->Triangles();
    // Every light when `which` is empty (their count changed: the words are laid out anew).
    const std::vector<uint8_t>* marked = which.empty() ? nullptr : &which;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, targets_.size(), 16), [&](const auto& range) {
        for (size_t t = range.begin(); t != range.end(); ++t) {
            std::vector<uint32_t>& seen = seen_[t];
            if (!marked) seen.assign(lobes_[t].size() * words, 0u);
            for (size_t k = 0; k < lobes_[t].size(); ++k) {
                const Hit& h = hits_[t * n + lobes_[t][k].ray];
                const glm::vec3& ny = tris[h.triangle & kIndex].normal;
                uint32_t* bits = &seen[k * words];
                See(HitPoint(h) + rays_->Epsilon() * ny, ny, bits, marked ? bits : nullptr, nullptr,
                    marked);
            }
            if (t >= glints_.size()) continue;
            std::vector<uint32_t>& glintSeen = glintSeen_[t];
            if (!marked) glintSeen.assign(glints_[t].size() * words, 0u);
            for (size_t k = 0; k < glints_[t].size(); ++k) {
                const Glint& g = glints_[t][k];
                const glm::vec3& ny = tris[g.triangle].normal;
                uint32_t* bits = &glintSeen[k * words];
                See(HitPoint(Hit{g.triangle, g.u, g.v}) + rays_->Epsilon() * ny, ny, bits,
                    marked ? bits : nullptr, nullptr, marked);
            }
        }
    });
    fresh_ = false;
    lightsFresh_ = false;
}

void GatherStage::Sky() {
    const int n = settings_.gatherRays, m = SecondRays();
    sky_.assign(targets_.size(), glm::vec3(0.0f));
    secondSky_.assign(secondStart_.back(), glm::vec3(0.0f));
    if (!scene_.environment.Active()) {
        for (auto& lobes : lobes_)
            for (LobeHit& e : lobes) e.sky = glm::vec3(0.0f);
        return;
    }
    tbb::parallel_for(tbb::blocked_range<size_t>(0, targets_.size(), 64), [&](const auto& range) {
        for (size_t t = range.begin(); t != range.end(); ++t) {
            glm::vec3 sum(0.0f);
            size_t k = 0;  // this target's short hits so far
            for (int r = 0; r < n; ++r) {
                const Hit& h = hits_[t * n + r];
                if (h.triangle == kEscaped) sum += scene_.environment.Radiance(Direction(t, r));
                if (!Front(h) || !(h.triangle & kShort)) continue;
                glm::vec3 second(0.0f);
                for (int j = 0; j < m; ++j)
                    if (second_[t][k * m + j].triangle == kEscaped)
                        second += scene_.environment.Radiance(
                            SecondDirection(t, r, h.triangle & kIndex, j));
                secondSky_[secondStart_[t] + k++] = second * (kPi / m);
            }
            sky_[t] = sum * (kPi / n);
            for (LobeHit& e : lobes_[t]) {
                if (e.hit.triangle != kEscaped) continue;
                float cosine;
                e.sky = scene_.environment.Radiance(LobeDirection(t, e.ray, e.from, cosine));
            }
        }
    });
    fresh_ = false;
}

glm::vec3 GatherStage::LobeLight(size_t entry, uint32_t tri, const glm::vec3& wo,
                                 const glm::vec3& y, const std::vector<uint32_t>& seen) const {
    const glm::vec3& ny = rays_->Triangles()[tri].normal;
    const Material& mat = rays_->MaterialOf(tri);
    const glm::vec3 mirror = 2.0f * glm::dot(ny, wo) * ny - wo;
    const float norm = (mat.phongExponent + 2.0f) / (2.0f * kPi);
    const int words = LightWords();
    glm::vec3 sum(0.0f);
    for (size_t l = 0; l < scene_.lights.size(); ++l) {
        if (!(seen[entry * words + l / 32] & (1u << (l % 32)))) continue;
        const LightArrival a = PunctualArrival(scene_.lights[l], y, ny, diameter_);
        const float c = glm::dot(mirror, a.toLight);
        if (a.reaches && c > 0.0f) sum += a.irradiance * (norm * std::pow(c, mat.phongExponent));
    }
    return sum;
}

void GatherStage::LobeLights() {
    const int n = settings_.gatherRays;
    const auto& tris = rays_->Triangles();
    const Surfels& s = inner_->GetSurfels();
    lobeLight_.assign(targets_.size(), glm::vec3(0.0f));
    lightsFresh_ = true;
    if (scene_.lights.empty() || !glossy_) return;
    const float glints = static_cast<float>(GlintCount());
    tbb::parallel_for(tbb::blocked_range<size_t>(0, targets_.size(), 64), [&](const auto& range) {
        for (size_t t = range.begin(); t != range.end(); ++t) {
            const glm::vec3& normal = s.normals[targets_[t]];
            const glm::vec3 x = points_[targets_[t]] + rays_->Epsilon() * normal;
            // The gather rays' glossy hits y: F0 (n + 2)/(2π) cosⁿθ_r · E_l(y) over the lights
            // y sees, weighed against the glints drawing the same point (power heuristic).
            glm::vec3 sum(0.0f);
            const std::vector<LobeHit>& lobes = lobes_[t];
            for (size_t q = 0; q < lobes.size(); ++q) {
                const Hit& h = hits_[t * n + lobes[q].ray];
                const uint32_t tri = h.triangle & kIndex;
                const glm::vec3& ny = tris[tri].normal;
                const glm::vec3 y = HitPoint(h) + rays_->Epsilon() * ny;
                const glm::vec3 d = Direction(t, lobes[q].ray);
                float weight = 1.0f;
                if (!glints_.empty() && !glints_[t].empty()) {
                    const glm::vec3 span = y - x;
                    const float dist2 = glm::dot(span, span), cy = -glm::dot(ny, d);
                    const float cosine = n * glm::dot(normal, d) / kPi;
                    const float area = cy > 0.0f ? glints * GlintDensity(tri) * dist2 / cy : 0.0f;
                    weight = cosine * cosine / (cosine * cosine + area * area);
                }
                sum +=
                    rays_->MaterialOf(tri).specular * LobeLight(q, tri, -d, y, seen_[t]) * weight;
            }
            // The glints the target sees: w_a · L · cosθ_x / (K p_a), p_a the glints' density
            // as a solid angle, L the punctual lights through the glint's lobe.
            glm::vec3 glinted(0.0f);
            for (size_t k = 0; t < glints_.size() && k < glints_[t].size(); ++k) {
                const Glint& g = glints_[t][k];
                if (!g.seen) continue;
                const glm::vec3& ny = tris[g.triangle].normal;
                const glm::vec3 y = HitPoint(Hit{g.triangle, g.u, g.v}) + rays_->Epsilon() * ny;
                const glm::vec3 span = y - x;
                const float dist2 = glm::dot(span, span);
                const glm::vec3 w = span / std::sqrt(dist2);
                const float cx = glm::dot(normal, w), cy = -glm::dot(ny, w);
                if (!(cx > 0.0f && cy > 0.0f && dist2 > 0.0f)) continue;
                const float density = GlintDensity(g.triangle) * dist2 / cy;
                const float area = glints * density, cosine = n * cx / kPi;
                const float weight = area * area / (area * area + cosine * cosine);
                const glm::vec3 light = LobeLight(k, g.triangle, -w, y, glintSeen_[t]);
                glinted += rays_->MaterialOf(g.triangle).specular * light *
                           (weight * cx / (glints * density));
            }
            lobeLight_[t] = sum * (kPi / n) + glinted;
        }
    });
}

void GatherStage::Evaluate() {
    auto start = std::chrono::steady_clock::now();
    indirect_ = inner_->SurfelIrradiance(Channel::kIndirect);
    direct_ = inner_->SurfelIrradiance(Channel::kDirect);
    const Surfels& s = inner_->GetSurfels();
    // The radiance each surfel reflects (and emits, where the solver carries the emission):
    // L = ρ/π · E over the surfel's whole irradiance.
    std::vector<glm::vec3> radiance(s.size());
    for (uint32_t i = 0; i < s.size(); ++i) {
        const Material& m = scene_.materials[scene_.primitives[surfelPrimitive_[i]].material];
        radiance[i] = m.albedo / kPi * (indirect_[i] + direct_[i]);
        if (shot_.empty()) radiance[i] += m.emission;
    }
    // Values per surfel interpolated at a hit.
    auto at = [&](const std::vector<glm::vec3>& f, const Hit& h) {
        const glm::uvec3& c = rays_->Corners(h.triangle & kIndex);
        const float u = h.u * (1.0f / 65535.0f), v = h.v * (1.0f / 65535.0f);
        return (1.0f - u - v) * f[c.x] + u * f[c.y] + v * f[c.z];
    };
    const int n = settings_.gatherRays, m = SecondRays();
    // What a lobe ray meets sends towards it: emission (no first shot weighs these) and
    // (ρ + F0)/π · E, a glossy surface's lobe taken as if it spread its light evenly (one
    // glossy bounce is followed, not two).
    std::vector<glm::vec3> lobeRadiance;
    if (glossy_) {
        lobeRadiance.resize(s.size());
        for (uint32_t i = 0; i < s.size(); ++i) {
            const Material& m = scene_.materials[scene_.primitives[surfelPrimitive_[i]].material];
            const glm::vec3 rho = m.albedo + (m.Glossy() ? m.specular : glm::vec3(0.0f));
            lobeRadiance[i] = rho / kPi * (indirect_[i] + direct_[i]) + m.emission;
        }
    }
    if (!lightsFresh_ || lobeLight_.size() != targets_.size()) LobeLights();
    std::vector<glm::vec3> gathered(targets_.size());
    tbb::parallel_for(tbb::blocked_range<size_t>(0, targets_.size(), 64), [&](const auto& range) {
        for (size_t t = range.begin(); t != range.end(); ++t) {
            glm::vec3 sum(0.0f);
            size_t k = 0;  // this target's short hits so far
            for (int r = 0; r < n; ++r) {
                const Hit& h = hits_[t * n + r];
                if (!Front(h)) continue;
                if (!(h.triangle & kShort)) {
                    sum += at(radiance, h);
                    continue;
                }
                // A short hit: its irradiance gathered again, E = first shot + punctual lights
                // (interpolated) + π/M Σ L over its secondary rays.
                glm::vec3 e = at(direct_, h) + secondSky_[secondStart_[t] + k];
                if (!shot_.empty()) e += at(shot_, h);
                glm::vec3 second(0.0f);
                for (int j = 0; j < m; ++j) {
                    const Hit& h2 = second_[t][k * m + j];
                    if (Front(h2)) second += at(radiance, h2);
                }
                e += second * (kPi / m);
                const Material& mat = rays_->MaterialOf(h.triangle & kIndex);
                sum += mat.albedo / kPi * e + (shot_.empty() ? mat.emission : glm::vec3(0.0f));
                ++k;
            }
            // Glossy hits: what their lobes reflect towards the target, F0 times the lobe
            // ray's estimate (the radiance where it lands, the sky where it escapes); the
            // punctual lights seen through the lobes are in lobeLight_ (LobeLights).
            for (const LobeHit& e : lobes_[t]) {
                const Material& mat = rays_->MaterialOf(hits_[t * n + e.ray].triangle & kIndex);
                sum += mat.specular * (Front(e.hit) ? at(lobeRadiance, e.hit) : e.sky) * e.weight;
            }
            gathered[t] = sum * (kPi / n) + sky_[t] + lobeLight_[t];
        }
    });
    for (size_t t = 0; t < targets_.size(); ++t) {
        const uint32_t i = targets_[t];
        indirect_[i] = (shot_.empty() ? glm::vec3(0.0f) : shot_[i]) + gathered[t];
    }
    fresh_ = true;
    msEvaluate_ = Ms(start);
}

void GatherStage::Iterate(int n) {
    inner_->Iterate(n);
    fresh_ = false;
}

std::vector<glm::vec3> GatherStage::SurfelIrradiance(Channel channel) {
    if (targets_.empty()) return inner_->SurfelIrradiance(channel);
    if (!fresh_) Evaluate();
    if (channel == Channel::kIndirect) return indirect_;
    if (channel == Channel::kDirect) return direct_;
    std::vector<glm::vec3> total(indirect_.size());
    for (size_t i = 0; i < total.size(); ++i) total[i] = indirect_[i] + direct_[i];
    return total;
}

void GatherStage::UpdateMaterials(const Scene& scene) {
    // Per primitive: whether its emission changed, and whether it emits where it did not
    // when the rays were traced (the emitters' sampling does not know it: trace again).
    bool emissionChanged = false, newEmitter = false;
    for (size_t p = 0; p < scene.primitives.size() && p < scene_.primitives.size(); ++p) {
        const glm::vec3& was = scene_.materials[scene_.primitives[p].material].emission;
        const glm::vec3& now = scene.materials[scene.primitives[p].material].emission;
        emissionChanged = emissionChanged || was != now;
        newEmitter = newEmitter || (glm::any(glm::greaterThan(now, glm::vec3(0.0f))) &&
                                    rays_->EmitterSlot(static_cast<uint32_t>(p)) < 0);
    }
    // Whether a lobe changed its shape (exponent), or a material turned glossy or diffuse:
    // the lobe rays go elsewhere.
    bool lobesChanged = scene.materials.size() != scene_.materials.size();
    // Whether the glints' density changed (a glossy material's F0, or which are glossy).
    bool glintsChanged = lobesChanged;
    for (size_t p = 0; p < scene.primitives.size() && p < scene_.primitives.size(); ++p) {
        const Material& a = scene.materials[scene.primitives[p].material];
        const Material& b = scene_.materials[scene_.primitives[p].material];
        lobesChanged = lobesChanged || a.phongExponent != b.phongExponent;
        glintsChanged =
            glintsChanged || a.Glossy() != b.Glossy() || (a.Glossy() && a.specular != b.specular);
    }
    // Only what a material edit changes (no vertex arrays copied on an edit). The ray scene
    // reads materials through the primitives (RayScene::MaterialOf), so it stays valid.
    scene_.materials = scene.materials;
    for (size_t p = 0; p < scene.primitives.size() && p < scene_.primitives.size(); ++p)
        scene_.primitives[p].material = scene.primitives[p].material;
    inner_->UpdateMaterials(scene);
    fresh_ = false;
    lightsFresh_ = false;
    // A scene that turned glossy takes the first shot back from the solver (its lobes would
    // miss it), one that turned diffuse hands it over.
    const bool handed = HandsOver();
    glossy_ = AnyGlossy(scene_.materials);
    if (HandsOver() != handed && !shot_.empty())
        inner_->SetEmitterDirect(HandsOver() ? shot_ : std::vector<glm::vec3>());
    if (lobesChanged && !targets_.empty()) {
        TraceLobes();
        Sky();
    }
    if ((lobesChanged || glintsChanged) && !targets_.empty()) {
        PlaceGlints();
        TraceGlints();
    }
    if (!emissionChanged || settings_.emitterRays <= 0 || shot_.empty()) return;
    // The first shot and the gather's emitter hits are linear in each emitting primitive's
    // emission: re-weighted from their coefficients, unless an emitter is new.
    auto start = std::chrono::steady_clock::now();
    const size_t slots = rays_->EmitterPrimitives().size();
    if (!newEmitter && shooter_ && shooter_->Reevaluate(*rays_, shot_) &&
        (targets_.empty() || emitterCoef_.size() == targets_.size() * slots)) {
        std::vector<glm::vec3> le(slots);
        for (size_t k = 0; k < slots; ++k)
            le[k] = scene_.materials[scene_.primitives[rays_->EmitterPrimitives()[k]].material]
                        .emission;
        for (size_t t = 0; t < targets_.size(); ++t) {
            emitterHits_[t] = glm::vec3(0.0f);
            for (size_t k = 0; k < slots; ++k)
                emitterHits_[t] += le[k] * emitterCoef_[t * slots + k];
            shot_[targets_[t]] += emitterHits_[t];
        }
        if (HandsOver()) inner_->SetEmitterDirect(shot_);
        msShot_ = Ms(start);
        return;
    }
    rays_ = std::make_unique<RayScene>(scene_, inner_->GetSurfels());
    if (!targets_.empty()) {
        Trace();
        TraceLobes();
        PlaceGlints();
        TraceGlints();
        Sky();
    }
    Shoot();
}

void GatherStage::Relit(const std::vector<PunctualLight>& before) {
    // The punctual lights that moved or turned: the lobe hits' view of them is traced again
    // (every light when their count changed). Colour, intensity, cone and range are re-read.
    const std::vector<PunctualLight>& now = scene_.lights;
    std::vector<uint8_t> placed(now.size(), 0);
    bool any = now.size() != before.size();
    for (size_t l = 0; l < now.size() && l < before.size(); ++l) {
        placed[l] = now[l].type != before[l].type || now[l].position != before[l].position ||
                    now[l].direction != before[l].direction;
        any = any || placed[l];
    }
    if (any) SeeLights(now.size() != before.size() ? std::vector<uint8_t>() : placed);
    if (now.empty() != before.empty() && !targets_.empty()) {  // glints wanted, or not
        PlaceGlints();
        TraceGlints();
    }
}

void GatherStage::UpdateLights(const Scene& scene) {
    const bool sky = !SameEnvironment(scene.environment, scene_.environment);
    const std::vector<PunctualLight> before = scene_.lights;
    scene_.lights = scene.lights;
    scene_.environment = scene.environment;
    inner_->UpdateLights(scene);
    Relit(before);
    if (sky && !targets_.empty()) Sky();
    fresh_ = false;
    lightsFresh_ = false;
}

std::string GatherStage::UpdateGeometry(const Scene& scene) {
    const std::vector<glm::vec3> before = inner_->GetSurfels().positions;
    const std::vector<glm::vec3> normalsBefore = inner_->GetSurfels().normals;
    const std::vector<PunctualLight> lightsBefore = scene_.lights;
    std::string done = inner_->UpdateGeometry(scene);
    scene_ = scene;
    const Surfels& s = inner_->GetSurfels();
    // What moved, and where it was and is: only the rays near it are traced again.
    Moved moved;
    moved.surfels.assign(s.size(), 0);
    Bounds was, is;
    bool emitterMoved = false;
    for (size_t i = 0; i < s.size(); ++i) {
        if (before[i] == s.positions[i] && normalsBefore[i] == s.normals[i]) continue;
        moved.surfels[i] = 1;
        was.Add(before[i]);
        is.Add(s.positions[i]);
        const uint32_t m = scene_.primitives[surfelPrimitive_[i]].material;
        emitterMoved = emitterMoved ||
                       glm::any(glm::greaterThan(scene_.materials[m].emission, glm::vec3(0.0f)));
    }
    // Rays that graze a moved surface's old place still count: the boxes are padded.
    const glm::vec3 pad(4.0f * rays_->Epsilon());
    for (Bounds* b : {&was, &is})
        if (!b->Empty()) moved.boxes.push_back({b->lo - pad, b->hi + pad});
    rays_->Update(s);
    diameter_ = scene_.Diameter();
    Place();
    raysRetraced_ = 0;
    // A moved emitter moves the points the shadow rays aim at: everything is traced again.
    const Moved* partial = emitterMoved ? nullptr : &moved;
    if (!targets_.empty()) {
        Trace(partial);
        TraceLobes(partial);
        PlaceGlints();
        TraceGlints(partial);
        Relit(lightsBefore);  // lights placed by a moved node
        Sky();
    }
    Shoot(partial);
    fresh_ = false;
    lightsFresh_ = false;
    return done;
}

std::string GatherStage::WarmStart(Solver& previous, const SurfelCarry& carry) {
    auto* before = dynamic_cast<GatherStage*>(&previous);
    std::string note = inner_->WarmStart(before ? *before->inner_ : previous, carry);
    fresh_ = false;
    return note;
}

SolverStats GatherStage::Stats() const {
    SolverStats s = inner_->Stats();
    s.emitterRays = shot_.empty() ? 0 : settings_.emitterRays;
    s.msEmitterDirect = msShot_;
    s.gatherRays = targets_.empty() ? 0 : settings_.gatherRays;
    s.gatherTargets = targets_.size();
    s.msGatherTrace = msTrace_;
    s.msGatherEvaluate = msEvaluate_;
    s.gatherRaysRetraced = raysRetraced_;
    s.gatherTraces = traces_;
    s.gatherDevice = "cpu (Embree)";
    return s;
}

GatherSettings GatherParts(const Scene& scene, const GatherSettings& settings,
                           std::vector<std::string>* notes) {
    CheckGatherRays(settings.emitterRays, "the first shot (emitter direct light)");
    CheckGatherRays(settings.gatherRays, "the final gather");
    const bool glossy = AnyGlossy(scene.materials);
    const bool emitters = std::any_of(
        scene.materials.begin(), scene.materials.end(),
        [](const Material& m) { return glm::any(glm::greaterThan(m.emission, glm::vec3(0.0f))); });
    GatherSettings s = settings;
    auto note = [&](const std::string& line) {
        if (notes) notes->push_back(line);
    };
    if (s.emitterRays > 0 && !emitters) {
        s.emitterRays = 0;
        note("no first shot: the scene has no emitting surfaces");
    } else if (s.emitterRays > 0 && glossy) {
        note(
            "the first shot serves the output vertices and the gather, not the solver: with "
            "glossy materials the solver carries the emission (its lobes reflect it)");
    }
    return s;
}

namespace {

// `solver` behind a gather stage with `parts` (GatherParts has checked them).
std::unique_ptr<Solver> Behind(std::unique_ptr<Solver> solver, const Scene& scene,
                               const GatherSettings& parts, std::vector<std::string>* notes) {
    if (parts.emitterRays == 0 && parts.gatherRays == 0) return solver;
    if (notes && parts.emitterRays > 0 && !AnyGlossy(scene.materials) &&
        !solver->TakesEmitterDirect())
        notes->push_back(
            "the first shot serves the output vertices and the gather, not the "
            "solver: solver '" +
            solver->Stats().solver + "' carries the emission itself");
    return std::make_unique<GatherStage>(std::move(solver), scene, parts);
}

}  // namespace

std::unique_ptr<Solver> WithGather(std::unique_ptr<Solver> solver, const Scene& scene,
                                   const GatherSettings& settings,
                                   std::vector<std::string>* notes) {
    return Behind(std::move(solver), scene, GatherParts(scene, settings, notes), notes);
}

std::unique_ptr<Solver> CreateGatheredSolver(const Scene& scene, SolverSettings settings,
                                             const GatherSettings& gather,
                                             const ProgressFn& progress,
                                             std::vector<std::string>* notes) {
    const GatherSettings parts = GatherParts(scene, gather, notes);
    settings.behindGather = parts.gatherRays > 0 && !AnyGlossy(scene.materials);
    std::unique_ptr<Solver> solver = CreateSolver(scene, settings, progress);
    if (progress && (parts.emitterRays > 0 || parts.gatherRays > 0))
        progress("gather: tracing", 0.0);
    return Behind(std::move(solver), scene, parts, notes);
}

}  // namespace penumbra
