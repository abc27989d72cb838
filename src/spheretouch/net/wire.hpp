// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// Little-endian byte writer and bounds-checked reader for the wire protocol (protocol.hpp) and
/// the block-set encoding (block_set.hpp). The reader never reads past its span, keeps the first
/// error (what was read, at which byte offset, what was expected) and checks every count against
/// a limit and against the bytes left before the caller allocates anything from it.
#pragma once
#include <spheretouch/abi.hpp>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <vector>

#include <spheretouch/geom/result.hpp>

static_assert(std::endian::native == std::endian::little,
              "wire encoding is little-endian and written with memcpy: port the writer/reader first");

namespace st::inline SPHERETOUCH_ABI::net {

/// Appends little-endian values to a byte vector.
class Writer {
 public:
  explicit Writer(std::vector<std::uint8_t>& out) : out_(out) {}            ///< appends to `out`
  void u8(std::uint8_t v) { raw(&v, 1); }                                   ///< one byte
  void u16(std::uint16_t v) { raw(&v, 2); }                                 ///< 2 bytes LE
  void u32(std::uint32_t v) { raw(&v, 4); }                                 ///< 4 bytes LE
  void u64(std::uint64_t v) { raw(&v, 8); }                                 ///< 8 bytes LE
  void f64(double v) { raw(&v, 8); }                                        ///< IEEE-754 binary64 LE
  void bytes(std::span<const std::uint8_t> b) { raw(b.data(), b.size()); }  ///< raw bytes
  void raw(const void* p, std::size_t n) {                                  ///< raw bytes
    if (n == 0) return;
    const std::size_t at = out_.size();
    out_.resize(at + n);  // not insert(): GCC 12 warns falsely on it (GCC bug 107138)
    std::memcpy(out_.data() + at, p, n);
  }
  std::size_t size() const { return out_.size(); }  ///< bytes in the vector
  /// Overwrites 4 bytes at `at` (for a length field written before its body).
  void patch_u32(std::size_t at, std::uint32_t v) { std::memcpy(out_.data() + at, &v, 4); }

 private:
  std::vector<std::uint8_t>& out_;
};

/// Reads little-endian values from a span; the first failure sticks and later reads return 0.
class Reader {
 public:
  /// `what` names the message for errors, e.g. "Result"; offsets are reported from `base`.
  Reader(std::span<const std::uint8_t> data, std::string what, std::size_t base = 0)
      : d_(data), what_(std::move(what)), base_(base) {}

  bool ok() const { return err_.empty(); }               ///< no failure so far
  const std::string& error() const { return err_; }      ///< first failure, or empty
  std::size_t offset() const { return pos_; }            ///< bytes consumed
  std::size_t left() const { return d_.size() - pos_; }  ///< bytes not yet consumed

  std::uint8_t u8(const char* field) {
    std::uint8_t v = 0;
    take(&v, 1, field);
    return v;
  }  ///< one byte
  std::uint16_t u16(const char* field) {
    std::uint16_t v = 0;
    take(&v, 2, field);
    return v;
  }  ///< 2 bytes LE
  std::uint32_t u32(const char* field) {
    std::uint32_t v = 0;
    take(&v, 4, field);
    return v;
  }  ///< 4 bytes LE
  std::uint64_t u64(const char* field) {
    std::uint64_t v = 0;
    take(&v, 8, field);
    return v;
  }  ///< 8 bytes LE
  /// A binary64 that must be finite (NaN/Inf never enter from the wire).
  double f64(const char* field) {
    const std::size_t at = pos_;
    double v = 0;
    if (take(&v, 8, field) && !std::isfinite(v)) {
      fail_at(at, field, ": not a finite number");
      v = 0;
    }
    return v;
  }
  /// A view of the next n bytes (n already checked by the caller against a limit).
  std::span<const std::uint8_t> bytes(std::size_t n, const char* field) {
    if (!ok()) return {};
    if (n > left()) {
      fail_at(pos_, field, ": needs ", n, " bytes, ", left(), " left");
      return {};
    }
    auto s = d_.subspan(pos_, n);
    pos_ += n;
    return s;
  }
  /// Checks `count` elements of `elem_bytes` each: count <= limit and they fit in the bytes left.
  /// Call before allocating from a count read off the wire.
  bool count_ok(std::uint64_t count, std::uint64_t limit, std::size_t elem_bytes, const char* field) {
    if (!ok()) return false;
    if (count > limit) {
      fail_at(pos_, field, ": count ", count, " exceeds the limit ", limit);
      return false;
    }
    if (elem_bytes != 0 && count > left() / elem_bytes) {
      fail_at(pos_, field, ": count ", count, " x ", elem_bytes, " bytes does not fit in the ", left(), " bytes left");
      return false;
    }
    return true;
  }
  /// Fails unless every byte has been consumed.
  bool expect_end() {
    if (ok() && left() != 0) fail_at(pos_, "end", ": ", left(), " trailing bytes");
    return ok();
  }
  /// Records a failure at byte `at` (relative to the span); only the first one is kept.
  template <class... A>
  void fail_at(std::size_t at, const char* field, A&&... more) {
    if (!ok()) return;
    err_ = st::fail(what_, " at byte ", base_ + at, ": ", field, std::forward<A>(more)...).message;
  }

 private:
  // Inline, so a field's fixed size makes the copy a load; the failure path is out of line.
  bool take(void* dst, std::size_t n, const char* field) {
    if (ok() && n <= left()) [[likely]] {
      std::memcpy(dst, d_.data() + pos_, n);
      pos_ += n;
      return true;
    }
    return short_of(n, field);
  }
  [[gnu::noinline, gnu::cold]] bool short_of(std::size_t n, const char* field) {
    if (ok()) fail_at(pos_, field, ": truncated (needs ", n, " bytes, ", left(), " left)");
    return false;
  }

  std::span<const std::uint8_t> d_;
  std::string what_;
  std::size_t base_ = 0;
  std::size_t pos_ = 0;
  std::string err_;
};

/// 64-bit FNV-1a (Fowler/Noll/Vo, http://www.isthe.com/chongo/tech/comp/fnv/) over bytes,
/// continuing from `h`. Identifies block sets by content (block_set.hpp).
inline std::uint64_t fnv1a64(std::span<const std::uint8_t> b, std::uint64_t h = 0xcbf29ce484222325ull) {
  for (std::uint8_t c : b) {
    h ^= c;
    h *= 0x100000001b3ull;
  }
  return h;
}

}  // namespace st::net
