// Invariant checks that print both operands, and the error type for input from outside.
// CHECK is for broken invariants (a bug); penumbra::Error is for bad input a user can fix.
#pragma once

#include <sstream>
#include <stdexcept>
#include <string>

namespace penumbra {

// Raised for problems caused by input (files, flags, sockets); the message says what to fix.
class Error : public std::runtime_error {
  public:
    explicit Error(const std::string& message) : std::runtime_error(message) {}
};

// The accelerator stopped answering (Vulkan's VK_ERROR_DEVICE_LOST): nothing on it can be
// used again. A session that meets it goes on with the CPU back end (service/session.h).
class DeviceLost : public Error {
  public:
    explicit DeviceLost(const std::string& message) : Error(message) {}
};

[[noreturn]] void CheckFailed(const char* file, int line, const std::string& what);

namespace detail {
template <typename A, typename B>
std::string CheckOperands(const char* expr, const A& a, const B& b) {
    std::ostringstream s;
    s << expr << " (" << a << " vs " << b << ")";
    return s.str();
}
}  // namespace detail

}  // namespace penumbra

#define PENUMBRA_CHECK(cond)                                             \
    do {                                                                 \
        if (!(cond)) ::penumbra::CheckFailed(__FILE__, __LINE__, #cond); \
    } while (0)

#define PENUMBRA_CHECK_OP(a, op, b)                                                      \
    do {                                                                                 \
        const auto& checkA_ = (a);                                                       \
        const auto& checkB_ = (b);                                                       \
        if (!(checkA_ op checkB_))                                                       \
            ::penumbra::CheckFailed(                                                     \
                __FILE__, __LINE__,                                                      \
                ::penumbra::detail::CheckOperands(#a " " #op " " #b, checkA_, checkB_)); \
    } while (0)

#define PENUMBRA_CHECK_EQ(a, b) PENUMBRA_CHECK_OP(a, ==, b)
#define PENUMBRA_CHECK_LT(a, b) PENUMBRA_CHECK_OP(a, <, b)
#define PENUMBRA_CHECK_LE(a, b) PENUMBRA_CHECK_OP(a, <=, b)
