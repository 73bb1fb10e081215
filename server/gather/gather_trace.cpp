// The gather stage's rays: the first shot, the estimate points, the gather rays and their
// secondary gathers at short hits, and the sky they see (gather_stage.h).
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
#include "gather/gather_detail.h"
#include "gather/gather_stage.h"
#include "gpu/ray_tracer.h"
#include "rays/sampling.h"

namespace penumbra {

using namespace gather_detail;

void GatherStage::Shoot(const Moved* moved, bool emitterPart) {
    if (settings_.emitterRays <= 0) return;
    auto start = std::chrono::steady_clock::now();
    const Surfels& s = inner_->GetSurfels();
    ++traces_;
    if (emitters_ && emitterPart) {
        if (!moved || !shooter_) {
            emitterShot_ =
                NewShooter().Trace(*rays_, points_, s.normals, CosineAtTargets(), shotSplit_);
            shotNext_ = SIZE_MAX;  // whole: a shot in parts under way is done
        } else {
            size_t traced = 0;
            emitterShot_ = shooter_->Retrace(*rays_, points_, s.normals, moved->surfels,
                                             moved->boxes, &traced);
            raysRetraced_ += traced;
        }
        for (size_t t = 0; t < targets_.size(); ++t) emitterShot_[targets_[t]] += emitterHits_[t];
    }
    if (skyParts_.Split()) {
        const float reach = 2.0f * diameter_;
        if (!moved || !sun_) {
            sun_ = std::make_unique<SunDirect>(SunRays(), settings_.seed);
            sunShot_ = sun_->Trace(*rays_, skyParts_, points_, s.normals, reach);
        } else {
            size_t traced = 0;
            sunShot_ = sun_->Retrace(*rays_, skyParts_, points_, s.normals, reach, moved->surfels,
                                     moved->boxes, &traced);
            raysRetraced_ += traced;
        }
    } else {
        sun_.reset();
        sunShot_.clear();
    }
    Combine();
    msShot_ = MsSince(start);
}

EmitterDirectSettings GatherStage::ShotSettings() const {
    EmitterDirectSettings es;
    es.rays = settings_.emitterRays;
    es.seed = settings_.seed;
    return es;
}

EmitterDirect& GatherStage::NewShooter() {
    shooter_ = std::make_unique<EmitterDirect>(ShotSettings());
    return *shooter_;
}

void GatherStage::SplitShot() {
    shotSplit_.clear();
    if (settings_.emitterRays <= 0) return;
    shotSplit_ = EmitterCosineRays(*rays_, points_, inner_->GetSurfels().normals, ShotSettings());
}

std::vector<int> GatherStage::CosineAtTargets() const {
    // At the targets the gather's rays join the shot's own cosine rays (emitterHits_).
    std::vector<int> extra(inner_->GetSurfels().size(), 0);
    for (uint32_t i : targets_) extra[i] = settings_.gatherRays;
    return extra;
}

void GatherStage::StartShotParts() {
    const Surfels& s = inner_->GetSurfels();
    targetOf_.assign(s.size(), -1);
    for (size_t t = 0; t < targets_.size(); ++t) targetOf_[targets_[t]] = static_cast<int32_t>(t);
    NewShooter().Start(*rays_, points_, s.normals, CosineAtTargets(), shotSplit_);
    emitterShot_.resize(s.size(), glm::vec3(0.0f));  // the old place's light until traced
    shotNext_ = 0;
    ShotPart();
}

void GatherStage::ShotPart() {
    if (!ShotPending()) return;
    auto start = std::chrono::steady_clock::now();
    const Surfels& s = inner_->GetSurfels();
    // Blocks of surfels until the part's time is spent (at least one block).
    constexpr size_t kBlock = 256;
    do {
        const size_t first = shotNext_, last = std::min(points_.size(), first + kBlock);
        shooter_->TracePart(*rays_, points_, s.normals, first, last, emitterShot_);
        for (size_t i = first; i < last; ++i)
            if (targetOf_[i] >= 0) emitterShot_[i] += emitterHits_[size_t(targetOf_[i])];
        shotNext_ = last;
    } while (ShotPending() && MsSince(start) < settings_.shotPartMs);
    Combine();
    msShot_ = MsSince(start);
}

void GatherStage::Combine() {
    const size_t n = inner_->GetSurfels().size();
    shot_.assign(n, glm::vec3(0.0f));
    if (emitterShot_.size() == n)
        for (size_t i = 0; i < n; ++i) shot_[i] += emitterShot_[i];
    if (sunShot_.size() == n)
        for (size_t i = 0; i < n; ++i) shot_[i] += sunShot_[i];
    if (HandsOver()) inner_->SetEmitterDirect(shot_);
    fresh_ = false;
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
    return Cached(h, d);
}

GatherStage::Hit GatherStage::Cached(const RayHit& h, const glm::vec3& d) const {
    return h.hit ? Found(h.triangle, h.u, h.v, d) : Hit{kEscaped, 0, 0};
}

GatherStage::Hit GatherStage::Found(uint32_t tri, float u, float v, const glm::vec3& d) const {
    const uint32_t back = glm::dot(rays_->Triangles()[tri].normal, d) >= 0.0f ? kBack : 0u;
    return Hit{tri | back, Quantise(u), Quantise(v)};
}

bool GatherStage::TraceOnGpu(std::vector<float>& distances) {
    const int n = settings_.gatherRays;
    const Surfels& surfels = inner_->GetSurfels();
    const auto& tris = rays_->Triangles();
    std::vector<gpu::TraceRay> rays(targets_.size() * n);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, targets_.size(), 64), [&](const auto& range) {
        for (size_t t = range.begin(); t != range.end(); ++t) {
            const uint32_t i = targets_[t];
            const glm::vec3 o = points_[i] + rays_->Epsilon() * surfels.normals[i];
            for (int r = 0; r < n; ++r) {
                gpu::TraceRay& ray = rays[t * n + r];
                ray.origin = o;
                ray.dir = Direction(t, r);
            }
        }
    });
    std::vector<gpu::TraceHit> found;
    try {
        tracer_->Build(rays_->Vertices());
        found = tracer_->Trace(rays);
    } catch (const Error& e) {
        // A device that fails mid-way (lost, out of memory): Embree from now on, and why.
        tracerNote_ = e.what();
        tracer_.reset();
        return false;
    }
    distances.resize(found.size());
    tbb::parallel_for(size_t(0), found.size(), [&](size_t k) {
        const gpu::TraceHit& h = found[k];
        if (h.triangle == gpu::TraceHit::kMissed || h.triangle >= tris.size()) {
            hits_[k] = Hit{kEscaped, 0, 0};
            distances[k] = std::numeric_limits<float>::infinity();
            return;
        }
        hits_[k] = Found(h.triangle, h.u, h.v, rays[k].dir);
        distances[k] = h.t;
    });
    return true;
}

// One thread's tracing of its targets' gather rays and secondaries (Trace): the cones and
// patterns a move's tests need, and the packets the CPU traces.
struct GatherStage::TargetTracer {
    GatherStage& stage;
    const Moved* moved;  // null: every ray is traced
    const bool onGpu;    // the gather rays were traced on the GPU (`distances` along them)
    const std::vector<float>& distances;
    const float shortHit;  // a hit nearer than this is gathered again
    const int n, m;        // gather rays a target, secondaries a short hit
    size_t count = 0;      // rays traced
    std::vector<BallCone> cones, wide, secondCones;
    std::vector<CosineCone> pattern, secondPattern;
    // Per normal met at this target's short hits, its secondaries' pattern.
    std::vector<std::pair<glm::vec3, std::vector<CosineCone>>> patterns;
    std::vector<uint8_t> kept, was;
    std::vector<Hit> relaid;
    // The rays a target traces on the CPU go out in packets of 8 from its point, and a short
    // hit's from the hit (`packed` holds the answers of either).
    std::vector<RayHit> packed;
    std::vector<glm::vec3> through;  // the gather rays' transmittances, as `packed`
    std::vector<glm::vec3> dirs, secondDirs;
    std::vector<int> batch, secondBatch;
    size_t t = 0;    // the target being traced
    glm::vec3 o{0};  // its ray origin

    TargetTracer(GatherStage& stage, const Moved* moved, bool onGpu,
                 const std::vector<float>& distances, float shortHit)
        : stage(stage),
          moved(moved),
          onGpu(onGpu),
          distances(distances),
          shortHit(shortHit),
          n(stage.settings_.gatherRays),
          m(stage.SecondRays()),
          kept(n),
          was(n),
          packed(std::max(n, m)),
          through(std::max(n, m)),
          dirs(n),
          secondDirs(m) {}

    // After a move: whether a cached hit still holds (its ray starts on a surface that did
    // not move, ends on one that did not, and passes by where the moved ones were and are).
    // The segment is the one to the hit point (no direction needed, which costs more to make
    // again than the test), or the ray to infinity when it escaped; `cones` (one per box,
    // from the ray's origin) turn most segments away before the slab test.
    template <typename Direction>
    bool Holds(const glm::vec3& from, const std::vector<BallCone>& at, const Direction& direction,
               const Hit& h) const {
        const std::vector<Bounds>& boxes = moved->boxes;
        if (h.triangle == kEscaped) {
            const glm::vec3 d = direction();
            for (size_t k = 0; k < boxes.size(); ++k)
                if (at[k].MayMeet(d, true) &&
                    boxes[k].Meets(from, d, std::numeric_limits<float>::infinity()))
                    return false;
            return true;
        }
        if (moved->Touches(*stage.rays_, h.triangle & kIndex)) return false;
        const glm::vec3 span = stage.HitPoint(h) - from;
        for (size_t k = 0; k < boxes.size(); ++k)
            if (at[k].MayMeet(span) && boxes[k].Meets(from, span, 1.0f)) return false;
        return true;
    }
    // The cones from `from` towards the boxes (`grow`: each box's ball grown by that much),
    // and which points of a cosine pattern about `normal` can fall in one (CosineCone); false
    // when none can: no ray from `from` meets a box.
    bool ConesAt(const glm::vec3& from, const glm::vec3& normal, float grow,
                 std::vector<BallCone>& into, std::vector<CosineCone>& intoPattern) const {
        into.clear(), intoPattern.clear();
        bool any = false;
        for (const Bounds& b : moved->boxes) {
            Ball ball(b);
            ball.radius += grow;
            into.emplace_back(from, ball);
            const BallCone& c = into.back();
            intoPattern.push_back(c.Inside() ? CosineCone()
                                             : CosineCone(normal, c.Axis(), c.SinHalf()));
            any = any || !intoPattern.back().Empty();
        }
        return any;
    }
    static bool MayMeet(const std::vector<CosineCone>& in, const glm::vec2& u) {
        for (const CosineCone& c : in)
            if (c.MayContain(u)) return true;
        return false;
    }
    Hit& HitOf(int r) { return stage.hits_[t * n + r]; }
    bool IsShort(int r) {
        const Hit& h = HitOf(r);
        return Front(h) && (h.triangle & kShort);
    }

    // Target t's gather rays (those a move can have changed, or all) and then its
    // secondaries. Returns whether any gather ray was traced again.
    bool Trace(size_t target) {
        t = target;
        const Surfels& surfels = stage.inner_->GetSurfels();
        const uint32_t i = stage.targets_[t];
        o = stage.points_[i] + stage.rays_->Epsilon() * surfels.normals[i];
        const bool all = !moved || moved->surfels[i];
        // Nothing moved in front of it: every hit holds, its secondaries are checked.
        const bool clear = !all && !ConesAt(o, surfels.normals[i], 0.0f, cones, pattern);
        bool same = !all;  // its short hits are the rays they were
        bool touched = !moved;
        batch.clear();
        for (int r = 0; r < n; ++r) {
            const Hit before = all ? Hit{kEscaped, 0, 0} : HitOf(r);
            was[r] = Front(before) && (before.triangle & kShort);
            kept[r] = !all && (clear || !MayMeet(pattern, R2Point(stage.rotation_[t], r)) ||
                               Holds(
                                   o, cones, [&] { return stage.Direction(t, r); }, before));
            if (!kept[r] && !onGpu) {
                dirs[batch.size()] = stage.Direction(t, r);
                batch.push_back(r);
            }
        }
        stage.rays_->IntersectFrom(o, dirs.data(), batch.size(),
                                   std::numeric_limits<float>::infinity(), packed.data(),
                                   stage.through_.empty() ? nullptr : through.data());
        size_t next = 0;  // the next of `batch`
        for (int r = 0; r < n; ++r) {
            if (kept[r]) continue;
            Hit& hit = HitOf(r);
            float dist = std::numeric_limits<float>::infinity();
            if (onGpu) {
                dist = distances[t * n + r];
            } else {
                dist = packed[next].hit ? packed[next].t : dist;
                hit = stage.Cached(packed[next], dirs[next]);
                if (!stage.through_.empty()) stage.through_[t * n + r] = through[next];
                ++next;
            }
            ++count;
            touched = true;
            const bool isShort = Front(hit) && dist < shortHit;
            if (isShort) hit.triangle |= kShort;
            same = same && isShort == static_cast<bool>(was[r]);
        }
        Secondaries(same);
        return touched;
    }

    // A secondary ray from a short hit y (within shortHit of o) that meets a ball runs in a
    // direction inside o's cone towards that ball grown by shortHit (the parallel ray from o
    // passes within shortHit of where it does): the pattern about y's normal is made once per
    // normal the target's short hits have, from o.
    const std::vector<CosineCone>& PatternFor(const glm::vec3& normal) {
        // Bit for bit: a −0 in the normal turns the pattern's basis (CosineDirection).
        for (const auto& [nm, p] : patterns)
            if (std::memcmp(&nm, &normal, sizeof(glm::vec3)) == 0) return p;
        if (wide.empty()) ConesAt(o, normal, shortHit + stage.rays_->Epsilon(), wide, pattern);
        patterns.emplace_back(normal, std::vector<CosineCone>());
        for (const BallCone& c : wide)
            patterns.back().second.push_back(
                c.Inside() ? CosineCone() : CosineCone(normal, c.Axis(), c.SinHalf()));
        return patterns.back().second;
    }

    // Ray r's secondary gather into `out`: the cached one (`old`, null where the hit did not
    // hold) where each ray holds, traced again where not (out may be old).
    void GatherAgain(int r, const Hit* old, Hit* out) {
        const Hit& hit = HitOf(r);
        const uint32_t tri = hit.triangle & kIndex;
        const glm::vec3& normal = stage.rays_->Triangles()[tri].normal;
        const std::vector<CosineCone>* filter = old ? &PatternFor(normal) : nullptr;
        if (filter && std::all_of(filter->begin(), filter->end(),
                                  [](const CosineCone& c) { return c.Empty(); })) {
            if (out != old) std::copy(old, old + m, out);  // none can meet a box
            return;
        }
        const glm::vec3 y = stage.HitPoint(hit) + stage.rays_->Epsilon() * normal;
        const glm::vec2 rot = stage.SecondRotation(t, r);
        // Which rays hold (none without `old`); the others are traced again, in packets of 8
        // from y (the same hits as one at a time).
        bool near = false;  // secondCones made at y
        secondBatch.clear();
        for (int j = 0; j < m; ++j) {
            const glm::vec2 u = R2Point(rot, j);
            auto d2 = [&] { return CosineDirection(normal, u); };
            bool holding = old && !MayMeet(*filter, u);
            if (old && !holding) {
                if (!near) ConesAt(y, normal, 0.0f, secondCones, secondPattern);
                near = true;
                holding = Holds(y, secondCones, d2, old[j]);
            }
            if (holding) {
                out[j] = old[j];
            } else {
                secondDirs[secondBatch.size()] = d2();
                secondBatch.push_back(j);
            }
        }
        stage.rays_->IntersectFrom(y, secondDirs.data(), secondBatch.size(),
                                   std::numeric_limits<float>::infinity(), packed.data());
        for (size_t k = 0; k < secondBatch.size(); ++k)
            out[secondBatch[k]] = stage.Cached(packed[k], secondDirs[k]);
        count += secondBatch.size();
    }

    // Target t's secondaries: in place where its short hits are the same rays as before
    // (`same`), laid out anew where not.
    void Secondaries(bool same) {
        patterns.clear();
        wide.clear();
        std::vector<Hit>& block = stage.second_[t];
        if (same) {
            Hit* at = block.data();
            for (int r = 0; r < n; ++r)
                if (IsShort(r)) {
                    GatherAgain(r, kept[r] ? at : nullptr, at);
                    at += m;
                }
            return;
        }
        relaid.clear();
        size_t old = 0;  // its old secondaries (none when all are traced)
        for (int r = 0; r < n; ++r) {
            if (IsShort(r)) {
                relaid.resize(relaid.size() + m);
                GatherAgain(r, kept[r] ? block.data() + old : nullptr,
                            relaid.data() + relaid.size() - m);
            }
            if (was[r]) old += m;
        }
        block.assign(relaid.begin(), relaid.end());
    }
};

void GatherStage::Trace(const Moved* moved) {
    auto start = std::chrono::steady_clock::now();
    ++traces_;
    const int n = settings_.gatherRays, m = SecondRays();
    const float shortHit = kShortHit * inner_->Stats().elementSize;
    hits_.resize(targets_.size() * n);  // in place: a target's hits are read, then written
    if (rays_->Passing())
        through_.resize(targets_.size() * n, glm::vec3(1.0f));
    else
        through_.clear();
    // All of them at once on the GPU where there is one (then only the secondaries below).
    std::vector<float> gpuDistances;
    // The GPU's tracer knows no surface that passes light: those scenes trace with Embree.
    const bool onGpu = !moved && tracer_ && !rays_->Passing() && TraceOnGpu(gpuDistances);
    second_.resize(targets_.size());
    // Per target: a gather ray was traced again (its emitter hits are weighed again).
    std::vector<uint8_t> touched(targets_.size(), moved ? 0 : 1);
    std::atomic<size_t> traced{0};
    tbb::parallel_for(tbb::blocked_range<size_t>(0, targets_.size(), 16), [&](const auto& range) {
        TargetTracer tracer(*this, moved, onGpu, gpuDistances, shortHit);
        for (size_t t = range.begin(); t != range.end(); ++t) touched[t] = tracer.Trace(t) ? 1 : 0;
        traced += tracer.count;
    });
    secondStart_.assign(targets_.size() + 1, 0);
    for (size_t t = 0; t < targets_.size(); ++t)
        secondStart_[t + 1] = secondStart_[t] + static_cast<uint32_t>(second_[t].size() / m);
    traced += SeeShort(moved, touched);
    WeighEmitterHits(moved != nullptr, touched);
    raysRetraced_ += moved ? traced.load() : 0;
    fresh_ = false;
    lightsFresh_ = false;
    msTrace_ = MsSince(start);
}

void GatherStage::WeighEmitterHits(bool afterMove, const std::vector<uint8_t>& touched) {
    // The emitters the gather rays meet, weighted against the first shot's rays, as a
    // coefficient per emitting primitive: again at the targets with a ray traced again.
    const int n = settings_.gatherRays;
    const auto& tris = rays_->Triangles();
    const Surfels& surfels = inner_->GetSurfels();
    const size_t slots = rays_->EmitterPrimitives().size();
    if (!afterMove) {
        emitterHits_.assign(targets_.size(), glm::vec3(0.0f));
        emitterCoef_.assign(slots <= EmitterDirect::kMaxSlots ? targets_.size() * slots : 0,
                            glm::vec3(0.0f));
    }
    if (settings_.emitterRays <= 0 || slots == 0) return;
    PENUMBRA_CHECK_EQ(shotSplit_.size(), points_.size());
    tbb::parallel_for(tbb::blocked_range<size_t>(0, targets_.size(), 64), [&](const auto& range) {
        for (size_t t = range.begin(); t != range.end(); ++t) {
            if (!touched[t]) continue;
            const uint32_t i = targets_[t];
            const glm::vec3 o = points_[i] + rays_->Epsilon() * surfels.normals[i];
            emitterHits_[t] = glm::vec3(0.0f);
            glm::vec3* coef = emitterCoef_.empty() ? nullptr : &emitterCoef_[t * slots];
            if (coef) std::fill(coef, coef + slots, glm::vec3(0.0f));
            for (int r = 0; r < n; ++r) {
                const Hit& h = hits_[t * n + r];
                if (!Front(h) || !(rays_->AreaPdf(h.triangle & kIndex) > 0.0f)) continue;
                const uint32_t tri = h.triangle & kIndex;
                // Weighted against the shot's rays at this surfel, its split.
                const int cosine = shotSplit_[i];
                const float c =
                    EmitterHitWeight(*rays_, settings_.emitterRays - cosine, cosine + n,
                                     surfels.normals[i], Direction(t, r), tri, Distance(o, h));
                // The emission map's tint at the hit is in the coefficient.
                const glm::vec3 tinted =
                    c *
                    rays_->TintsAt(tri, h.u * (1.0f / 65535.0f), h.v * (1.0f / 65535.0f)).emission;
                const glm::vec3 seen = Through(t, r) * tinted;
                emitterHits_[t] += rays_->MaterialOf(tri).emission * seen;
                if (coef) coef[rays_->EmitterSlot(tris[tri].primitive)] += seen;
            }
        }
    });
}

void GatherStage::Sky() {
    const int n = settings_.gatherRays, m = SecondRays();
    sky_.assign(targets_.size(), glm::vec3(0.0f));
    secondSky_.assign(secondStart_.back(), glm::vec3(0.0f));
    // The cosine rays read the sky without the sun the first shot carries; a lobe ray
    // (drawn from a glossy lobe, not by the cosine) reads the whole sky.
    const Environment& sky = CosineSky();
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
                if (h.triangle == kEscaped) sum += Through(t, r) * sky.Radiance(Direction(t, r));
                if (!Front(h) || !(h.triangle & kShort)) continue;
                glm::vec3 second(0.0f);
                for (int j = 0; j < m; ++j)
                    if (second_[t][k * m + j].triangle == kEscaped)
                        second += sky.Radiance(SecondDirection(t, r, h.triangle & kIndex, j));
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

}  // namespace penumbra
