// SPDX-License-Identifier: BSD-3-Clause
// The OBJ reader (double precision: the file's numbers exactly). Declared in mesh_io.hpp.
#include <spheretouch/geom/mesh_io.hpp>

#include <string>
#include <vector>

#include <spheretouch/geom/mesh_io_detail.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {

using namespace detail;

Result<LoadedMesh> parse_obj(std::string_view text, const std::string& name) {
  Lines lines(text);
  std::string_view line;
  LoadReport rep;
  rep.reader = "spheretouch OBJ reader";
  rep.precision = "double (correctly rounded)";
  std::vector<Vec3> pos;
  std::vector<Tri> faces;
  std::vector<std::uint32_t> poly;
  struct Pending {
    std::size_t line;
    std::size_t face;
    long long index;
  };
  while (lines.next(line)) {
    std::string_view rest = line;
    const std::string_view kw = token(rest);
    if (kw == "v") {
      Vec3 p;
      for (int k = 0; k < 3; ++k) {
        const std::string_view t = token(rest);
        if (t.empty())
          return fail_at_line(name, lines.line_no(), ": vertex ", pos.size(), ": expected 3 coordinates, found ", k);
        if (!to_double(t, p[k]))
          return fail_at_line(name, lines.line_no(), ": vertex ", pos.size(), ": ", quote(t), " is not a number");
        if (!std::isfinite(p[k]))
          return fail_at_line(name, lines.line_no(), ": vertex ", pos.size(), ": coordinate ", quote(t),
                              " is not finite");
      }
      pos.push_back(p);
    } else if (kw == "f") {
      poly.clear();
      for (std::string_view t = token(rest); !t.empty(); t = token(rest)) {
        const std::string_view idx = t.substr(0, t.find('/'));  // v, v/vt, v/vt/vn, v//vn
        long long v = 0;
        if (!to_int(idx, v) || v == 0)
          return fail_at_line(name, lines.line_no(), ": face ", rep.polygons, ": vertex reference ", quote(t),
                              " is not a non-zero integer");
        // Negative indices count back from the last vertex defined so far (OBJ spec).
        const long long resolved = v > 0 ? v - 1 : static_cast<long long>(pos.size()) + v;
        if (resolved < 0 || resolved >= static_cast<long long>(pos.size()))
          return fail_at_line(name, lines.line_no(), ": face ", rep.polygons, ": vertex index ", v, " out of range (",
                              pos.size(), " vertices defined so far)");
        poly.push_back(static_cast<std::uint32_t>(resolved));
      }
      if (poly.size() < 3)
        return fail_at_line(name, lines.line_no(), ": face ", rep.polygons, ": has ", poly.size(),
                            " corners (expected at least 3)");
      fan(poly, faces, rep);
    } else if (kw == "p" || kw == "l") {
      ++rep.skipped_primitives;
    }
    // vt, vn, g, o, s, usemtl, mtllib and other statements carry no geometry we use.
  }
  if (faces.empty()) return fail(name, ": no triangles (no 'f' statement with 3 or more corners)");
  return finish(name, pos, std::move(faces), std::move(rep));
}

}  // namespace st::geom
