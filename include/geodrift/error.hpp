#pragma once

/// @file
/// geodrift's exceptions and checks (STYLE.md §8): Error (I/O and other failures, naming the
/// path), InvalidArgument (a value outside its documented domain; the message names the value
/// and the limit), GEODRIFT_CHECK (input validation at API boundaries, always on) and
/// GEODRIFT_ASSERT (internal invariants, off under NDEBUG unless GEODRIFT_ENABLE_ASSERTS; throws
/// Error, never aborts). Numerical outcomes (no convergence, a failed factorisation) are not
/// exceptions: they are reported in solver::Summary.

#include <sstream>
#include <stdexcept>
#include <string>

namespace geodrift {

/// Base of every exception geodrift throws (I/O failures name the path).
class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// An argument outside its documented domain: non-finite value, scale <= 0, latitude outside
/// [-90, 90], malformed file line, ... The message names the argument, its value and the limit.
class InvalidArgument : public Error {
 public:
  using Error::Error;
};

namespace detail {
/// Out-of-line thrower keeps GEODRIFT_CHECK's call sites small (the message stream is only
/// built on failure).
[[noreturn]] inline void throw_invalid_argument(const std::string& msg) {
  throw InvalidArgument(msg);
}
[[noreturn]] inline void assertion_failed(const char* cond, const char* file, int line) {
  std::ostringstream os;
  os << "geodrift internal assertion failed: " << cond << " at " << file << ":" << line;
  throw Error(os.str());
}
}  // namespace detail
}  // namespace geodrift

/// Validates an input at an API boundary; always on. `msg` is a stream expression:
/// GEODRIFT_CHECK(lat >= -90 && lat <= 90, "latitude " << lat << " deg outside [-90, 90]").
#define GEODRIFT_CHECK(cond, msg)                         \
  do {                                                    \
    if (!(cond)) {                                        \
      std::ostringstream geodrift_check_os_;              \
      geodrift_check_os_ << msg;                          \
      ::geodrift::detail::throw_invalid_argument(geodrift_check_os_.str()); \
    }                                                     \
  } while (false)

/// Internal invariant. Active unless NDEBUG is defined, or always when GEODRIFT_ENABLE_ASSERTS
/// is defined (CI and the test build turn it on in Release). Throws geodrift::Error rather than
/// aborting, so a library user's process is never killed by a geodrift invariant.
#if !defined(NDEBUG) || defined(GEODRIFT_ENABLE_ASSERTS)
#define GEODRIFT_ASSERT(cond)                                                 \
  do {                                                                        \
    if (!(cond)) ::geodrift::detail::assertion_failed(#cond, __FILE__, __LINE__); \
  } while (false)
#else
#define GEODRIFT_ASSERT(cond) \
  do {                        \
  } while (false)
#endif
