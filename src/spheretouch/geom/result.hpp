// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// Result<T>: the value of a cold, validating step (import, config, decode) or an error
/// message naming the file, field or offset at fault. Hot paths never use it.
#pragma once
#include <spheretouch/abi.hpp>
#include <sstream>
#include <string>
#include <utility>
#include <variant>

namespace st {
inline namespace SPHERETOUCH_ABI {

/// An error with a human-readable message that names what was wrong and where.
struct Error {
  std::string message;  ///< e.g. "hand.off:12: face 7: vertex index 1200 out of range [0, 1197)"
};

/// Either a value or an Error; check ok() before value().
template <class T>
class [[nodiscard]] Result {
 public:
  Result(T value) : v_(std::move(value)) {}                             ///< success
  Result(Error error) : v_(std::move(error)) {}                         ///< failure
  bool ok() const { return v_.index() == 0; }                           ///< true when a value is held
  explicit operator bool() const { return ok(); }                       ///< same as ok()
  T& value() & { return std::get<0>(v_); }                              ///< the value (must be ok())
  const T& value() const& { return std::get<0>(v_); }                   ///< the value (must be ok())
  T&& value() && { return std::get<0>(std::move(v_)); }                 ///< move the value out
  const std::string& error() const { return std::get<1>(v_).message; }  ///< the message (must be !ok())

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
