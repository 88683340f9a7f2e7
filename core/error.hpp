#pragma once
// The one error family of Terrabound (see docs/commands.md: one line, exit 2 or 3).
// InputError: bad DEM, eps, config, URL      -> HTTP 400, exit 2
// NotFound:   tile outside the pyramid/data  -> HTTP 404
// IoError:    read/write/store failure       -> HTTP 500, exit 3
#include <stdexcept>

namespace tb {
struct Error : std::runtime_error {
    using std::runtime_error::runtime_error;
};
struct InputError : Error {
    using Error::Error;
};
struct NotFound : Error {
    using Error::Error;
};
struct IoError : Error {
    using Error::Error;
};
} // namespace tb

// Caller-contract checks: live unless NDEBUG (tests build with asserts on).
#ifdef NDEBUG
#define TB_ASSERT(cond) ((void)0)
#else
#include <cstdio>
#include <cstdlib>
#define TB_ASSERT(cond)                                                                            \
    ((cond) ? (void)0                                                                              \
            : (std::fprintf(stderr, "%s:%d: assertion failed: %s\n", __FILE__, __LINE__, #cond),   \
               std::abort()))
#endif
