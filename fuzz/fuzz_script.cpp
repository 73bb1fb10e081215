// Fuzz target: the CLI's script parser (`penumbra script FILE`), each line parsed as the
// script command parses it before running it. A line may be refused with penumbra::Error;
// nothing may crash, leak or hang. One app parses every line (cleared between lines): the
// script builds one a line, which takes a millisecond and a half under the sanitizers, and
// whether a line parses depends on the line alone (the commands have no parse callbacks).
#include <cstdint>
#include <sstream>
#include <string>

#include "base/check.h"
#include "cmd/service_cli.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    static CLI::App app{"script line"};
    static penumbra::cli::ServiceCommands commands(app, /*forScript=*/true);
    std::istringstream in(std::string(reinterpret_cast<const char*>(data), size));
    std::string line;
    int number = 0;
    while (std::getline(in, line)) {
        try {
            app.clear();
            penumbra::cli::ParseScriptLine(line, "fuzz:" + std::to_string(++number), app);
        } catch (const penumbra::Error&) {
        }
    }
    return 0;
}
