// Fuzz target: the CLI's script parser (`penumbra script FILE`), each line parsed as the
// script command parses it before running it. A line may be refused with penumbra::Error;
// nothing may crash, leak or hang.
#include <cstdint>
#include <sstream>
#include <string>

#include "base/check.h"
#include "cmd/service_cli.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    std::istringstream in(std::string(reinterpret_cast<const char*>(data), size));
    std::string line;
    int number = 0;
    while (std::getline(in, line)) {
        try {
            penumbra::cli::CheckScriptLine(line, "fuzz:" + std::to_string(++number));
        } catch (const penumbra::Error&) {
        }
    }
    return 0;
}
