// SPDX-License-Identifier: BSD-3-Clause
// The OFF reader (double precision: the file's numbers exactly). Declared in mesh_io.hpp.
#include <spheretouch/geom/mesh_io.hpp>

#include <string>
#include <vector>

#include <spheretouch/geom/mesh_io_detail.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {

using namespace detail;

Result<LoadedMesh> parse_off(std::string_view text, const std::string& name) {
  Lines lines(text);
  std::string_view line;
  if (!lines.next(line)) return fail(name, ": empty file (expected an 'OFF' header)");
  std::string_view rest = line;
  const std::string_view magic = token(rest);
  // OFF and its variants with per-vertex extras (COFF, NOFF, STOFF, ...): extras are ignored.
  if (magic.size() < 3 || magic.substr(magic.size() - 3) != "OFF")
    return fail_at_line(name, lines.line_no(), ": expected an 'OFF' header, found ", quote(magic));
  if (rest.find_first_not_of(" \t\r") == std::string_view::npos) {
    if (!lines.next(line)) return fail(name, ": file ends before the vertex and face counts");
    rest = line;
  }
  long long nv = -1, nf = -1;
  const std::string_view tv = token(rest), tf = token(rest);
  if (!to_int(tv, nv) || !to_int(tf, nf) || nv < 0 || nf < 0)
    return fail_at_line(name, lines.line_no(), ": expected vertex and face counts, found ", quote(line));
  // Counts are checked against the file size before anything is reserved: a vertex needs at
  // least 6 bytes of text ("0 0 0\n"), a face at least 8.
  if (std::size_t(nv) > text.size() / 6 + 1 || std::size_t(nf) > text.size() / 8 + 1)
    return fail_at_line(name, lines.line_no(), ": counts ", nv, " vertices, ", nf, " faces exceed what a ", text.size(),
                        "-byte file can hold");
  LoadReport rep;
  rep.reader = "spheretouch OFF reader";
  rep.precision = "double (correctly rounded)";
  std::vector<Vec3> pos;
  pos.reserve(std::size_t(nv));
  for (long long i = 0; i < nv; ++i) {
    if (!lines.next(line)) return fail(name, ": file ends after ", i, " of ", nv, " vertices");
    rest = line;
    Vec3 p;
    for (int k = 0; k < 3; ++k) {
      const std::string_view t = token(rest);
      if (t.empty()) return fail_at_line(name, lines.line_no(), ": vertex ", i, ": expected 3 coordinates, found ", k);
      if (!to_double(t, p[k]))
        return fail_at_line(name, lines.line_no(), ": vertex ", i, ": ", quote(t), " is not a number");
      if (!std::isfinite(p[k]))
        return fail_at_line(name, lines.line_no(), ": vertex ", i, ": coordinate ", quote(t), " is not finite");
    }
    pos.push_back(p);
  }
  std::vector<Tri> faces;
  faces.reserve(std::size_t(nf));
  std::vector<std::uint32_t> poly;
  for (long long i = 0; i < nf; ++i) {
    if (!lines.next(line)) return fail(name, ": file ends after ", i, " of ", nf, " faces");
    rest = line;
    long long n = 0;
    const std::string_view tn = token(rest);
    if (!to_int(tn, n))
      return fail_at_line(name, lines.line_no(), ": face ", i, ": expected a corner count, found ", quote(tn));
    if (n < 3) return fail_at_line(name, lines.line_no(), ": face ", i, ": has ", n, " corners (expected at least 3)");
    if (std::size_t(n) > line.size())
      return fail_at_line(name, lines.line_no(), ": face ", i, ": corner count ", n, " exceeds the line");
    poly.clear();
    for (long long k = 0; k < n; ++k) {
      const std::string_view t = token(rest);
      long long v = -1;
      if (t.empty())
        return fail_at_line(name, lines.line_no(), ": face ", i, ": expected ", n, " vertex indices, found ", k);
      if (!to_int(t, v))
        return fail_at_line(name, lines.line_no(), ": face ", i, ": index ", quote(t), " is not an integer");
      if (v < 0 || v >= nv)
        return fail_at_line(name, lines.line_no(), ": face ", i, ": vertex index ", v, " out of range [0, ", nv, ")");
      poly.push_back(static_cast<std::uint32_t>(v));
    }
    fan(poly, faces, rep);  // trailing numbers (a face colour) are ignored
  }
  if (faces.empty()) return fail(name, ": no triangles (0 faces)");
  return finish(name, pos, std::move(faces), std::move(rep));
}

}  // namespace st::geom
