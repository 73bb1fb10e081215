// penumbra-server as a real process on loopback TCP and a Unix socket, with the client
// library and the CLI as its clients: shared sessions, edits seen by watchers, raw bad bytes,
// clients that vanish, refused requests, SIGTERM.
#include "net/server_process.h"

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <asio.hpp>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <fstream>
#include <glm/glm.hpp>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <thread>

#include "client/client.h"
#include "gather/gather_stage.h"
#include "output/irradiance_writer.h"
#include "protocol/frame.h"
#include "scene/gltf_loader.h"
#include "scene/sun_sky.h"
#include "solver/solver.h"
#include "test_util.h"

namespace penumbra {
namespace {

using testing::ServerProcess;

using namespace std::chrono_literals;
namespace fb = protocol::fb;

// The protocol error code a client call fails with, or -1 when it succeeds.
template <typename F>
int ErrorCodeOf(F call, std::string* message = nullptr) {
    try {
        call();
    } catch (const client::ClientError& e) {
        if (message) *message = e.what();
        return e.code();
    }
    return -1;
}

client::LoadOptions Cornell() {
    client::LoadOptions o;
    o.path = "cornell-box.gltf";
    o.solver = "antiradiance";  // compared with local solves at these settings
    o.solverOptions["bins"] = "64";
    o.elementSize = 0.06f;
    o.device = "cpu";
    return o;
}

// Collects the frames a subscription delivers.
struct Watcher {
    std::mutex m;
    std::condition_variable cv;
    std::vector<client::Frame> frames;
    void operator()(const client::Frame& f) {
        std::lock_guard lock(m);
        frames.push_back(f);
        cv.notify_all();
    }
    // The first converged frame that includes edit `edit` (waits up to 60 s).
    std::optional<client::Frame> Until(uint64_t edit) {
        std::unique_lock lock(m);
        std::optional<client::Frame> got;
        cv.wait_for(lock, 60s, [&] {
            for (const auto& f : frames)
                if (f.lastEdit >= edit && f.converged) {
                    got = f;
                    return true;
                }
            return false;
        });
        return got;
    }
    size_t Count() {
        std::lock_guard lock(m);
        return frames.size();
    }
};

// A .glb of one JSON chunk holding `doc` (its buffers as data URIs stay in the JSON): header
// (magic, version 2, length), chunk (length, "JSON").
std::vector<uint8_t> GlbOf(const nlohmann::json& doc) {
    std::string json = doc.dump();
    json.resize((json.size() + 3) / 4 * 4, ' ');
    std::string glb = "glTF";
    auto word = [&](uint32_t v) {
        for (int i = 0; i < 4; ++i) glb.push_back(char(v >> (8 * i)));
    };
    word(2);
    word(uint32_t(12 + 8 + json.size()));
    word(uint32_t(json.size()));
    glb += "JSON" + json;
    return std::vector<uint8_t>(glb.begin(), glb.end());
}

// Loads the Cornell box through `c`, subscribes `watch` and waits for the first converged
// frame; false if none came.
bool LoadAndWatch(client::Client& c, Watcher& watch) {
    c.Load(Cornell());
    c.Subscribe(std::ref(watch));
    return watch.Until(0).has_value();
}

float MeanOf(const client::Frame& f, const std::string& node) {
    double sum = 0.0;
    size_t n = 0;
    for (const auto& p : f.primitives)
        if (p.node == node)
            for (size_t i = 0; i < p.rgb.size(); ++i) sum += p.rgb[i], ++n;
    return n ? float(sum / n) : 0.0f;
}

// Floor vertices within `radius` (xz) of `centre`: their mean irradiance.
float FloorNear(const client::Frame& f, glm::vec2 centre, float radius,
                const std::vector<glm::vec3>& positions) {
    double sum = 0.0;
    size_t n = 0;
    for (const auto& p : f.primitives) {
        if (p.node != "floor") continue;
        for (size_t v = 0; v < positions.size() && v * 3 + 2 < p.rgb.size(); ++v)
            if (glm::length(glm::vec2(positions[v].x, positions[v].z) - centre) < radius)
                sum += (p.rgb[v * 3] + p.rgb[v * 3 + 1] + p.rgb[v * 3 + 2]) / 3.0, ++n;
    }
    return n ? float(sum / n) : -1.0f;
}

// Sends `bytes` on a raw connection to the server's Unix socket, reads until the server
// closes it, and decodes the first frame of the reply (`closed`: it ended with EOF).
// Reads `raw` until the server closes it; the first message it sent (`closed`: it ended in an
// orderly close).
protocol::Message ReadUntilClosed(asio::local::stream_protocol::socket& raw, bool* closed) {
    std::vector<uint8_t> reply;
    std::error_code ec;
    std::array<uint8_t, 4096> buf;
    while (!ec) {
        size_t n = raw.read_some(asio::buffer(buf), ec);
        reply.insert(reply.end(), buf.begin(), buf.begin() + n);
    }
    *closed = ec == asio::error::eof;
    protocol::Decoder d;
    d.Feed(reply.data(), reply.size());
    protocol::Message m;
    EXPECT_EQ(d.Next(m), protocol::Decoder::Result::kMessage) << reply.size() << " bytes";
    return m;
}

protocol::Message RawExchange(const ServerProcess& server, const std::vector<uint8_t>& bytes,
                              bool* closed) {
    asio::io_context io;
    asio::local::stream_protocol::socket raw(io);
    raw.connect(asio::local::stream_protocol::endpoint(server.SocketPath()));
    asio::write(raw, asio::buffer(bytes));
    return ReadUntilClosed(raw, closed);
}

TEST(ServerProcess, TwoClientsOneEditsOneWatchesOverTcpAndUnix) {
    ServerProcess server("two-clients");
    client::Client editor(server.Tcp(), "editor");
    client::Client viewer(server.Unix(), "viewer");
    EXPECT_EQ(editor.ProtocolVersion(), 1);
    client::SceneInfo info = editor.Load(Cornell());
    EXPECT_FALSE(info.reused);
    ASSERT_TRUE(info.Node("tall_block"));
    EXPECT_TRUE(info.Node("tall_block")->dynamic);
    // The viewer joins the same session instead of building another.
    client::SceneInfo joined = viewer.Load(Cornell());
    EXPECT_TRUE(joined.reused);

    Watcher watch;
    viewer.Subscribe(std::ref(watch));
    auto start = watch.Until(0);
    ASSERT_TRUE(start) << "no converged first frame";

    // Floor positions (in the file's vertex order) to locate "under the block".
    Scene scene = LoadGltf(std::string(PENUMBRA_SOURCE_DIR) + "/scenes/cornell-box.gltf");
    const auto& floorPos = scene.primitives[0].positions;
    ASSERT_EQ(scene.primitives[0].node, "floor");
    const glm::vec2 oldSpot(0.3685f, 0.3513f), newSpot(0.3685f - 0.15f, 0.3513f + 0.1f);

    // Move the tall block: the floor where it stood brightens, where it went darkens.
    const client::NodeInfo* tall = info.Node("tall_block");
    std::array<float, 16> m = tall->matrix;
    m[12] -= 0.15f;
    m[14] += 0.1f;
    uint64_t moveEdit = editor.SetTransform("tall_block", m);
    auto moved = watch.Until(moveEdit);
    ASSERT_TRUE(moved) << "the watcher never saw a converged frame with edit " << moveEdit;
    EXPECT_GE(moved->lastEdit, moveEdit);
    float oldBefore = FloorNear(*start, oldSpot, 0.05f, floorPos);
    float oldAfter = FloorNear(*moved, oldSpot, 0.05f, floorPos);
    float newBefore = FloorNear(*start, newSpot, 0.05f, floorPos);
    float newAfter = FloorNear(*moved, newSpot, 0.05f, floorPos);
    // Under the block the floor was dark (the block stands on it); uncovered, it is lit.
    EXPECT_GT(oldAfter, 0.0f);
    EXPECT_GT(oldAfter, 5.0f * oldBefore)
        << "floor where the block stood: " << oldBefore << " → " << oldAfter;
    EXPECT_LT(newAfter, 0.8f * newBefore)
        << "floor under the block's new place: " << newBefore << " → " << newAfter;
    // Some frame on the way said how the move was taken: the Cornell box's blocks would need
    // more motion links than the budget allows (Sec. 3.3), so the server rebuilt the links
    // and says why.
    bool noted = false;
    {
        std::lock_guard lock(watch.m);
        for (const auto& f : watch.frames)
            noted = noted || (f.note.find("links rebuilt: moved tall_block") == 0 &&
                              f.note.find("motion links were not built") != std::string::npos);
    }
    EXPECT_TRUE(noted);

    // Dim the light to a quarter: everything darkens to a quarter (light is linear).
    uint64_t dimEdit = editor.SetLight("ceiling_light", std::nullopt, 17.0f / 4.0f);
    EXPECT_GT(dimEdit, moveEdit);
    auto dimmed = watch.Until(dimEdit);
    ASSERT_TRUE(dimmed);
    for (const char* node : {"floor", "back_wall", "left_wall", "tall_block"}) {
        float before = MeanOf(*moved, node), after = MeanOf(*dimmed, node);
        EXPECT_NEAR(after, 0.25f * before, 0.01f * before) << node;
    }
    // The editor's Get sees the same state as the watcher's stream, in f16 too.
    client::Frame got = editor.Get(client::Channel::kIndirect, client::Format::kFloat16);
    EXPECT_GE(got.lastEdit, dimEdit);
    EXPECT_NEAR(MeanOf(got, "floor"), MeanOf(*dimmed, "floor"), 2e-3f * MeanOf(*dimmed, "floor"));
}

// A scene with a spot light, uploaded as .glb: SceneInfo lists the light, the three
// channels stream (total = direct + indirect), and SetLight moves and re-aims the spot.
TEST(ServerProcess, PunctualLightsOverTheWire) {
    ServerProcess server("punctual");
    SceneBuilder b;
    testing::AddWhiteCorner(b, 8, 4);
    PunctualLight spot;
    spot.name = "spot";
    spot.type = LightType::kSpot;
    spot.position = glm::vec3(0, 1, 0);
    spot.direction = glm::vec3(0, -1, 0);
    spot.innerCone = 0.4f;
    spot.outerCone = 0.6f;
    spot.intensity = 8.0f;
    b.AddLight(spot);
    auto dir = testing::TempDir("punctual-scene");
    std::string path = (dir / "spot.glb").string();
    b.WriteGltf(path);
    std::ifstream in(path, std::ios::binary);
    client::LoadOptions o;
    o.glb.assign(std::istreambuf_iterator<char>(in), {});
    o.name = "spot.glb";
    o.device = "cpu";
    o.solver = "antiradiance";
    o.solverOptions["bins"] = "64";
    o.elementSize = 0.1f;

    client::Client c(server.Unix(), "lights");
    client::SceneInfo info = c.Load(o);
    ASSERT_EQ(info.lights.size(), 1u);
    EXPECT_EQ(info.lights[0].name, "spot");
    EXPECT_EQ(info.lights[0].type, "spot");
    EXPECT_NEAR(info.lights[0].outerCone, 0.6f, 1e-6f);
    ASSERT_TRUE(info.Node("spot"));

    Watcher watch;
    c.Subscribe(std::ref(watch), client::Channel::kDirect);
    auto first = watch.Until(0);
    ASSERT_TRUE(first);
    // Under the spot: E = I / d² = 8 lux, in the floor's vertex nearest the origin.
    Scene scene = b.Build();
    const auto& floor = scene.primitives[0].positions;
    size_t under = 0;
    for (size_t i = 0; i < floor.size(); ++i)
        if (glm::length(floor[i]) < glm::length(floor[under])) under = i;
    ASSERT_EQ(first->primitives[0].node, "floor");
    EXPECT_NEAR(first->primitives[0].rgb[under * 3], 8.0f, 1e-3f);
    client::Frame direct = c.Get(client::Channel::kDirect);
    client::Frame indirect = c.Get(client::Channel::kIndirect);
    client::Frame total = c.Get(client::Channel::kTotal);
    ASSERT_EQ(total.primitives.size(), 2u);
    for (size_t p = 0; p < 2; ++p)
        for (size_t i = 0; i < total.primitives[p].rgb.size(); ++i)
            EXPECT_NEAR(total.primitives[p].rgb[i],
                        direct.primitives[p].rgb[i] + indirect.primitives[p].rgb[i], 1e-5f);
    EXPECT_GT(MeanOf(indirect, "wall"), 0.0f);
    EXPECT_EQ(MeanOf(direct, "wall"), 0.0f);  // the spot does not reach the wall

    // Raise the spot to 2 m and widen it: under it, E = 8 / 4.
    client::Client::LightChange change;
    change.position = std::array<float, 3>{0, 2, 0};
    change.innerCone = 0.5f;
    change.outerCone = 0.7f;
    uint64_t edit = c.SetLight("spot", change);
    auto moved = watch.Until(edit);
    ASSERT_TRUE(moved);
    EXPECT_NEAR(moved->primitives[0].rgb[under * 3], 2.0f, 1e-3f);
    EXPECT_NEAR(c.Info().lights[0].position[1], 2.0f, 1e-6f);
    // A cone wider than 90° is refused; the connection stays.
    change = {};
    change.outerCone = 2.0f;
    EXPECT_THROW(c.SetLight("spot", change), client::ClientError);
    EXPECT_EQ(c.Info().lights.size(), 1u);
}

// The environment at load time: a constant sky through the Cornell box's open front adds
// light (the same as a bake with that sky); a sky file must lie under the scene root.
TEST(ServerProcess, EnvironmentAtLoad) {
    ServerProcess server("environment");
    client::Client c(server.Unix(), "sky");
    client::LoadOptions o = Cornell();
    o.environmentColor = std::array<float, 3>{1.0f, 1.0f, 1.0f};
    o.environmentIntensity = 0.5f;
    client::SceneInfo info = c.Load(o);
    EXPECT_EQ(info.environment, "constant");
    EXPECT_FLOAT_EQ(info.environmentIntensity, 0.5f);
    c.Step(8);
    client::Frame lit = c.Get();

    Scene scene = LoadGltf(std::string(PENUMBRA_SOURCE_DIR) + "/scenes/cornell-box.gltf");
    scene.environment = ConstantEnvironment(glm::vec3(1.0f));
    scene.environment.intensity = 0.5f;
    SolverSettings s;
    s.solver = "antiradiance";
    s.prepareMoves = true;  // as the server builds scenes (service::ServiceDefaults)
    SetOption(s.options, "motion-link-budget", 1.0f);
    SetOption(s.options, "bins", 64);
    s.elementSize = 0.06f;
    s.device = DeviceChoice::kCpu;
    auto solver = CreateGatheredSolver(scene, s, {});  // as the server: gather on
    solver->Iterate(lit.iterations);
    std::vector<glm::vec3> want =
        PrimitiveIrradiance(solver->GetSurfels(), solver->SurfelIrradiance(), scene, 0);
    ASSERT_EQ(lit.primitives[0].node, "floor");
    ASSERT_EQ(lit.primitives[0].rgb.size(), want.size() * 3);
    for (size_t i = 0; i < want.size(); ++i)
        EXPECT_NEAR(lit.primitives[0].rgb[i * 3], want[i].x, 1e-4f * (1.0f + want[i].x));

    client::LoadOptions bad = Cornell();
    bad.reload = true;
    bad.environment = "../sky.exr";
    EXPECT_EQ(ErrorCodeOf([&] { c.Load(bad); }), int(fb::ErrorCode::OutsideRoot));
    bad.environment = "cornell-box.gltf";  // not an EXR
    EXPECT_EQ(ErrorCodeOf([&] { c.Load(bad); }), int(fb::ErrorCode::LoadFailed));
    bad.environment = "";
    bad.environmentColor = std::array<float, 3>{1.0f, -1.0f, 1.0f};
    EXPECT_EQ(ErrorCodeOf([&] { c.Load(bad); }), int(fb::ErrorCode::InvalidArgument));
    EXPECT_TRUE(c.Connected());
}

// The sky of a loaded session: SetEnvironment scales it, and gives a scene loaded without one
// its first sky (links rebuilt for back occlusion). Each converges to a solve of the scene with
// that sky; bad requests are refused and the connection kept.
TEST(ServerProcess, SkyChangedInALoadedSession) {
    ServerProcess server("sky-edit");
    client::Client c(server.Unix(), "sky");
    auto converged = [](float intensity) {
        Scene scene = LoadGltf(std::string(PENUMBRA_SOURCE_DIR) + "/scenes/cornell-box.gltf");
        scene.environment = ConstantEnvironment(glm::vec3(0.5f, 0.6f, 1.0f));
        scene.environment.intensity = intensity;
        SolverSettings s;
        s.solver = "antiradiance";
        s.prepareMoves = true;  // as the server builds scenes (service::ServiceDefaults)
        SetOption(s.options, "motion-link-budget", 1.0f);
        SetOption(s.options, "motion-link-budget", 1.0f);
        SetOption(s.options, "bins", 64);
        s.elementSize = 0.06f;
        s.device = DeviceChoice::kCpu;
        auto solver = CreateGatheredSolver(scene, s, {});  // as the server
        solver->Iterate(40);
        return PrimitiveIrradiance(solver->GetSurfels(), solver->SurfelIrradiance(), scene, 0);
    };
    auto expectClose = [](const client::Frame& f, const std::vector<glm::vec3>& want) {
        ASSERT_EQ(f.primitives[0].rgb.size(), want.size() * 3);
        double num = 0, den = 0;
        for (size_t i = 0; i < want.size(); ++i) {
            double d = f.primitives[0].rgb[i * 3 + 2] - want[i].z;
            num += d * d;
            den += double(want[i].z) * want[i].z;
        }
        EXPECT_LT(std::sqrt(num / den), 0.01);
    };
    // Loaded without a sky; the sky arrives as an edit (a link rebuild).
    c.Load(Cornell());
    client::Client::EnvironmentChange sky;
    sky.color = std::array<float, 3>{0.5f, 0.6f, 1.0f};
    sky.intensity = 2.0f;
    uint64_t edit = c.SetEnvironment(sky);
    EXPECT_GT(edit, 0u);
    // The rebuild runs on a thread; step until a frame includes it (at most a minute: on a
    // loaded 2-core machine it can take seconds).
    client::Frame f = c.Get();
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (f.lastEdit < edit && std::chrono::steady_clock::now() < deadline) {
        c.Step(1);
        f = c.Get();
    }
    EXPECT_GE(f.lastEdit, edit);
    c.Step(40);
    expectClose(c.Get(), converged(2.0f));
    // Dimmed and turned (a constant sky looks the same turned): re-binned in place.
    client::Client::EnvironmentChange dim;
    dim.intensity = 0.5f;
    dim.rotation = 1.0f;
    c.SetEnvironment(dim);
    c.Step(40);
    expectClose(c.Get(), converged(0.5f));

    client::Client::EnvironmentChange bad;
    bad.path = "../sky.exr";
    EXPECT_EQ(ErrorCodeOf([&] { c.SetEnvironment(bad); }), int(fb::ErrorCode::OutsideRoot));
    bad.path = "cornell-box.gltf";
    EXPECT_EQ(ErrorCodeOf([&] { c.SetEnvironment(bad); }), int(fb::ErrorCode::LoadFailed));
    bad = {};
    bad.off = true;
    bad.color = std::array<float, 3>{1.0f, 1.0f, 1.0f};
    EXPECT_EQ(ErrorCodeOf([&] { c.SetEnvironment(bad); }), int(fb::ErrorCode::InvalidArgument));
    bad = {};
    bad.intensity = std::nanf("");
    EXPECT_EQ(ErrorCodeOf([&] { c.SetEnvironment(bad); }), int(fb::ErrorCode::InvalidArgument));
    EXPECT_TRUE(c.Connected());
}

// Issue 62: a scene loaded with a sun and a clear sky, the sun moved live (SetEnvironment
// `sun`): the light turns, the clear sky follows it, and a frame including the edit comes.
TEST(ServerProcess, ASunAndItsClearSkyMoveLive) {
    ServerProcess server("sun-sky");
    client::Client c(server.Unix(), "sun");
    client::LoadOptions o = Cornell();
    o.solver = "";  // the default solver
    o.solverOptions.clear();
    o.sun = std::array<float, 3>{135.0f, 30.0f, 80000.0f};
    o.clearSky = true;
    client::SceneInfo info = c.Load(o);
    ASSERT_EQ(info.lights.size(), 1u);
    EXPECT_EQ(info.lights[0].name, "sun");
    EXPECT_EQ(info.lights[0].type, "directional");
    EXPECT_NEAR(info.lights[0].direction[1], -0.5f, 1e-5f);  // shining down from 30°
    EXPECT_NE(info.environment.find("Preetham, turbidity 3, sun at azimuth 135"), std::string::npos)
        << info.environment;
    c.Step(2);
    const client::Frame before = c.Get(client::Channel::kTotal);

    client::Client::EnvironmentChange move;
    move.sun = std::array<float, 2>{225.0f, 60.0f};
    move.sunIlluminance = 90000.0f;
    const uint64_t edit = c.SetEnvironment(move);
    client::Frame after = c.Get(client::Channel::kTotal);
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (after.lastEdit < edit && std::chrono::steady_clock::now() < deadline) {
        c.Step(1);
        after = c.Get(client::Channel::kTotal);
    }
    ASSERT_GE(after.lastEdit, edit);
    info = c.Info();
    const glm::vec3 to = SunDirection({225.0f, 60.0f});
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(info.lights[0].direction[k], -to[k], 1e-4f) << k;
    EXPECT_EQ(info.lights[0].intensity, 90000.0f);
    EXPECT_NE(info.environment.find("azimuth 225°, elevation 60°"), std::string::npos)
        << info.environment;
    double changed = 0;
    for (size_t i = 0; i < before.primitives[0].rgb.size(); ++i)
        changed += std::abs(after.primitives[0].rgb[i] - before.primitives[0].rgb[i]);
    EXPECT_GT(changed, 0.0);

    // A sun below the horizon, an unknown sky, a turbidity past the model: refused, the
    // connection kept; a scene without a sun has none to move.
    client::Client::EnvironmentChange bad;
    bad.sun = std::array<float, 2>{0.0f, -10.0f};
    EXPECT_EQ(ErrorCodeOf([&] { c.SetEnvironment(bad); }), int(fb::ErrorCode::InvalidArgument));
    bad = {};
    bad.clearSky = true;
    bad.turbidity = 25.0f;
    EXPECT_EQ(ErrorCodeOf([&] { c.SetEnvironment(bad); }), int(fb::ErrorCode::InvalidArgument));
    client::LoadOptions plain = Cornell();
    plain.path = "blocker.gltf";
    c.Load(plain);
    EXPECT_EQ(ErrorCodeOf([&] { c.SetEnvironment(move); }), int(fb::ErrorCode::NotFound));
    client::LoadOptions skyOnly = Cornell();
    skyOnly.reload = true;
    skyOnly.clearSky = true;  // a clear sky needs a sun
    EXPECT_EQ(ErrorCodeOf([&] { c.Load(skyOnly); }), int(fb::ErrorCode::InvalidArgument));
    EXPECT_TRUE(c.Connected());
}

TEST(ServerProcess, GarbageOnOneConnectionDoesNotDisturbAnother) {
    ServerProcess server("garbage");
    client::Client viewer(server.Unix(), "viewer");
    Watcher watch;
    ASSERT_TRUE(LoadAndWatch(viewer, watch));

    // The reply is an Error frame (bad magic), then the server closes the connection.
    std::string junk = "GET / HTTP/1.1\r\nHost: x\r\n\r\n";
    bool closed = false;
    protocol::Message m = RawExchange(server, {junk.begin(), junk.end()}, &closed);
    EXPECT_TRUE(closed);
    ASSERT_EQ(m.header.type, protocol::MessageType::kError);
    EXPECT_EQ(m.As<fb::Error>()->code(), fb::ErrorCode::BadMagic);

    // Meanwhile the viewer keeps receiving frames for a new edit.
    uint64_t edit = viewer.SetLight("ceiling_light", std::array<float, 3>{1, 1, 1}, 10.0f);
    EXPECT_TRUE(watch.Until(edit));
}

TEST(ServerProcess, OversizedFrameGetsAnErrorAndTheConnectionCloses) {
    ServerProcess server("oversized", "--max-frame-bytes 4096");
    // A header announcing 1 MiB: refused from the header alone, before any payload.
    std::vector<uint8_t> header = {'P', 'N', 'B', 'R', 1, 0, 10, 0, 0, 0, 16, 0, 7, 0, 0, 0};
    bool closed = false;
    protocol::Message m = RawExchange(server, header, &closed);
    EXPECT_TRUE(closed);
    EXPECT_EQ(m.header.requestId, 7u);
    EXPECT_EQ(m.As<fb::Error>()->code(), fb::ErrorCode::TooLarge);
    EXPECT_NE(std::string(m.As<fb::Error>()->message()->c_str()).find("4096"), std::string::npos);
}

// Issue 24: a client that sends half a frame and stalls holds nothing for long: after
// --frame-timeout it gets Error Stalled and is closed; the server keeps serving the others.
TEST(ServerProcess, AStalledHalfFrameTimesOut) {
    ServerProcess server("stalled", "--frame-timeout 1");
    const std::vector<uint8_t> half = {'P', 'N', 'B', 'R', 1, 0, 1, 0};
    const auto start = std::chrono::steady_clock::now();
    bool closed = false;
    protocol::Message m = RawExchange(server, half, &closed);
    const double waited =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    EXPECT_TRUE(closed);
    ASSERT_EQ(m.header.type, protocol::MessageType::kError);
    EXPECT_EQ(m.As<fb::Error>()->code(), fb::ErrorCode::Stalled);
    EXPECT_NE(std::string(m.As<fb::Error>()->message()->c_str()).find("--frame-timeout"),
              std::string::npos);
    EXPECT_GE(waited, 0.9);
    client::Client after(server.Unix(), "after");
    EXPECT_EQ(after.ProtocolVersion(), 1);
}

// Issue 63: connections that never speak hold a client slot no longer than --hello-timeout:
// with every slot taken by silent sockets a new client is refused (LimitReached, counted),
// then each silent one gets Error HelloRequired and is closed, and clients get in again.
TEST(ServerProcess, SilentConnectionsCannotHoldTheSlots) {
    ServerProcess server("silent", "--max-clients 3 --hello-timeout 2");
    asio::io_context io;
    std::vector<asio::local::stream_protocol::socket> silent;
    const auto start = std::chrono::steady_clock::now();  // before the server accepts them
    for (int i = 0; i < 3; ++i) {
        silent.emplace_back(io);
        silent.back().connect(asio::local::stream_protocol::endpoint(server.SocketPath()));
    }
    std::string message;
    const int refused = ErrorCodeOf([&] { client::Client c(server.Unix(), "early"); }, &message);
    EXPECT_EQ(refused, int(fb::ErrorCode::LimitReached)) << message;
    for (auto& raw : silent) {
        bool closed = false;
        protocol::Message m = ReadUntilClosed(raw, &closed);
        EXPECT_TRUE(closed);
        ASSERT_EQ(m.header.type, protocol::MessageType::kError);
        EXPECT_EQ(m.As<fb::Error>()->code(), fb::ErrorCode::HelloRequired);
        EXPECT_NE(std::string(m.As<fb::Error>()->message()->c_str()).find("--hello-timeout"),
                  std::string::npos);
    }
    EXPECT_GE(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(), 1.9);
    client::Client after(server.Unix(), "after");
    EXPECT_EQ(after.ProtocolVersion(), 1);
    const nlohmann::json stats = nlohmann::json::parse(after.Stats(""));
    const nlohmann::json& net = stats.contains("server") ? stats["server"] : stats;
    EXPECT_EQ(net.value("hello_timeouts", 0), 3) << stats.dump();
    EXPECT_EQ(net.value("refused_full", 0), 1) << stats.dump();
}

// Issue 63: one host cannot take every slot: past --max-clients-per-address TCP connections
// from one address, the next gets LimitReached naming the address (logged, counted); a Unix
// socket's clients are not counted, and a closed connection frees its address's slot.
TEST(ServerProcess, OneAddressCannotTakeEverySlot) {
    ServerProcess server("per-address", "--max-clients-per-address 2");
    std::vector<std::unique_ptr<client::Client>> held;
    held.push_back(std::make_unique<client::Client>(server.Tcp(), "first"));
    held.push_back(std::make_unique<client::Client>(server.Tcp(), "second"));
    std::string message;
    EXPECT_EQ(ErrorCodeOf([&] { client::Client c(server.Tcp(), "third"); }, &message),
              int(fb::ErrorCode::LimitReached))
        << message;
    EXPECT_NE(message.find("clients from 127.0.0.1 (--max-clients-per-address)"), std::string::npos)
        << message;
    client::Client local(server.Unix(), "local");  // not counted
    held.pop_back();                               // closes: its slot is free again
    std::unique_ptr<client::Client> again;
    for (int i = 0; i < 100 && !again; ++i) {  // the server forgets it once it sees the close
        try {
            again = std::make_unique<client::Client>(server.Tcp(), "again");
        } catch (const std::exception&) {
            std::this_thread::sleep_for(std::chrono::milliseconds(20));
        }
    }
    ASSERT_TRUE(again) << server.Log();
    const nlohmann::json stats = nlohmann::json::parse(local.Stats(""));
    const nlohmann::json& net = stats.contains("server") ? stats["server"] : stats;
    EXPECT_GE(net.value("refused_address", 0), 1) << stats.dump();
    EXPECT_NE(server.Log().find("refused a connection: LimitReached"), std::string::npos);
}

// Issue 63: a scene nobody holds any more makes room for the next. At --max-scenes, a load
// drops the scene loaded longest ago that no connected client loaded or joined and nobody
// watches (logged, counted); while its loader is connected the next load is refused.
TEST(ServerProcess, ASceneNobodyHoldsMakesRoomForTheNext) {
    ServerProcess server("evict", "--max-scenes 1");
    client::LoadOptions blocker;
    blocker.path = "blocker.gltf";
    blocker.device = "cpu";
    blocker.elementSize = 0.2f;
    {
        client::Client a(server.Unix(), "first");
        a.Load(Cornell());
        client::Client b(server.Unix(), "second");
        std::string message;
        EXPECT_EQ(ErrorCodeOf([&] { b.Load(blocker); }, &message), int(fb::ErrorCode::LimitReached))
            << message;
        EXPECT_NE(message.find("held by a connected client"), std::string::npos) << message;
    }  // both leave: nobody holds the Cornell box
    client::Client c(server.Unix(), "third");
    client::SceneInfo info;
    for (int i = 0; i < 100 && info.scene.empty(); ++i) {  // once the server saw them close
        try {
            info = c.Load(blocker);
        } catch (const std::exception&) {
            std::this_thread::sleep_for(std::chrono::milliseconds(20));
        }
    }
    EXPECT_EQ(info.scene, "blocker.gltf") << server.Log();
    EXPECT_NE(server.Log().find("evicted cornell-box.gltf to make room"), std::string::npos)
        << server.Log();
    const nlohmann::json stats = nlohmann::json::parse(c.Stats(""));
    EXPECT_EQ(stats.value("evicted_scenes", 0), 1) << stats.dump();
    ASSERT_EQ(stats["scenes"].size(), 1u) << stats.dump();
}

// Issue 63: a scene's owner (the client that loaded it) unloads it; another client may not
// while the owner is connected, nor reload it; a subscriber is told (Error NoScene, no more
// frames) and keeps its connection; once the owner has gone anyone may unload.
TEST(ServerProcess, OnlyTheOwnerUnloadsItsSceneAndSubscribersAreTold) {
    ServerProcess server("unload");
    client::Client owner(server.Unix(), "owner");
    owner.Load(Cornell());
    client::Client viewer(server.Unix(), "viewer");
    client::Client other(server.Unix(), "other");
    std::mutex m;
    std::condition_variable cv;
    std::string why;
    int frames = 0;
    viewer.Subscribe(
        [&](const client::Frame&) {
            std::lock_guard lock(m);
            ++frames;
        },
        client::Channel::kIndirect, client::Format::kFloat32, "cornell-box.gltf",
        [&](const std::string& reason) {
            std::lock_guard lock(m);
            why = reason;
            cv.notify_all();
        });
    std::string message;
    EXPECT_EQ(ErrorCodeOf([&] { other.UnloadScene("cornell-box.gltf"); }, &message),
              int(fb::ErrorCode::Forbidden))
        << message;
    EXPECT_NE(message.find("loaded by another client"), std::string::npos) << message;
    client::LoadOptions reload = Cornell();
    reload.reload = true;
    EXPECT_EQ(ErrorCodeOf([&] { other.Load(reload); }, &message), int(fb::ErrorCode::Forbidden))
        << message;

    owner.UnloadScene("cornell-box.gltf");
    {
        std::unique_lock lock(m);
        ASSERT_TRUE(cv.wait_for(lock, std::chrono::seconds(10), [&] { return !why.empty(); }))
            << server.Log();
    }
    EXPECT_NE(why.find("cornell-box.gltf' was unloaded"), std::string::npos) << why;
    int seen;
    {
        std::lock_guard lock(m);
        seen = frames;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    {
        std::lock_guard lock(m);
        EXPECT_EQ(frames, seen) << "frames after the scene went";
    }
    EXPECT_TRUE(viewer.Connected());
    EXPECT_EQ(ErrorCodeOf([&] { viewer.Step(1, "cornell-box.gltf"); }, &message),
              int(fb::ErrorCode::NoScene))
        << message;
    const nlohmann::json stats = nlohmann::json::parse(viewer.Stats(""));
    EXPECT_EQ(stats.value("unloaded_scenes", 0), 1) << stats.dump();
    EXPECT_EQ(stats["scenes"].size(), 0u) << stats.dump();

    // Loaded again by the owner, who then leaves: now anyone may unload it.
    owner.Load(Cornell());
    owner.Close();
    bool unloaded = false;
    for (int i = 0; i < 100 && !unloaded; ++i) {  // once the server saw the owner go
        try {
            other.UnloadScene("cornell-box.gltf");
            unloaded = true;
        } catch (const std::exception&) {
            std::this_thread::sleep_for(std::chrono::milliseconds(20));
        }
    }
    EXPECT_TRUE(unloaded) << server.Log();
    EXPECT_NE(server.Log().find("unloaded cornell-box.gltf"), std::string::npos) << server.Log();
}

// Issue 63: one client owns at most --max-scenes-per-client scenes (2 by default): a third
// load of its own is refused with the limit named until it unloads one; joins do not count.
TEST(ServerProcess, OneClientCannotOwnEverySceneSlot) {
    ServerProcess server("quota", "--max-scenes 4");
    auto coarse = [](const std::string& path) {
        client::LoadOptions o;
        o.path = path;
        o.device = "cpu";
        o.elementSize = 0.3f;
        return o;
    };
    client::Client greedy(server.Unix(), "greedy");
    greedy.Load(coarse("blocker.gltf"));
    greedy.Load(coarse("maze.gltf"));
    std::string message;
    EXPECT_EQ(ErrorCodeOf([&] { greedy.Load(coarse("glossy-box.gltf")); }, &message),
              int(fb::ErrorCode::LimitReached))
        << message;
    EXPECT_NE(message.find("--max-scenes-per-client 2"), std::string::npos) << message;
    client::Client other(server.Unix(), "other");
    EXPECT_TRUE(other.Load(coarse("maze.gltf")).reused);  // a join takes no slot of its own
    other.Load(coarse("glossy-box.gltf"));
    greedy.UnloadScene("blocker.gltf");
    EXPECT_TRUE(greedy.Load(coarse("glossy-box.gltf")).reused);
    EXPECT_EQ(greedy.Load(coarse("cornell-box.gltf")).scene, "cornell-box.gltf");
}

// Issue 63: with --scene-idle-timeout a scene that no connected client loaded or joined and
// nobody watches is dropped after that long (logged, stats expired_scenes); one a connected
// client holds stays.
TEST(ServerProcess, AnIdleSceneIsDroppedAHeldOneStays) {
    ServerProcess server("idle-scene", "--scene-idle-timeout 1");
    client::LoadOptions blocker;
    blocker.path = "blocker.gltf";
    blocker.device = "cpu";
    blocker.elementSize = 0.2f;
    {
        client::Client gone(server.Unix(), "gone");
        gone.Load(blocker);
    }  // leaves: nobody holds the blocker
    client::Client stays(server.Unix(), "stays");
    stays.Load(Cornell());
    nlohmann::json stats;
    for (int i = 0; i < 200; ++i) {  // the blocker goes after about a second
        stats = nlohmann::json::parse(stays.Stats(""));
        if (stats["scenes"].size() == 1) break;
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    ASSERT_EQ(stats["scenes"].size(), 1u) << stats.dump() << server.Log();
    EXPECT_EQ(stats["scenes"][0].value("scene", ""), "cornell-box.gltf") << stats.dump();
    EXPECT_EQ(stats.value("expired_scenes", 0), 1) << stats.dump();
    EXPECT_NE(server.Log().find("dropped blocker.gltf: no client held or watched it"),
              std::string::npos)
        << server.Log();
    std::this_thread::sleep_for(std::chrono::milliseconds(1500));  // held: it stays
    stats = nlohmann::json::parse(stays.Stats(""));
    EXPECT_EQ(stats["scenes"].size(), 1u) << stats.dump();
}

// Issue 62: refined output over the socket. LoadScene's refine subdivides the scene before it
// is lit; SceneInfo carries each refined primitive's vertices and triangles (every edge within
// the bound), and the frames' values are on those vertices.
TEST(ServerProcess, ARefinedSceneStreamsItsRefinedMeshes) {
    ServerProcess server("refined");
    client::Client c(server.Unix(), "refined");
    client::LoadOptions load;
    load.path = "blocker.gltf";
    load.device = "cpu";
    load.refine = 0.1f;
    const client::SceneInfo info = c.Load(load);
    ASSERT_FALSE(info.refined.empty()) << server.Log();
    client::Frame frame = c.Get(client::Channel::kIndirect, client::Format::kFloat32);
    for (const client::RefinedPrimitive& r : info.refined) {
        const size_t vertices = r.positions.size() / 3;
        ASSERT_EQ(r.normals.size(), r.positions.size());
        ASSERT_EQ(r.parentTriangles.size() * 3, r.indices.size());
        for (size_t t = 0; t < r.indices.size(); ++t) {
            ASSERT_LT(r.indices[t], vertices);
            const uint32_t a = r.indices[t], b = r.indices[t - t % 3 + (t + 1) % 3];
            const glm::vec3 pa(r.positions[3 * a], r.positions[3 * a + 1], r.positions[3 * a + 2]);
            const glm::vec3 pb(r.positions[3 * b], r.positions[3 * b + 1], r.positions[3 * b + 2]);
            ASSERT_LE(glm::distance(pa, pb), 0.1f + 1e-5f);  // the nodes here are not scaled
        }
        auto it =
            std::find_if(frame.primitives.begin(), frame.primitives.end(), [&](const auto& p) {
                return p.node == r.node && p.mesh == r.mesh && p.primitive == r.primitive;
            });
        ASSERT_NE(it, frame.primitives.end()) << r.node;
        EXPECT_EQ(it->rgb.size(), 3 * vertices) << r.node;
        const client::NodeInfo* node = info.Node(r.node);
        ASSERT_NE(node, nullptr);
    }
    // A refine that is not a length is refused before anything loads.
    load.refine = -1.0f;
    load.reload = true;
    EXPECT_THROW(c.Load(load), client::ClientError);
}

// Issue 63: a server whose scenes come and go gives their memory back. Each round loads four
// scenes on new threads (their builds and workers) and unloads them; the server's resident
// memory after the fourth round is where it was after the first (with glibc's default
// thresholds, raised by the office's large blocks, its per-thread arenas kept ~5 MiB a round).
TEST(ServerProcess, DroppedScenesGiveTheirMemoryBack) {
    ServerProcess server("memory-back");
    auto rssMiB = [&] {
        std::ifstream in("/proc/" + std::to_string(server.Pid()) + "/status");
        for (std::string line; std::getline(in, line);)
            if (line.rfind("VmRSS:", 0) == 0) return std::stod(line.substr(6)) / 1024.0;
        return 0.0;
    };
    auto round = [&] {  // two scenes at a time: --max-scenes-per-client
        client::Client c(server.Unix(), "loader");
        for (auto pair : {std::array{"office.gltf", "maze.gltf"},
                          std::array{"blocker.gltf", "cornell-box.gltf"}}) {
            for (const char* path : pair) {
                client::LoadOptions load;
                load.path = path;
                load.device = "cpu";
                c.Load(load);
                c.Step(20, path);  // its worker at work
            }
            for (const char* path : pair) c.UnloadScene(path);
        }
    };
    round();
    const double first = rssMiB();
    ASSERT_GT(first, 0.0);
    for (int i = 0; i < 3; ++i) round();
    EXPECT_LT(rssMiB() - first, 6.0) << "after one round " << first << " MiB, now " << rssMiB();
}

// The response to one HTTP GET of `path` from `url` (http://HOST:PORT), whole.
std::string HttpGet(const std::string& url, const std::string& path) {
    const std::string hostPort = url.substr(7);
    const size_t colon = hostPort.rfind(':');
    asio::io_context io;
    asio::ip::tcp::socket socket(io);
    socket.connect({asio::ip::make_address(hostPort.substr(0, colon)),
                    uint16_t(std::stoi(hostPort.substr(colon + 1)))});
    const std::string request = "GET " + path + " HTTP/1.1\r\nHost: x\r\n\r\n";
    asio::write(socket, asio::buffer(request));
    std::string response;
    std::error_code ec;
    asio::read(socket, asio::dynamic_buffer(response), ec);  // until the server closes
    return response;
}

// Issue 63: --metrics serves Prometheus text with the clients, scenes and frames, and health
// and readiness for a supervisor; the protocol's clients are unaffected.
TEST(ServerProcess, MetricsAndHealthOverHttp) {
    ServerProcess server("metrics", "--metrics tcp://127.0.0.1:0");
    ASSERT_FALSE(server.Http().empty()) << server.Log();
    client::Client c(server.Unix(), "watched");
    const std::string material = c.Load(Cornell()).materials.at(0).name;
    c.Step(2);
    // Two edits: each one's time to its first frame goes into the edit-to-frame histogram.
    c.SetMaterial(material, std::array{0.5f, 0.5f, 0.5f}, {});
    const uint64_t edit = c.SetMaterial(material, std::array{0.6f, 0.6f, 0.6f}, {});
    for (int i = 0; i < 500 && c.Get().lastEdit < edit; ++i)
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    ASSERT_GE(c.Get().lastEdit, edit);
    EXPECT_EQ(HttpGet(server.Http(), "/healthz").rfind("HTTP/1.1 200 OK", 0), 0u);
    EXPECT_NE(HttpGet(server.Http(), "/readyz").find("\r\n\r\nready"), std::string::npos);
    const std::string metrics = HttpGet(server.Http(), "/metrics");
    EXPECT_EQ(metrics.rfind("HTTP/1.1 200 OK", 0), 0u) << metrics;
    EXPECT_NE(metrics.find("text/plain; version=0.0.4"), std::string::npos) << metrics;
    EXPECT_NE(metrics.find("\npenumbra_clients 1\n"), std::string::npos) << metrics;
    EXPECT_NE(metrics.find("\npenumbra_scenes 1\n"), std::string::npos) << metrics;
    EXPECT_NE(metrics.find("penumbra_scene_frames_total{scene=\"cornell-box.gltf\"}"),
              std::string::npos)
        << metrics;
    EXPECT_NE(metrics.find("penumbra_refused_connections_total{reason=\"hello_timeout\"} 0"),
              std::string::npos)
        << metrics;
    const std::string scene = "{scene=\"cornell-box.gltf\"";
    EXPECT_NE(metrics.find("# TYPE penumbra_edit_to_frame_seconds histogram"), std::string::npos)
        << metrics;
    EXPECT_NE(metrics.find("penumbra_edit_to_frame_seconds_count" + scene + "} 2\n"),
              std::string::npos)
        << metrics;
    EXPECT_NE(metrics.find("penumbra_edit_to_frame_seconds_bucket" + scene + ",le=\"+Inf\"} 2\n"),
              std::string::npos)
        << metrics;
    // The buckets count up to the total: the one at 30 s holds both edits.
    EXPECT_NE(metrics.find("penumbra_edit_to_frame_seconds_bucket" + scene + ",le=\"30\"} 2\n"),
              std::string::npos)
        << metrics;
    EXPECT_NE(metrics.find("penumbra_frame_seconds_count" + scene + "}"), std::string::npos)
        << metrics;
    EXPECT_EQ(HttpGet(server.Http(), "/nothing").rfind("HTTP/1.1 404", 0), 0u);
    EXPECT_TRUE(c.Connected());
}

// Issue 63: a connection that sends nothing, subscribes to nothing and waits on nothing is
// closed after --idle-timeout (Error Stalled, counted); a subscriber stays, however quiet.
TEST(ServerProcess, IdleConnectionsCloseSubscribersStay) {
    ServerProcess server("idle", "--idle-timeout 1");
    client::Client quiet(server.Unix(), "quiet");
    client::Client viewer(server.Unix(), "viewer");
    viewer.Load(Cornell());  // a request in progress holds the deadline off, as a subscription
    viewer.Subscribe([](const client::Frame&) {});
    std::this_thread::sleep_for(std::chrono::milliseconds(2500));
    std::string message;
    EXPECT_EQ(ErrorCodeOf([&] { quiet.Stats(""); }, &message), int(fb::ErrorCode::Stalled))
        << message;
    EXPECT_NE(message.find("--idle-timeout"), std::string::npos) << message;
    const nlohmann::json stats = nlohmann::json::parse(viewer.Stats(""));
    const nlohmann::json& net = stats.contains("server") ? stats["server"] : stats;
    EXPECT_EQ(net.value("idle_timeouts", 0), 1) << stats.dump();
}

// Issue 63: a load that fails names the file relative to the scene root, never the server's
// own paths (its root, its temporary files).
// Issue 63: limits before work. A file that declares more triangles than
// --max-scene-triangles, or buffers past --max-scene-bytes, is refused (LimitReached) from its
// JSON alone, before its buffers are read: here the buffer it declares (1 TB) does not exist.
TEST(ServerProcess, DeclaredSizesAreCheckedBeforeReading) {
    const auto root = testing::TempDir("declared-root");
    const std::string mesh =
        R"("meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
           "nodes": [{"mesh": 0}, {"mesh": 0}], "scenes": [{"nodes": [0, 1]}],
           "accessors": [{"count": 4, "componentType": 5126, "type": "VEC3"},
                         {"count": 3000, "componentType": 5125, "type": "SCALAR"}], )";
    std::ofstream(root / "huge.gltf")
        << R"({"asset": {"version": "2.0"}, )" << mesh
        << R"("buffers": [{"byteLength": 1000000000000, "uri": "nowhere.bin"}]})";
    std::ofstream(root / "many.gltf")
        << R"({"asset": {"version": "2.0"}, )" << mesh
        << R"("buffers": [{"byteLength": 12, "uri": "nowhere.bin"}]})";
    ServerProcess server("declared", "--max-scene-triangles 1500", "penumbra-server",
                         root.string());
    client::Client c(server.Unix(), "loader");
    client::LoadOptions o;
    o.device = "cpu";
    std::string message;
    o.path = "huge.gltf";
    EXPECT_EQ(ErrorCodeOf([&] { c.Load(o); }, &message), int(fb::ErrorCode::LimitReached));
    EXPECT_NE(message.find("huge.gltf: its buffers declare 1000000000000 bytes"), std::string::npos)
        << message;
    o.path = "many.gltf";  // 1,000 triangles, placed by two nodes
    EXPECT_EQ(ErrorCodeOf([&] { c.Load(o); }, &message), int(fb::ErrorCode::LimitReached));
    EXPECT_NE(message.find("many.gltf: its accessors declare 2000 triangles"), std::string::npos)
        << message;
    EXPECT_NE(message.find("--max-scene-triangles"), std::string::npos) << message;
}

// Issue 63: images are bounded before they are read or decoded: a file past --max-scene-bytes
// is not read, and a small PNG whose header claims 10,000 × 10,000 pixels (1.6 GB decoded) is
// refused from its header.
TEST(ServerProcess, ImageSizesAreCheckedBeforeReading) {
    const auto root = testing::TempDir("image-root");
    {
        std::ofstream bin(root / "tri.bin", std::ios::binary);
        const float data[] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 1};
        bin.write(reinterpret_cast<const char*>(data), sizeof data);  // 3 positions, 3 uvs
    }
    auto scene = [&](const std::string& name, const std::string& image) {
        std::ofstream(root / name)
            << R"({"asset": {"version": "2.0"}, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
              "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1},
                                          "material": 0}]}],
              "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
              "textures": [{"source": 0}], "images": [{"uri": ")"
            << image << R"("}],
              "buffers": [{"byteLength": 60, "uri": "tri.bin"}],
              "bufferViews": [{"buffer": 0, "byteLength": 36}, {"buffer": 0, "byteOffset": 36, "byteLength": 24}],
              "accessors": [{"bufferView": 0, "count": 3, "componentType": 5126, "type": "VEC3",
                             "min": [0, 0, 0], "max": [1, 1, 0]},
                            {"bufferView": 1, "count": 3, "componentType": 5126, "type": "VEC2"}]})";
    };
    // A PNG's signature and IHDR (10000 × 10000, 8-bit RGB): all stb_image reads for its size.
    const unsigned char bomb[] = {0x89, 'P',  'N', 'G', 0x0d, 0x0a, 0x1a, 0x0a, 0,    0, 0,
                                  13,   'I',  'H', 'D', 'R',  0,    0,    0x27, 0x10, 0, 0,
                                  0x27, 0x10, 8,   2,   0,    0,    0,    0,    0,    0, 0};
    std::ofstream(root / "bomb.png", std::ios::binary)
        .write(reinterpret_cast<const char*>(bomb), sizeof bomb);
    std::ofstream(root / "big.png", std::ios::binary) << std::string(2'000'000, 'x');
    scene("bomb.gltf", "bomb.png");
    scene("big.gltf", "big.png");
    ServerProcess server("image-limits", "--max-scene-bytes 1000000", "penumbra-server",
                         root.string());
    client::Client c(server.Unix(), "loader");
    client::LoadOptions o;
    o.device = "cpu";
    std::string message;
    o.path = "bomb.gltf";
    EXPECT_EQ(ErrorCodeOf([&] { c.Load(o); }, &message), int(fb::ErrorCode::LimitReached));
    EXPECT_NE(message.find("is 10000 × 10000 pixels"), std::string::npos) << message;
    o.path = "big.gltf";
    EXPECT_EQ(ErrorCodeOf([&] { c.Load(o); }, &message), int(fb::ErrorCode::LimitReached));
    EXPECT_NE(message.find("big.png' is 2000000 bytes; the limit is 1000000"), std::string::npos)
        << message;
    EXPECT_TRUE(c.Connected());
}

TEST(ServerProcess, LoadErrorsNameFilesRelativeToTheRoot) {
    const auto root = testing::TempDir("relative-root");
    std::filesystem::create_directories(root / "rooms");
    std::ofstream(root / "rooms" / "broken.gltf") << "{\"asset\": {\"version\": \"2.0\"}, ";
    ServerProcess server("relative", "", "penumbra-server", root.string());
    client::Client c(server.Unix(), "loader");
    client::LoadOptions o;
    o.path = "rooms/broken.gltf";
    o.device = "cpu";
    std::string message;
    EXPECT_EQ(ErrorCodeOf([&] { c.Load(o); }, &message), int(fb::ErrorCode::LoadFailed));
    EXPECT_NE(message.find("rooms/broken.gltf"), std::string::npos) << message;
    EXPECT_EQ(message.find(root.string()), std::string::npos) << message;
    client::LoadOptions upload;
    upload.glb = {'g', 'l', 'T', 'F', 2, 0, 0, 0, 12, 0, 0, 0};
    upload.name = "mine.glb";
    upload.device = "cpu";
    EXPECT_EQ(ErrorCodeOf([&] { c.Load(upload); }, &message), int(fb::ErrorCode::LoadFailed));
    EXPECT_EQ(message.find("penumbra-upload-"), std::string::npos) << message;
}

// Issue 24: an uploaded .glb whose buffer names a file (here one the server could read)
// is refused: an upload must hold everything it uses, nothing on the server's disk is read.
TEST(ServerProcess, AnUploadCannotReadTheServersFiles) {
    ServerProcess server("upload-uri");
    std::ifstream in(std::string(PENUMBRA_SOURCE_DIR) + "/scenes/cornell-box.gltf");
    nlohmann::json doc = nlohmann::json::parse(in);
    doc["buffers"][0]["uri"] = "../../../../../../etc/hostname";
    client::LoadOptions o;
    o.glb = GlbOf(doc);
    o.name = "reader.glb";
    o.device = "cpu";
    client::Client c(server.Unix(), "uploader");
    std::string message;
    EXPECT_EQ(ErrorCodeOf([&] { c.Load(o); }, &message), int(fb::ErrorCode::LoadFailed));
    EXPECT_NE(message.find("etc/hostname' refused: an uploaded .glb must hold its buffers"),
              std::string::npos)
        << message;
    // The server goes on serving.
    EXPECT_EQ(c.Load(Cornell()).nodes.empty(), false);
}

// Issue 23, part 3: what the scene's answer leaves out reaches the client (SceneInfo
// `warnings`, `penumbra info`) and the server's log, which also has a line for each load and
// each refusal.
TEST(ServerProcess, SceneInfoCarriesTheScenesWarnings) {
    ServerProcess server("warnings");
    std::ifstream in(std::string(PENUMBRA_SOURCE_DIR) + "/scenes/cornell-box.gltf");
    nlohmann::json doc = nlohmann::json::parse(in);
    doc["extensionsUsed"] = {"KHR_materials_clearcoat"};
    for (auto& m : doc["materials"]) m.erase("emissiveFactor");
    client::LoadOptions o = Cornell();
    o.path.clear();
    o.glb = GlbOf(doc);
    o.name = "dark.glb";
    client::Client c(server.Unix(), "warned");
    const client::SceneInfo info = c.Load(o);
    std::string all;
    for (const auto& w : info.warnings) all += w + "\n";
    EXPECT_NE(all.find("extension 'KHR_materials_clearcoat' ignored"), std::string::npos) << all;
    EXPECT_NE(all.find("no light"), std::string::npos) << all;
    EXPECT_EQ(c.Info().warnings.size(), info.warnings.size());
    EXPECT_TRUE(c.Load(Cornell()).warnings.empty());
    o.path = "no-such.gltf";
    o.glb.clear();
    EXPECT_EQ(ErrorCodeOf([&] { c.Load(o); }), int(fb::ErrorCode::NotFound));

    const std::string log = server.Log();
    EXPECT_NE(log.find("client 1 'warned': loaded dark.glb (solver antiradiance on cpu"),
              std::string::npos)
        << log;
    EXPECT_NE(log.find("warning: dark.glb: no light"), std::string::npos) << log;
    EXPECT_NE(log.find("client 1 'warned': NotFound: "), std::string::npos) << log;
}

// Issue 24, part 6: symlinks under --scene-root that lead out of it (a scene, a sky) are
// refused like "..", for LoadScene and SetEnvironment; one that stays inside is followed.
TEST(ServerProcess, SymlinksOutOfTheSceneRootAreRefused) {
    namespace fs = std::filesystem;
    const fs::path dir = testing::TempDir("symlinked-root");
    const fs::path root = dir / "root", outside = dir / "outside";
    fs::create_directories(root);
    fs::create_directories(outside);
    const fs::path scene = fs::path(PENUMBRA_SOURCE_DIR) / "scenes" / "cornell-box.gltf";
    fs::copy_file(scene, root / "inside.gltf");
    fs::copy_file(scene, outside / "secret.gltf");
    std::ofstream(outside / "sky.exr") << "not read";
    fs::create_symlink(outside / "secret.gltf", root / "out.gltf");
    fs::create_symlink(outside / "sky.exr", root / "sky.exr");
    fs::create_symlink(root / "inside.gltf", root / "alias.gltf");
    fs::create_directory_symlink(outside, root / "door");

    ServerProcess server("symlinks", "", "penumbra-server", root.string());
    client::Client c(server.Unix());
    client::LoadOptions o = Cornell();
    for (const char* path : {"out.gltf", "door/secret.gltf"}) {
        o.path = path;
        std::string message;
        EXPECT_EQ(ErrorCodeOf([&] { c.Load(o); }, &message), int(fb::ErrorCode::OutsideRoot))
            << path;
        EXPECT_NE(message.find("outside the scene root"), std::string::npos) << message;
    }
    o.path = "inside.gltf";
    o.environment = "sky.exr";
    EXPECT_EQ(ErrorCodeOf([&] { c.Load(o); }), int(fb::ErrorCode::OutsideRoot));
    o.environment.clear();
    o.path = "alias.gltf";
    EXPECT_NO_THROW(c.Load(o));
    client::Client::EnvironmentChange sky;
    sky.path = "sky.exr";
    EXPECT_EQ(ErrorCodeOf([&] { c.SetEnvironment(sky); }), int(fb::ErrorCode::OutsideRoot));
    sky.path = "door/sky.exr";
    EXPECT_EQ(ErrorCodeOf([&] { c.SetEnvironment(sky); }), int(fb::ErrorCode::OutsideRoot));
}

// A connection that speaks raw frames, for requests the client library would never send.
struct RawConnection {
    asio::io_context io;
    asio::local::stream_protocol::socket socket{io};
    protocol::Decoder decoder;
    explicit RawConnection(const ServerProcess& server) {
        socket.connect(asio::local::stream_protocol::endpoint(server.SocketPath()));
    }
    // Sends one frame and returns the next message that arrives.
    protocol::Message Exchange(protocol::MessageType type, uint32_t id,
                               const std::vector<uint8_t>& payload) {
        std::vector<uint8_t> bytes;
        protocol::AppendFrame(bytes, type, id, payload);
        asio::write(socket, asio::buffer(bytes));
        protocol::Message m;
        std::vector<uint8_t> buf(1 << 16);
        while (decoder.Next(m) == protocol::Decoder::Result::kNeedMore) {
            const size_t n = socket.read_some(asio::buffer(buf));
            decoder.Feed(buf.data(), n);
        }
        return m;
    }
};

std::vector<uint8_t> Bytes(const flatbuffers::FlatBufferBuilder& b) {
    return {b.GetBufferPointer(), b.GetBufferPointer() + b.GetSize()};
}

TEST(ServerProcess, RequestsBeforeHelloAreRefused) {
    ServerProcess server("hello");
    RawConnection raw(server);
    flatbuffers::FlatBufferBuilder b;
    b.Finish(fb::CreateGetStatsDirect(b, ""));
    const protocol::Message m = raw.Exchange(protocol::MessageType::kGetStats, 3, Bytes(b));
    EXPECT_EQ(m.As<fb::Error>()->code(), fb::ErrorCode::HelloRequired);
}

// Issue 23, part 7: protocol traps a client written from SPEC.md falls into. A request with
// id 0 (the id of pushed frames) is refused and the connection stays; an empty payload is
// the table with its defaults; "" names the scene this connection loaded, not the newest.
TEST(ServerProcess, ProtocolTrapsAreClosed) {
    ServerProcess server("traps");
    RawConnection raw(server);
    flatbuffers::FlatBufferBuilder hello;
    hello.Finish(fb::CreateHelloDirect(hello, "raw"));
    protocol::Message m = raw.Exchange(protocol::MessageType::kHello, 0, Bytes(hello));
    ASSERT_EQ(m.header.type, protocol::MessageType::kError);
    EXPECT_EQ(m.header.requestId, 0u);
    EXPECT_EQ(m.As<fb::Error>()->code(), fb::ErrorCode::InvalidArgument);
    EXPECT_NE(m.As<fb::Error>()->message()->str().find("id 0 is reserved"), std::string::npos);
    m = raw.Exchange(protocol::MessageType::kHello, 1, Bytes(hello));
    EXPECT_EQ(m.header.type, protocol::MessageType::kWelcome);
    m = raw.Exchange(protocol::MessageType::kGetStats, 2, {});  // empty: every scene
    ASSERT_EQ(m.header.type, protocol::MessageType::kStats);
    EXPECT_EQ(m.header.requestId, 2u);
    EXPECT_TRUE(nlohmann::json::parse(m.As<fb::Stats>()->json()->str()).contains("server"));

    client::Client a(server.Unix(), "a"), b(server.Unix(), "b"), watcher(server.Unix(), "w");
    a.Load(Cornell());
    client::LoadOptions blocker = Cornell();
    blocker.path = "blocker.gltf";
    b.Load(blocker);                                // the newest now
    EXPECT_EQ(a.Info().scene, "cornell-box.gltf");  // a's own scene, not the newest
    EXPECT_EQ(b.Info().scene, "blocker.gltf");
    EXPECT_EQ(watcher.Info().scene, "blocker.gltf");  // loaded nothing: the newest
    EXPECT_NO_THROW(a.SetTransform("tall_block", a.Info().Node("tall_block")->matrix));
    EXPECT_TRUE(a.Info().Node("tall_block")->boundsMin.has_value());  // motion bounds given
    EXPECT_FALSE(a.Info().Node("floor")->boundsMin.has_value());
}

// Issue 23, part 6: a remote load says how it goes when asked (LoadScene `progress`):
// Progress messages under the request's id, fractions within [0, 1], before the reply; a
// load that does not ask gets none.
TEST(ServerProcess, ARemoteLoadReportsItsProgress) {
    ServerProcess server("progress");
    client::Client c(server.Unix(), "progress");
    struct Report {
        std::string stage;
        double fraction, left;
    };
    std::mutex m;
    std::vector<Report> reports;
    client::LoadOptions o = Cornell();
    o.elementSize = 0.03f;  // a build of a second or so
    o.progress = [&](const std::string& stage, double fraction, double left) {
        std::lock_guard lock(m);
        reports.push_back({stage, fraction, left});
    };
    const client::SceneInfo info = c.Load(o);
    std::lock_guard lock(m);
    ASSERT_FALSE(reports.empty()) << "no Progress message during a " << info.buildSeconds
                                  << " s build";
    std::set<std::string> stages;
    for (const Report& r : reports) {
        EXPECT_GE(r.fraction, 0.0) << r.stage;
        EXPECT_LE(r.fraction, 1.0) << r.stage;
        stages.insert(r.stage);
    }
    std::string names;
    for (const auto& st : stages) names += st + "; ";
    std::printf("%zu progress reports over %zu stages (%s) in a %.2f s build\n", reports.size(),
                stages.size(), names.c_str(), info.buildSeconds);
    const size_t before = reports.size();
    client::LoadOptions quiet = Cornell();
    quiet.reload = true;
    c.Load(quiet);
    EXPECT_EQ(reports.size(), before);
}

TEST(ServerProcess, BadRequestsGetClearErrorsAndTheConnectionStays) {
    ServerProcess server("bad-requests");
    client::Client c(server.Tcp());
    EXPECT_EQ(ErrorCodeOf([&] { c.Info(); }), int(fb::ErrorCode::NoScene));
    client::LoadOptions outside = Cornell();
    outside.path = "../CMakeLists.txt";
    EXPECT_EQ(ErrorCodeOf([&] { c.Load(outside); }), int(fb::ErrorCode::OutsideRoot));
    outside.path = "/etc/passwd";
    EXPECT_EQ(ErrorCodeOf([&] { c.Load(outside); }), int(fb::ErrorCode::OutsideRoot));
    outside.path = "no-such.gltf";
    EXPECT_EQ(ErrorCodeOf([&] { c.Load(outside); }), int(fb::ErrorCode::NotFound));
    client::LoadOptions rays = Cornell();
    rays.gatherRays = -1;
    EXPECT_EQ(ErrorCodeOf([&] { c.Load(rays); }), int(fb::ErrorCode::InvalidArgument));
    rays.gatherRays = 0;
    rays.emitterRays = 1 << 20;
    EXPECT_EQ(ErrorCodeOf([&] { c.Load(rays); }), int(fb::ErrorCode::InvalidArgument));
    c.Load(Cornell());
    std::array<float, 16> nan{};
    nan.fill(std::nanf(""));
    EXPECT_EQ(ErrorCodeOf([&] { c.SetTransform("tall_block", nan); }),
              int(fb::ErrorCode::InvalidArgument));
    std::array<float, 16> zero{};
    EXPECT_EQ(ErrorCodeOf([&] { c.SetTransform("tall_block", zero); }),
              int(fb::ErrorCode::InvalidArgument));
    std::array<float, 16> id{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    EXPECT_EQ(ErrorCodeOf([&] { c.SetTransform("no_such_node", id); }),
              int(fb::ErrorCode::NotFound));
    EXPECT_EQ(ErrorCodeOf([&] { c.SetTransform("floor", id); }), int(fb::ErrorCode::StaticNode));
    EXPECT_EQ(ErrorCodeOf([&] { c.SetLight("floor", std::nullopt, 1.0f); }),
              int(fb::ErrorCode::NotFound));
    // After all that, the same connection still works.
    EXPECT_NO_THROW(c.Stats());
    EXPECT_TRUE(c.Connected());
}

// A morphing mesh driven over the socket (SetVertices): morph weights and whole vertex lists
// are taken in place by the implicit solver (a relink a frame), by a rebuild of the links
// with the antiradiance solver; bad deformations are refused with their reasons.
TEST(ServerProcess, DeformsAMorphingMeshOverTheSocket) {
    ServerProcess server("deform");
    client::Client c(server.Tcp(), "deformer");
    client::LoadOptions o;
    o.path = "morph-room.gltf";
    o.solver = "implicit";
    o.solverOptions["bins"] = "64";
    o.elementSize = 0.15f;
    o.device = "cpu";
    o.gatherRays = 64;
    o.emitterRays = 64;
    client::SceneInfo info = c.Load(o);
    const client::NodeInfo* blob = info.Node("blob");
    ASSERT_TRUE(blob);
    EXPECT_TRUE(blob->dynamic);
    EXPECT_EQ(blob->morphTargets, 2u);
    EXPECT_EQ(blob->morphWeights, std::vector<float>({0.0f, 0.0f}));
    Watcher watch;
    c.Subscribe(std::ref(watch));
    auto start = watch.Until(0);
    ASSERT_TRUE(start);

    const uint64_t squash = c.SetMorphWeights("blob", {1.0f, 0.5f});
    auto squashed = watch.Until(squash);
    ASSERT_TRUE(squashed) << "no converged frame with the deformation";
    EXPECT_EQ(c.Info().Node("blob")->morphWeights, std::vector<float>({1.0f, 0.5f}));
    auto noted = [&](const std::string& what) {
        std::lock_guard lock(watch.m);
        for (const auto& f : watch.frames)
            if (f.note.find(what) != std::string::npos) return true;
        return false;
    };
    EXPECT_TRUE(noted("deformed blob: links rebuilt in place"));
    // The squashed blob is wider and lower: its own light changes.
    EXPECT_GT(std::abs(MeanOf(*squashed, "blob") - MeanOf(*start, "blob")),
              0.02f * MeanOf(*start, "blob"));

    // Whole vertex lists: the rest mesh shrunk to 80% about the node's origin.
    Scene scene = LoadGltf(std::string(PENUMBRA_SOURCE_DIR) + "/scenes/morph-room.gltf");
    std::vector<float> shrunk;
    for (uint32_t p : scene.nodes[FindNode(scene, "blob")].primitives)
        for (const glm::vec3& v : scene.primitives[p].objectPositions)
            shrunk.insert(shrunk.end(), {0.8f * v.x, 0.8f * v.y, 0.8f * v.z});
    const uint64_t shrink = c.SetVertices("blob", shrunk);
    ASSERT_TRUE(watch.Until(shrink));

    // Refused, each with its reason, changing nothing.
    std::vector<float> fewer(shrunk.begin(), shrunk.end() - 3);
    EXPECT_EQ(ErrorCodeOf([&] { c.SetVertices("blob", fewer); }),
              int(fb::ErrorCode::InvalidArgument));
    std::vector<float> ragged(shrunk.begin(), shrunk.end() - 1);
    EXPECT_EQ(ErrorCodeOf([&] { c.SetVertices("blob", ragged); }),
              int(fb::ErrorCode::InvalidArgument));
    std::vector<float> nan = shrunk;
    nan[10] = std::nanf("");
    EXPECT_EQ(ErrorCodeOf([&] { c.SetVertices("blob", nan); }),
              int(fb::ErrorCode::InvalidArgument));
    EXPECT_EQ(ErrorCodeOf([&] { c.SetMorphWeights("blob", {1.0f}); }),
              int(fb::ErrorCode::InvalidArgument));
    EXPECT_EQ(ErrorCodeOf([&] { c.SetMorphWeights("floor", {1.0f}); }),
              int(fb::ErrorCode::StaticNode));
    EXPECT_EQ(ErrorCodeOf([&] { c.SetMorphWeights("nothing", {1.0f}); }),
              int(fb::ErrorCode::NotFound));
    EXPECT_EQ(c.Info().Node("blob")->morphWeights, std::vector<float>({1.0f, 0.5f}));

    // The antiradiance solver's links are built for the rest shape: it rebuilds them, warm.
    ServerProcess other("deform-rebuild");
    client::Client d(other.Unix(), "second");
    client::LoadOptions a = o;
    a.solver = "antiradiance";
    EXPECT_EQ(d.Load(a).solver, "antiradiance");
    Watcher second;
    d.Subscribe(std::ref(second));
    ASSERT_TRUE(second.Until(0));
    const uint64_t again = d.SetMorphWeights("blob", {0.0f, 1.0f});
    ASSERT_TRUE(second.Until(again));
    bool rebuilt = false;
    {
        std::lock_guard lock(second.m);
        for (const auto& f : second.frames)
            rebuilt = rebuilt || f.note.find("links rebuilt: deformed blob") == 0;
    }
    EXPECT_TRUE(rebuilt);
    EXPECT_NO_THROW(d.Stats());
}

// A scene reloaded under the same name while another client watches it: the new session's
// subscribers get the new session's frames, never the old one's that share their numbers
// (the server encodes each frame once for all its subscribers).
TEST(ServerProcess, AReloadedSceneStreamsItsOwnFrames) {
    ServerProcess server("reload");
    client::Client a(server.Unix(), "first");
    Watcher old;
    ASSERT_TRUE(LoadAndWatch(a, old));
    const client::Frame before = *old.Until(0);
    auto blueOverRed = [](const client::Frame& f) {
        double r = 0, b = 0;
        for (const auto& p : f.primitives)
            if (p.node == "floor")
                for (size_t i = 0; i + 2 < p.rgb.size(); i += 3) r += p.rgb[i], b += p.rgb[i + 2];
        return r > 0 ? b / r : 0.0;
    };
    // The same file again, under a blue sky: a new session of the same name, reloaded by its
    // owner (`a`, which stays connected and subscribed; another client may not reload it),
    // joined by `b`.
    client::Client b(server.Tcp(), "second");
    client::LoadOptions blue = Cornell();
    blue.reload = true;
    blue.environmentColor = std::array<float, 3>{0.0f, 0.0f, 1.0f};
    blue.environmentIntensity = 4.0f;
    EXPECT_FALSE(a.Load(blue).reused);
    EXPECT_TRUE(b.Load(Cornell()).reused);
    Watcher fresh;
    b.Subscribe(std::ref(fresh), client::Channel::kIndirect, client::Format::kFloat32);
    auto after = fresh.Until(0);
    ASSERT_TRUE(after);
    std::lock_guard lock(fresh.m);
    ASSERT_FALSE(fresh.frames.empty());
    for (const auto& f : fresh.frames) {
        EXPECT_EQ(f.lastEdit, 0u);
        EXPECT_GT(blueOverRed(f), 1.5 * blueOverRed(before))
            << "frame " << f.frame << " of the reloaded session looks like the old one's";
    }
    client::Frame got = b.Get();
    if (got.frame == fresh.frames.back().frame) {
        EXPECT_NEAR(MeanOf(got, "floor"), MeanOf(fresh.frames.back(), "floor"),
                    1e-5f * MeanOf(got, "floor"));
    }
    // `a`, subscribed to the old build, was moved to the new one: its frames turn blue too.
    bool moved = false;
    for (int i = 0; i < 500 && !moved; ++i) {
        {
            std::lock_guard watched(old.m);
            moved =
                !old.frames.empty() && blueOverRed(old.frames.back()) > 1.5 * blueOverRed(before);
        }
        if (!moved) std::this_thread::sleep_for(20ms);
    }
    EXPECT_TRUE(moved) << "the old build's subscriber got no frames of the new one";
    EXPECT_TRUE(a.Connected());
}

TEST(ServerProcess, AClientKilledMidStreamHarmsNoOne) {
    ServerProcess server("killed");
    client::Client viewer(server.Unix(), "viewer");
    Watcher watch;
    ASSERT_TRUE(LoadAndWatch(viewer, watch));
    // A CLI watcher process, killed with SIGKILL while frames stream to it.
    std::string cmd = std::string(PENUMBRA_BINARY_DIR) + "/penumbra --connect " + server.Tcp() +
                      " watch --timeout 30 > /dev/null 2>&1";
    pid_t pid = fork();
    if (pid == 0) {
        execl("/bin/sh", "sh", "-c", ("exec " + cmd).c_str(), nullptr);
        _exit(127);
    }
    std::array<float, 16> id{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0.2f, 0, 0.2f, 1};
    viewer.SetTransform("short_block", id);  // frames flow while the process is killed
    std::this_thread::sleep_for(300ms);
    kill(pid, SIGKILL);
    waitpid(pid, nullptr, 0);
    uint64_t edit = viewer.SetLight("ceiling_light", std::nullopt, 12.0f);
    EXPECT_TRUE(watch.Until(edit));
    EXPECT_NO_THROW(viewer.Stats());
}

// Issue 24: a scene whose link rebuild fails part way, for real: once the scene is loaded
// the server's address space is capped (prlimit) a little above what it uses, so a move that
// needs a new solver runs out of memory while building it. The frame says the edit was not
// applied, the scene keeps streaming as it was to everyone, new clients are served, and once
// the cap is lifted the next move rebuilds.
TEST(ServerProcess, ARebuildThatRunsOutOfMemoryKeepsTheSceneServing) {
    ServerProcess server("rebuild-oom");
    client::Client editor(server.Unix(), "editor");
    client::LoadOptions o = Cornell();
    o.elementSize = 0.03f;  // a solver of some size: its rebuild needs more than the headroom
    const client::SceneInfo info = editor.Load(o);
    Watcher watch;
    editor.Subscribe(std::ref(watch));
    ASSERT_TRUE(watch.Until(0));

    auto vmKiB = [&] {
        std::ifstream in("/proc/" + std::to_string(server.Pid()) + "/status");
        std::string line;
        while (std::getline(in, line))
            if (line.rfind("VmSize:", 0) == 0) return std::stol(line.substr(7));
        return 0L;
    };
    const long used = vmKiB();
    rlimit old{};
    ASSERT_EQ(prlimit(server.Pid(), RLIMIT_AS, nullptr, &old), 0);
    rlimit cap = old;
    cap.rlim_cur = static_cast<rlim_t>(used + 24 * 1024) * 1024;  // 24 MiB of headroom
    ASSERT_EQ(prlimit(server.Pid(), RLIMIT_AS, &cap, nullptr), 0);
    std::printf("server address space %.0f MiB, capped at %.0f MiB; %u elements\n", used / 1024.0,
                double(cap.rlim_cur) / 1048576.0, info.elements);

    std::array<float, 16> m = info.Node("tall_block")->matrix;
    m[12] += 0.3f;  // outside its motion bounds: the links are rebuilt
    const uint64_t move = editor.SetTransform("tall_block", m);
    std::optional<client::Frame> after = watch.Until(move);
    ASSERT_TRUE(after) << server.Log();
    bool failed = false;
    {
        std::lock_guard lock(watch.m);
        for (const auto& f : watch.frames)
            if (f.note.find("link rebuild failed") != std::string::npos) {
                failed = true;
                std::printf("%s\n", f.note.c_str());
            }
    }
    EXPECT_TRUE(failed) << "no frame said the rebuild failed; last note: " << after->note;

    // Still serving: the scene as it was, to this client and to a new one.
    EXPECT_NE(editor.Stats().find("last_error"), std::string::npos);
    EXPECT_NEAR(editor.Info().Node("tall_block")->matrix[12], info.Node("tall_block")->matrix[12],
                1e-6f);
    client::Client late(server.Tcp(), "late");
    EXPECT_EQ(late.Get().primitives.size(), after->primitives.size());

    ASSERT_EQ(prlimit(server.Pid(), RLIMIT_AS, &old, nullptr), 0);
    const uint64_t again = editor.SetTransform("tall_block", m);
    std::optional<client::Frame> moved = watch.Until(again);
    ASSERT_TRUE(moved) << server.Log();
    std::string notes;
    {
        std::lock_guard lock(watch.m);
        for (const auto& f : watch.frames)
            if (f.lastEdit >= again) notes += f.note + "; ";
    }
    EXPECT_NE(notes.find("links rebuilt: moved tall_block"), std::string::npos) << notes;
    EXPECT_NEAR(editor.Info().Node("tall_block")->matrix[12], m[12], 1e-6f);
}

TEST(ServerProcess, CliCommandsAndScriptAgainstTheServer) {
    ServerProcess server("cli");
    std::string connect = "--connect " + server.Unix() + " ";
    auto load = testing::Execute(connect + "load cornell-box.gltf --element-size 0.06");
    ASSERT_EQ(load.exitCode, 0) << load.output;
    EXPECT_NE(load.output.find("movable: short_block, tall_block"), std::string::npos)
        << load.output;
    // Issue 63: `wait` without edits of its own waits until the scene has converged.
    auto waited = testing::Execute(connect + "wait --timeout 60");
    ASSERT_EQ(waited.exitCode, 0) << waited.output;
    auto settled =
        nlohmann::json::parse(testing::Execute(connect + "stats").output, nullptr, false);
    ASSERT_FALSE(settled.is_discarded());
    const nlohmann::json& scene = settled.contains("scenes") ? settled["scenes"].back() : settled;
    EXPECT_TRUE(scene["converged"].get<bool>()) << scene.dump();
    EXPECT_GT(scene["frames"].get<int>(), 1) << scene.dump();
    auto dir = server.Dir();
    std::ofstream(dir / "edits.txt") << "# a scripted edit session\n"
                                        "move tall_block --translate 0.05,0,0 --rotate-y 15\n"
                                        "light ceiling_light --intensity 8 --color 1,0.9,0.8\n"
                                        "wait --timeout 60\n"
                                        "get -o " +
                                            (dir / "after.json").string() + "\n";
    auto script = testing::Execute(connect + "script " + (dir / "edits.txt").string());
    ASSERT_EQ(script.exitCode, 0) << script.output;
    // The script's `wait` waited for its own two edits: `get` wrote a frame with both.
    EXPECT_NE(script.output.find(", edit 2, channel"), std::string::npos) << script.output;
    auto file = ReadIrradianceJson((dir / "after.json").string());
    EXPECT_EQ(file.primitives.size(), 8u);  // one per node of the Cornell box
    // Refusals exit 1 with the reason; an unreachable server exits 5.
    auto refused = testing::Execute(connect + "move floor --translate 1,0,0");
    EXPECT_EQ(refused.exitCode, 1);
    EXPECT_NE(refused.output.find("static"), std::string::npos) << refused.output;
    auto typo = testing::Execute(connect + "move tall_blok --translate 1,0,0");
    EXPECT_EQ(typo.exitCode, 1);
    EXPECT_NE(typo.output.find("movable nodes: short_block, tall_block"), std::string::npos)
        << typo.output;
    auto negative = testing::Execute(connect + "light ceiling_light --intensity -3");
    EXPECT_EQ(negative.exitCode, 1);
    EXPECT_NE(negative.output.find("--intensity must be a number ≥ 0"), std::string::npos)
        << negative.output;
    // --connect after the command, and from the environment.
    auto after = testing::Execute("stats --connect " + server.Unix());
    EXPECT_EQ(after.exitCode, 0) << after.output;
    auto env = testing::Execute("stats", "PENUMBRA_CONNECT=" + server.Unix());
    EXPECT_EQ(env.exitCode, 0) << env.output;
    // get -o -: the JSON alone on standard output (-q: no note on stderr either, which
    // Execute merges in).
    auto piped = testing::Execute(connect + "get -o - -q");
    EXPECT_EQ(piped.exitCode, 0) << piped.output;
    const auto got = nlohmann::json::parse(piped.output, nullptr, false);
    ASSERT_FALSE(got.is_discarded()) << piped.output.substr(0, 400);
    EXPECT_EQ(got["primitives"].size(), 8u);
    // watch --json: JSON Lines, one object per frame (a subscriber gets the latest frame at
    // once, so one comes even though the scene has converged).
    auto lines = testing::Execute(connect + "watch --frames 1 --json --timeout 60");
    EXPECT_EQ(lines.exitCode, 0) << lines.output;
    std::istringstream in(lines.output);
    int frames = 0;
    for (std::string line; std::getline(in, line);) {
        const auto frame = nlohmann::json::parse(line, nullptr, false);
        ASSERT_FALSE(frame.is_discarded()) << line;
        EXPECT_TRUE(frame.contains("frame") && frame.contains("edit") && frame.contains("fps"))
            << line;
        ++frames;
    }
    EXPECT_EQ(frames, 1);
    auto gone = testing::Execute("--connect unix:///nonexistent/socket stats");
    EXPECT_EQ(gone.exitCode, 5) << gone.output;
    std::ofstream(dir / "bad.txt") << "move tall_block --translate 1,2\n";
    auto bad = testing::Execute(connect + "script " + (dir / "bad.txt").string());
    EXPECT_EQ(bad.exitCode, 1);
    EXPECT_NE(bad.output.find("bad.txt:1"), std::string::npos) << bad.output;
}

TEST(ServerProcess, SigtermShutsDownCleanly) {
    ServerProcess server("sigterm");
    client::Client c(server.Unix());
    Watcher watch;
    ASSERT_TRUE(LoadAndWatch(c, watch));
    EXPECT_EQ(server.Terminate(), 0) << server.Log();
    c.Wait();  // the server closed our connection
    EXPECT_FALSE(c.Connected());
    EXPECT_FALSE(std::filesystem::exists(server.SocketPath())) << "socket file left behind";
    EXPECT_NE(server.Log().find("SIGTERM"), std::string::npos) << server.Log();
}

// Issue 24: SIGTERM while a scene is loading: the build stops at its next progress report
// (the office's takes seconds), the loading client gets an error or a closed connection,
// and the server exits 0 without its socket file.
TEST(ServerProcess, SigtermMidLoadStopsTheBuild) {
    ServerProcess server("sigterm-load");
    client::LoadOptions o;
    o.path = "office.gltf";
    o.device = "cpu";
    o.solver = "antiradiance";  // its links take seconds to build (the light field's <1 s)
    std::atomic<bool> answered{false};
    std::thread loader([&] {
        try {
            client::Client c(server.Unix());
            c.Load(o);
        } catch (const std::exception&) {
        }
        answered = true;
    });
    std::this_thread::sleep_for(std::chrono::milliseconds(800));
    EXPECT_FALSE(answered.load()) << "the office loaded in under 0.8 s: no build to stop";
    const auto start = std::chrono::steady_clock::now();
    EXPECT_EQ(server.Terminate(), 0) << server.Log();
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    loader.join();
    std::printf("exited %.2f s after SIGTERM\n", seconds);
    EXPECT_LT(seconds, 3.0) << server.Log();
    EXPECT_FALSE(std::filesystem::exists(server.SocketPath())) << "socket file left behind";
}

TEST(EmbeddedMode, ScriptRunsWithoutAServer) {
    auto dir = testing::TempDir("embedded");
    std::ofstream(dir / "edits.txt") << "light emitter --intensity 4\n"
                                        "wait\n"
                                        "get -o " +
                                            (dir / "lit.glb").string() + "\n";
    auto r = testing::Execute("script " + (dir / "edits.txt").string() + " --scene " +
                              PENUMBRA_SOURCE_DIR + "/scenes/blocker.gltf");
    ASSERT_EQ(r.exitCode, 0) << r.output;
    EXPECT_NE(r.output.find("embedded server: loaded blocker.gltf"), std::string::npos) << r.output;
    EXPECT_TRUE(std::filesystem::exists(dir / "lit.glb"));
    auto none = testing::Execute("move tall_block --translate 1,0,0");
    EXPECT_EQ(none.exitCode, 1);
    EXPECT_NE(none.output.find("--connect"), std::string::npos) << none.output;
}

}  // namespace
}  // namespace penumbra

namespace penumbra {
namespace {

// A server started with --token-file lets in only clients that give the token in Hello:
// without it or with another, Error Unauthorized and the connection closes; with it the
// session goes on. The CLI reads the token from PENUMBRA_TOKEN_FILE.
TEST(ServerProcess, TokenFileGuardsHello) {
    const auto dir = testing::TempDir("token");
    const std::string tokenFile = (dir / "token").string();
    testing::WriteFile(tokenFile, "s3cret-token\n");
    testing::ServerProcess server("token", "--token-file " + tokenFile);
    for (const std::string& wrong : {std::string(), std::string("guess")}) {
        try {
            client::Client c(server.Tcp(), "test", wrong);
            ADD_FAILURE() << "let in with token '" << wrong << "'";
        } catch (const client::ClientError& e) {
            EXPECT_EQ(e.code(), 8) << e.what();
            EXPECT_NE(std::string(e.what()).find("token"), std::string::npos) << e.what();
        }
    }
    client::Client c(server.Tcp(), "test", "s3cret-token");
    client::LoadOptions o;
    o.path = "blocker.gltf";
    EXPECT_GT(c.Load(o).elements, 0u);
    EXPECT_EQ(nlohmann::json::parse(c.Stats(""))["server"].value("refused_unauthorized", 0), 2);
    const auto refused = testing::Execute("--connect " + server.Unix() + " info");
    EXPECT_NE(refused.exitCode, 0) << refused.output;
    const auto let = testing::Execute("--connect " + server.Unix() + " info",
                                      "PENUMBRA_TOKEN_FILE=" + tokenFile);
    EXPECT_EQ(let.exitCode, 0) << let.output;
    EXPECT_NE(let.output.find("blocker"), std::string::npos) << let.output;
    std::filesystem::remove_all(dir);
}

// The most a delta stream's value may differ from the full stream's `e` at tolerance `t`
// (SPEC.md "Delta frames"), `m` the frame's mean |E|; beside it fp16's rounding.
float DeltaBound(float e, float t, float m) {
    return t * std::max(std::abs(e), m / 20.0f) * 1.001f + std::abs(e) * 1e-3f + 1e-6f;
}

// Issue 64: a delta stream (the clients' default) sends only the vertices that drifted past
// the subscriber's tolerance, and what the client holds stays within it of the full f32
// stream, frame by frame; at tolerance 0 it is the full stream's fp16, exactly. The first
// frame is a keyframe, later ones deltas of far fewer bytes.
TEST(ServerProcess, ADeltaStreamStaysWithinItsToleranceOfTheFullStream) {
    ServerProcess server("delta");
    client::Client c(server.Unix(), "loader");
    c.Load(Cornell());
    Watcher full, delta, lossless;
    client::Client fullClient(server.Unix(), "full"), deltaClient(server.Unix(), "delta"),
        losslessClient(server.Unix(), "lossless");
    fullClient.Subscribe(std::ref(full), client::Channel::kIndirect, client::Format::kFloat32);
    deltaClient.Subscribe(std::ref(delta));  // the default: a delta stream at 0.005
    losslessClient.Subscribe(std::ref(lossless), client::Channel::kIndirect, client::Format::kDelta,
                             "", {}, 0.0f);
    // A light dimmed like a slider, 1% a step, then left to converge.
    uint64_t edit = 0;
    for (int i = 1; i <= 10; ++i) {
        edit = c.SetLight("ceiling_light", std::nullopt, 17.0f * (1.0f - 0.01f * i));
        std::this_thread::sleep_for(50ms);
    }
    ASSERT_TRUE(full.Until(edit) && delta.Until(edit) && lossless.Until(edit)) << server.Log();
    std::lock_guard a(full.m), b(delta.m), l(lossless.m);
    std::map<uint64_t, const client::Frame*> byNumber;
    size_t fullBytes = 0;
    for (const auto& f : full.frames) byNumber[f.frame] = &f, fullBytes += f.wireBytes;
    auto check = [&](const std::vector<client::Frame>& frames, float t, const char* what) {
        size_t compared = 0, bytes = 0, keyframes = 0, wrong = 0;
        std::string first;
        for (const auto& f : frames) {
            bytes += f.wireBytes;
            keyframes += f.keyframe;
            auto it = byNumber.find(f.frame);
            if (it == byNumber.end()) continue;
            const client::Frame& e = *it->second;
            EXPECT_EQ(f.primitives.size(), e.primitives.size());
            double sum = 0.0;
            size_t n = 0;
            for (const auto& p : e.primitives)
                for (float v : p.rgb) sum += std::abs(v), ++n;
            const float m = float(sum / n);
            for (size_t p = 0; p < std::min(e.primitives.size(), f.primitives.size()); ++p) {
                EXPECT_EQ(f.primitives[p].node, e.primitives[p].node);
                EXPECT_EQ(f.primitives[p].rgb.size(), e.primitives[p].rgb.size());
                for (size_t i = 0; i < e.primitives[p].rgb.size(); ++i) {
                    const float want = e.primitives[p].rgb[i], got = f.primitives[p].rgb[i];
                    const bool ok = t == 0.0f
                                        ? got == protocol::HalfToFloat(protocol::FloatToHalf(want))
                                        : std::abs(got - want) <= DeltaBound(want, t, m);
                    if (!ok && wrong++ == 0)
                        first = "frame " + std::to_string(f.frame) + " " + e.primitives[p].node +
                                " value " + std::to_string(i) + ": " + std::to_string(got) +
                                " for " + std::to_string(want);
                }
            }
            ++compared;
        }
        EXPECT_EQ(wrong, 0u) << what << ": the first: " << first;
        EXPECT_GT(compared, 5u) << what;
        EXPECT_TRUE(frames.front().keyframe) << what;
        EXPECT_EQ(keyframes, 1u) << what << ": one keyframe, then deltas";
        std::printf("%s: %zu frames, %zu bytes (the f32 stream: %zu frames, %zu bytes)\n", what,
                    frames.size(), bytes, full.frames.size(), fullBytes);
        return double(bytes) / double(frames.size());
    };
    const double perDelta = check(delta.frames, 0.005f, "tolerance 0.005");
    check(lossless.frames, 0.0f, "lossless to fp16");
    EXPECT_LT(perDelta, 0.5 * double(fullBytes) / full.frames.size());
}

// Issue 64: a delta subscriber that reads too slowly loses frames at the server, and the
// frame after a loss is a keyframe: what it holds is never built on a frame it did not get.
// The office, lossless to fp16, its lamps dimmed and raised every few milliseconds: every
// frame changes most vertices, so the socket's buffers fill while the reader stops.
TEST(ServerProcess, ADeltaSubscriberThatFallsBehindGetsAKeyframe) {
    ServerProcess server("delta-behind");
    client::Client c(server.Unix(), "loader");
    client::LoadOptions o;
    o.path = "office.gltf";
    o.device = "cpu";
    c.Load(o);
    Watcher full;
    std::atomic<int> seen{0};
    std::atomic<uint64_t> stoppedAt{0};
    std::atomic<bool> stop{false};
    std::mutex m;
    std::condition_variable resume;
    bool go = false;
    std::vector<client::Frame> frames;
    client::Client fullClient(server.Unix(), "full"), slow(server.Unix(), "slow");
    fullClient.Subscribe(std::ref(full), client::Channel::kIndirect, client::Format::kFloat32);
    slow.Subscribe(
        [&](const client::Frame& f) {
            std::unique_lock lock(m);
            if (++seen == 2) {  // the reader stops until the server has made 60 more frames
                stoppedAt = f.frame;
                resume.wait_for(lock, 60s, [&] { return go; });
            }
            frames.push_back(f);
        },
        client::Channel::kIndirect, client::Format::kDelta, "", {}, 0.0f);
    std::thread editor([&] {
        for (int i = 0; !stop; ++i) {
            c.SetLight("fixture_0", std::nullopt, i % 2 ? 40.0f : 20.0f);
            std::this_thread::sleep_for(20ms);
        }
    });
    // 60 frames of most vertices each are more than the sockets' buffers hold.
    client::Client watcher(server.Unix(), "stats");
    for (int i = 0; i < 1200; ++i) {
        const uint64_t made =
            nlohmann::json::parse(watcher.Stats("office.gltf")).value("frames", 0);
        if (stoppedAt > 0 && made >= stoppedAt + 60) break;
        std::this_thread::sleep_for(50ms);
    }
    {
        std::lock_guard lock(m);
        go = true;
    }
    resume.notify_all();
    for (int i = 0; i < 300 && seen < 6; ++i) std::this_thread::sleep_for(50ms);
    stop = true;
    editor.join();
    const uint64_t last = c.SetLight("fixture_0", std::nullopt, 30.0f);
    ASSERT_TRUE(full.Until(last)) << server.Log();
    for (int i = 0; i < 400; ++i) {  // the slow one's converged frame too
        {
            std::lock_guard lock(m);
            if (!frames.empty() && frames.back().converged && frames.back().lastEdit >= last) break;
        }
        std::this_thread::sleep_for(25ms);
    }
    slow.Close();
    fullClient.Close();
    std::lock_guard lock(m), f(full.m);
    ASSERT_GE(frames.size(), 3u) << server.Log();
    size_t keyframes = 0, gaps = 0;
    for (size_t i = 1; i < frames.size(); ++i) {
        const bool gap = frames[i].frame != frames[i - 1].frame + 1;
        gaps += gap;
        if (gap) {
            EXPECT_TRUE(frames[i].keyframe) << "frame " << frames[i].frame << " after a gap";
        }
        keyframes += frames[i].keyframe;
    }
    EXPECT_GE(gaps, 1u) << "the slow reader lost no frame";
    EXPECT_GE(keyframes, 1u);
    // What it holds is the full stream's values in fp16, exactly.
    const client::Frame& mine = frames.back();
    bool compared = false;
    for (const auto& e : full.frames)
        if (e.frame == mine.frame) {
            compared = true;
            ASSERT_EQ(e.primitives.size(), mine.primitives.size());
            size_t wrong = 0;
            for (size_t p = 0; p < e.primitives.size(); ++p)
                for (size_t i = 0; i < e.primitives[p].rgb.size(); ++i)
                    wrong += mine.primitives[p].rgb[i] !=
                             protocol::HalfToFloat(protocol::FloatToHalf(e.primitives[p].rgb[i]));
            EXPECT_EQ(wrong, 0u);
        }
    EXPECT_TRUE(compared) << "frame " << mine.frame << " not in the full stream";
}

// Issue 63: on a server without --token-file every client is a "user": it edits the scenes it
// loaded, not another connected client's (Error Forbidden naming the editor role), though it
// may watch and read them; once the owner has gone, anyone may edit.
TEST(ServerProcess, OnlyTheOwnerEditsItsSceneWhileConnected) {
    ServerProcess server("owner-edits");
    client::Client owner(server.Unix(), "owner");
    const client::SceneInfo info = owner.Load(Cornell());
    const std::string material = info.materials.at(0).name;
    client::Client other(server.Unix(), "other");
    EXPECT_EQ(other.Role(), "user");
    std::string message;
    EXPECT_EQ(ErrorCodeOf(
                  [&] {
                      other.SetMaterial(material, std::array{0.f, 0.f, 0.f}, {});
                  },
                  &message),
              int(fb::ErrorCode::Forbidden))
        << message;
    EXPECT_NE(message.find("editor role"), std::string::npos) << message;
    EXPECT_EQ(ErrorCodeOf([&] { other.Step(1); }), int(fb::ErrorCode::Forbidden));
    client::Client::EnvironmentChange sky;
    sky.color = std::array{1.f, 1.f, 1.f};
    EXPECT_EQ(ErrorCodeOf([&] { other.SetEnvironment(sky); }), int(fb::ErrorCode::Forbidden));
    EXPECT_GT(other.Get().frame, 0u);  // reading is anyone's
    EXPECT_GT(owner.SetMaterial(material, std::array{0.5f, 0.5f, 0.5f}, {}), 0u);
    owner.Close();
    uint64_t edit = 0;
    for (int i = 0; i < 100 && edit == 0; ++i) {  // once the server saw the owner go
        try {
            edit = other.SetMaterial(material, std::array{0.4f, 0.4f, 0.4f}, {});
        } catch (const client::ClientError&) {
            std::this_thread::sleep_for(std::chrono::milliseconds(20));
        }
    }
    EXPECT_GT(edit, 1u) << server.Log();
}

// Issue 63: a token file gives each token a role. A viewer joins and watches but loads,
// edits and steps nothing; an editor edits and reloads another client's scene but may not
// unload it; an admin may, and owns scenes beyond --max-scenes-per-client. A token alone on
// its line is an editor's; a bad file stops the server with the line named.
TEST(ServerProcess, TokenRolesLimitWhatAClientMayDo) {
    const auto dir = testing::TempDir("roles");
    const std::string tokenFile = (dir / "tokens").string();
    testing::WriteFile(tokenFile,
                       "# who may do what\n"
                       "admin a-token\n"
                       "editor e-token   # the loader\n"
                       "\n"
                       "viewer v-token\n"
                       "bare-token\n");
    ServerProcess server("roles", "--token-file " + tokenFile + " --max-scenes-per-client 1");
    client::Client loader(server.Unix(), "loader", "e-token");
    client::Client viewer(server.Unix(), "viewer", "v-token");
    client::Client editor(server.Unix(), "editor", "bare-token");
    client::Client admin(server.Unix(), "admin", "a-token");
    EXPECT_EQ(loader.Role(), "editor");
    EXPECT_EQ(editor.Role(), "editor");
    EXPECT_EQ(viewer.Role(), "viewer");
    EXPECT_EQ(admin.Role(), "admin");
    std::string message;
    EXPECT_EQ(ErrorCodeOf([&] { viewer.Load(Cornell()); }, &message), int(fb::ErrorCode::Forbidden))
        << message;
    EXPECT_NE(message.find("viewer role"), std::string::npos) << message;
    const client::SceneInfo info = loader.Load(Cornell());
    const std::string material = info.materials.at(0).name;
    EXPECT_TRUE(viewer.Load(Cornell()).reused);  // joining is a viewer's
    EXPECT_EQ(ErrorCodeOf(
                  [&] {
                      viewer.SetMaterial(material, std::array{0.f, 0.f, 0.f}, {});
                  },
                  &message),
              int(fb::ErrorCode::Forbidden))
        << message;
    EXPECT_EQ(ErrorCodeOf([&] { viewer.Step(1); }), int(fb::ErrorCode::Forbidden));
    EXPECT_EQ(ErrorCodeOf([&] { viewer.UnloadScene(); }), int(fb::ErrorCode::Forbidden));
    EXPECT_GT(viewer.Get().frame, 0u);

    EXPECT_GT(editor.SetMaterial(material, std::array{0.5f, 0.5f, 0.5f}, {}), 0u);
    client::LoadOptions reload = Cornell();
    reload.reload = true;
    EXPECT_EQ(editor.Load(reload).scene, "cornell-box.gltf");
    EXPECT_EQ(ErrorCodeOf([&] { editor.UnloadScene("cornell-box.gltf"); }, &message),
              int(fb::ErrorCode::Forbidden))
        << message;
    EXPECT_NE(message.find("admin role"), std::string::npos) << message;
    // The quota of one: the loader's second scene is refused, the admin's are not.
    client::LoadOptions blocker;
    blocker.path = "blocker.gltf";
    blocker.device = "cpu";
    blocker.elementSize = 0.3f;
    EXPECT_EQ(ErrorCodeOf([&] { loader.Load(blocker); }), int(fb::ErrorCode::LimitReached));
    admin.Load(blocker);
    blocker.path = "maze.gltf";
    admin.Load(blocker);
    admin.UnloadScene("cornell-box.gltf");
    const nlohmann::json stats = nlohmann::json::parse(admin.Stats(""));
    EXPECT_EQ(stats["scenes"].size(), 2u) << stats.dump();
    EXPECT_EQ(stats["server"].value("forbidden_requests", 0), 5) << stats.dump();

    testing::WriteFile(tokenFile, "admin a\nroot b\n");
    const auto bad =
        testing::Execute("--token-file " + tokenFile + " --listen unix://" + (dir / "s").string(),
                         "", "penumbra-server");
    EXPECT_EQ(bad.exitCode, 2) << bad.output;
    EXPECT_NE(bad.output.find(tokenFile + ":2: unknown role 'root'"), std::string::npos)
        << bad.output;
    std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace penumbra
