// The service commands of the `penumbra` CLI (load, info, watch, move, light, material,
// get, step, stats, script), run through the client library against a server given by
// --connect, or against an embedded in-process server when --scene names a glTF instead.
#pragma once

#include <CLI/CLI.hpp>
#include <memory>
#include <string>

namespace penumbra::cli {

// Exit statuses of the service commands (docs/CLI.md).
inline constexpr int kExitOk = 0;
inline constexpr int kExitRefused = 1;     // the server answered with an error, or bad input
inline constexpr int kExitInternal = 3;    // a bug
inline constexpr int kExitTimeout = 4;     // watch/wait ran out of time
inline constexpr int kExitConnection = 5;  // could not connect, or the connection was lost

class ServiceCommands {
  public:
    // Adds the commands to `app`. `forScript`: the subset a script line may use.
    ServiceCommands(CLI::App& app, bool forScript = false);
    ~ServiceCommands();

    // True when one of these commands was parsed.
    bool Parsed() const;
    // Runs the parsed command: connects (or starts the embedded server), runs, disconnects.
    int Run();

  private:
    // The constructor's parts: each adds its subcommands and their options to `app`.
    void AddLoad(CLI::App& app);
    void AddWatch(CLI::App& app);
    void AddObjectEdits(CLI::App& app);
    void AddLightEdits(CLI::App& app);
    void AddReads(CLI::App& app);
    struct State;
    std::unique_ptr<State> s_;
};

// One line of a `script` file parsed into `app` (a CLI::App with ServiceCommands added for
// script use), as `script` does before it runs the line: text from '#' on is a comment;
// false for a line with no command. A line that is not a script command throws
// penumbra::Error naming `where` (file:line), the line and why.
bool ParseScriptLine(const std::string& line, const std::string& where, CLI::App& app);

}  // namespace penumbra::cli
