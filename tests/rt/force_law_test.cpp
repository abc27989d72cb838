// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/rt/force_law.*: defaults, continuity, monotonicity, validation, and the property
// that any PD (0, denormals, 1e-300..1e300, -1, NaN, ±Inf) gives a finite force in [0, F_max].
#include <spheretouch/rt/force_law.hpp>

#include <doctest/doctest.h>

#include <cmath>
#include <limits>
#include <vector>

#include <spheretouch/rt/constants.hpp>

using namespace st::rt;

namespace {
std::vector<double> nasty_inputs() {
  using L = std::numeric_limits<double>;
  std::vector<double> v = {
      0.0,           -0.0,           L::denorm_min(), 2 * L::denorm_min(), L::min() / 3,    L::min(),
      -1.0,          -L::max(),      L::max(),        L::quiet_NaN(),      -L::quiet_NaN(), L::signaling_NaN(),
      L::infinity(), -L::infinity(), L::epsilon()};
  for (int e = -300; e <= 300; e += 5) {
    v.push_back(std::pow(10.0, e));
    v.push_back(-std::pow(10.0, e));
  }
  for (double x = 0; x < 100; x += 0.01) v.push_back(x);
  return v;
}
std::vector<ForceLawConfig> configs() {
  std::vector<ForceLawConfig> cs;
  ForceLawConfig c = DefaultForceLawConfig();
  cs.push_back(c);
  c.pd_unit_mm = 1.0;  // PD in mm: stiff
  cs.push_back(c);
  c.log_base = 10.0;
  cs.push_back(c);
  c.pd_unit_mm = 1000.0;  // PD in metres
  cs.push_back(c);
  c.a = -50;  // knee far out
  cs.push_back(c);
  c = DefaultForceLawConfig();
  c.kind = LawKind::linear;
  cs.push_back(c);
  c.spring_N_per_mm = 1e300;
  cs.push_back(c);
  return cs;
}
}  // namespace

TEST_CASE("force law: defaults are the documented ones") {
  const ForceLaw law;
  CHECK(law.knee_mm() == doctest::Approx(10.0 * std::exp(-2.0)).epsilon(1e-12));
  CHECK(law.max_stiffness_N_per_mm() == doctest::Approx(0.08 * std::exp(2.0)).epsilon(1e-12));
  CHECK(law.max_stiffness_N_per_mm() <= kOmniStableStiffnessNPerMm);
  // Past the knee it is eq. (1) with PD in cm and natural log.
  CHECK(law.magnitude_N(20.0) == doctest::Approx(0.8 * (std::log(2.0) + 3.0)).epsilon(1e-12));
  CHECK(law.raw_N(20.0) == doctest::Approx(law.magnitude_N(20.0)).epsilon(1e-12));
  // Saturates at the Omni's peak force.
  CHECK(law.magnitude_N(1000.0) == kOmniPeakForceN);
  // Raw law is negative below u·e^-a and NaN below 0: the reason for the fix.
  CHECK(law.raw_N(0.1) < 0);
  CHECK(std::isnan(law.raw_N(-1)));
  CHECK(law.magnitude_N(0.1) > 0);
}

TEST_CASE("force law: continuous at the knee, non-decreasing, slope bounded") {
  for (const ForceLawConfig& c : configs()) {
    auto made = ForceLaw::make(c);
    REQUIRE(made.ok());
    const ForceLaw& law = made.value();
    const double x0 = law.knee_mm();
    if (c.kind == LawKind::log) {
      const double below = law.magnitude_N(x0 * (1 - 1e-9));
      const double above = law.magnitude_N(x0 * (1 + 1e-9));
      CHECK(std::abs(above - below) <= 1e-6 * std::max(1.0, above));
    }
    double prev = 0;
    for (double x = 0; x < 50; x += 0.001) {
      const double f = law.magnitude_N(x);
      CHECK_MESSAGE(f >= prev, "x = " << x);
      if (x > 0) CHECK(f - prev <= law.max_stiffness_N_per_mm() * 0.001 * (1 + 1e-9) + 1e-12);
      prev = f;
    }
  }
}

TEST_CASE("force law: every input gives a finite force in [0, F_max]") {
  const auto inputs = nasty_inputs();
  for (const ForceLawConfig& c : configs()) {
    auto made = ForceLaw::make(c);
    REQUIRE(made.ok());
    for (double pd : inputs) {
      const double f = made.value().magnitude_N(pd);
      CHECK_MESSAGE(std::isfinite(f), "pd = " << pd);
      CHECK_MESSAGE(f >= 0.0, "pd = " << pd);
      CHECK_MESSAGE(f <= c.max_force_N, "pd = " << pd);
    }
    CHECK(made.value().magnitude_N(std::numeric_limits<double>::infinity()) == c.max_force_N);
    CHECK(made.value().magnitude_N(std::numeric_limits<double>::quiet_NaN()) == 0.0);
  }
}

TEST_CASE("force law: invalid configs are refused with the field named") {
  auto bad = [](auto edit, const char* field) {
    ForceLawConfig c = DefaultForceLawConfig();
    edit(c);
    auto r = ForceLaw::make(c);
    REQUIRE_FALSE(r.ok());
    CHECK_MESSAGE(r.error().find(field) != std::string::npos, r.error());
  };
  bad([](ForceLawConfig& c) { c.log_base = 1.0; }, "log_base");
  bad([](ForceLawConfig& c) { c.log_base = std::nan(""); }, "log_base");
  bad([](ForceLawConfig& c) { c.pd_unit_mm = 0; }, "pd_unit_mm");
  bad([](ForceLawConfig& c) { c.b_N = -1; }, "b_N");
  bad([](ForceLawConfig& c) { c.a = INFINITY; }, "a =");
  bad([](ForceLawConfig& c) { c.max_force_N = 0; }, "max_force_N");
  bad([](ForceLawConfig& c) { c.a = 1e6; }, "knee");  // base^a overflows: knee 0
  bad(
      [](ForceLawConfig& c) {
        c.kind = LawKind::linear;
        c.spring_N_per_mm = -0.5;
      },
      "spring_N_per_mm");
}
