// SPDX-License-Identifier: BSD-3-Clause
// The STL reader, ASCII and binary (float32; exact duplicate vertices welded). Declared in
// mesh_io.hpp.
#include <spheretouch/geom/mesh_io.hpp>

#include <bit>
#include <cstring>
#include <string>
#include <vector>

#include <spheretouch/geom/mesh_io_detail.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {

using namespace detail;

Result<LoadedMesh> parse_stl(std::string_view bytes, const std::string& name) {
  LoadReport rep;
  Welder weld;
  std::vector<Tri> faces;
  std::vector<std::uint32_t> poly;
  // Binary: 80-byte header, u32 facet count N, N x {normal, 3 vertices: 12 float32; u16
  // attribute}, little-endian; recognised by its exact size (an ASCII file can't match it by
  // chance in practice, and binary headers often start with "solid" too).
  if (bytes.size() >= 84) {
    std::uint32_t n = 0;
    std::memcpy(&n, bytes.data() + 80, 4);
    static_assert(std::endian::native == std::endian::little, "binary STL is read with memcpy");
    if (bytes.size() == 84 + 50 * std::uint64_t{n}) {
      rep.reader = "spheretouch STL (binary) reader";
      rep.precision = "float (binary STL stores float32; widened exactly)";
      faces.reserve(n);
      for (std::uint32_t f = 0; f < n; ++f) {
        float c[9];
        std::memcpy(c, bytes.data() + 84 + 50 * std::size_t{f} + 12, sizeof c);  // skip the normal
        poly.clear();
        for (int k = 0; k < 3; ++k) {
          const Vec3 q(c[3 * k], c[3 * k + 1], c[3 * k + 2]);
          if (!q.allFinite())
            return fail(name, ": facet ", f, " (byte ", 84 + 50 * std::size_t{f} + 12 + 12 * k, "): vertex ", k,
                        " is not finite");
          poly.push_back(weld.add(q));
        }
        fan(poly, faces, rep);
      }
      rep.welded_vertices = weld.welded();
      if (faces.empty()) return fail(name, ": no triangles (0 facets)");
      return finish(name, weld.positions(), std::move(faces), std::move(rep));
    }
  }
  // ASCII: solid NAME { facet normal n n n / outer loop / vertex x y z (3 or more) / endloop /
  // endfacet } endsolid NAME, possibly several solids; keywords are matched per line.
  rep.reader = "spheretouch STL (ascii) reader";
  rep.precision = "double (correctly rounded)";
  Lines lines(bytes);
  std::string_view line;
  enum class At { Outside, Solid, Facet, Loop, EndLoop } at = At::Outside;
  std::size_t facet = 0;
  while (lines.next(line, false)) {
    std::string_view rest = line;
    const std::string_view kw = token(rest);
    auto expected = [&](const char* what) {
      return fail_at_line(name, lines.line_no(), ": expected ", what, ", found ", quote(line));
    };
    switch (at) {
      case At::Outside:
        if (kw != "solid" && facet == 0 && bytes.size() >= 84) {
          std::uint32_t n = 0;
          std::memcpy(&n, bytes.data() + 80, 4);
          return fail(name, ": not an ASCII STL (no 'solid' line) and not a binary one either (", n, " facets take ",
                      84 + 50 * std::uint64_t{n}, " bytes, the file has ", bytes.size(), ")");
        }
        if (kw != "solid") return expected("'solid'");
        at = At::Solid;
        break;
      case At::Solid:
        if (kw == "endsolid") {
          at = At::Outside;
          break;
        }
        if (kw != "facet") return expected("'facet' or 'endsolid'");
        if (const std::string_view n = token(rest); !n.empty()) {
          if (n != "normal") return expected("'facet normal NX NY NZ'");
          for (int k = 0; k < 3; ++k) {  // the normal is not used, but must be well formed
            double d;
            if (!to_double(token(rest), d)) return expected("'facet normal NX NY NZ'");
          }
        }
        at = At::Facet;
        break;
      case At::Facet:
        if (kw != "outer" || token(rest) != "loop") return expected("'outer loop'");
        poly.clear();
        at = At::Loop;
        break;
      case At::Loop:
        if (kw == "endloop") {
          if (poly.size() < 3)
            return fail_at_line(name, lines.line_no(), ": facet ", facet, ": has ", poly.size(),
                                " vertices (expected at least 3)");
          fan(poly, faces, rep);
          at = At::EndLoop;
          break;
        }
        if (kw != "vertex") return expected("'vertex X Y Z' or 'endloop'");
        {
          Vec3 q;
          for (int k = 0; k < 3; ++k) {
            const std::string_view t = token(rest);
            if (!to_double(t, q[k]))
              return fail_at_line(name, lines.line_no(), ": facet ", facet, ": ", quote(t), " is not a number");
            if (!std::isfinite(q[k]))
              return fail_at_line(name, lines.line_no(), ": facet ", facet, ": coordinate ", quote(t), " is not finite");
          }
          poly.push_back(weld.add(q));
        }
        break;
      case At::EndLoop:
        if (kw != "endfacet") return expected("'endfacet'");
        ++facet;
        at = At::Solid;
        break;
    }
  }
  if (at == At::Outside && facet == 0 && lines.line_no() == 0) return fail(name, ": empty file");
  if (at != At::Outside && at != At::Solid) return fail(name, ": file ends inside facet ", facet);
  rep.welded_vertices = weld.welded();
  if (faces.empty()) return fail(name, ": no triangles (no complete facet)");
  return finish(name, weld.positions(), std::move(faces), std::move(rep));
}

}  // namespace st::geom
