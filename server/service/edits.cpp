// A session's edits: validated on submission against the scene as edited so far
// (`validated_`), then queued for the worker (session.cpp), which applies them between frames.
#include <algorithm>
#include <cmath>
#include <glm/gtc/matrix_transform.hpp>
#define GLM_ENABLE_EXPERIMENTAL
#include <glm/gtx/quaternion.hpp>

#include "base/check.h"
#include "base/numeric.h"
#include "scene/motion.h"
#include "scene/sun_sky.h"
#include "service/session.h"

namespace penumbra::service {

namespace {

using Clock = std::chrono::steady_clock;

bool FiniteNonNegative(glm::vec3 v) {
    for (int i = 0; i < 3; ++i)
        if (!std::isfinite(v[i]) || v[i] < 0.0f) return false;
    return true;
}

// Why the geometry of `node`'s subtree in `scene` lies out of reach: a vertex outside the box
// [lo, hi] (empty when none does).
std::string OutOfReach(const Scene& scene, int node, const glm::vec3& lo, const glm::vec3& hi) {
    std::vector<int> stack{node};
    while (!stack.empty()) {
        const SceneNode& n = scene.nodes[size_t(stack.back())];
        stack.pop_back();
        for (int c : n.children) stack.push_back(c);
        for (uint32_t p : n.primitives)
            for (const glm::vec3& v : scene.primitives[p].positions)
                if (glm::any(glm::lessThan(v, lo)) || glm::any(glm::greaterThan(v, hi)))
                    return "would take its geometry out of reach (a vertex at " +
                           std::to_string(v.x) + ", " + std::to_string(v.y) + ", " +
                           std::to_string(v.z) + "): a move or scale may reach " +
                           std::to_string(int(kMoveReach)) +
                           " scene diameters past the loaded scene's bounds";
    }
    return {};
}

std::string NodeList(const Scene& scene, bool dynamicOnly) {
    std::string out;
    for (const auto& n : scene.nodes) {
        if (n.primitives.empty() && n.children.empty()) continue;
        if (dynamicOnly && !n.dynamic) continue;
        out += (out.empty() ? "" : ", ") + n.name;
    }
    return out.empty() ? "(none)" : out;
}

// Gives every primitive of `node` a material of its own (a copy named material@node) so a
// light edit changes that node only; returns the materials it now uses.
std::vector<uint32_t> OwnMaterials(Scene& scene, int node) {
    std::vector<uint32_t> used;
    for (uint32_t pi : scene.nodes[node].primitives) {
        Primitive& p = scene.primitives[pi];
        bool shared = false;
        for (size_t q = 0; q < scene.primitives.size() && !shared; ++q)
            shared =
                scene.primitives[q].material == p.material && scene.primitives[q].nodeIndex != node;
        if (shared) {
            Material copy = scene.materials[p.material];
            copy.name += "@" + scene.nodes[node].name;
            scene.materials.push_back(copy);
            uint32_t fresh = static_cast<uint32_t>(scene.materials.size() - 1);
            for (uint32_t pj : scene.nodes[node].primitives)
                if (scene.primitives[pj].material == p.material)
                    scene.primitives[pj].material = fresh;
        }
        if (std::find(used.begin(), used.end(), p.material) == used.end())
            used.push_back(p.material);
    }
    return used;
}

bool SubtreeHasPrimitives(const Scene& scene, int node) {
    if (!scene.nodes[node].primitives.empty()) return true;
    for (int c : scene.nodes[node].children)
        if (SubtreeHasPrimitives(scene, c)) return true;
    return false;
}

bool SubtreeHasLights(const Scene& scene, int node) {
    for (const auto& l : scene.lights)
        for (int n = l.node; n >= 0; n = scene.nodes[n].parent)
            if (n == node) return true;
    return false;
}

}  // namespace

uint64_t Session::Queue(std::function<void(Scene&)> apply, bool moves, std::string what,
                        bool lights) {
    // Caller holds mutex_ and has applied `apply` to validated_ already.
    uint64_t id = nextEdit_++;
    pending_.push_back(Pending{id, Clock::now(), std::move(apply), moves, lights, std::move(what)});
    if (!rebuild_) editWaiting_ = true;
    wake_.notify_all();
    return id;
}

uint64_t Session::Submit(const TransformEdit& edit) {
    std::lock_guard lock(mutex_);
    int node = FindNode(validated_, edit.node);
    if (node < 0)
        throw ServiceError(ErrorKind::kNotFound,
                           "no node '" + edit.node + "' in scene '" + name_ +
                               "'; movable nodes: " + NodeList(validated_, true));
    // Lights are always movable; geometry only when marked dynamic.
    const bool geometry = SubtreeHasPrimitives(validated_, node);
    const bool lights = SubtreeHasLights(validated_, node);
    if (geometry && !validated_.nodes[node].dynamic)
        throw ServiceError(ErrorKind::kStaticNode,
                           "node '" + edit.node +
                               "' is static; mark it extras.penumbra.dynamic in the glTF to move "
                               "it (movable nodes: " +
                               NodeList(validated_, true) + ")");
    const glm::mat4 before = validated_.nodes[node].local;
    try {
        SetNodeTransform(validated_, node, edit.local);
    } catch (const Error& e) {
        throw ServiceError(ErrorKind::kInvalidArgument, e.what());
    }
    if (std::string why = OutOfReach(validated_, node, reachLo_, reachHi_); !why.empty()) {
        SetNodeTransform(validated_, node, before);  // valid: it was the node's
        throw ServiceError(ErrorKind::kInvalidArgument, "transform of '" + edit.node + "' " + why);
    }
    glm::mat4 local = edit.local;
    std::string what = "moved " + edit.node;
    if (OutsideBounds(validated_, validated_.nodes[node])) what += " (outside its motion bounds)";
    return Queue([node, local](Scene& s) { SetNodeTransform(s, node, local); }, geometry, what,
                 lights);
}

uint64_t Session::Submit(const DeformEdit& edit) {
    std::lock_guard lock(mutex_);
    const int node = FindNode(validated_, edit.node);
    if (node < 0 || validated_.nodes[node].primitives.empty())
        throw ServiceError(ErrorKind::kNotFound,
                           (node < 0 ? "no node '" + edit.node + "' in scene '" + name_ + "'"
                                     : "node '" + edit.node + "' has no mesh of its own") +
                               "; deformable nodes: " + NodeList(validated_, true));
    if (!validated_.nodes[node].dynamic)
        throw ServiceError(ErrorKind::kStaticNode,
                           "node '" + edit.node +
                               "' is static; mark it extras.penumbra.dynamic in the glTF to "
                               "deform it (deformable nodes: " +
                               NodeList(validated_, true) + ")");
    if (edit.weights && !edit.positions.empty())
        throw ServiceError(ErrorKind::kInvalidArgument,
                           "give either vertex positions or morph weights, not both");
    std::function<void(Scene&)> apply;
    if (edit.weights) {
        std::vector<float> weights = *edit.weights;
        apply = [node, weights](Scene& s) { SetNodeMorphWeights(s, node, weights); };
    } else {
        auto positions = std::make_shared<const std::vector<glm::vec3>>(edit.positions);
        auto normals = std::make_shared<const std::vector<glm::vec3>>(edit.normals);
        apply = [node, positions, normals](Scene& s) {
            SetNodeVertices(s, node, *positions, *normals);
        };
    }
    try {
        apply(validated_);  // throws, changing nothing, for a wrong count or bad numbers
    } catch (const Error& e) {
        throw ServiceError(ErrorKind::kInvalidArgument, e.what());
    }
    std::string what = "deformed " + edit.node;
    if (OutsideBounds(validated_, validated_.nodes[node])) what += " (outside its motion bounds)";
    return Queue(std::move(apply), true, what, false);
}

uint64_t Session::Submit(const LightEdit& edit) {
    std::lock_guard lock(mutex_);
    if (int li = FindLight(validated_, edit.light); li >= 0) return SubmitPunctual(li, edit);
    if (std::find(lightNodes_.begin(), lightNodes_.end(), edit.light) == lightNodes_.end()) {
        std::string lights;
        for (const auto& l : validated_.lights) lights += (lights.empty() ? "" : ", ") + l.name;
        for (const auto& l : lightNodes_) lights += (lights.empty() ? "" : ", ") + l;
        throw ServiceError(ErrorKind::kNotFound, "no light '" + edit.light + "' in scene '" +
                                                     name_ +
                                                     "'; lights (punctual, then emissive nodes): " +
                                                     (lights.empty() ? "(none)" : lights));
    }
    if (edit.position || edit.direction || edit.innerCone || edit.outerCone || edit.range)
        throw ServiceError(ErrorKind::kInvalidArgument,
                           "'" + edit.light +
                               "' is an emissive surface: only its colour and intensity can "
                               "change (move its node with SetTransform)");
    if (edit.intensity && (!std::isfinite(*edit.intensity) || *edit.intensity < 0.0f))
        throw ServiceError(ErrorKind::kInvalidArgument,
                           "light intensity must be a finite number ≥ 0");
    if (edit.color && !FiniteNonNegative(*edit.color))
        throw ServiceError(ErrorKind::kInvalidArgument,
                           "light colour must be three finite numbers ≥ 0");
    int node = FindNode(validated_, edit.light);
    LightEdit e = edit;
    // The node's primitives that emitted when the scene was loaded: a lamp's housing stays
    // dark when its bulb is dimmed or brightened (and a bulb turned off can be turned on).
    const std::vector<uint32_t> emitting =
        lightPrimitives_[std::find(lightNodes_.begin(), lightNodes_.end(), edit.light) -
                         lightNodes_.begin()];
    // Emission = colour × intensity, where the current emission E splits into intensity
    // max(E) and colour E / max(E); an absent part keeps its current value.
    auto apply = [node, e, emitting](Scene& s) {
        OwnMaterials(s, node);
        std::vector<uint32_t> materials;
        for (uint32_t pi : emitting)
            if (std::find(materials.begin(), materials.end(), s.primitives[pi].material) ==
                materials.end())
                materials.push_back(s.primitives[pi].material);
        for (uint32_t m : materials) {
            glm::vec3& emission = s.materials[m].emission;
            float peak = std::max(emission.x, std::max(emission.y, emission.z));
            glm::vec3 color = peak > 0.0f ? emission / peak : glm::vec3(1.0f);
            if (e.color) color = *e.color;
            float intensity = e.intensity ? *e.intensity : peak;
            emission = color * intensity;
        }
    };
    apply(validated_);
    return Queue(apply, false, "light " + edit.light);
}

uint64_t Session::SubmitPunctual(int li, const LightEdit& edit) {
    // Caller holds mutex_. Check the light as it will be, then queue the change.
    auto invalid = [](const std::string& why) {
        return ServiceError(ErrorKind::kInvalidArgument, why);
    };
    if (edit.intensity && (!std::isfinite(*edit.intensity) || *edit.intensity < 0.0f))
        throw invalid("light intensity must be a finite number ≥ 0 (cd, or lux if directional)");
    if (edit.color && !FiniteNonNegative(*edit.color))
        throw invalid("light colour must be three finite numbers ≥ 0");
    if (edit.range && (!std::isfinite(*edit.range) || *edit.range < 0.0f))
        throw invalid("light range must be a finite number of metres ≥ 0 (0: infinite)");
    if (edit.position && !Finite(*edit.position))
        throw invalid("light position must be three finite numbers");
    if (edit.direction && (!Finite(*edit.direction) || !(glm::length(*edit.direction) > 1e-12f)))
        throw invalid("light direction must be a finite, non-zero vector");
    PunctualLight next = validated_.lights[li];
    if (edit.innerCone) next.innerCone = *edit.innerCone;
    if (edit.outerCone) next.outerCone = *edit.outerCone;
    if ((edit.innerCone || edit.outerCone) && next.type != LightType::kSpot)
        throw invalid("'" + edit.light + "' is not a spot light: it has no cone");
    if (!(next.innerCone >= 0.0f && next.innerCone < next.outerCone &&
          next.outerCone <= 1.5707964f))
        throw invalid("spot cone angles need 0 ≤ inner < outer ≤ π/2 radians");
    LightEdit e = edit;
    int node = validated_.lights[li].node;
    auto apply = [li, node, e](Scene& s) {
        PunctualLight& light = s.lights[li];
        if (e.color) light.color = *e.color;
        if (e.intensity) light.intensity = *e.intensity;
        if (e.range) light.range = *e.range;
        if (e.innerCone) light.innerCone = *e.innerCone;
        if (e.outerCone) light.outerCone = *e.outerCone;
        if (e.position || e.direction) {
            // The node's new world matrix: at the position, −Z turned onto the direction.
            glm::vec3 p = e.position ? *e.position : light.position;
            glm::vec3 d = glm::normalize(e.direction ? *e.direction : light.direction);
            glm::mat4 world = glm::translate(glm::mat4(1.0f), p) *
                              glm::mat4_cast(glm::rotation(glm::vec3(0, 0, -1), d));
            const SceneNode& n = s.nodes[node];
            glm::mat4 parent = n.parent >= 0 ? s.nodes[n.parent].world : glm::mat4(1.0f);
            SetNodeTransform(s, node, glm::inverse(parent) * world);
        }
    };
    try {
        apply(validated_);
    } catch (const Error& err) {
        throw invalid(err.what());
    }
    return Queue(apply, false, "light " + edit.light, true);
}

uint64_t Session::Submit(const MaterialEdit& edit) {
    std::lock_guard lock(mutex_);
    std::vector<uint32_t> matches;
    for (size_t i = 0; i < validated_.materials.size(); ++i)
        if (validated_.materials[i].name == edit.material ||
            validated_.materials[i].name.rfind(edit.material + "@", 0) == 0)
            matches.push_back(static_cast<uint32_t>(i));
    if (matches.empty()) {
        std::string names;
        for (const auto& m : validated_.materials) names += (names.empty() ? "" : ", ") + m.name;
        throw ServiceError(ErrorKind::kNotFound, "no material '" + edit.material + "' in scene '" +
                                                     name_ + "'; materials: " + names);
    }
    if (edit.albedo && (!FiniteNonNegative(*edit.albedo) ||
                        glm::any(glm::greaterThan(*edit.albedo, glm::vec3(1.0f)))))
        throw ServiceError(
            ErrorKind::kInvalidArgument,
            "albedo must be three numbers in [0, 1] (above 1 a surface creates light)");
    for (auto [value, name] : {std::pair{edit.roughness, "roughness"}, {edit.metallic, "metallic"}})
        if (value && !(*value >= 0.0f && *value <= 1.0f))
            throw ServiceError(ErrorKind::kInvalidArgument,
                               std::string(name) + " must be a number in [0, 1]");
    if (edit.emission && !FiniteNonNegative(*edit.emission))
        throw ServiceError(ErrorKind::kInvalidArgument,
                           "emission must be three finite numbers ≥ 0");
    MaterialEdit e = edit;
    auto apply = [matches, e](Scene& s) {
        for (uint32_t m : matches) {
            // `albedo` is the base colour; the diffuse albedo and any glossy lobe follow.
            if (e.albedo) s.materials[m].baseColor = *e.albedo;
            if (e.roughness) s.materials[m].roughness = *e.roughness;
            if (e.metallic) s.materials[m].metallic = *e.metallic;
            DeriveReflectance(s.materials[m]);
            if (e.emission) s.materials[m].emission = *e.emission;
        }
    };
    apply(validated_);
    return Queue(apply, false, "material " + edit.material);
}

uint64_t Session::Submit(const EnvironmentEdit& edit) {
    std::lock_guard lock(mutex_);
    if (edit.intensity && !(*edit.intensity >= 0.0f && std::isfinite(*edit.intensity)))
        throw ServiceError(ErrorKind::kInvalidArgument,
                           "environment intensity must be a finite number ≥ 0");
    if (edit.rotation && !std::isfinite(*edit.rotation))
        throw ServiceError(ErrorKind::kInvalidArgument, "environment rotation must be finite");
    Environment next = edit.replace ? *edit.replace : validated_.environment;
    uint64_t sunEdit = 0;
    if (edit.sun || edit.sunIlluminance || edit.clearSky || edit.turbidity) {
        const int li = FindLight(validated_, kSunName);
        if (li < 0 || validated_.lights[li].type != LightType::kDirectional)
            throw ServiceError(ErrorKind::kNotFound,
                               "scene '" + name_ +
                                   "' has no sun: load it with one (LoadScene `sun`) or give it a "
                                   "directional light called 'sun'");
        SunPosition at = SunPositionOf(validated_.lights[li]);
        try {
            if (edit.sun) at = {edit.sun->x, edit.sun->y};
            ValidateSunPosition(at);
            const float turbidity = edit.turbidity          ? *edit.turbidity
                                    : next.turbidity > 0.0f ? next.turbidity
                                                            : kDefaultTurbidity;
            // A clear sky follows its sun; one asked for replaces the sky.
            if (edit.turbidity && !edit.clearSky && next.turbidity <= 0.0f)
                throw Error("turbidity is a clear sky's: the sky is not one (ask for sky clear)");
            if (edit.clearSky || (!edit.replace && next.turbidity > 0.0f)) {
                const float intensity = next.intensity;
                next = ClearSky(at, turbidity);
                next.intensity = edit.clearSky ? 1.0f : intensity;
            }
        } catch (const Error& e) {
            throw ServiceError(ErrorKind::kInvalidArgument, e.what());
        }
        if (edit.sun || edit.sunIlluminance) {
            LightEdit move;
            move.light = kSunName;
            if (edit.sun) move.direction = -SunDirection(at);
            move.intensity = edit.sunIlluminance;
            sunEdit = SubmitPunctual(li, move);
        }
        if (!edit.clearSky && !edit.replace && !edit.intensity && !edit.rotation &&
            next.turbidity <= 0.0f)
            return sunEdit;  // the sun alone: the sky is not its own
    }
    if (edit.intensity) next.intensity = *edit.intensity;
    if (edit.rotation) next.rotation = *edit.rotation;
    try {
        ValidateEnvironment(next);
    } catch (const Error& e) {
        throw ServiceError(ErrorKind::kInvalidArgument, e.what());
    }
    // Back occlusion `auto` is decided when the links are built: a sky appearing or going
    // changes which surfaces occlude from both sides, so the links are rebuilt.
    const bool rebuild =
        BackOcclusionChanges(settings_.solver.backOcclusion, validated_.environment, next);
    auto apply = [next](Scene& s) { s.environment = next; };
    apply(validated_);
    std::string what = next.Active() ? "sky " + next.source : "sky off";
    return Queue(apply, rebuild, what, true);
}

}  // namespace penumbra::service
