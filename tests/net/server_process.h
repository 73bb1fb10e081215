// penumbra-server (or a copy of it with a test fixture linked in) as a real process on a Unix
// socket and loopback TCP, for the tests that talk to it.
#pragma once

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>

#include "test_util.h"

namespace penumbra::testing {

// Starts penumbra-server on a Unix socket and an ephemeral loopback TCP port.
class ServerProcess {
  public:
    // `binary`: the server program under the build folder; `root`: its --scene-root (default:
    // the bundled scenes).
    explicit ServerProcess(const std::string& name, const std::string& extra = "",
                           const std::string& binary = "penumbra-server",
                           const std::string& root = "") {
        dir_ = TempDir("server-" + name);
        unixUrl_ = "unix://" + (dir_ / "s.sock").string();
        std::string ready = (dir_ / "ready").string();
        std::string cmd = std::string(PENUMBRA_BINARY_DIR) + "/" + binary + " --listen " +
                          unixUrl_ + " --listen tcp://127.0.0.1:0 --scene-root " +
                          (root.empty() ? std::string(PENUMBRA_SOURCE_DIR) + "/scenes" : root) +
                          " --device cpu --ready-file " + ready + " " + extra;
        pid_ = fork();
        if (pid_ == 0) {
            std::string log = (dir_ / "server.log").string();
            execl("/bin/sh", "sh", "-c", ("exec " + cmd + " 2>" + log).c_str(), nullptr);
            _exit(127);
        }
        for (int i = 0; i < 300 && !std::filesystem::exists(ready); ++i)
            std::this_thread::sleep_for(std::chrono::milliseconds(20));
        std::ifstream in(ready);
        std::string line;
        while (std::getline(in, line))
            if (line.rfind("tcp://", 0) == 0)
                tcpUrl_ = line;
            else if (line.rfind("http://", 0) == 0)
                httpUrl_ = line;
        EXPECT_FALSE(tcpUrl_.empty()) << "server did not become ready: " << Log();
    }
    ~ServerProcess() {
        if (pid_ > 0) {
            kill(pid_, SIGKILL);
            waitpid(pid_, nullptr, 0);
        }
    }
    // Sends SIGTERM and returns the exit status (-1 if it did not exit within 10 s).
    int Terminate() {
        kill(pid_, SIGTERM);
        for (int i = 0; i < 500; ++i) {
            int status;
            if (waitpid(pid_, &status, WNOHANG) == pid_) {
                pid_ = -1;
                return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
            }
            std::this_thread::sleep_for(std::chrono::milliseconds(20));
        }
        return -1;
    }
    std::string Log() const {
        std::ifstream in(dir_ / "server.log");
        return {std::istreambuf_iterator<char>(in), {}};
    }
    const std::string& Unix() const { return unixUrl_; }
    const std::string& Tcp() const { return tcpUrl_; }
    const std::string& Http() const { return httpUrl_; }  // with --metrics
    std::filesystem::path Dir() const { return dir_; }
    std::string SocketPath() const { return unixUrl_.substr(7); }
    pid_t Pid() const { return pid_; }

  private:
    std::filesystem::path dir_;
    std::string unixUrl_, tcpUrl_, httpUrl_;
    pid_t pid_ = -1;
};

}  // namespace penumbra::testing
