#pragma once
/// Errors and invariant checks.
///
/// Library code never prints and never aborts: a broken invariant or bad input
/// throws arpos::Error carrying the source location; expected failures (marker
/// lost, ICP did not converge) are returned as data in result structs instead.

#include <sstream>
#include <stdexcept>
#include <string>

namespace arpos {

/// Every error ARPos throws. what() is a complete sentence for a person.
class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& message) : std::runtime_error(message) {}
};

/// Bad input from a file or user: the message names the file or key.
class InputError : public Error {
 public:
  explicit InputError(const std::string& message) : Error(message) {}
};

namespace internal {
[[noreturn]] void ThrowCheckFailure(const char* file, int line, const char* expr,
                                    const std::string& message);
}  // namespace internal

}  // namespace arpos

/// ARPOS_CHECK(cond, "message " << value): throws arpos::Error with file and line.
#define ARPOS_CHECK(cond, msg)                                                      \
  do {                                                                              \
    if (!(cond)) {                                                                  \
      std::ostringstream arpos_check_stream_;                                       \
      arpos_check_stream_ << msg;                                                   \
      ::arpos::internal::ThrowCheckFailure(__FILE__, __LINE__, #cond,               \
                                           arpos_check_stream_.str());              \
    }                                                                               \
  } while (false)

/// Throws arpos::InputError with a streamed message (no source location: it is
/// meant for the user, who needs the file and what is wrong, not our line).
#define ARPOS_INPUT_ERROR(msg)                      \
  do {                                              \
    std::ostringstream arpos_input_stream_;         \
    arpos_input_stream_ << msg;                     \
    throw ::arpos::InputError(arpos_input_stream_.str()); \
  } while (false)
