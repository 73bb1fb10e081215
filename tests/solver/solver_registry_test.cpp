// The solver registry and the options each solver declares: checks in-process, then a solver
// that is a test fixture (fixtures/constant_solver.cpp, linked into penumbra-constant and
// penumbra-server-constant) listed by --help, baked and served through the registry alone.
#include <gtest/gtest.h>

#include "client/client.h"
#include "net/server_process.h"
#include "output/irradiance_writer.h"
#include "solvers/antiradiance/settings.h"
#include "solvers/registry.h"
#include "test_util.h"

namespace penumbra {
namespace {

using testing::Execute;

const std::string kCornell = std::string(PENUMBRA_SOURCE_DIR) + "/scenes/cornell-box.gltf";

// What `fn` throws as penumbra::Error ("" when it does not throw).
template <typename F>
std::string ErrorOf(F fn) {
    try {
        fn();
    } catch (const Error& e) {
        return e.what();
    }
    return {};
}

TEST(SolverRegistry, NamesTheSolversThereAreAndChecksTheirOptions) {
    ASSERT_FALSE(Solvers().empty());
    EXPECT_EQ(Solvers().front().name, "antiradiance");
    EXPECT_EQ(&FindSolver("antiradiance"), &Solvers().front());
    const std::string unknown = ErrorOf([] { FindSolver("nosuch"); });
    EXPECT_NE(unknown.find("unknown solver 'nosuch' (available: antiradiance"), std::string::npos)
        << unknown;

    SolverSettings s;
    s.solver = "antiradiance";
    s.options = {{"bins", "64"}, {"scheme", "symmetric"}, {"oracle", "2.5"}};
    EXPECT_EQ(ErrorOf([&] { CheckSolverSettings(s); }), "");
    const AntiradianceSettings own = ReadAntiradianceSettings(s);
    EXPECT_EQ(own.bins, 64);
    EXPECT_EQ(own.scheme, Scheme::kSymmetric);
    EXPECT_EQ(own.oracle, 2.5f);
    // Each refusal names the option and what would do.
    const std::pair<SolverOptions, const char*> bad[] = {
        {{{"bin", "64"}}, "has no option 'bin' (it takes bins, scheme"},
        {{{"bins", "sixty"}}, "'bins' of solver 'antiradiance' is 'sixty', not a whole number"},
        {{{"bins", "64.5"}}, "not a whole number"},
        {{{"bins", "2048"}}, "outside 0…1024"},
        {{{"bins", "30"}}, "bin count 30 must be a multiple of 4 in 32…1024"},
        {{{"oracle", "nan"}}, "not a number"},
        {{{"scheme", "sym"}}, "is 'sym' (use adaptive, symmetric or asymmetric)"},
    };
    for (const auto& [options, expected] : bad) {
        s.options = options;
        const std::string why = ErrorOf([&] { CheckSolverSettings(s); });
        EXPECT_NE(why.find(expected), std::string::npos) << why;
    }
    // Behind a final gather, defaults that cost less; options given are kept.
    s.options.clear();
    s.behindGather = true;
    EXPECT_EQ(ReadAntiradianceSettings(s).bins, kBinsBehindGather);
    EXPECT_EQ(ReadAntiradianceSettings(s).antiradianceTolerance, kSettleBehindGather);
    SetOption(s.options, "bins", 96);
    EXPECT_EQ(ReadAntiradianceSettings(s).bins, 96);
}

TEST(SolverRegistry, AFixtureSolverIsListedByHelp) {
    const auto help = Execute("--help", "", "penumbra-constant");
    ASSERT_EQ(help.exitCode, 0) << help.output;
    EXPECT_NE(help.output.find("constant: a test fixture"), std::string::npos) << help.output;
    const auto bake = Execute("bake --help", "", "penumbra-constant");
    EXPECT_NE(bake.output.find("--value"), std::string::npos) << bake.output;
    EXPECT_NE(bake.output.find("[constant; default 1]"), std::string::npos) << bake.output;
    const auto wrong =
        Execute("bake " + kCornell + " -o x.json --solver nosuch", "", "penumbra-constant");
    EXPECT_EQ(wrong.exitCode, 2) << wrong.output;
    EXPECT_NE(wrong.output.find("available: antiradiance, implicit, lightfield, constant"),
              std::string::npos)
        << wrong.output;
    // The plain program has no such solver.
    const auto plain = Execute("bake " + kCornell + " -o x.json --solver constant");
    EXPECT_EQ(plain.exitCode, 2) << plain.output;
}

// Every vertex of every primitive in `file` at `lux`.
void ExpectEverywhere(const IrradianceFile& file, float lux) {
    size_t vertices = 0;
    for (const IrradianceRecord& p : file.primitives)
        for (const glm::vec3& e : p.irradiance) {
            ASSERT_EQ(e, glm::vec3(lux)) << p.node;
            ++vertices;
        }
    EXPECT_GT(vertices, 0u);
}

TEST(SolverRegistry, AFixtureSolverIsBaked) {
    const auto dir = testing::TempDir("registry-bake");
    const std::string out = (dir / "constant.json").string();
    const auto r = Execute("bake " + kCornell + " -o " + out +
                               " --solver constant --value 2.5 --gather off --direct-rays 0",
                           "", "penumbra-constant");
    ASSERT_EQ(r.exitCode, 0) << r.output;
    const IrradianceFile file = ReadIrradianceJson(out);
    EXPECT_EQ(file.solver, "constant");
    ExpectEverywhere(file, 2.5f);
    // Behind the gather stage (on by default) it runs too; the stage keeps the first shot,
    // which this solver cannot take, and says so.
    const auto gathered =
        Execute("bake " + kCornell + " -o " + out + " --solver constant --element-size 0.2", "",
                "penumbra-constant");
    ASSERT_EQ(gathered.exitCode, 0) << gathered.output;
    EXPECT_NE(gathered.output.find("solver 'constant' carries the emission itself"),
              std::string::npos)
        << gathered.output;
    for (const IrradianceRecord& p : ReadIrradianceJson(out).primitives)
        for (const glm::vec3& e : p.irradiance)
            EXPECT_TRUE(std::isfinite(e.x) && e.x >= 0.0f) << p.node;
    // Another solver's options are refused by name.
    const auto bins = Execute("bake " + kCornell + " -o " + out + " --solver constant --bins 64",
                              "", "penumbra-constant");
    EXPECT_EQ(bins.exitCode, 1) << bins.output;
    EXPECT_NE(
        bins.output.find("solver 'constant' has no option 'bins' (it takes value; 'bins' is an "
                         "option of antiradiance and implicit"),
        std::string::npos)
        << bins.output;
}

TEST(SolverRegistry, AFixtureSolverIsServed) {
    testing::ServerProcess server("registry", "", "penumbra-server-constant");
    const std::string connect = "--connect " + server.Unix() + " ";
    const auto load = Execute(connect +
                                  "load cornell-box.gltf --solver constant --value 3 "
                                  "--gather-rays 0 --emitter-direct 0 --element-size 0.2",
                              "", "penumbra-constant");
    ASSERT_EQ(load.exitCode, 0) << load.output << server.Log();
    EXPECT_NE(load.output.find("constant"), std::string::npos) << load.output;
    const std::string out = (server.Dir() / "served.json").string();
    const auto wait = Execute(connect + "wait --timeout 60", "", "penumbra-constant");
    ASSERT_EQ(wait.exitCode, 0) << wait.output;
    const auto get = Execute(connect + "get -o " + out, "", "penumbra-constant");
    ASSERT_EQ(get.exitCode, 0) << get.output;
    ExpectEverywhere(ReadIrradianceJson(out), 3.0f);
    // Bad options are refused by the server itself (the CLI checks them before sending), an
    // unknown solver naming the solvers there are.
    client::Client c(server.Unix());
    client::LoadOptions o;
    o.path = "cornell-box.gltf";
    o.reload = true;
    for (const auto& [solver, options, code, expected] :
         {std::tuple<std::string, client::LoadOptions::Options, int, std::string>{
              "constant", {{"value", "-1"}}, 20, "option 'value' of solver 'constant' is -1"},
          {"constant", {{"bins", "64"}}, 20, "solver 'constant' has no option 'bins'"},
          {"nosuch", {}, 26, "available: antiradiance, implicit, lightfield, constant"}}) {
        o.solver = solver;
        o.solverOptions = options;
        try {
            c.Load(o);
            ADD_FAILURE() << solver << " loaded";
        } catch (const client::ClientError& e) {
            EXPECT_EQ(e.code(), code) << e.what();
            EXPECT_NE(std::string(e.what()).find(expected), std::string::npos) << e.what();
        }
    }
}

}  // namespace
}  // namespace penumbra
