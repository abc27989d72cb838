// SPDX-License-Identifier: BSD-3-Clause
// Tests for src/app: the command line as a user runs it (the real binary, through a shell).
#include <spheretouch/geom/mesh_io.hpp>
#include <spheretouch/geom/primitives.hpp>

#include "test_util.hpp"

using st::test::contains;
using st::test::run_command;
using st::test::spheretouch_exe;

TEST_CASE("--help explains the command and every subcommand") {
  const auto top = run_command(spheretouch_exe() + " --help");
  CHECK(top.exit_code == 0);
  CHECK(contains(top.output, "info"));
  CHECK(contains(top.output, "export"));
  for (const char* sub : {"info", "export"}) {
    const auto r = run_command(spheretouch_exe() + " " + sub + " --help");
    INFO(sub << ": " << r.output);
    CHECK(r.exit_code == 0);
    CHECK(contains(r.output, "Usage"));
    CHECK(contains(r.output, "--units"));
  }
  const auto none = run_command(spheretouch_exe());
  CHECK(none.exit_code != 0);
}

TEST_CASE("info on a generated and a real mesh reports reader, topology and counts") {
  st::test::TempDir d;
  st::test::write_file(d.file("t.off"), "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 1 2 3\n3 0 3 2\n");
  const auto r = run_command(spheretouch_exe() + " info " + d.file("t.off") + " " + st::test::model("hand_L2.off"));
  INFO(r.output);
  CHECK(r.exit_code == 0);
  CHECK(contains(r.output, "faces       4 "));
  CHECK(contains(r.output, "faces       38240 "));
  CHECK(contains(r.output, "closed, manifold"));
  CHECK(contains(r.output, "precision double"));
}

TEST_CASE("info says how the winding was made consistent and outward, and --keep-winding keeps the file's") {
  st::test::TempDir d;
  // The tetrahedron above with every face wound inward, and with one face wound inward.
  st::test::write_file(d.file("in.off"),
                       "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n3 0 3 1\n3 1 3 2\n3 0 2 3\n");
  st::test::write_file(d.file("one.off"),
                       "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 3 1\n3 1 2 3\n3 0 3 2\n");
  auto r = run_command(spheretouch_exe() + " info " + d.file("in.off") + " " + d.file("one.off"));
  INFO(r.output);
  CHECK(r.exit_code == 0);
  CHECK(contains(r.output,
                 "winding     4 faces flipped to wind consistently and outward (1 closed part was inside out)"));
  CHECK(contains(r.output, "winding     1 face flipped to wind consistently and outward\n"));
  r = run_command(spheretouch_exe() + " info --keep-winding " + d.file("one.off"));
  CHECK(r.exit_code == 0);
  CHECK(contains(r.output, "winding     as read"));
  CHECK(contains(r.output, "3 misoriented edges"));  // the file's topology, kept
}

TEST_CASE("info on a soup (each face its own corners) reports it closed, its shared corners counted") {
  st::test::TempDir d;
  // The tetrahedron above, written as 12 vertices (three per face), one face wound inward.
  st::test::write_file(d.file("soup.off"),
                       "OFF\n12 4 0\n0 0 0\n0 1 0\n1 0 0\n0 0 0\n1 0 0\n0 0 1\n1 0 0\n0 1 0\n0 0 1\n0 0 0\n"
                       "0 1 0\n0 0 1\n3 0 1 2\n3 3 4 5\n3 6 7 8\n3 9 10 11\n");
  const auto r = run_command(spheretouch_exe() + " info " + d.file("soup.off"));
  INFO(r.output);
  CHECK(r.exit_code == 0);
  CHECK(contains(r.output, "vertices    12 (8 at the position of another"));
  CHECK(contains(r.output, "closed, manifold"));
  CHECK(contains(r.output, "winding     1 face flipped to wind consistently and outward\n"));
}

TEST_CASE("export writes the format the output's extension names, or refuses it") {
  st::test::TempDir d;
  st::test::write_file(d.file("t.off"), "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 1 2 3\n3 0 3 2\n");
  auto r = run_command(spheretouch_exe() + " export " + d.file("t.off") + " -o " + d.file("t.ply"));
  INFO(r.output);
  CHECK(r.exit_code == 0);
  CHECK(st::test::read_file(d.file("t.ply")).rfind("ply\n", 0) == 0);  // PLY, as named (it was OFF)
  r = run_command(spheretouch_exe() + " info " + d.file("t.ply"));
  CHECK(r.exit_code == 0);
  CHECK(contains(r.output, "faces       4 "));
  r = run_command(spheretouch_exe() + " export " + d.file("t.off") + " -o " + d.file("t.stl"));
  CHECK(r.exit_code == 2);
  CHECK(contains(r.output, "t.stl: cannot write '.stl' meshes"));
  CHECK_FALSE(std::filesystem::exists(d.file("t.stl")));
}

TEST_CASE("run --view SCENE takes SCENE as the scene (the view on its default address)") {
  st::test::TempDir d;
  // A scene with an unknown section: the run stops at its parse, naming it, so nothing binds.
  st::test::write_file(d.file("s.toml"), "[nonsense]\nx = 1\n");
  auto r = run_command(spheretouch_exe() + " run --view " + d.file("s.toml"));
  INFO(r.output);
  CHECK(r.exit_code == 2);
  CHECK(contains(r.output, "s.toml"));
  CHECK(contains(r.output, "nonsense"));
  CHECK_FALSE(contains(r.output, "expected ADDR:PORT"));  // before: the scene was taken as the address
  r = run_command(spheretouch_exe() + " run");
  CHECK(r.exit_code == 2);
  CHECK(contains(r.output, "a scene file is required"));
  r = run_command(spheretouch_exe() + " run --view not-an-address");
  CHECK(r.exit_code == 2);
  CHECK(contains(r.output, "a scene file is required"));
}

TEST_CASE("info --scene describes the probe and every object with its placement and material") {
  st::test::TempDir d;
  REQUIRE(st::geom::write_off(st::geom::make_icosphere(10, 4), d.file("ball.off")).ok());
  st::test::write_file(
      d.file("s.toml"),
      "[probe]\nbuiltin = \"capsule\"\n[[object]]\nname = \"ball\"\nmesh = \"ball.off\"\nposition_mm = "
      "[1, 2, 3]\n[[object]]\nbuiltin = \"box\"\nrotation_deg = [0, 0, 45]\n[object.material]\nlaw = "
      "\"linear\"\nspring_n_per_mm = 0.7\nstatic_friction = 0.5\ndynamic_friction = 0.25\n");
  const auto r = st::test::run_command(st::test::spheretouch_exe() + " info --scene " + d.file("s.toml"));
  INFO(r.output);
  CHECK(r.exit_code == 0);
  CHECK(st::test::contains(r.output, "probe:\ncapsule (generated)"));
  CHECK(st::test::contains(r.output, "object 1 \"ball\":"));
  CHECK(st::test::contains(r.output, "faces       320"));  // icosphere, frequency 4: 20 * 4^2
  CHECK(st::test::contains(r.output, "placement   position [1, 2, 3] mm"));
  CHECK(st::test::contains(r.output, "object 2 \"object 2\":\nbox (generated)"));
  CHECK(st::test::contains(r.output, "rotation [0, 0, 45] deg"));
  CHECK(st::test::contains(r.output,
                           "material    linear law 0.7 N/mm, damping 0 N s/mm, friction static 0.5 dynamic 0.25"));
  const auto bad = st::test::run_command(st::test::spheretouch_exe() + " info 2>&1");
  CHECK(bad.exit_code == 2);
  CHECK(st::test::contains(bad.output, "give mesh files, or --scene SCENE"));
}

TEST_CASE("info and export fail with the file named, exit code 2") {
  st::test::TempDir d;
  st::test::write_file(d.file("bad.off"), "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 5\n");
  auto r = run_command(spheretouch_exe() + " info " + d.file("bad.off"));
  CHECK(r.exit_code == 2);
  CHECK(contains(r.output, "bad.off:6: face 0: vertex index 5 out of range [0, 3)"));
  st::test::write_file(d.file("open.off"), "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  r = run_command(spheretouch_exe() + " export " + d.file("open.off") + " -o " + d.file("o.off") + " --subdivide 1");
  CHECK(r.exit_code == 2);
  CHECK(contains(r.output, "open mesh"));
}

TEST_CASE("export: rescale then subdivide, readable again with the same face count") {
  st::test::TempDir d;
  const auto r = run_command(spheretouch_exe() + " export " + st::test::model("hand.off") + " -o " + d.file("h.off") +
                             " --diagonal 50 --subdivide 1");
  INFO(r.output);
  REQUIRE(r.exit_code == 0);
  const auto info = run_command(spheretouch_exe() + " info " + d.file("h.off"));
  CHECK(contains(info.output, "faces       9560 "));
}
