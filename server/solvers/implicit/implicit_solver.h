// The implicit-visibility solver (Dong, Kautz, Theobalt, Seidel, PG 2007) behind the Solver
// interface, CPU back end (with a Vulkan device, the links are created, composited and bounced
// there). Algorithm 1: the
// surfels and their hierarchy are made once; every frame that geometry changed, the hierarchy is
// refitted (UpdateElements) and the links are built anew (implicit_links.h); every bounce, each
// leaf gathers the light of the closest sender in each of its front bins (Eq. 5) and the exitant
// light is pulled up the tree.
//
// Radiance of a sender node s seen from a bin: per node and bin, the exitant intensity of its
// leaves I(ω) = Σ A_i L_i cos⁺(n_i, ω) and their front-facing projected area
// F(ω) = Σ A_i cos⁺(n_i, ω); L_s(ω) = I(ω) / max(F(ω), F(−ω)). The larger of the front- and
// back-facing areas is what the sender shows: a closed solid hides its back faces behind its
// front ones (F(ω) = F(−ω)), a surface turned away still hides what is behind it and sends
// nothing (the paper's closest element as a blocker). A leaf's irradiance
// E = Σ_bins cos⁺θ · ω_bin · CosineNorm · L, with L the closest sender's radiance towards it,
// or the environment's where the bin is empty (Sec. 4.4). Weighting each bin by its solid
// angle (not Eq. 5's A cosθ / r² of the sender) is the paper's own assumption that the
// closest element covers the bin: a bin is never under-filled, and a closed room keeps its
// energy (docs/SOLVER.md, "Implicit visibility").
#pragma once

#include <memory>

#include "direct/direct_stage.h"
#include "gpu/fwd.h"
#include "hierarchy/directions.h"
#include "hierarchy/hierarchy.h"
#include "solver/solver.h"
#include "solvers/bin_lobes.h"
#include "solvers/implicit/implicit_links.h"
#include "solvers/implicit/settings.h"
#include "solvers/receiver_light.h"

namespace penumbra {

class VulkanBounce;
class VulkanCompositing;

class ImplicitSolver : public Solver {
  public:
    ImplicitSolver(const Scene& scene, const SolverSettings& settings, const ImplicitSettings& own,
                   const ProgressFn& progress);
    ~ImplicitSolver() override;

    void Iterate(int n) override;
    std::vector<glm::vec3> SurfelIrradiance(Channel channel = Channel::kIndirect) override;
    const Surfels& GetSurfels() const override { return surfels_; }
    void UpdateMaterials(const Scene& scene) override;
    void UpdateLights(const Scene& scene) override;
    SolverStats Stats() const override;
    std::vector<std::string> ValidationMessages() const override;
    // Any move or deformation that keeps the primitives, their refinement and the number of
    // punctual lights: the links are rebuilt every frame anyway.
    std::string GeometryMismatch(const Scene& scene) const override;
    std::string UpdateGeometry(const Scene& scene) override;
    void SetEmitterDirect(const std::vector<glm::vec3>& perSurfel) override;
    bool TakesEmitterDirect() const override { return true; }
    std::string WarmStart(Solver& previous, const SurfelCarry& carry) override;

    const ImplicitLinks& Links() const { return links_; }
    const Hierarchy& GetHierarchy() const { return hierarchy_; }
    const Directions& GetDirections() const { return dirs_; }
    // Per node and bin, Σ A cos⁺(n, ω_b) at the last relink (ImplicitLinker::Build's
    // `frontArea`).
    const std::vector<float>& ProjectedAreas() const { return projected_; }
    // Per node the closed solid its members bound, or kNoSolid; empty: none in the scene
    // (ImplicitLinker::Build's `solid`).
    const std::vector<uint32_t>& Solids() const { return solid_; }

  private:
    // The last geometry that passed GeometryMismatch: every primitive's positions and
    // normals, and what they refined into, so that the UpdateGeometry that follows a check
    // of the same geometry (the service's check, then its update, every deformed frame)
    // takes it instead of refining again.
    struct Checked {
        std::vector<std::vector<glm::vec3>> positions, normals;
        Surfels surfels;
        bool valid = false;
        bool Same(const Scene& scene) const;
    };
    mutable Checked checked_;
    mutable size_t refinements_ = 0;  // RefineScene runs for geometry updates (stats)
    // Refit, links, projected areas. `moved` (per surfel, or null): what moved since the
    // last relink; the pairs of what never moved since the first move keep their links
    // (ImplicitLinker::Build's `moving`).
    void Relink(const std::vector<uint8_t>* moved = nullptr);
    void Bounce();     // one gather over the links and the pull of the new light
    void Reradiate();  // the leaves' radiance from what they gathered; divergence checked
    // Whether Bounce runs on the device: one was asked for, the shares fit on it, and no leaf
    // is glossy (the glossy leaves' bounces run here only).
    bool BouncesOnDevice() const;
    void ReadMaterials(const Scene& scene);  // the scene's materials, then the leaves' light
    void FindSolids(const Scene& scene);     // solid_ from the scene's closed nodes
    // E_d per leaf from the direct stage, the lights' glossy rows (GlossyDirectRows) with the
    // lights as `scene` places them.
    void CopyDirect(const Scene& scene);
    // Glossy leaves (the paper's glossy receivers, Sec. 5, made to reflect all the light they
    // gather, not only the direct): ReadGlossy finds them and their lobes from materials_,
    // MirrorRows their mirror bins for their normals now, GlossyDirectRows the punctual
    // lights' light through their lobes; Bounce's ReflectGlossy the light each sends along
    // every bin from what arrived over its links (implicit_glossy.cpp).
    void ReadGlossy();
    void MirrorRows();
    void GlossyDirectRows();
    // Glossy slot g's light leaving along each bin: F0 × (the lobe over what arrived, per
    // bin of travel after mirroring, + the lights' glossy rows).
    void ReflectGlossy(uint32_t g);
    // The glossy radiance sender node s sends along bin t towards a receiver, over `p` its
    // projected area there (Bounce).
    glm::vec3 GlossySent(uint32_t s, uint32_t t, float p) const {
        return p > 0.0f ? glossyIntensity_[size_t(s) * dirs_.Count() + t] / p : glm::vec3(0.0f);
    }
    void ExitantTables();  // I and P per node and bin from the leaves' radiance
    std::vector<direct::GpuReceiver> LeafReceivers() const;

    SolverSettings settings_;
    ImplicitSettings own_;
    ProgressFn progress_;
    float elementSize_ = 0.0f;
    Surfels surfels_;
    Hierarchy hierarchy_;
    Directions dirs_;
    // With --device gpu or lavapipe: the device the links are created on (the rest runs here).
    std::unique_ptr<gpu::Context> device_;
    std::unique_ptr<VulkanLinkCreation> vulkanLinks_;
    // Why the closest rule's links are made on the CPU on a device (empty: they are not).
    std::string closestOnHost_;
    // With a device: the leaves' bins composited there too (vulkan_composite.h), where they fit.
    std::unique_ptr<VulkanCompositing> vulkanComposite_;
    // With a device: the bounces there (vulkan_bounce.h), unless bounceUnfit_ says why the
    // last relink's shares do not fit on it; how many ran there.
    std::unique_ptr<VulkanBounce> vulkanBounce_;
    std::string bounceUnfit_;
    size_t deviceBounces_ = 0;
    ImplicitLinker linker_;
    ImplicitLinks links_;
    // Per node: its subtree holds an element that moved since the first move (the linker
    // keeps the links of the pairs of other nodes for it); empty before any move.
    std::vector<uint8_t> moving_;
    size_t incrementalRelinks_ = 0;  // relinks that kept the unmoved pairs' links (stats)
    // Per node: the closed solid all its members bound (NodeSolids), or
    // kNoSolid; empty when the scene has none. Fixed by the triangles' connectivity, so it
    // is found once (a deformation keeps it).
    std::vector<uint32_t> solid_;
    ReceiverLight light_;  // per leaf, in hierarchy leaf order
    std::vector<Material> materials_;
    // Per node and bin: exitant intensity (RGB, ExitantTables; laid out as a ShareTable, its
    // rows followed by the nodes' Σ A L and the environment: every light a share reads) and
    // front-facing projected area (Relink).
    std::vector<glm::vec3> intensity_;
    std::vector<glm::vec3> sums_;  // per node: Σ A L over its leaves
    std::vector<float> projected_;
    // Per share of links_, where Bounce reads the light it sees in intensity_ and the factor
    // on it (Relink: the weight, over the sender's shown projected area where it is read
    // through a bin, over a facing flat sender's area where its Σ A L is read).
    std::vector<uint32_t> gatherAt_;
    std::vector<float> gatherFactor_;
    std::vector<glm::vec3> environment_;  // per bin, radiance travelling along it
    // Glossy leaves: per leaf its slot (kNotGlossy: diffuse); per slot its leaf, F0 and lobe
    // (lobes_ over lobeWeights_, bin_lobes.h); per slot and link bin (towards the sender) the
    // bin the light arriving from there leaves along (mirror_); per slot and bin the lights'
    // direct light through the lobe before F0 (glossyDirect_) and the radiance leaving along
    // it (glossyLeaving_); per node and bin the glossy intensity Σ A cos⁺ · leaving, pulled up
    // (glossyIntensity_; empty: no glossy leaf), and whether a glossy leaf lies below
    // (glossyNode_).
    static constexpr uint32_t kNotGlossy = 0xffffffffu;
    struct GlossySlot {
        uint32_t leaf;
        glm::vec3 specular;
        uint32_t lobe;
    };
    std::vector<uint32_t> glossyOf_;
    std::vector<GlossySlot> glossy_;
    std::vector<GlossyLobe> lobes_;
    std::vector<BinWeight> lobeWeights_;
    std::vector<uint32_t> mirror_;
    std::vector<glm::vec4> glossyDirect_;
    std::vector<glm::vec3> glossyArrived_;  // per slot and bin: cos θ Ω L arrived, mirrored
    std::vector<glm::vec3> glossyLeaving_;
    std::vector<glm::vec3> glossyIntensity_;
    std::vector<uint8_t> glossyNode_;
    std::vector<PunctualLight> lightPlaces_;  // the lights as the direct stage last placed them
    std::unique_ptr<direct::DirectStage> directStage_;
    direct::SkyBins sky_;
    int lights_ = 0, mapSize_ = 0;
    int iterations_ = 0;
    size_t relinks_ = 0;
    double setupSeconds_ = 0.0, msTotal_ = 0.0;
    // Each part's milliseconds summed over every relink and bounce so far (Stats' passes,
    // which SolverStats keeps as totals: the service's frames and the benches take the
    // difference).
    double msUpdate_ = 0.0, msCreate_ = 0.0, msPush_ = 0.0, msIllumination_ = 0.0;
    double msGeometry_ = 0.0;
    size_t geometryUpdates_ = 0;
    std::string divergence_;
};

}  // namespace penumbra
