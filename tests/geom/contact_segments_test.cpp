// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/geom/contact_segments.*: the segment of two crossing triangles and its vector area
// against a hand computation; rows without a segment add nothing; the first segment's midpoint;
// the sums' order (lane by lane in the order added, across batches: bit for bit the same as the
// rows' areas summed so); and a ball pressed into a box's face, whose vector area is the disc's
// π ρ² n.
#include <spheretouch/geom/contact_segments.hpp>

#include <doctest/doctest.h>

#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include <spheretouch/geom/contact.hpp>
#include <spheretouch/geom/primitives.hpp>
#include <spheretouch/geom/simd.hpp>
#include "test_models.hpp"

using namespace st::geom;

namespace {

constexpr double kPiSegments = 3.14159265358979323846;

FaceRec rec(const Vec3& a, const Vec3& b, const Vec3& c) {
  FaceRec r;
  r.v[0] = a, r.v[1] = b, r.v[2] = c;
  r.n = (b - a).cross(c - a).normalized();
  r.c = r.n.dot(a);
  return r;
}

// Object face in z = 0 (normal +z) and probe face in x = 0 (normal +x): L = z × x = +y. The
// object face meets x = 0 for y in [−1, 2] (its hypotenuse x + y = 2), the probe face meets z = 0
// for y in [−1.5, 1.5]: the segment runs from (0, −1, 0) to (0, 1.5, 0).
const FaceRec kObject = rec({-1, -1, 0}, {3, -1, 0}, {-1, 3, 0});
const FaceRec kProbe = rec({0, -2, -1}, {0, 2, -1}, {0, 0, 3});

bool same_bits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }

/// A row's vector area alone (lane 0; the other lanes add +0).
Vec3 row_area(const FaceRec& a, const FaceRec& b, const Vec3& o) {
  SegmentAreaSum s(o);
  s.add(&a, &b);
  s.finish();
  return s.area();
}

// n random rows: two triangles around the same point (about half of them cross).
void random_rows(unsigned seed, int n, std::vector<FaceRec>& objects, std::vector<FaceRec>& probes) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  auto rand_rec = [&](const Vec3& c) {
    return rec(c + Vec3(u(rng), u(rng), u(rng)), c + Vec3(u(rng), u(rng), u(rng)), c + Vec3(u(rng), u(rng), u(rng)));
  };
  for (int i = 0; i < n; ++i) {
    const Vec3 c(5 * u(rng), 5 * u(rng), 5 * u(rng));
    objects.push_back(rand_rec(c)), probes.push_back(rand_rec(c));
  }
}

}  // namespace

TEST_CASE("contact segments: two crossing triangles, against the hand computation") {
  // From o = (1, 0, 0): ½ (s0 − o) × (s1 − o) = ½ (−1, −1, 0) × (−1, 1.5, 0) = (0, 0, −1.25).
  SegmentAreaSum s(Vec3(1, 0, 0));
  s.add(&kObject, &kProbe);
  s.finish();
  CHECK((s.area() - Vec3(0, 0, -1.25)).norm() < 1e-15);
  CHECK(s.abs_sum() == doctest::Approx(1.25).epsilon(1e-15));
  // From a point on the segment's line the area is zero (its length too).
  SegmentAreaSum on_line(Vec3(0, 7, 0));
  on_line.add(&kObject, &kProbe);
  on_line.finish();
  CHECK(on_line.area().norm() < 1e-15);
  CHECK(on_line.abs_sum() < 1e-15);
  // The faces swapped: L turns over, so does the area.
  CHECK((row_area(kProbe, kObject, Vec3(1, 0, 0)) - Vec3(0, 0, 1.25)).norm() < 1e-15);

  FirstSegment first;
  first.add(&kObject, &kProbe);
  first.finish();
  REQUIRE(first.found());
  CHECK((first.midpoint() - Vec3(0, 0.25, 0)).norm() < 1e-15);
}

TEST_CASE("contact segments: rows without a segment add nothing") {
  FaceRec apart = kProbe;  // moved clear of the object face
  for (Vec3& v : apart.v) v += Vec3(0, 10, 0);
  apart.c = apart.n.dot(apart.v[0]);
  FaceRec parallel = kObject;  // the object face lifted: parallel planes
  for (Vec3& v : parallel.v) v += Vec3(0, 0, 0.5);
  parallel.c = parallel.n.dot(parallel.v[0]);
  FaceRec degenerate{};   // no normal
  FaceRec huge = kProbe;  // huge coordinates (products near overflow), no crossing
  for (Vec3& v : huge.v) v = v * 1e300 + Vec3(0, 1e305, 0);
  huge.c = huge.n.dot(huge.v[0]);
  SegmentAreaSum s(Vec3(1, 0, 0));
  for (const FaceRec* b : {&apart, &parallel, &degenerate, &huge}) s.add(&kObject, b);
  s.finish();
  CHECK(s.area() == Vec3::Zero());
  CHECK(s.abs_sum() == 0);
  SegmentAreaSum none(Vec3::Zero());
  none.finish();
  CHECK(none.area() == Vec3::Zero());
  CHECK(none.abs_sum() == 0);

  // The first segment: after rows without one, in a later group of four.
  FirstSegment first;
  for (int i = 0; i < 5; ++i) first.add(&kObject, &apart);
  CHECK_FALSE(first.found());
  first.add(&kObject, &kProbe);
  first.add(&kObject, &apart);
  first.finish();
  REQUIRE(first.found());
  CHECK((first.midpoint() - Vec3(0, 0.25, 0)).norm() < 1e-15);
  FirstSegment nothing;
  nothing.add(&kObject, &apart);
  nothing.finish();
  CHECK_FALSE(nothing.found());
  CHECK(nothing.midpoint() == Vec3::Zero());
}

TEST_CASE("contact segments: the sums are the rows' areas summed lane by lane, in the order added") {
  // Random rows, two triangles around the same point (about half of them cross), more than one
  // batch and not a multiple of four.
  std::vector<FaceRec> objects, probes;
  random_rows(7, 77, objects, probes);
  const Vec3 o(0.1, -0.2, 0.3);
  SegmentAreaSum s(o);
  for (int i = 0; i < 77; ++i) s.add(&objects[i], &probes[i]);
  s.finish();
  // Lane l holds rows l, l + 4, l + 8, ...; the total is (lane 0 + lane 1) + (lane 2 + lane 3).
  Vec3 lane[4] = {Vec3::Zero(), Vec3::Zero(), Vec3::Zero(), Vec3::Zero()};
  int crossing = 0;
  for (int i = 0; i < 77; ++i) {
    const Vec3 a = row_area(objects[i], probes[i], o);
    crossing += a != Vec3::Zero() ? 1 : 0;
    lane[i % 4] += a;
  }
  CHECK(crossing > 20);
  const Vec3 want = (lane[0] + lane[1]) + (lane[2] + lane[3]);
  for (int k = 0; k < 3; ++k) CHECK(same_bits(s.area()[k], want[k]));
  // The same rows in the same order: the same bits again.
  SegmentAreaSum again(o);
  for (int i = 0; i < 77; ++i) again.add(&objects[i], &probes[i]);
  again.finish();
  for (int k = 0; k < 3; ++k) CHECK(same_bits(again.area()[k], s.area()[k]));
  CHECK(same_bits(again.abs_sum(), s.abs_sum()));
}

TEST_CASE("contact segments: a ball pressed into a box's face has the disc's vector area π ρ² n") {
  const Mesh box = make_box({40, 40, 40});  // top face z = 20
  const Mesh ball = make_icosphere(10, 16);
  for (double d : {0.5, 2.0, 5.0}) {
    CAPTURE(d);
    Pose p = Pose::Identity();
    p.translation() = Vec3(1.3, -2.1, 30.0 - d);
    const std::vector<FacePair> pairs = st::test::brute_force(ball, box, p);
    REQUIRE(!pairs.empty());
    // Records in the box's local frame: the ball's vertices moved there.
    const Vec3 shift = p.linear() * ball.origin + p.translation() - box.origin;
    auto face_rec = [](const Mesh& m, std::uint32_t f, const Eigen::Matrix3d& R, const Vec3& t) {
      return rec(R * m.local[m.faces[f][0]] + t, R * m.local[m.faces[f][1]] + t, R * m.local[m.faces[f][2]] + t);
    };
    std::vector<FaceRec> objects, probes;
    for (const FacePair& fp : pairs) {
      objects.push_back(face_rec(box, fp.object, Eigen::Matrix3d::Identity(), Vec3::Zero()));
      probes.push_back(face_rec(ball, fp.probe, p.linear(), shift));
    }
    FirstSegment first;
    for (std::size_t i = 0; i < pairs.size() && !first.found(); ++i) first.add(&objects[i], &probes[i]);
    first.finish();
    REQUIRE(first.found());
    CHECK(std::abs(first.midpoint().z() - 20) < 1e-9);  // on the intersection curve, in the top face
    // From the disc's centre every row's triangle turns the same way: Σ|a| = |Σa|.
    const Vec3 centre(1.3, -2.1, 20);
    SegmentAreaSum s(centre);
    for (std::size_t i = 0; i < pairs.size(); ++i) s.add(&objects[i], &probes[i]);
    s.finish();
    const double rho2 = 100 - (10 - d) * (10 - d);  // the disc's radius², ball radius 10
    const Vec3 a = s.area();
    CHECK(a.z() == doctest::Approx(kPiSegments * rho2).epsilon(0.02));  // the facets cut a polygon inside the circle
    CHECK(a.z() <= kPiSegments * rho2);
    CHECK(std::hypot(a.x(), a.y()) < 1e-9 * a.z());
    CHECK(s.abs_sum() == doctest::Approx(a.norm()).epsilon(1e-9));
    // Over a closed curve Σa does not depend on the origin (up to rounding); Σ|a| does.
    SegmentAreaSum far(centre + Vec3(50, 40, -30));
    for (std::size_t i = 0; i < pairs.size(); ++i) far.add(&objects[i], &probes[i]);
    far.finish();
    CHECK((far.area() - a).norm() < 1e-9 * far.abs_sum());
    CHECK(far.abs_sum() > 2 * s.abs_sum());  // inflated: what FD's cancellation test must not see
  }
}

TEST_CASE("contact segments: every instruction set gives the same bits (simd.hpp's Quad, one switch for all kernels)") {
  std::vector<FaceRec> objects, probes;
  random_rows(11, 61, objects, probes);
  objects.push_back(kObject), probes.push_back(kObject);  // parallel planes: no segment
  const Vec3 o(0.1, -0.2, 0.3), n(0.3, 0.9, -0.1);
  const simd::Isa before = simd::active_isa();
  struct Sums {
    Vec3 area, centroid, area_centroid, first;
    double abs_sum = 0, length = 0;
  };
  std::vector<Sums> by_isa;
  for (int i = 0; i <= static_cast<int>(simd::best_isa()); ++i) {
    REQUIRE(simd::set_isa(static_cast<simd::Isa>(i)));
    SegmentAreaSum s(o);
    FirstSegment f;
    for (std::size_t k = 0; k < objects.size(); ++k) {
      s.add(&objects[k], &probes[k]);
      if (!f.found()) f.add(&objects[k], &probes[k]);
    }
    s.finish();
    f.finish();
    Sums r;
    r.area = s.area(), r.centroid = s.centroid(), r.abs_sum = s.abs_sum(), r.length = s.length();
    CHECK(s.area_centroid(n, r.area_centroid) == (n.dot(r.area) > 0));
    REQUIRE(f.found());
    r.first = f.midpoint();
    by_isa.push_back(r);
  }
  REQUIRE(simd::set_isa(before));
  CHECK(by_isa.front().length > 0);
  for (const Sums& r : by_isa) {
    for (int k = 0; k < 3; ++k) {
      CHECK(same_bits(r.area[k], by_isa.front().area[k]));
      CHECK(same_bits(r.centroid[k], by_isa.front().centroid[k]));
      CHECK(same_bits(r.first[k], by_isa.front().first[k]));
    }
    CHECK(same_bits(r.abs_sum, by_isa.front().abs_sum));
    CHECK(same_bits(r.length, by_isa.front().length));
  }
}
