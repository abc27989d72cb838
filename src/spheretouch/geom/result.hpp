// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// Result<T>: the value of a cold, validating step (import, config, decode) or an error
/// message naming the file, field or offset at fault. Hot paths never use it.
#pragma once
#include <spheretouch/abi.hpp>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <variant>

namespace st {
inline namespace SPHERETOUCH_ABI {

/// An error with a human-readable message that names what was wrong and where.
struct Error {
  std::string message;  ///< e.g. "hand.off:12: face 7: vertex index 1200 out of range [0, 1197)"
};

/// What Result::value() throws when it holds an error: the error's message, so a caller who did
/// not check ok() still learns what was wrong and where (what() is the message).
class BadResultAccess : public std::runtime_error {
 public:
  /// Carries `message` (what()).
  explicit BadResultAccess(const std::string& message) : std::runtime_error(message) {}
};

/// Either a value or an Error; check ok() before value() (which throws BadResultAccess with the
/// error's message otherwise). Hot paths never use it.
template <class T>
class [[nodiscard]] Result {
 public:
  Result(T value) : v_(std::move(value)) {}        ///< success
  Result(Error error) : v_(std::move(error)) {}    ///< failure
  bool ok() const { return v_.index() == 0; }      ///< true when a value is held
  explicit operator bool() const { return ok(); }  ///< same as ok()
  /// The value; throws BadResultAccess (the error's message) when there is none.
  T& value() & {
    if (!ok()) throw BadResultAccess(std::get<1>(v_).message);
    return std::get<0>(v_);
  }
  /// The value; throws BadResultAccess (the error's message) when there is none.
  const T& value() const& {
    if (!ok()) throw BadResultAccess(std::get<1>(v_).message);
    return std::get<0>(v_);
  }
  /// Moves the value out; throws BadResultAccess (the error's message) when there is none.
  T&& value() && {
    if (!ok()) throw BadResultAccess(std::get<1>(v_).message);
    return std::get<0>(std::move(v_));
  }
  /// The error's message; empty when the result holds a value.
  const std::string& error() const {
    static const std::string none;
    return ok() ? none : std::get<1>(v_).message;
  }

 private:
  std::variant<T, Error> v_;
};

/// Result of a step that produces no value.
struct Ok {};
using Status = Result<Ok>;  ///< success (Ok) or an Error

/// Builds an Error from pieces streamed together: fail("f.off:", line, ": expected 3 numbers").
template <class... Args>
Error fail(Args&&... args) {
  std::ostringstream os;
  os.precision(17);
  (os << ... << std::forward<Args>(args));
  return Error{os.str()};
}

}  // namespace SPHERETOUCH_ABI
}  // namespace st
