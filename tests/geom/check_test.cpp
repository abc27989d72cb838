// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/geom/check.*: an ST_ASSERT that fails calls the installed handler with its
// condition, words, file and line (so a test can see an assert fire), and the library's own
// preconditions fire where it was built with its asserts checked.
#ifndef ST_CHECKS
#define ST_CHECKS  // this file's own ST_ASSERTs are checked in every build
#endif
#include <doctest/doctest.h>

#include <cstring>
#include <string>

#include <spheretouch/geom/check.hpp>
#include <spheretouch/geom/contact.hpp>
#include <spheretouch/rt/saturation.hpp>

namespace {

struct Fired {
  st::AssertInfo info;
};
[[noreturn]] void throw_fired(const st::AssertInfo& info) { throw Fired{info}; }

int checked_half(int even) {
  ST_ASSERT(even % 2 == 0, "checked_half takes an even number");
  return even / 2;
}

}  // namespace

TEST_CASE("ST_ASSERT calls the installed handler with what broke and where; the handler can be restored") {
  const st::AssertHandler before = st::set_assert_handler(throw_fired);
  CHECK(checked_half(8) == 4);  // holds: no call
  bool fired = false;
  try {
    (void)checked_half(7);
  } catch (const Fired& f) {
    fired = true;
    CHECK(std::string(f.info.cond) == "even % 2 == 0");
    CHECK(std::string(f.info.what) == "checked_half takes an even number");
    CHECK(std::strstr(f.info.file, "check_test.cpp") != nullptr);
    CHECK(f.info.line > 0);
  }
  CHECK(fired);
  const bool restored_ours = st::set_assert_handler(before) == &throw_fired;
  CHECK(restored_ours);
}

TEST_CASE("the library's preconditions fire where its asserts are checked (debug and sanitizer builds)") {
  if (!st::library_checks_enabled()) {
    MESSAGE("the library was built without ST_CHECKS (release): its asserts are compiled out");
    return;
  }
  const st::AssertHandler before = st::set_assert_handler(throw_fired);
  // A Saturator whose config fails check(): the constructor's precondition.
  st::rt::SaturationConfig bad = st::rt::DefaultSaturationConfig();
  bad.peak_N = -1;
  REQUIRE_FALSE(st::rt::Saturator::check(bad).empty());
  CHECK_THROWS_AS(st::rt::Saturator{bad}, Fired);
  // A ContactBuilder's too.
  st::geom::ContactConfig cc = st::geom::DefaultContactConfig();
  cc.hold_margin_mm = -1;
  REQUIRE_FALSE(st::geom::check(cc).empty());
  CHECK_THROWS_AS(st::geom::ContactBuilder{cc}, Fired);
  st::set_assert_handler(before);
}
