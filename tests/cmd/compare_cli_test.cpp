// `penumbra compare` and `penumbra reference` as real processes: zero error on identical
// files, the known numbers on known differences, the --max-rmse gate, and clear errors.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>

#include "test_util.h"

namespace penumbra {
namespace {

using testing::Execute;
using testing::ProcessResult;

// Writes an irradiance file with one node "a" of `values` (grey) and one node "b" of 1s.
std::string WriteFile(const std::filesystem::path& dir, const std::string& name,
                      const std::vector<float>& values, const std::string& channel = "indirect") {
    nlohmann::json j;
    j["units"] = "lux";
    j["solver"] = "test";
    j["channel"] = channel;
    nlohmann::json a = nlohmann::json::array(), b = nlohmann::json::array();
    for (float v : values) a.push_back({v, v, v});
    for (size_t i = 0; i < 4; ++i) b.push_back({1.0, 1.0, 1.0});
    j["primitives"] = {{{"node", "a"}, {"mesh", 0}, {"primitive", 0}, {"irradiance", a}},
                       {{"node", "b"}, {"mesh", 1}, {"primitive", 0}, {"irradiance", b}}};
    j["stats"] = nlohmann::json::object();
    auto path = dir / name;
    std::ofstream(path) << j.dump();
    return path.string();
}

nlohmann::json CompareJson(const std::string& a, const std::string& b) {
    ProcessResult r = Execute("compare " + a + " " + b + " --json");
    EXPECT_EQ(r.exitCode, 0) << r.output;
    return nlohmann::json::parse(r.output);
}

TEST(CompareCli, IdenticalFilesGiveZero) {
    auto dir = testing::TempDir("compare-same");
    std::string f = WriteFile(dir, "a.json", {1, 2, 3, 4});
    nlohmann::json j = CompareJson(f, f);
    EXPECT_EQ(j["rel_rmse"].get<double>(), 0.0);
    EXPECT_EQ(j["mean_rel"].get<double>(), 0.0);
    EXPECT_EQ(j["max_rel"].get<double>(), 0.0);
    EXPECT_EQ(j["vertices"].get<int>(), 8);
    EXPECT_TRUE(j["nodes"].contains("a"));
    EXPECT_TRUE(j["nodes"].contains("b"));
}

TEST(CompareCli, KnownDifferencesGiveKnownNumbers) {
    auto dir = testing::TempDir("compare-known");
    // Reference node a = (1, 1, 1, 1); judged a = (1.1, 1, 1, 2): per-vertex relative errors
    // 0.1, 0, 0, 1 (all channels alike); node b identical.
    std::string ref = WriteFile(dir, "ref.json", {1, 1, 1, 1});
    std::string test = WriteFile(dir, "test.json", {1.1f, 1, 1, 2});
    nlohmann::json j = CompareJson(test, ref);
    // Overall: Σ|a−b|² = 3·(0.01 + 1), Σ|b|² = 3·8.
    EXPECT_NEAR(j["rel_rmse"].get<double>(), std::sqrt(1.01 / 8.0), 1e-6);
    EXPECT_NEAR(j["mean_rel"].get<double>(), 1.1 / 8.0, 1e-6);
    EXPECT_NEAR(j["max_rel"].get<double>(), 1.0, 1e-6);
    EXPECT_EQ(j["worst"]["node"], "a");
    EXPECT_EQ(j["worst"]["vertex"], 3);
    EXPECT_NEAR(j["nodes"]["a"]["rel_rmse"].get<double>(), std::sqrt(1.01 / 4.0), 1e-6);
    EXPECT_NEAR(j["nodes"]["a"]["mean_rel"].get<double>(), 1.1 / 4.0, 1e-6);
    EXPECT_EQ(j["nodes"]["b"]["rel_rmse"].get<double>(), 0.0);
}

TEST(CompareCli, MaxRmseGatesWithExitStatus4) {
    auto dir = testing::TempDir("compare-gate");
    std::string ref = WriteFile(dir, "ref.json", {1, 1, 1, 1});
    std::string test = WriteFile(dir, "test.json", {1.1f, 1, 1, 2});  // rel RMSE 0.355
    EXPECT_EQ(Execute("compare " + test + " " + ref + " --max-rmse 0.5").exitCode, 0);
    ProcessResult r = Execute("compare " + test + " " + ref + " --max-rmse 0.3");
    EXPECT_EQ(r.exitCode, 4) << r.output;
    EXPECT_NE(r.output.find("exceeds --max-rmse"), std::string::npos) << r.output;
}

TEST(CompareCli, MismatchedFilesFailClearly) {
    auto dir = testing::TempDir("compare-bad");
    std::string ref = WriteFile(dir, "ref.json", {1, 1, 1, 1});
    std::string shorter = WriteFile(dir, "short.json", {1, 1, 1});
    ProcessResult r = Execute("compare " + shorter + " " + ref);
    EXPECT_EQ(r.exitCode, 1);
    EXPECT_NE(r.output.find("node 'a'"), std::string::npos) << r.output;
    std::string direct = WriteFile(dir, "direct.json", {1, 1, 1, 1}, "direct");
    r = Execute("compare " + direct + " " + ref);
    EXPECT_EQ(r.exitCode, 1);
    EXPECT_NE(r.output.find("channels differ"), std::string::npos) << r.output;
    std::ofstream(dir / "garbage.json") << "{not json";
    r = Execute("compare " + (dir / "garbage.json").string() + " " + ref);
    EXPECT_EQ(r.exitCode, 1);
    EXPECT_NE(r.output.find("garbage.json: not JSON: parse error at line 1"), std::string::npos)
        << r.output;
    EXPECT_EQ(r.output.find("[json.exception"), std::string::npos) << "library tag leaked";
}

TEST(ReferenceCli, WritesIrradianceWithStandardErrorsAndStats) {
    auto dir = testing::TempDir("reference-cli");
    auto out = dir / "ref.json";
    std::string scene = std::string(PENUMBRA_SOURCE_DIR) + "/scenes/blocker.gltf";
    ProcessResult r = Execute("reference " + scene + " -o " + out.string() +
                              " --samples 16 --seed 5 --threads 2");
    ASSERT_EQ(r.exitCode, 0) << r.output;
    nlohmann::json j = nlohmann::json::parse(std::ifstream(out));
    EXPECT_EQ(j["solver"], "reference");
    EXPECT_EQ(j["channel"], "indirect");
    for (const char* key : {"samples", "max_depth", "seed", "threads", "rays", "rays_per_second",
                            "seconds", "rel_stderr"})
        EXPECT_TRUE(j["stats"].contains(key)) << key;
    for (const auto& p : j["primitives"]) EXPECT_EQ(p["stderr"].size(), p["irradiance"].size());
    // Its own output compares to zero error.
    EXPECT_EQ(Execute("compare " + out.string() + " " + out.string() + " --max-rmse 0").exitCode,
              0);
    EXPECT_EQ(Execute("reference " + scene + " -o " + out.string() + " --samples 1").exitCode, 1);
}

}  // namespace
}  // namespace penumbra
