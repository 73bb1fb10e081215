// Every Vulkan pass equals its CPU twin on lavapipe, with validation layers on and no
// validation message allowed. Tolerance: relative 1e-5 of the table's largest value —
// both sides sum in the same order in fp32, so only fused multiply-adds differ.
#include "solver/antiradiance/vulkan_passes.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "base/check.h"
#include "bundled_scenes.h"
#include "solver/antiradiance/antiradiance_solver.h"
#include "solver/antiradiance/cpu_passes.h"
#include "solver/antiradiance/model.h"
#include "solver/solver.h"
#include "test_util.h"

namespace penumbra {
namespace {

using Pass = VulkanAntiradiance::Pass;

class VulkanTwin : public ::testing::Test {
  protected:
    void SetUp() override {
        SolverSettings s;
        s.bins = 64;
        s.elementSize = 0.08f;
        scene_ = scenes::CornellBox().Build();
        model_ = std::make_unique<AntiradianceModel>(BuildAntiradianceModel(scene_, s, {}));
        gpu_ = std::make_unique<VulkanAntiradiance>(*model_, /*lavapipe=*/true,
                                                    /*validation=*/true);
    }
    void TearDown() override {
        auto messages = gpu_->ValidationMessages();
        for (const auto& m : messages) ADD_FAILURE() << "validation: " << m;
    }

    static void ExpectTablesEqual(const std::vector<float>& gpu, const std::vector<float>& cpu,
                                  const char* what) {
        ASSERT_EQ(gpu.size(), cpu.size()) << what;
        float scale = 0.0f;
        for (float v : cpu) scale = std::max(scale, std::abs(v));
        ASSERT_GT(scale, 0.0f) << what << " is all zero: the test would prove nothing";
        size_t worst = 0;
        float worstErr = 0.0f;
        for (size_t i = 0; i < cpu.size(); ++i) {
            float e = std::abs(gpu[i] - cpu[i]);
            if (e > worstErr) worstErr = e, worst = i;
        }
        EXPECT_LE(worstErr, 1e-5f * scale)
            << what << ": at " << worst << " GPU " << gpu[worst] << " vs CPU " << cpu[worst];
    }

    // CPU tables after the emitters' I_ex, the global pass and (if `push`) the push pass.
    void CpuTables(std::vector<float>& iex, std::vector<float>& lin, bool push) const {
        iex.assign(model_->TableFloats(), 0.0f);
        lin.assign(model_->TableFloats(), 0.0f);
        cpu::InitEmission(*model_, iex.data());
        cpu::GlobalPass(*model_, iex.data(), lin.data());
        if (push) cpu::PushPass(*model_, lin.data());
    }

    Scene scene_;
    std::unique_ptr<AntiradianceModel> model_;
    std::unique_ptr<VulkanAntiradiance> gpu_;
};

TEST_F(VulkanTwin, GlobalPassMatchesCpu) {
    std::vector<float> iex, lin;
    CpuTables(iex, lin, false);
    gpu_->RunPass(Pass::kGlobal);
    ExpectTablesEqual(gpu_->ReadLin(), lin, "L_in after the global pass");
}

TEST_F(VulkanTwin, PushPassMatchesCpu) {
    std::vector<float> iex, lin;
    CpuTables(iex, lin, false);
    gpu_->WriteLin(lin);
    cpu::PushPass(*model_, lin.data());
    gpu_->RunPass(Pass::kPush);
    ExpectTablesEqual(gpu_->ReadLin(), lin, "L_in after push");
}

TEST_F(VulkanTwin, LocalPassMatchesCpuInEveryMode) {
    std::vector<float> iex, lin;
    CpuTables(iex, lin, true);
    for (LocalMode mode : {kBoth, kReflect, kAntiradiance}) {
        std::vector<float> next(iex.size(), 0.0f), irr(model_->leaves.size() * 3);
        cpu::LocalPass(*model_, lin.data(), iex.data(), next.data(), irr.data(), mode);
        gpu_->WriteLin(lin);
        gpu_->WriteIex(iex, false);
        gpu_->WriteIex(std::vector<float>(iex.size(), 0.0f), true);
        gpu_->RunPass(Pass::kLocal, mode);
        ExpectTablesEqual(gpu_->ReadIex(true), next, "I_ex after the local pass");
        ExpectTablesEqual(gpu_->ReadLeafIrradiance(), irr, "irradiance");
    }
}

TEST_F(VulkanTwin, PullPassMatchesCpu) {
    std::vector<float> iex, lin;
    CpuTables(iex, lin, true);
    std::vector<float> next(iex.size(), 0.0f), irr(model_->leaves.size() * 3);
    cpu::LocalPass(*model_, lin.data(), iex.data(), next.data(), irr.data(), kBoth);
    gpu_->WriteIex(next, false);
    cpu::PullPass(*model_, next.data());
    gpu_->RunPass(Pass::kPull);
    ExpectTablesEqual(gpu_->ReadIex(false), next, "I_ex after pull");
}

TEST_F(VulkanTwin, IterationsMatchCpuBackend) {
    cpu::CpuBackend cpu(*model_);
    for (int i = 0; i < 4; ++i) {
        cpu.Iterate(kBoth);
        gpu_->Iterate(kBoth);
    }
    ExpectTablesEqual(gpu_->ReadLeafIrradiance(), cpu.LeafIrradiance(),
                      "irradiance after 4 iterations");
    for (const auto& p : gpu_->PassTimings()) EXPECT_GT(p.msTotal, 0.0) << p.name;
}

}  // namespace
}  // namespace penumbra

namespace penumbra {
namespace {

// A warm start (a solution carried over a link rebuild) on lavapipe gives what it gives on
// the CPU back end: same rows in, same irradiance after an iteration.
TEST(VulkanPasses, WarmStartMatchesTheCpuBackEnd) {
    Scene scene = scenes::CornellBox().Build();
    SolverSettings s;
    s.bins = 64;
    s.elementSize = 0.1f;
    s.device = DeviceChoice::kCpu;
    s.validation = true;
    auto source = CreateSolver(scene, s);
    source->Iterate(8);
    std::vector<float> rows = source->SurfelExitant();
    std::vector<uint8_t> keep(source->GetSurfels().size(), 1);
    for (size_t i = 0; i < keep.size(); i += 3) keep[i] = 0;  // some start from emission
    auto cpu = CreateSolver(scene, s);
    s.device = DeviceChoice::kLavapipe;
    auto gpu = CreateSolver(scene, s);
    cpu->WarmStart(rows, keep);
    gpu->WarmStart(rows, keep);
    cpu->Iterate(1);
    gpu->Iterate(1);
    double rel = testing::RelativeRms(gpu->SurfelIrradiance(), cpu->SurfelIrradiance());
    EXPECT_LT(rel, 1e-5);
    // And it is a warm start: one iteration lands near the source's solution.
    EXPECT_LT(testing::RelativeRms(cpu->SurfelIrradiance(), source->SurfelIrradiance()), 0.3);
    EXPECT_THROW(cpu->WarmStart(std::vector<float>(7), keep), Error);
    for (const auto& m : dynamic_cast<AntiradianceSolver&>(*gpu).ValidationMessages())
        ADD_FAILURE() << "validation: " << m;
}

}  // namespace
}  // namespace penumbra
