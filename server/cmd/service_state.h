// What the service commands share (service_cli.cpp parses into it, service_commands.cpp
// runs from it): the parsed arguments and one function per command. Internal to cmd/.
#pragma once

#include <CLI/CLI.hpp>
#include <array>
#include <chrono>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "client/client.h"
#include "cmd/service_cli.h"

namespace penumbra::cli {

using Clock = std::chrono::steady_clock;

struct ServiceCommands::State {
    bool forScript = false;
    std::string connect, session, embeddedScene, device = "auto";
    bool quiet = false;

    CLI::App *load = nullptr, *info = nullptr, *watch = nullptr, *move = nullptr, *light = nullptr,
             *material = nullptr, *sky = nullptr, *get = nullptr, *step = nullptr, *stats = nullptr,
             *unload = nullptr, *script = nullptr, *wait = nullptr, *sleep = nullptr,
             *deform = nullptr;

    client::LoadOptions loadOptions;
    std::string loadPath;
    bool upload = false;
    std::vector<float> skyColor;
    float skyRotationDegrees = 0.0f;
    std::vector<float> sun;  // load: azimuth, elevation, lux; sky: azimuth, elevation[, lux]
    std::string skyModel;    // "clear"
    std::optional<float> turbidity;

    int watchFrames = 0;
    uint64_t minEdit = 0;
    double timeout = 0.0;
    bool untilConverged = false;
    bool watchJson = false;
    std::string channel = "indirect", format = "delta";
    float tolerance = client::kDefaultTolerance;  // watch's delta stream

    std::string node;
    std::vector<float> translate, matrix, color, albedo, emission, position, direction, cone;
    float rotateY = 0.0f;
    std::vector<float> weights;  // deform --weights
    std::string verticesFile;    // deform --vertices
    // Optional, so that a negative value reaches the server and is refused there with why.
    std::optional<float> intensity, range;
    std::optional<float> roughness, metallic;
    std::string skyPath;
    bool skyOff = false;
    std::optional<float> skyIntensity, skyTurnDegrees;

    std::string output, gltf, color0 = "tonemapped";
    int stepIterations = 1;
    std::string scriptFile;
    double sleepSeconds = 0.0;

    uint64_t lastEdit = 0;  // newest edit this run sent (for `wait`)

    // Runs the command that was parsed (one Run* per command).
    int Execute(client::Client& c);
    int RunLoad(client::Client& c);
    int RunInfo(client::Client& c);
    int RunWatch(client::Client& c);
    int RunMove(client::Client& c);
    int RunDeform(client::Client& c);
    int RunLight(client::Client& c);
    int RunMaterial(client::Client& c);
    int RunSky(client::Client& c);
    int RunGet(client::Client& c);
    int RunStep(client::Client& c);
    int RunStats(client::Client& c);
    int RunUnload(client::Client& c);
    int RunSleep(client::Client& c);
    int RunWait(client::Client& c);
    int RunScript(client::Client& c);
    int Wait(client::Client& c, uint64_t edit, double timeoutSeconds);
};

// "x,y,z" options as three numbers; throws penumbra::Error naming `what` otherwise.
std::array<float, 3> Triple(const std::vector<float>& v, const char* what);

}  // namespace penumbra::cli
