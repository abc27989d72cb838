// SPDX-License-Identifier: BSD-3-Clause
// Mesh import/export: the shared pieces of the readers, choosing a reader, and OFF output. Our
// own readers for the text formats (mesh_io_off/obj/ply/stl.cpp) keep the file's doubles exactly;
// assimp (float, mesh_io_assimp.cpp) reads the rest. See mesh_io.hpp for the face-numbering rule.
#include <spheretouch/geom/mesh_io.hpp>

#include <algorithm>
#include <charconv>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <spheretouch/geom/mesh_io_detail.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {
namespace detail {

/// Reads a whole file; the error names the file.
Result<std::string> slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return fail(path, ": cannot open (", std::strerror(errno), ")");
  std::string data;
  in.seekg(0, std::ios::end);
  const auto size = in.tellg();
  if (size < 0) return fail(path, ": cannot read");
  data.resize(static_cast<std::size_t>(size));
  in.seekg(0);
  in.read(data.data(), size);
  if (!in) return fail(path, ": read error");
  return data;
}

std::string lower_ext(const std::string& path) {
  const auto slash = path.find_last_of('/');
  const auto dot = path.find_last_of('.');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
  std::string e = path.substr(dot);
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return e;
}

/// Pops the next whitespace-separated token from `s`; empty when none is left.
std::string_view token(std::string_view& s) {
  std::size_t i = 0;
  while (i < s.size() && std::isspace(static_cast<unsigned char>(s[i]))) ++i;
  std::size_t j = i;
  while (j < s.size() && !std::isspace(static_cast<unsigned char>(s[j]))) ++j;
  std::string_view t = s.substr(i, j - i);
  s.remove_prefix(j);
  return t;
}

/// Correctly rounded decimal -> double (std::from_chars); accepts a leading '+'.
bool to_double(std::string_view t, double& out) {
  if (!t.empty() && t.front() == '+') t.remove_prefix(1);
  const auto r = std::from_chars(t.data(), t.data() + t.size(), out);
  return r.ec == std::errc() && r.ptr == t.data() + t.size();
}

bool to_int(std::string_view t, long long& out) {
  if (!t.empty() && t.front() == '+') t.remove_prefix(1);
  const auto r = std::from_chars(t.data(), t.data() + t.size(), out);
  return r.ec == std::errc() && r.ptr == t.data() + t.size();
}

std::string quote(std::string_view t) {
  std::string s(t.substr(0, 40));
  return "'" + s + (t.size() > 40 ? "...'" : "'");
}

/// Appends the fan triangulation of one polygon, (v0, vk, vk+1), to `faces`.
void fan(const std::vector<std::uint32_t>& poly, std::vector<Tri>& faces, LoadReport& rep) {
  ++rep.polygons;
  if (poly.size() > 3) ++rep.fanned_polygons;
  for (std::size_t k = 1; k + 1 < poly.size(); ++k) faces.push_back({poly[0], poly[k], poly[k + 1]});
}

Result<LoadedMesh> finish(const std::string& name, const std::vector<Vec3>& pos, std::vector<Tri> faces, LoadReport rep) {
  LoadedMesh out{make_mesh(name, pos, std::move(faces)), std::move(rep)};
  if (Status s = out.mesh.validate(); !s) return Error{s.error()};
  out.report.degenerate = out.mesh.degenerate_faces();
  return out;
}

}  // namespace detail

using namespace detail;

namespace {

// LoadReport::size_warning for a mesh read as `options` says.
std::string size_warning(const Mesh& mesh, const std::string& path, const LoadConfig& options) {
  const double d = mesh.bounds().diagonal();
  if (!(d > 0) || (d >= kPlausibleMinMm && d <= kPlausibleMaxMm)) return {};
  // The unit that would bring the diagonal nearest 300 mm (a hand-sized object), if any.
  const double file_units = d / (unit_to_mm(options.units).value() * options.scale);
  const char* best = nullptr;
  double best_err = 1e300;
  for (const char* u : {"um", "mm", "cm", "m", "in"}) {
    const double mm = file_units * unit_to_mm(u).value() * options.scale;
    const double err = std::abs(std::log10(mm / 300.0));
    if (mm >= kPlausibleMinMm && mm <= kPlausibleMaxMm && err < best_err) best = u, best_err = err;
  }
  std::ostringstream os;
  os.precision(3);
  os << path << ": warning: " << d << " mm across (bounding-box diagonal) read as units = \"" << options.units << "\""
     << (options.scale != 1.0 ? " with scale" : "") << ": implausibly " << (d < kPlausibleMinMm ? "small" : "large")
     << " for a touched object";
  if (best && best != options.units)
    os << "; units = \"" << best << "\" would make it " << file_units * unit_to_mm(best).value() * options.scale << " mm";
  return os.str();
}

}  // namespace

Result<double> unit_to_mm(std::string_view units) {
  if (units == "mm") return 1.0;
  if (units == "um") return 1e-3;
  if (units == "cm") return 10.0;
  if (units == "m") return 1000.0;
  if (units == "in") return 25.4;
  return fail("units '", units, "' not known (expected one of: um, mm, cm, m, in)");
}

Result<LoadedMesh> parse_mesh(std::string_view bytes, const std::string& ext, const std::string& name) {
  if (ext == ".off") return parse_off(bytes, name);
  if (ext == ".obj") return parse_obj(bytes, name);
  if (ext == ".ply") return parse_ply(bytes, name);
  if (ext == ".stl") return parse_stl(bytes, name);
  return fail(name, ": parse_mesh reads .off, .obj, .ply and .stl, not '", ext, "'");
}

Result<LoadedMesh> load_mesh(const std::string& path, const LoadConfig& options) {
  const auto t0 = std::chrono::steady_clock::now();
  Result<double> unit = unit_to_mm(options.units);
  if (!unit) return fail(path, ": ", unit.error());
  if (!std::isfinite(options.scale) || options.scale <= 0)
    return fail(path, ": scale ", options.scale, " must be finite and positive");
  std::ifstream probe(path);
  if (!probe) return fail(path, ": cannot open (", std::strerror(errno), ")");
  probe.close();
  const std::string ext = lower_ext(path);
  Result<LoadedMesh> r = Error{""};
  if (ext == ".off" || ext == ".obj" || ext == ".ply" || ext == ".stl") {
    Result<std::string> text = slurp(path);
    if (!text) return Error{text.error()};
    r = parse_mesh(text.value(), ext, path);
  } else {
    if (ext.empty() || !assimp_reads(ext))
      return fail(path, ": unknown mesh format '", ext,
                  "' (expected .off, .obj, .ply, .stl, .gltf, .glb or another assimp format)");
    r = load_with_assimp(path, options);
  }
  if (!r) return r;
  const double s = unit.value() * options.scale;
  if (s != 1.0) {
    Mesh& m = r.value().mesh;
    m.scale(s);
    m.recentre();
    if (Status v = m.validate(); !v) return Error{v.error()};
  }
  if (options.orient) r.value().report.orientation = orient_faces(r.value().mesh);
  r.value().report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  r.value().report.size_warning = size_warning(r.value().mesh, path, options);
  return r;
}

namespace {

// The mesh as text in `format` ("off", "ply" or "obj"), shortest round-trip doubles, faces in order.
std::string mesh_text(const Mesh& mesh, std::string_view format) {
  std::string out;
  out.reserve(mesh.num_vertices() * 60 + mesh.num_faces() * 24 + 256);
  const std::string nv = std::to_string(mesh.num_vertices()), nf = std::to_string(mesh.num_faces());
  if (format == "off") {
    out += "OFF\n" + nv + " " + nf + " 0\n";
  } else if (format == "ply") {
    out += "ply\nformat ascii 1.0\ncomment spheretouch export\nelement vertex " + nv +
           "\nproperty double x\nproperty double y\nproperty double z\nelement face " + nf +
           "\nproperty list uchar int vertex_indices\nend_header\n";
  } else {
    out += "# spheretouch export: " + nv + " vertices, " + nf + " faces\n";
  }
  char buf[32];
  for (std::uint32_t i = 0; i < mesh.num_vertices(); ++i) {
    const Vec3 p = mesh.vertex(i);
    if (format == "obj") out += "v ";
    for (int k = 0; k < 3; ++k) {
      auto r = std::to_chars(buf, buf + sizeof buf, p[k]);  // shortest round-trip form
      out.append(buf, r.ptr);
      out += k < 2 ? ' ' : '\n';
    }
  }
  for (const Tri& f : mesh.faces) {
    out += format == "obj" ? "f" : "3";
    for (int k = 0; k < 3; ++k) {
      out += ' ';
      auto r = std::to_chars(buf, buf + sizeof buf, f[k] + (format == "obj" ? 1u : 0u));  // OBJ counts from 1
      out.append(buf, r.ptr);
    }
    out += '\n';
  }
  return out;
}

Status write_text(const std::string& out, const std::string& path) {
  std::ofstream o(path, std::ios::binary);
  if (!o) return fail(path, ": cannot create (", std::strerror(errno), ")");
  o.write(out.data(), static_cast<std::streamsize>(out.size()));
  if (!o) return fail(path, ": write error");
  return Ok{};
}

}  // namespace

Status write_off(const Mesh& mesh, const std::string& path) { return write_text(mesh_text(mesh, "off"), path); }

Status write_mesh(const Mesh& mesh, const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (ext == ".off" || ext == ".ply" || ext == ".obj") return write_text(mesh_text(mesh, ext.substr(1)), path);
  return fail(path, ": cannot write '", ext.empty() ? std::string("(no extension)") : ext,
              "' meshes (expected .off, .ply or .obj: the format is chosen by the extension)");
}

}  // namespace st::geom
