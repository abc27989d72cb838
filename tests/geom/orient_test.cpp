// SPDX-License-Identifier: BSD-3-Clause
// Tests for src/spheretouch/geom/orient.*: windings made consistent and outward (closed parts out
// of their material, cavities inward, open parts as their majority), what cannot be oriented
// counted, the model set left alone, and the force on a file wound inside out.
#include <spheretouch/geom/orient.hpp>

#include <limits>
#include <random>

#include <spheretouch/geom/collide.hpp>
#include <spheretouch/geom/contact.hpp>
#include <spheretouch/geom/mesh_io.hpp>
#include <spheretouch/geom/primitives.hpp>
#include <spheretouch/geom/sphere_tree.hpp>

#include "test_models.hpp"

using namespace st;
using namespace st::geom;

namespace {

// Six times the signed volume of faces [begin, end) (positive: wound outward).
double volume6(const Mesh& m, std::size_t begin = 0, std::size_t end = SIZE_MAX) {
  double v = 0;
  for (std::size_t f = begin; f < std::min(end, m.faces.size()); ++f) {
    const Tri& t = m.faces[f];
    v += m.local[t[0]].dot(m.local[t[1]].cross(m.local[t[2]]));
  }
  return v;
}

void flip(Tri& t) { std::swap(t[1], t[2]); }

// Two meshes as one (the second's vertices after the first's), optionally moved.
Mesh join(const Mesh& a, const Mesh& b, const Vec3& b_shift = Vec3::Zero()) {
  Mesh m = a;
  const auto n = static_cast<std::uint32_t>(m.local.size());
  for (std::uint32_t i = 0; i < b.local.size(); ++i) m.local.push_back(b.vertex(i) - a.origin + b_shift);
  for (Tri t : b.faces) m.faces.push_back({t[0] + n, t[1] + n, t[2] + n});
  return m;
}

// Vertices at the same position merged (the first kept), faces re-indexed.
Mesh weld(Mesh m) {
  std::vector<std::uint32_t> to(m.local.size());
  std::vector<Vec3> kept;
  for (std::uint32_t i = 0; i < m.local.size(); ++i) {
    std::uint32_t k = 0;
    while (k < kept.size() && kept[k] != m.local[i]) ++k;
    if (k == kept.size()) kept.push_back(m.local[i]);
    to[i] = k;
  }
  for (Tri& t : m.faces)
    for (auto& v : t) v = to[v];
  m.local = kept;
  return m;
}

}  // namespace

TEST_CASE("orient_faces: a box as it should be, inside out, or with one face the wrong way, is wound outward") {
  const Mesh good = make_box(Vec3(100, 60, 40));
  REQUIRE(volume6(good) > 0);
  for (int mode = 0; mode < 4; ++mode) {
    CAPTURE(mode);
    Mesh m = good;
    std::size_t wrong = 0;
    for (std::size_t f = 0; f < m.faces.size(); ++f)
      if (mode == 1 || (mode == 2 && f == 5) || (mode == 3 && f % 2 == 1)) flip(m.faces[f]), ++wrong;
    const OrientReport r = orient_faces(m);
    CHECK(r.flipped == wrong);
    CHECK(r.parts == 1);
    CHECK(r.closed_parts == 1);
    CHECK(r.inverted_parts == (mode == 1 ? 1u : 0u));
    CHECK(r.unorientable_edges == 0);
    CHECK(m.faces == good.faces);  // every face back to its outward winding, corners as they were
    CHECK(m.topology().misoriented_edges == 0);
    CHECK(orient_faces(m).flipped == 0);  // a second pass changes nothing
    CHECK(describe_winding(r).empty() == (mode == 0));
  }
}

TEST_CASE("orient_faces: random closed meshes, faces flipped at random and the whole inside out, come back exactly") {
  std::mt19937 rng(7);
  const std::vector<Mesh> shapes = {make_icosphere(10, 4), make_capsule(3, 20, 12), make_box(Vec3(1e-3, 2e-3, 5e-4)),
                                    make_icosphere(1e4, 2)};
  for (int trial = 0; trial < 40; ++trial) {
    const Mesh& good = shapes[std::size_t(trial) % shapes.size()];
    Mesh m = good;
    const bool inside_out = trial % 3 == 0;
    std::bernoulli_distribution some(trial % 2 ? 0.1 : 0.45);
    for (Tri& t : m.faces)
      if (inside_out != some(rng)) flip(t);
    CAPTURE(trial);
    const OrientReport r = orient_faces(m);
    CHECK(m.faces == good.faces);
    CHECK(r.closed_parts == 1);
    CHECK(r.unorientable_edges == 0);
  }
}

TEST_CASE("coincident_vertices: each vertex names the lowest index at its position (-0 = +0, NaN alone)") {
  Mesh m;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  m.local = {Vec3(1, 2, 3),
             Vec3(0, 0, 0),
             Vec3(1, 2, 3),
             Vec3(-0.0, 0, -0.0),
             Vec3(nan, 0, 0),
             Vec3(nan, 0, 0),
             Vec3(1, 2, 3.0000000000000004),
             Vec3(0, 0, 0)};
  CHECK(coincident_vertices(m) == std::vector<std::uint32_t>{0, 1, 0, 1, 4, 5, 6, 1});
  CHECK(coincident_vertices(Mesh{}).empty());
}

TEST_CASE("orient_faces: a soup (three corners per face, as PLY and OFF are read) is joined at its corners") {
  // Each face its own three vertices: without joining coincident corners every face is an open
  // part of its own and keeps the winding the file gave it.
  using st::test::soup;
  std::mt19937 rng(11);
  for (const Mesh& shape : {make_box(Vec3(100, 60, 40)), make_icosphere(10, 4)}) {
    const Mesh good = soup(shape);
    REQUIRE(good.topology().closed());  // joined through its coincident corners
    for (int trial = 0; trial < 6; ++trial) {
      Mesh m = good;
      std::bernoulli_distribution some(0.3);
      for (Tri& t : m.faces)
        if ((trial % 2 == 1) != some(rng)) flip(t);
      CAPTURE(trial);
      const OrientReport r = orient_faces(m);
      CHECK(r.parts == 1);
      CHECK(r.closed_parts == 1);
      CHECK(m.faces == good.faces);
      CHECK(m.local == good.local);  // no vertex merged or moved
    }
  }
}

TEST_CASE("orient_faces: a hollow solid's cavity is wound inward, a body inside the cavity outward") {
  // Outer box 100, a cavity of 50 inside it, a ball of radius 10 inside the cavity (nesting 0, 1, 2).
  const Mesh outer = make_box(Vec3(100, 100, 100)), cavity = make_box(Vec3(50, 50, 50)), ball = make_icosphere(10, 3);
  const Mesh good = join(join(outer, cavity), ball);
  const std::size_t n_out = outer.faces.size(), n_cav = cavity.faces.size();
  for (int mode = 0; mode < 8; ++mode) {
    CAPTURE(mode);
    Mesh m = good;
    for (std::size_t f = 0; f < m.faces.size(); ++f) {
      const int part = f < n_out ? 0 : f < n_out + n_cav ? 1 : 2;
      if ((mode >> part) & 1) flip(m.faces[f]);
    }
    const OrientReport r = orient_faces(m);
    CHECK(r.parts == 3);
    CHECK(r.closed_parts == 3);
    CHECK(r.cavities == 1);
    CHECK(volume6(m, 0, n_out) > 0);
    CHECK(volume6(m, n_out, n_out + n_cav) < 0);  // the cavity's wall faces into the cavity
    CHECK(volume6(m, n_out + n_cav) > 0);
  }
}

TEST_CASE("orient_faces: closed parts pushed into each other are each wound outward; one wholly inside is a cavity") {
  // A ball of radius 10 and an 8 mm cube moved along x: inside it (0), through its surface (5, 12:
  // some corners out), apart (18). One vertex of the cube inside the ball made it a cavity before,
  // wound inward, and the force on its faces pulled the probe in.
  const Mesh ball = make_icosphere(10, 4), cube = make_box(Vec3(8, 8, 8));
  const Mesh probe = make_icosphere(1, 2);
  const SphereTree probe_tree = SphereTree::build(probe).value();
  for (const double shift : {0.0, 5.0, 12.0, 18.0})
    for (const bool cube_first : {true, false})
      for (int mode = 0; mode < 4; ++mode) {  // either part inside out
        CAPTURE(shift);
        CAPTURE(cube_first);
        CAPTURE(mode);
        const Mesh good = cube_first ? join(cube, ball, Vec3(-shift, 0, 0)) : join(ball, cube, Vec3(shift, 0, 0));
        const std::size_t n_first = (cube_first ? cube : ball).faces.size();
        Mesh m = good;
        for (std::size_t f = 0; f < m.faces.size(); ++f)
          if ((mode >> (f < n_first ? 0 : 1)) & 1) flip(m.faces[f]);
        const OrientReport r = orient_faces(m);
        const bool nested = shift == 0.0;
        CHECK(r.closed_parts == 2);
        CHECK(r.cavities == (nested ? 1u : 0u));
        const double v_first = volume6(m, 0, n_first), v_second = volume6(m, n_first);
        const double v_cube = cube_first ? v_first : v_second, v_ball = cube_first ? v_second : v_first;
        CHECK(v_ball > 0);
        CHECK((v_cube < 0) == nested);
        if (shift < 10) continue;
        // A small ball 0.3 mm into the cube's face farthest from the ball (+x, outside it).
        const Vec3 cube_centre = cube_first ? Vec3(0, 0, 0) : Vec3(shift, 0, 0);
        const Vec3 ball_centre = cube_first ? Vec3(-shift, 0, 0) : Vec3(0, 0, 0);
        const Vec3 at = cube_centre + Vec3(4 + 1 - 0.3, 0, 0), out = Vec3::UnitX();
        REQUIRE((at - ball_centre).norm() > 12);  // clear of the ball
        const SphereTree tree = SphereTree::build(m).value();
        Pose p = Pose::Identity();
        p.translation() = at;  // (the body frame: m.origin is 0 here)
        CollideScratch sc;
        CollideResult cr;
        collide(probe, probe_tree, m, tree, p, CollideConfig{}, sc, cr);
        REQUIRE_FALSE(cr.pairs.empty());
        ContactBuilder b;
        const ContactModel c = b.build(probe, m, p, cr.pairs);
        REQUIRE(c.in_contact());
        CHECK(to_eigen(c.force_dir).dot(out) > 0.99);
        CHECK(c.penetration_mm == doctest::Approx(0.3).epsilon(0.2));
      }
}

TEST_CASE("orient_faces: an open sheet is made consistent with the winding most of its area had") {
  Mesh g = st::test::grid(6);  // 72 faces, +z
  const std::vector<Tri> up = g.faces;
  for (int k : {3, 17, 40}) flip(g.faces[std::size_t(k)]);
  OrientReport r = orient_faces(g);
  CHECK(r.flipped == 3);
  CHECK(r.closed_parts == 0);
  CHECK(g.faces == up);
  CHECK(describe_winding(r) ==
        "3 faces flipped to wind consistently and outward; 1 open part (no inside: a contact takes the side the "
        "probe comes from)");
  // Most of it wound -z: it stays -z, the few +z faces join it.
  for (std::size_t f = 0; f < g.faces.size(); ++f)
    if (f % 5 != 0) flip(g.faces[f]);
  r = orient_faces(g);
  CHECK(r.flipped == (g.faces.size() + 4) / 5);
  for (std::size_t f = 0; f < g.faces.size(); ++f) {
    Tri down = up[f];
    flip(down);
    CHECK(g.faces[f] == down);
  }
}

TEST_CASE("orient_faces: parts that meet only at a non-manifold edge are each wound outward") {
  // Unit cubes at (0.5, 0.5, 0.5) and (1.5, 1.5, 0.5) share the edge x = y = 1 (four faces use it).
  const Mesh cube = make_box(Vec3(1, 1, 1));
  Mesh m = weld(join(cube, cube, Vec3(1, 1, 0)));
  REQUIRE(m.topology().nonmanifold_edges == 1);
  for (std::size_t f = cube.faces.size(); f < m.faces.size(); ++f) flip(m.faces[f]);  // the second inside out
  const OrientReport r = orient_faces(m);
  CHECK(r.parts == 2);
  CHECK(r.closed_parts == 2);  // each cube uses the shared edge twice: both closed
  CHECK(r.inverted_parts == 1);
  CHECK(volume6(m, 0, cube.faces.size()) > 0);
  CHECK(volume6(m, cube.faces.size()) > 0);
  CHECK(m.topology().misoriented_edges == 0);
}

TEST_CASE("orient_faces: a Möbius strip's disagreeing edge is counted; degenerate and empty meshes pass") {
  // A strip of 12 quads around a circle with a half twist; the last quad's far edge is the first's
  // near edge reversed.
  Mesh m;
  const int n = 12;
  for (int i = 0; i < n; ++i) {
    const double a = 2 * 3.14159265358979 * i / n, t = a / 2;
    const Vec3 c(10 * std::cos(a), 10 * std::sin(a), 0),
        w(std::cos(t) * std::cos(a), std::cos(t) * std::sin(a), std::sin(t));
    m.local.push_back(c + 2 * w);
    m.local.push_back(c - 2 * w);
  }
  for (std::uint32_t i = 0; i < std::uint32_t(n); ++i) {
    const std::uint32_t a = 2 * i, b = 2 * i + 1;
    std::uint32_t c = 2 * ((i + 1) % n), d = c + 1;
    if (i + 1 == std::uint32_t(n)) std::swap(c, d);  // the twist
    m.faces.push_back({a, b, d});
    m.faces.push_back({a, d, c});
  }
  const OrientReport r = orient_faces(m);
  CHECK(r.parts == 1);
  CHECK(r.unorientable_edges >= 1);
  CHECK_FALSE(describe_winding(r).empty());

  Mesh deg = make_box(Vec3(10, 10, 10));
  deg.local.push_back(Vec3(1, 2, 3));
  const auto v = static_cast<std::uint32_t>(deg.local.size() - 1);
  deg.faces.push_back({v, v, v});
  deg.faces.push_back({0, 0, 1});
  flip(deg.faces[2]);
  const OrientReport rd = orient_faces(deg);
  CHECK(rd.flipped == 1);
  CHECK(volume6(deg, 0, 12) > 0);

  Mesh empty;
  CHECK(orient_faces(empty).flipped == 0);
  CHECK(describe_winding(orient_faces(empty)).empty());
}

TEST_CASE("load_mesh: a file wound inside out loads outward (orient, the default) and the force pushes the ball out") {
  st::test::TempDir d;
  // A 100 mm box whose every triangle is wound clockwise seen from outside.
  std::string off = "OFF\n8 12 0\n";
  for (int x : {-50, 50})
    for (int y : {-50, 50})
      for (int z : {-50, 50}) off += std::to_string(x) + " " + std::to_string(y) + " " + std::to_string(z) + "\n";
  for (const char* t :
       {"0 2 1", "1 2 3", "4 5 6", "5 7 6", "0 1 4", "1 5 4", "2 6 3", "3 6 7", "0 4 2", "2 4 6", "1 3 5", "3 7 5"})
    off += std::string("3 ") + t + "\n";
  st::test::write_file(d.file("inside_out.off"), off);

  const Mesh ball = make_icosphere(10, 3);
  const SphereTree bt = SphereTree::build(ball).value();
  Pose p = Pose::Identity();
  p.translation() = Vec3(5, 3, 50 + 10 - 2);  // 2 mm into the top face
  auto model_for = [&](bool orient) {
    LoadConfig o;
    o.orient = orient;
    Result<LoadedMesh> lm = load_mesh(d.file("inside_out.off"), o);
    REQUIRE(lm.ok());
    CHECK(lm.value().report.orientation.flipped == (orient ? 12u : 0u));
    const Mesh& box = lm.value().mesh;
    const SphereTree ot = SphereTree::build(box).value();
    CollideScratch sc;
    CollideResult r;
    CollideConfig c;
    c.sort_pairs = true;
    collide(ball, bt, box, ot, p, c, sc, r);
    REQUIRE_FALSE(r.pairs.empty());
    ContactBuilder b;
    return b.build(ball, box, p, r.pairs);
  };
  const ContactModel fixed = model_for(true);
  REQUIRE(fixed.in_contact());
  CHECK(to_eigen(fixed.force_dir).z() == doctest::Approx(1.0).epsilon(1e-9));
  CHECK(fixed.penetration_mm == doctest::Approx(2.0).epsilon(0.15));  // the icosphere's facets sit inside its radius
  // As read, the file's winding turns the force into the box, through the ball: what orient prevents.
  const ContactModel as_read = model_for(false);
  CHECK(to_eigen(as_read.force_dir).z() < -0.99);
}

TEST_CASE("orient_faces: the model set is wound outward already (nothing flipped)") {
  for (const char* name : {"hand_L2.off", "elephant.off", "bunny.off", "armadillo.off"}) {
    CAPTURE(name);
    LoadConfig o;
    o.orient = false;
    Result<LoadedMesh> lm = load_mesh(st::test::model(name), o);
    REQUIRE(lm.ok());
    Mesh m = lm.value().mesh;
    const OrientReport r = orient_faces(m);
    CHECK(r.flipped == 0);
    CHECK(r.parts == 1);
    CHECK(r.closed_parts == 1);
    CHECK(r.cavities == 0);
  }
}
