// SPDX-License-Identifier: BSD-3-Clause
// Tests for src/spheretouch/geom/mesh_io.*: every format from a small generated file, face order, every bad
// input's message, precision far from the origin, units and scale, degenerate-face policy.
#include <spheretouch/geom/mesh_io.hpp>

#include <cmath>
#include <cstring>
#include <limits>

#include "test_util.hpp"

using namespace st;
using namespace st::geom;
using st::test::contains;
using st::test::TempDir;
using st::test::write_file;
using namespace std::string_literals;

namespace {

// A square pyramid whose five faces are all different, coordinates exact in float.
const std::vector<Vec3> kPos = {{0, 0, 0}, {2, 0, 0}, {2, 2, 0}, {0, 2, 0}, {1, 1, 1.5}};
const std::vector<Tri> kTris = {{0, 2, 1}, {0, 3, 2}, {0, 1, 4}, {1, 2, 4}, {2, 3, 4}, {3, 0, 4}};

std::string off_text() {
  // The base is one quad (0 3 2 1) -> fan (0,3,2), (0,2,1): written as a polygon to test fanning.
  return "OFF\n# a pyramid\n5 5 0\n0 0 0\n2 0 0\n2 2 0\n0 2 0\n1 1 1.5\n4 0 3 2 1\n3 0 1 4\n3 1 2 4\n3 2 3 4\n3 3 0 "
         "4\n";
}
const std::vector<Tri> kFannedOff = {{0, 3, 2}, {0, 2, 1}, {0, 1, 4}, {1, 2, 4}, {2, 3, 4}, {3, 0, 4}};

/// Face i of `m` must be the triangle kPos[want[i]] in the same cyclic order.
void check_faces(const Mesh& m, const std::vector<Tri>& want) {
  REQUIRE(m.num_faces() == want.size());
  for (std::size_t i = 0; i < want.size(); ++i)
    for (int k = 0; k < 3; ++k) {
      INFO("face " << i << " corner " << k);
      CHECK(m.vertex(m.faces[i][k]).isApprox(kPos[want[i][k]], 0.0));
      CHECK((m.vertex(m.faces[i][k]) - kPos[want[i][k]]).norm() == 0.0);
    }
}

std::string binary_stl(const std::vector<Tri>& tris) {
  std::string s(80, ' ');
  const auto n = static_cast<std::uint32_t>(tris.size());
  s.append(reinterpret_cast<const char*>(&n), 4);
  for (const Tri& t : tris) {
    const Vec3 nrm = (kPos[t[1]] - kPos[t[0]]).cross(kPos[t[2]] - kPos[t[0]]).normalized();
    float f[12] = {float(nrm.x()), float(nrm.y()), float(nrm.z())};
    for (int k = 0; k < 3; ++k)
      for (int c = 0; c < 3; ++c) f[3 + 3 * k + c] = float(kPos[t[k]][c]);
    s.append(reinterpret_cast<const char*>(f), sizeof f);
    s.append(2, '\0');
  }
  return s;
}

std::string base64(const std::string& in) {
  static const char* tbl = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  std::size_t i = 0;
  for (; i + 2 < in.size(); i += 3) {
    const unsigned v = (unsigned char)in[i] << 16 | (unsigned char)in[i + 1] << 8 | (unsigned char)in[i + 2];
    out += tbl[v >> 18 & 63];
    out += tbl[v >> 12 & 63];
    out += tbl[v >> 6 & 63];
    out += tbl[v & 63];
  }
  if (i + 1 == in.size()) {
    const unsigned v = (unsigned char)in[i] << 16;
    out += tbl[v >> 18 & 63];
    out += tbl[v >> 12 & 63];
    out += "==";
  } else if (i + 2 == in.size()) {
    const unsigned v = (unsigned char)in[i] << 16 | (unsigned char)in[i + 1] << 8;
    out += tbl[v >> 18 & 63];
    out += tbl[v >> 12 & 63];
    out += tbl[v >> 6 & 63];
    out += '=';
  }
  return out;
}

std::string gltf_text() {
  std::string bin;
  for (const Vec3& p : kPos)
    for (int c = 0; c < 3; ++c) {
      float f = float(p[c]);
      bin.append(reinterpret_cast<const char*>(&f), 4);
    }
  const std::size_t pos_bytes = bin.size();
  for (const Tri& t : kTris)
    for (int k = 0; k < 3; ++k) {
      std::uint16_t i = std::uint16_t(t[k]);
      bin.append(reinterpret_cast<const char*>(&i), 2);
    }
  const std::size_t idx_bytes = bin.size() - pos_bytes;
  return R"({"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[0]}],"nodes":[{"mesh":0}],
"meshes":[{"primitives":[{"attributes":{"POSITION":0},"indices":1,"mode":4}]}],
"buffers":[{"byteLength":)" +
         std::to_string(bin.size()) + R"(,"uri":"data:application/octet-stream;base64,)" + base64(bin) + R"("}],
"bufferViews":[{"buffer":0,"byteOffset":0,"byteLength":)" +
         std::to_string(pos_bytes) + R"(},
{"buffer":0,"byteOffset":)" +
         std::to_string(pos_bytes) + R"(,"byteLength":)" + std::to_string(idx_bytes) + R"(}],
"accessors":[{"bufferView":0,"componentType":5126,"count":5,"type":"VEC3","min":[0,0,0],"max":[2,2,1.5]},
{"bufferView":1,"componentType":5123,"count":18,"type":"SCALAR"}]})";
}

/// The same glTF with its buffer in a separate file named by `uri`; `bin` gets the buffer's bytes.
std::string gltf_external(const std::string& uri, std::string& bin) {
  std::string t = gltf_text();
  const std::size_t a = t.find("data:application"), b = t.find('"', a);
  const std::string b64 = t.substr(a + 37, b - a - 37);  // after "data:application/octet-stream;base64,"
  bin.clear();
  const std::string tbl = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  unsigned acc = 0;
  int bits = 0;
  for (char c : b64) {
    if (c == '=') break;
    acc = acc << 6 | unsigned(tbl.find(c));
    bits += 6;
    if (bits >= 8) bin += char(acc >> (bits -= 8) & 0xFF);
  }
  return t.replace(a, b - a, uri);
}

std::string load_error(const std::string& path, const LoadConfig& o = {}) {
  Result<LoadedMesh> r = load_mesh(path, o);
  REQUIRE_FALSE(r.ok());
  return r.error();
}

}  // namespace

TEST_CASE("OFF: double path, polygons fan-triangulated in file order") {
  TempDir d;
  write_file(d.file("p.off"), off_text());
  Result<LoadedMesh> r = load_mesh(d.file("p.off"));
  REQUIRE(r.ok());
  check_faces(r.value().mesh, kFannedOff);
  CHECK(r.value().report.precision.rfind("double", 0) == 0);
  CHECK(r.value().report.polygons == 5);
  CHECK(r.value().report.fanned_polygons == 1);
  CHECK(r.value().mesh.topology().closed());
  CHECK(r.value().mesh.topology().manifold());
}

TEST_CASE("OBJ: double path, negative indices, v/vt/vn forms, order kept across materials") {
  TempDir d;
  write_file(d.file("p.obj"),
             "mtllib none.mtl\nv 0 0 0\nv 2 0 0\nv 2 2 0\nv 0 2 0\nv 1 1 1.5\nvt 0 0\nvn 0 0 1\n"
             "usemtl a\nf 1/1/1 3/1/1 2/1/1\nusemtl b\nf 1//1 4//1 3//1\nusemtl a\nf -5 -4 -1\nf 2/1 3/1 5/1\n"
             "usemtl b\nf 3 4 5\nf 4 1 5\n");
  Result<LoadedMesh> r = load_mesh(d.file("p.obj"));
  REQUIRE(r.ok());
  check_faces(r.value().mesh, kTris);
  CHECK(r.value().report.reader == "spheretouch OBJ reader");
}

TEST_CASE("ASCII PLY: double path, extra properties skipped") {
  TempDir d;
  std::string s =
      "ply\nformat ascii 1.0\ncomment test\nelement vertex 5\nproperty float x\nproperty float y\n"
      "property float z\nproperty uchar red\nelement face 6\nproperty list uchar int vertex_indices\n"
      "property int flags\nend_header\n";
  for (const Vec3& p : kPos)
    s += std::to_string(p.x()) + " " + std::to_string(p.y()) + " " + std::to_string(p.z()) + " 7\n";
  for (const Tri& t : kTris)
    s += "3 " + std::to_string(t[0]) + " " + std::to_string(t[1]) + " " + std::to_string(t[2]) + " 0\n";
  write_file(d.file("p.ply"), s);
  Result<LoadedMesh> r = load_mesh(d.file("p.ply"));
  REQUIRE(r.ok());
  check_faces(r.value().mesh, kTris);
  CHECK(r.value().report.precision.rfind("double", 0) == 0);
}

TEST_CASE("binary PLY, ASCII and binary STL (ours), glTF (assimp) keep face order") {
  TempDir d;
  SUBCASE("binary PLY") {
    std::string s =
        "ply\nformat binary_little_endian 1.0\nelement vertex 5\nproperty float x\nproperty float y\n"
        "property float z\nelement face 6\nproperty list uchar int vertex_indices\nend_header\n";
    for (const Vec3& p : kPos)
      for (int c = 0; c < 3; ++c) {
        float f = float(p[c]);
        s.append(reinterpret_cast<const char*>(&f), 4);
      }
    for (const Tri& t : kTris) {
      s += char(3);
      for (int k = 0; k < 3; ++k) {
        std::int32_t i = std::int32_t(t[k]);
        s.append(reinterpret_cast<const char*>(&i), 4);
      }
    }
    write_file(d.file("p.ply"), s);
    Result<LoadedMesh> r = load_mesh(d.file("p.ply"));
    REQUIRE(r.ok());
    check_faces(r.value().mesh, kTris);
    CHECK(r.value().report.reader == "spheretouch PLY (binary) reader");
  }
  SUBCASE("ASCII STL") {
    std::string s = "solid p\n";
    for (const Tri& t : kTris) {
      s += "facet normal 0 0 0\nouter loop\n";
      for (int k = 0; k < 3; ++k)
        s += "vertex " + std::to_string(kPos[t[k]].x()) + " " + std::to_string(kPos[t[k]].y()) + " " +
             std::to_string(kPos[t[k]].z()) + "\n";
      s += "endloop\nendfacet\n";
    }
    s += "endsolid p\n";
    write_file(d.file("p.stl"), s);
    Result<LoadedMesh> r = load_mesh(d.file("p.stl"));
    REQUIRE(r.ok());
    check_faces(r.value().mesh, kTris);
    CHECK(r.value().mesh.num_vertices() == 5);  // welded
    CHECK(r.value().mesh.topology().closed());
  }
  SUBCASE("binary STL") {
    write_file(d.file("p.stl"), binary_stl(kTris));
    Result<LoadedMesh> r = load_mesh(d.file("p.stl"));
    REQUIRE(r.ok());
    check_faces(r.value().mesh, kTris);
    CHECK(r.value().report.welded_vertices == 18 - 5);
  }
  SUBCASE("glTF with an embedded buffer") {
    write_file(d.file("p.gltf"), gltf_text());
    Result<LoadedMesh> r = load_mesh(d.file("p.gltf"));
    REQUIRE(r.ok());
    check_faces(r.value().mesh, kTris);
    CHECK(r.value().report.precision.rfind("float", 0) == 0);
  }
}

TEST_CASE("bad input: each error names the file and the item") {
  TempDir d;
  CHECK(contains(load_error(d.file("missing.off")), "missing.off: cannot open"));
  write_file(d.file("x.xyzzy"), "hello");
  CHECK(contains(load_error(d.file("x.xyzzy")), "unknown mesh format '.xyzzy'"));
  write_file(d.file("noext"), "hello");
  CHECK(contains(load_error(d.file("noext")), "unknown mesh format"));
  write_file(d.file("empty.off"), "OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n");
  CHECK(contains(load_error(d.file("empty.off")), "empty.off: no triangles"));
  write_file(d.file("range.off"), "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n");
  CHECK(contains(load_error(d.file("range.off")), "range.off:6: face 0: vertex index 3 out of range [0, 3)"));
  write_file(d.file("nan.off"), "OFF\n3 1 0\n0 0 0\n1 nan 0\n0 1 0\n3 0 1 2\n");
  CHECK(contains(load_error(d.file("nan.off")), "nan.off:4: vertex 1: coordinate 'nan' is not finite"));
  write_file(d.file("inf.obj"), "v 0 0 0\nv 1 0 inf\nv 0 1 0\nf 1 2 3\n");
  CHECK(contains(load_error(d.file("inf.obj")), "inf.obj:2: vertex 1: coordinate 'inf' is not finite"));
  write_file(d.file("big.off"), "OFF\n3 1 0\n1e200 0 0\n0 1 0\n0 0 1\n3 0 1 2\n");  // finite, but not usable
  CHECK(contains(load_error(d.file("big.off")),
                 "big.off: vertex 0: coordinate too large (9.9999999999999997e+199, 0, 0)"));
  write_file(d.file("word.off"), "OFF\n3 1 0\n0 0 0\n1 zero 0\n0 1 0\n3 0 1 2\n");
  CHECK(contains(load_error(d.file("word.off")), "word.off:4: vertex 1: 'zero' is not a number"));
  write_file(d.file("short.off"), "OFF\n3 1 0\n0 0 0\n1 0 0\n");
  CHECK(contains(load_error(d.file("short.off")), "short.off: file ends after 2 of 3 vertices"));
  write_file(d.file("header.off"), "PLY\n3 1 0\n");
  CHECK(contains(load_error(d.file("header.off")), "header.off:1: expected an 'OFF' header"));
  write_file(d.file("huge.off"), "OFF\n999999999999 1 0\n");
  CHECK(contains(load_error(d.file("huge.off")), "exceed what a"));
  write_file(d.file("obj0.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n");
  CHECK(contains(load_error(d.file("obj0.obj")), "obj0.obj:4: face 0: vertex reference '0' is not a non-zero integer"));
  write_file(d.file("objr.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n");
  CHECK(contains(load_error(d.file("objr.obj")), "objr.obj:4: face 0: vertex index 4 out of range"));
  write_file(d.file("line.obj"), "v 0 0 0\nv 1 0 0\nf 1 2\n");
  CHECK(contains(load_error(d.file("line.obj")), "line.obj:3: face 0: has 2 corners"));
  write_file(d.file("p.ply"),
             "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
             "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 9\n");
  CHECK(contains(load_error(d.file("p.ply")), "p.ply:13: face 0: vertex index 9 out of range [0, 3)"));
  write_file(d.file("bad.stl"), "solid x\nfacet normal 0 0 0\nouter loop\nvertex 0 0\n");
  CHECK(contains(load_error(d.file("bad.stl")), "bad.stl"));
  write_file(d.file("u.off"), off_text());
  LoadConfig bad_units;
  bad_units.units = "furlong";
  CHECK(contains(load_error(d.file("u.off"), bad_units), "units 'furlong' not known"));
}

TEST_CASE("binary PLY: either byte order, any scalar type, doubles kept exactly") {
  // Big-endian doubles for x, y, z (one not representable in float), a skipped uchar colour
  // and a ushort-counted list of uint indices; a skipped second element after the faces.
  auto be = [](auto v) {
    std::string b(sizeof v, '\0');
    std::memcpy(b.data(), &v, sizeof v);
    return std::string(b.rbegin(), b.rend());
  };
  std::string s =
      "ply\r\nformat binary_big_endian 1.0\r\nelement vertex 5\r\nproperty float64 x\r\nproperty double y\r\n"
      "property double z\r\nproperty uchar red\r\nelement face 5\r\nproperty list ushort uint vertex_indices\r\n"
      "element edge 1\r\nproperty int vertex1\r\nend_header\r\n";
  const std::vector<Vec3> pos = {{0, 0, 0}, {2, 0, 0}, {2, 2, 0}, {0, 2, 0}, {1, 1, 1.5 + 1e-12}};
  for (const Vec3& p : pos) {
    for (int c = 0; c < 3; ++c) s += be(p[c]);
    s += char(7);
  }
  const std::vector<std::vector<std::uint32_t>> polys = {{0, 3, 2, 1}, {0, 1, 4}, {1, 2, 4}, {2, 3, 4}, {3, 0, 4}};
  for (const auto& poly : polys) {
    s += be(std::uint16_t(poly.size()));
    for (std::uint32_t i : poly) s += be(i);
  }
  s += be(std::int32_t(1));
  Result<LoadedMesh> r = parse_mesh(s, ".ply", "be.ply");
  REQUIRE_MESSAGE(r.ok(), r.error());
  const Mesh& m = r.value().mesh;
  REQUIRE(m.num_faces() == 6);
  CHECK(m.faces[0] == Tri{0, 3, 2});
  CHECK(m.faces[1] == Tri{0, 2, 1});
  CHECK(m.vertex(4).z() == 1.5 + 1e-12);  // a double property stays a double
  CHECK(r.value().report.fanned_polygons == 1);
}

TEST_CASE("hostile PLY: truncated or inconsistent files are refused with a message (fuzz findings)") {
  auto error = [](const std::string& text) {
    Result<LoadedMesh> r = parse_mesh(text, ".ply", "h.ply");
    REQUIRE_FALSE(r.ok());
    return r.error();
  };
  // fuzz_mesh's first finding: a binary header cut off before end_header crashed assimp 5.2.5
  // (read past the buffer); our reader refuses the broken line, and a header without
  // end_header ends where the text ends.
  CHECK(contains(error("ply\nformat binary_little_endian 1.0\nelement vertex 5\nproperty flo\0\0\0\0@\0\0"s),
                 "h.ply:4: property without a name"));
  CHECK(contains(error("ply\nformat binary_little_endian 1.0\nelement vertex 5\n"),
                 "h.ply: file ends inside the header"));
  const std::string head =
      "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
  CHECK(contains(error(head + std::string(35, '\0')),
                 "h.ply: byte 169: element 'vertex': 3 items of at least 12 bytes do not fit in the 35 bytes left"));
  std::string tris(36, '\0');
  CHECK(contains(error(head + tris + "\x03\x01"s),
                 "h.ply: byte 206: face 0: list of 3 values does not fit in the 1 bytes left"));
  CHECK(contains(error(head + tris + "\x03\x00\x00\x00\x00\x01\x00\x00\x00\x07\x00\x00\x00"s),
                 "h.ply: byte 218: face 0: vertex index 7 out of range [0, 3)"));
  CHECK(contains(error(head + tris + "\x02\x00\x00\x00\x00\x01\x00\x00\x00"s), "face 0: has 2 corners"));
  const std::string nan_x = "\x00\x00\xc0\x7f"s;
  CHECK(contains(error(head + nan_x + std::string(32, '\0') + "\x03\x00\x00\x00\x00\x01\x00\x00\x00\x02\x00\x00\x00"s),
                 "vertex 0: coordinate nan is not finite"));
  CHECK(contains(error("ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty quad x\nend_header\n"),
                 "element 'vertex' property 'x': type must be one of"));
  CHECK(contains(
      error(
          "ply\nformat binary_little_endian 1.0\nelement face 1\nproperty list float int vertex_indices\nend_header\n"),
      "with an integer count type"));
  CHECK(contains(error("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float x\nproperty float "
                       "y\nend_header\n"),
                 "element 'vertex' declares property 'x' twice"));
  CHECK(contains(error("ply\nformat ascii 1.0\nelement vertex 1\nproperty list uchar float x\nproperty float "
                       "y\nproperty float z\nend_header\n"),
                 "property 'x' is a list"));
  CHECK(contains(error("ply\nformat text 1.0\nend_header\n"),
                 "h.ply:2: format 'text' is not ascii, binary_little_endian or binary_big_endian"));
}

TEST_CASE("STL (ours): ASCII in double precision, several solids, hostile files refused (fuzz findings)") {
  auto error = [](const std::string& text) {
    Result<LoadedMesh> r = parse_mesh(text, ".stl", "h.stl");
    REQUIRE_FALSE(r.ok());
    return r.error();
  };
  const std::string facet =
      "facet normal 0 0 1\n outer loop\n  vertex 1000000.001 0 0\n  vertex 1000001 0 0\n  vertex 1000000 1 0\n "
      "endloop\nendfacet\n";
  Result<LoadedMesh> r =
      parse_mesh("solid a\n" + facet + "endsolid a\nsolid b\n" + facet + "endsolid b\n", ".stl", "two.stl");
  REQUIRE_MESSAGE(r.ok(), r.error());
  CHECK(r.value().mesh.num_faces() == 2);
  CHECK(r.value().mesh.num_vertices() == 3);  // the second solid's vertices weld onto the first's
  CHECK(r.value().report.welded_vertices == 3);
  CHECK(r.value().mesh.vertex(0).x() == 1000000.001);  // assimp's float would give 1000000
  // fuzz_mesh: a truncated ASCII STL leaked two objects inside assimp 5.2.5 (tests/lsan.supp);
  // our reader names the line.
  CHECK(
      contains(error("solid x\nfacet normal 0 0 0\nouter loop\nvertex 0 0\n"), "h.stl:4: facet 0: '' is not a number"));
  CHECK(contains(error("solid x\nfacet normal 0 0 0\nouter loop\nvertex 0 0 0\n"), "h.stl: file ends inside facet 0"));
  CHECK(contains(error("solid x\nfacet normal 0 0 0\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\n"),
                 "h.stl: file ends inside facet 0"));
  CHECK(contains(error("solid x\nfacet normal 0 0 0\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nendloop\nendfacet\n"),
                 "h.stl:6: facet 0: has 2 vertices (expected at least 3)"));
  CHECK(contains(error("solid x\nfacet normal 0 0 0\nouter loop\nvertex 0 inf 0\n"),
                 "h.stl:4: facet 0: coordinate 'inf' is not finite"));
  CHECK(contains(error("solid x\nfacet normal 0 0\n"), "h.stl:2: expected 'facet normal NX NY NZ'"));
  CHECK(contains(error("solid x\nendsolid x\n"), "h.stl: no triangles"));
  CHECK(contains(error(""), "h.stl: empty file"));
  // Binary: recognised by its exact size; a count that does not match is named.
  std::string bin = binary_stl(kTris);
  CHECK(contains(
      error(bin + "x"),
      "not an ASCII STL (no 'solid' line) and not a binary one either (6 facets take 384 bytes, the file has 385)"));
  const float nan = std::numeric_limits<float>::quiet_NaN();
  std::memcpy(bin.data() + 84 + 50 * 2 + 12 + 12 + 4, &nan, 4);
  CHECK(contains(error(bin), "h.stl: facet 2 (byte 208): vertex 1 is not finite"));
}

TEST_CASE("degenerate faces are reported and kept in place") {
  TempDir d;
  // Face 1 is collinear, face 2 repeats a vertex; faces 0 and 3 are fine.
  write_file(d.file("deg.off"), "OFF\n5 4 0\n0 0 0\n1 0 0\n0 1 0\n2 0 0\n0 0 1\n3 0 1 2\n3 0 1 3\n3 0 0 2\n3 0 1 4\n");
  Result<LoadedMesh> r = load_mesh(d.file("deg.off"));
  REQUIRE(r.ok());
  CHECK(r.value().mesh.num_faces() == 4);
  CHECK(r.value().report.degenerate == std::vector<std::uint32_t>{1, 2});
  CHECK(r.value().mesh.faces[3] == Tri{0, 1, 4});
}

TEST_CASE("units and scale convert to millimetres") {
  TempDir d;
  write_file(d.file("p.off"), off_text());
  LoadConfig o;
  o.units = "cm";
  o.scale = 2;
  Result<LoadedMesh> r = load_mesh(d.file("p.off"), o);
  REQUIRE(r.ok());
  CHECK(r.value().mesh.vertex(4).isApprox(Vec3(20, 20, 30), 1e-15));
  CHECK(unit_to_mm("in").value() == 25.4);
}

TEST_CASE("a mesh 10^6 mm from the origin keeps its shape to 1e-9 relative") {
  TempDir d;
  for (const double offset : {1e6, -1e6, 3.7e6}) {
    std::string s = "OFF\n5 5 0\n";
    std::vector<Vec3> placed;
    char buf[80];  // three %.17g of up to 24 characters, two spaces and a newline
    for (const Vec3& p : kPos) {
      // Perturb the shape so it is not grid-aligned, then place it far away.
      const Vec3 q = Vec3(offset, offset / 2, -offset) + p * 1.2345678;
      placed.push_back(q);
      std::snprintf(buf, sizeof buf, "%.17g %.17g %.17g\n", q.x(), q.y(), q.z());
      s += buf;
    }
    s += "4 0 3 2 1\n3 0 1 4\n3 1 2 4\n3 2 3 4\n3 3 0 4\n";
    write_file(d.file("far.off"), s);
    Result<LoadedMesh> r = load_mesh(d.file("far.off"));
    REQUIRE(r.ok());
    const Mesh& m = r.value().mesh;
    CHECK(m.origin.norm() > 0.5 * std::abs(offset));
    for (int a = 0; a < 5; ++a)
      for (int b = 0; b < 5; ++b) {
        const Vec3 want = placed[b] - placed[a];  // exact: both within a factor 2 (Sterbenz)
        const Vec3 got = m.local[b] - m.local[a];
        CHECK((got - want).norm() <= 1e-9 * std::max(1.0, want.norm()));
      }
    // Round trip through write_off keeps every coordinate exactly.
    REQUIRE(write_off(m, d.file("back.off")).ok());
    Result<LoadedMesh> back = load_mesh(d.file("back.off"));
    REQUIRE(back.ok());
    for (std::uint32_t i = 0; i < 5; ++i) CHECK((back.value().mesh.vertex(i) - placed[i]).norm() == 0.0);
  }
}

TEST_CASE("write_mesh writes the format the extension names, and reads back the same mesh") {
  st::test::TempDir d;
  std::string s = "OFF\n5 5 0\n";
  const Vec3 v[5] = {{0.1, 0.2, 0.3}, {1e6 + 0.123456789, -2, 3}, {1.0 / 3, 2.0 / 3, 1e-9}, {-5, 7, 11}, {2, 2, 2}};
  char buf[128];
  for (const Vec3& p : v) {
    std::snprintf(buf, sizeof buf, "%.17g %.17g %.17g\n", p.x(), p.y(), p.z());
    s += buf;
  }
  s += "3 0 1 2\n3 0 2 3\n3 1 3 4\n3 2 4 0\n3 4 3 2\n";
  write_file(d.file("in.off"), s);
  const Mesh m = load_mesh(d.file("in.off")).value().mesh;
  for (const std::string ext : {".off", ".ply", ".obj", ".PLY"}) {
    CAPTURE(ext);
    const std::string out = d.file("out" + ext);
    REQUIRE(write_mesh(m, out).ok());
    Result<LoadedMesh> back = load_mesh(out);
    REQUIRE(back.ok());
    CHECK(back.value().report.precision.rfind("double", 0) == 0);
    REQUIRE(back.value().mesh.num_faces() == m.num_faces());
    for (std::uint32_t f = 0; f < m.num_faces(); ++f)
      for (int k = 0; k < 3; ++k) {
        // As exact as loading the original: a body is stored relative to its centre, so each
        // vertex comes back within a few ulps of the body's largest coordinate (1e6 mm here).
        const Vec3 want = v[m.faces[f][k]];
        const Vec3 got = back.value().mesh.vertex(back.value().mesh.faces[f][k]);
        CHECK((got - want).norm() <= 4 * 0x1p-52 * 1e6);
      }
  }
  // The file says what it is: a .ply starts as PLY, an .obj has v/f lines.
  CHECK(st::test::read_file(d.file("out.ply")).rfind("ply\n", 0) == 0);
  CHECK(st::test::read_file(d.file("out.obj")).find("\nf 1 2 3\n") != std::string::npos);
  // Any other extension is refused, naming it, and writes nothing.
  for (const std::string bad : {"out.stl", "out.gltf", "out"}) {
    CAPTURE(bad);
    const Status r = write_mesh(m, d.file(bad));
    REQUIRE_FALSE(r.ok());
    CHECK(r.error().find("cannot write") != std::string::npos);
    CHECK(r.error().find(".off, .ply or .obj") != std::string::npos);
    CHECK_FALSE(std::filesystem::exists(d.file(bad)));
  }
}

TEST_CASE("a mesh whose size is implausible in its units gets a warning naming the units that fit") {
  st::test::TempDir d;
  // A 20 cm box written in metres (a CAD export), read as the default millimetres: 0.35 mm across.
  write_file(d.file("box_m.off"),
             "OFF\n8 12 0\n0 0 0\n0.2 0 0\n0 0.2 0\n0.2 0.2 0\n0 0 0.2\n0.2 0 0.2\n0 0.2 0.2\n0.2 0.2 0.2\n"
             "3 0 2 1\n3 1 2 3\n3 4 5 6\n3 5 7 6\n3 0 1 4\n3 1 5 4\n3 2 6 3\n3 3 6 7\n3 0 4 2\n3 2 4 6\n"
             "3 1 3 5\n3 3 7 5\n");
  Result<LoadedMesh> mm = load_mesh(d.file("box_m.off"));
  REQUIRE(mm.ok());  // loaded anyway: the user may mean it
  const std::string& w = mm.value().report.size_warning;
  INFO(w);
  CHECK(w.find("box_m.off") != std::string::npos);
  CHECK(w.find("implausibly small") != std::string::npos);
  CHECK(w.find("units = \"m\" would make it 346 mm") != std::string::npos);
  // Read in metres: 346 mm across, plausible, no warning.
  LoadConfig in_m;
  in_m.units = "m";
  CHECK(load_mesh(d.file("box_m.off"), in_m).value().report.size_warning.empty());
  // Far too large (a building in mm read as metres).
  LoadConfig huge;
  huge.units = "m";
  huge.scale = 1e4;
  const std::string big = load_mesh(d.file("box_m.off"), huge).value().report.size_warning;
  CHECK(big.find("implausibly large") != std::string::npos);
  // The model set is plausible as it is.
  CHECK(load_mesh(st::test::model("hand.off")).value().report.size_warning.empty());
}

TEST_CASE("real meshes: the model set loads closed and manifold") {
  for (const char* name : {"hand.off", "hand_L2.off", "elephant.off", "armadillo_L1.off"}) {
    Result<LoadedMesh> r = load_mesh(st::test::model(name));
    REQUIRE(r.ok());
    const Topology t = r.value().mesh.topology();
    INFO(name);
    CHECK(t.closed());
    CHECK(t.manifold());
  }
  CHECK(load_mesh(st::test::model("hand_L2.off")).value().mesh.num_faces() == 38240);
  CHECK(load_mesh(st::test::model("elephant.off")).value().mesh.num_faces() == 88928);
  CHECK(load_mesh(st::test::model("armadillo_L1.off")).value().mesh.num_faces() == 208000);
}

TEST_CASE("assimp formats: a file opens no other file unless allowed, and never one outside its directory") {
  TempDir d;
  std::filesystem::create_directories(d.path / "mesh");
  std::string bin;
  write_file(d.file("mesh/ext.gltf"), gltf_external("p.bin", bin));
  write_file(d.file("mesh/p.bin"), bin);
  // Default: only the file itself.
  const std::string e = load_error(d.file("mesh/ext.gltf"));
  CHECK(contains(e, "ext.gltf"));
  CHECK(contains(e, "p.bin"));
  CHECK(contains(e, "not opened"));
  // Allowed: a buffer in the same directory loads, exactly.
  LoadConfig allow;
  allow.allow_external_files = true;
  Result<LoadedMesh> r = load_mesh(d.file("mesh/ext.gltf"), allow);
  REQUIRE_MESSAGE(r.ok(), r.error());
  check_faces(r.value().mesh, kTris);
  // Outside the directory, by ../ or by a symlink: refused even when allowed (its bytes would
  // come back as coordinates).
  write_file(d.file("secret.bin"), bin);
  write_file(d.file("mesh/up.gltf"), gltf_external("../secret.bin", bin));
  CHECK(contains(load_error(d.file("mesh/up.gltf"), allow), "secret.bin"));
  std::filesystem::create_symlink(d.path / "secret.bin", d.path / "mesh" / "link.bin");
  write_file(d.file("mesh/link.gltf"), gltf_external("link.bin", bin));
  CHECK(contains(load_error(d.file("mesh/link.gltf"), allow), "link.bin"));
}

TEST_CASE("assimp formats: a tiny file that makes assimp allocate gigabytes is refused at its budget") {
  // DirectX .x: assimp sizes its vertex array from the count (200 million vertices, 2.4 GB), a
  // 100-byte file. The reader runs in a child with a memory budget; this process never grows.
  TempDir d;
  write_file(
      d.file("bomb.x"),
      "xof 0303txt 0032\nMesh m {\n 200000000;\n 0.0;0.0;0.0;,\n 1.0;0.0;0.0;,\n 0.0;1.0;0.0;;\n 1;\n 3;0,1,2;;\n}\n");
  const std::string e = load_error(d.file("bomb.x"));
  CHECK(contains(e, "bomb.x"));
  CHECK(contains(e, "budget"));
  // A legitimate file still loads under the same budget.
  write_file(d.file("ok.gltf"), gltf_text());
  CHECK(load_mesh(d.file("ok.gltf")).ok());
}
