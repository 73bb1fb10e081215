// What the fuzz targets share: a file of the input's bytes for readers that take a path.
#pragma once

#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

namespace penumbra::fuzz {

// A file in the temporary directory, private to this process, holding the input; removed
// when it goes out of scope.
class InputFile {
  public:
    InputFile(const uint8_t* data, size_t size, const std::string& extension)
        : path_(std::filesystem::temp_directory_path() /
                ("penumbra-fuzz-" + std::to_string(::getpid()) + extension)) {
        std::ofstream out(path_, std::ios::binary | std::ios::trunc);
        out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
    }
    ~InputFile() {
        std::error_code ignored;
        std::filesystem::remove(path_, ignored);
    }
    std::string Path() const { return path_.string(); }

  private:
    std::filesystem::path path_;
};

}  // namespace penumbra::fuzz
