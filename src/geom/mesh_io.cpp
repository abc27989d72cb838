// Mesh import/export. Our own readers for the text formats keep the file's doubles exactly;
// assimp (float) reads the rest. See mesh_io.hpp for the face-numbering rule.
#include "geom/mesh_io.hpp"

#include <assimp/Importer.hpp>
#include <assimp/scene.h>

#include <algorithm>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>
#include <unordered_map>

namespace st::geom {
namespace {

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

/// Splits text into lines and lines into whitespace-separated tokens, counting line numbers.
class Lines {
 public:
  explicit Lines(std::string_view text) : text_(text) {}
  /// Next line with `#...` comments and surrounding blanks removed; false at end of text.
  bool next(std::string_view& line, bool strip_comments = true) {
    while (pos_ < text_.size()) {
      std::size_t end = text_.find('\n', pos_);
      if (end == std::string_view::npos) end = text_.size();
      line = text_.substr(pos_, end - pos_);
      pos_ = end + 1;
      ++line_no_;
      if (strip_comments) {
        const auto hash = line.find('#');
        if (hash != std::string_view::npos) line = line.substr(0, hash);
      }
      while (!line.empty() && std::isspace(static_cast<unsigned char>(line.back()))) line.remove_suffix(1);
      while (!line.empty() && std::isspace(static_cast<unsigned char>(line.front()))) line.remove_prefix(1);
      if (!line.empty()) return true;
    }
    return false;
  }
  std::size_t line_no() const { return line_no_; }  ///< 1-based number of the last line returned

 private:
  std::string_view text_;
  std::size_t pos_ = 0;
  std::size_t line_no_ = 0;
};

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

Result<LoadedMesh> finish(const std::string& name, const std::vector<Vec3>& pos, std::vector<Tri> faces,
                          LoadReport rep) {
  LoadedMesh out{make_mesh(name, pos, std::move(faces)), std::move(rep)};
  if (Status s = out.mesh.validate(); !s) return Error{s.error()};
  out.report.degenerate = out.mesh.degenerate_faces();
  return out;
}

Result<LoadedMesh> load_with_assimp(const std::string& path) {
  Assimp::Importer importer;
  // No post-processing at all: every aiProcess step may reorder, split or merge faces.
  const aiScene* scene = importer.ReadFile(path, 0);
  if (!scene || !scene->mRootNode) return fail(path, ": assimp could not read it: ", importer.GetErrorString());
  LoadReport rep;
  rep.reader = "assimp";
  rep.precision = "float (Debian's assimp has single-precision ai_real: ~7 significant digits)";
  std::vector<Vec3> pos;
  std::vector<Tri> faces;
  // Exact-duplicate vertices are welded (formats like STL repeat them per face), so closedness
  // and subdivision see the real topology. Welding never reorders faces.
  struct Hash {
    std::size_t operator()(const Vec3& v) const {
      std::size_t h = 1469598103934665603ull;
      for (int i = 0; i < 3; ++i) {
        std::uint64_t b;
        const double d = v[i] == 0.0 ? 0.0 : v[i];  // +0 and -0 weld together
        std::memcpy(&b, &d, 8);
        h = (h ^ b) * 1099511628211ull;
      }
      return h;
    }
  };
  std::unordered_map<Vec3, std::uint32_t, Hash> index_of;
  std::vector<std::uint32_t> poly;
  // Depth-first over the node tree in child order: meshes in the order nodes reference them,
  // each with its accumulated node transform (applied in double).
  struct Item { const aiNode* node; Eigen::Matrix4d xf; };
  std::vector<Item> stack{{scene->mRootNode, Eigen::Matrix4d::Identity()}};
  std::size_t raw_vertices = 0;
  while (!stack.empty()) {
    Item it = stack.back();
    stack.pop_back();
    Eigen::Matrix4d local;
    const aiMatrix4x4& m = it.node->mTransformation;
    local << m.a1, m.a2, m.a3, m.a4, m.b1, m.b2, m.b3, m.b4, m.c1, m.c2, m.c3, m.c4, m.d1, m.d2, m.d3, m.d4;
    const Eigen::Matrix4d xf = it.xf * local;
    for (unsigned mi = 0; mi < it.node->mNumMeshes; ++mi) {
      const aiMesh* mesh = scene->mMeshes[it.node->mMeshes[mi]];
      std::vector<std::uint32_t> remap(mesh->mNumVertices);
      raw_vertices += mesh->mNumVertices;
      for (unsigned v = 0; v < mesh->mNumVertices; ++v) {
        const aiVector3D& a = mesh->mVertices[v];
        const Eigen::Vector4d p = xf * Eigen::Vector4d(a.x, a.y, a.z, 1.0);
        const Vec3 q = p.head<3>();
        auto [slot, fresh] = index_of.try_emplace(q, static_cast<std::uint32_t>(pos.size()));
        if (fresh) pos.push_back(q);
        remap[v] = slot->second;
      }
      for (unsigned f = 0; f < mesh->mNumFaces; ++f) {
        const aiFace& face = mesh->mFaces[f];
        if (face.mNumIndices < 3) { ++rep.skipped_primitives; continue; }
        poly.clear();
        for (unsigned k = 0; k < face.mNumIndices; ++k) {
          if (face.mIndices[k] >= mesh->mNumVertices)
            return fail(path, ": mesh ", mi, " face ", f, ": vertex index ", face.mIndices[k], " out of range [0, ",
                        mesh->mNumVertices, ")");
          poly.push_back(remap[face.mIndices[k]]);
        }
        fan(poly, faces, rep);
      }
    }
    for (unsigned c = it.node->mNumChildren; c-- > 0;) stack.push_back({it.node->mChildren[c], xf});
  }
  rep.welded_vertices = raw_vertices - pos.size();
  if (faces.empty()) return fail(path, ": no triangles (", rep.skipped_primitives, " points/lines ignored)");
  return finish(path, pos, std::move(faces), std::move(rep));
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

Result<LoadedMesh> parse_off(std::string_view text, const std::string& name) {
  Lines lines(text);
  std::string_view line;
  if (!lines.next(line)) return fail(name, ": empty file (expected an 'OFF' header)");
  std::string_view rest = line;
  const std::string_view magic = token(rest);
  // OFF and its variants with per-vertex extras (COFF, NOFF, STOFF, ...): extras are ignored.
  if (magic.size() < 3 || magic.substr(magic.size() - 3) != "OFF")
    return fail(name, ":", lines.line_no(), ": expected an 'OFF' header, found ", quote(magic));
  if (rest.find_first_not_of(" \t\r") == std::string_view::npos) {
    if (!lines.next(line)) return fail(name, ": file ends before the vertex and face counts");
    rest = line;
  }
  long long nv = -1, nf = -1;
  const std::string_view tv = token(rest), tf = token(rest);
  if (!to_int(tv, nv) || !to_int(tf, nf) || nv < 0 || nf < 0)
    return fail(name, ":", lines.line_no(), ": expected vertex and face counts, found ", quote(line));
  // Counts are checked against the file size before anything is reserved: a vertex needs at
  // least 6 bytes of text ("0 0 0\n"), a face at least 8.
  if (std::size_t(nv) > text.size() / 6 + 1 || std::size_t(nf) > text.size() / 8 + 1)
    return fail(name, ":", lines.line_no(), ": counts ", nv, " vertices, ", nf, " faces exceed what a ",
                text.size(), "-byte file can hold");
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
      if (t.empty()) return fail(name, ":", lines.line_no(), ": vertex ", i, ": expected 3 coordinates, found ", k);
      if (!to_double(t, p[k])) return fail(name, ":", lines.line_no(), ": vertex ", i, ": ", quote(t), " is not a number");
      if (!std::isfinite(p[k])) return fail(name, ":", lines.line_no(), ": vertex ", i, ": coordinate ", quote(t), " is not finite");
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
    if (!to_int(tn, n)) return fail(name, ":", lines.line_no(), ": face ", i, ": expected a corner count, found ", quote(tn));
    if (n < 3) return fail(name, ":", lines.line_no(), ": face ", i, ": has ", n, " corners (expected at least 3)");
    if (std::size_t(n) > line.size()) return fail(name, ":", lines.line_no(), ": face ", i, ": corner count ", n, " exceeds the line");
    poly.clear();
    for (long long k = 0; k < n; ++k) {
      const std::string_view t = token(rest);
      long long v = -1;
      if (t.empty()) return fail(name, ":", lines.line_no(), ": face ", i, ": expected ", n, " vertex indices, found ", k);
      if (!to_int(t, v)) return fail(name, ":", lines.line_no(), ": face ", i, ": index ", quote(t), " is not an integer");
      if (v < 0 || v >= nv)
        return fail(name, ":", lines.line_no(), ": face ", i, ": vertex index ", v, " out of range [0, ", nv, ")");
      poly.push_back(static_cast<std::uint32_t>(v));
    }
    fan(poly, faces, rep);  // trailing numbers (a face colour) are ignored
  }
  if (faces.empty()) return fail(name, ": no triangles (0 faces)");
  return finish(name, pos, std::move(faces), std::move(rep));
}

Result<LoadedMesh> parse_obj(std::string_view text, const std::string& name) {
  Lines lines(text);
  std::string_view line;
  LoadReport rep;
  rep.reader = "spheretouch OBJ reader";
  rep.precision = "double (correctly rounded)";
  std::vector<Vec3> pos;
  std::vector<Tri> faces;
  std::vector<std::uint32_t> poly;
  struct Pending { std::size_t line; std::size_t face; long long index; };
  while (lines.next(line)) {
    std::string_view rest = line;
    const std::string_view kw = token(rest);
    if (kw == "v") {
      Vec3 p;
      for (int k = 0; k < 3; ++k) {
        const std::string_view t = token(rest);
        if (t.empty()) return fail(name, ":", lines.line_no(), ": vertex ", pos.size(), ": expected 3 coordinates, found ", k);
        if (!to_double(t, p[k])) return fail(name, ":", lines.line_no(), ": vertex ", pos.size(), ": ", quote(t), " is not a number");
        if (!std::isfinite(p[k])) return fail(name, ":", lines.line_no(), ": vertex ", pos.size(), ": coordinate ", quote(t), " is not finite");
      }
      pos.push_back(p);
    } else if (kw == "f") {
      poly.clear();
      for (std::string_view t = token(rest); !t.empty(); t = token(rest)) {
        const std::string_view idx = t.substr(0, t.find('/'));  // v, v/vt, v/vt/vn, v//vn
        long long v = 0;
        if (!to_int(idx, v) || v == 0)
          return fail(name, ":", lines.line_no(), ": face ", rep.polygons, ": vertex reference ", quote(t), " is not a non-zero integer");
        // Negative indices count back from the last vertex defined so far (OBJ spec).
        const long long resolved = v > 0 ? v - 1 : static_cast<long long>(pos.size()) + v;
        if (resolved < 0 || resolved >= static_cast<long long>(pos.size()))
          return fail(name, ":", lines.line_no(), ": face ", rep.polygons, ": vertex index ", v, " out of range (",
                      pos.size(), " vertices defined so far)");
        poly.push_back(static_cast<std::uint32_t>(resolved));
      }
      if (poly.size() < 3)
        return fail(name, ":", lines.line_no(), ": face ", rep.polygons, ": has ", poly.size(), " corners (expected at least 3)");
      fan(poly, faces, rep);
    } else if (kw == "p" || kw == "l") {
      ++rep.skipped_primitives;
    }
    // vt, vn, g, o, s, usemtl, mtllib and other statements carry no geometry we use.
  }
  if (faces.empty()) return fail(name, ": no triangles (no 'f' statement with 3 or more corners)");
  return finish(name, pos, std::move(faces), std::move(rep));
}

Result<LoadedMesh> parse_ply_ascii(std::string_view text, const std::string& name) {
  // Header: element/property declarations; body: whitespace-separated values in element order.
  Lines lines(text);
  std::string_view line;
  if (!lines.next(line, false) || line != "ply") return fail(name, ":1: expected the 'ply' magic line");
  struct Property { std::string name; bool list = false; };
  struct Element { std::string name; long long count = 0; std::vector<Property> props; };
  std::vector<Element> elements;
  bool format_seen = false;
  for (;;) {
    if (!lines.next(line, false)) return fail(name, ": file ends inside the header (no 'end_header')");
    std::string_view rest = line;
    const std::string_view kw = token(rest);
    if (kw == "end_header") break;
    if (kw == "comment" || kw == "obj_info") continue;
    if (kw == "format") {
      const std::string_view f = token(rest);
      if (f != "ascii") return fail(name, ":", lines.line_no(), ": format ", quote(f), " is not ascii (binary PLY is read by assimp)");
      format_seen = true;
    } else if (kw == "element") {
      Element e;
      e.name = std::string(token(rest));
      const std::string_view c = token(rest);
      if (!to_int(c, e.count) || e.count < 0)
        return fail(name, ":", lines.line_no(), ": element '", e.name, "': count ", quote(c), " is not a non-negative integer");
      if (std::size_t(e.count) > text.size()) return fail(name, ":", lines.line_no(), ": element '", e.name, "': count ", e.count, " exceeds the file size");
      elements.push_back(std::move(e));
    } else if (kw == "property") {
      if (elements.empty()) return fail(name, ":", lines.line_no(), ": property before any element");
      Property p;
      std::string_view t = token(rest);
      if (t == "list") { p.list = true; token(rest); token(rest); }
      p.name = std::string(token(rest));
      if (p.name.empty()) return fail(name, ":", lines.line_no(), ": property without a name");
      elements.back().props.push_back(p);
    } else {
      return fail(name, ":", lines.line_no(), ": unknown header line ", quote(line));
    }
  }
  if (!format_seen) return fail(name, ": header has no 'format' line");
  // The body is a stream of tokens; line numbers are tracked for messages.
  LoadReport rep;
  rep.reader = "spheretouch PLY (ascii) reader";
  rep.precision = "double (correctly rounded)";
  std::vector<Vec3> pos;
  std::vector<Tri> faces;
  std::vector<std::uint32_t> poly;
  std::string_view rest;
  auto next_token = [&](std::string_view& t) -> bool {
    for (;;) {
      t = token(rest);
      if (!t.empty()) return true;
      if (!lines.next(line, false)) return false;
      rest = line;
    }
  };
  bool vertices_done = false;
  for (const Element& e : elements) {
    const bool is_vertex = e.name == "vertex", is_face = e.name == "face";
    int axis_of[64];
    for (std::size_t k = 0; k < e.props.size() && k < 64; ++k)
      axis_of[k] = e.props[k].name == "x" ? 0 : e.props[k].name == "y" ? 1 : e.props[k].name == "z" ? 2 : -1;
    if (is_vertex) {
      int found = 0;
      for (std::size_t k = 0; k < e.props.size() && k < 64; ++k) found += axis_of[k] >= 0;
      if (found != 3) return fail(name, ": element 'vertex' lacks x, y and z properties");
      pos.reserve(std::size_t(e.count));
    }
    for (long long i = 0; i < e.count; ++i) {
      Vec3 p = Vec3::Zero();
      for (std::size_t k = 0; k < e.props.size(); ++k) {
        const Property& prop = e.props[k];
        std::string_view t;
        if (!next_token(t)) return fail(name, ": file ends inside element '", e.name, "' ", i, " of ", e.count);
        if (prop.list) {
          long long n = 0;
          if (!to_int(t, n) || n < 0 || std::size_t(n) > text.size())
            return fail(name, ":", lines.line_no(), ": ", e.name, " ", i, ": list length ", quote(t), " is not valid");
          const bool indices = is_face && (prop.name == "vertex_indices" || prop.name == "vertex_index");
          poly.clear();
          for (long long j = 0; j < n; ++j) {
            if (!next_token(t)) return fail(name, ": file ends inside ", e.name, " ", i);
            if (!indices) continue;
            long long v = -1;
            if (!to_int(t, v)) return fail(name, ":", lines.line_no(), ": face ", i, ": index ", quote(t), " is not an integer");
            if (!vertices_done || v < 0 || v >= static_cast<long long>(pos.size()))
              return fail(name, ":", lines.line_no(), ": face ", i, ": vertex index ", v, " out of range [0, ", pos.size(), ")");
            poly.push_back(static_cast<std::uint32_t>(v));
          }
          if (indices) {
            if (poly.size() < 3) return fail(name, ":", lines.line_no(), ": face ", i, ": has ", poly.size(), " corners (expected at least 3)");
            fan(poly, faces, rep);
          }
        } else if (is_vertex && k < 64 && axis_of[k] >= 0) {
          double d;
          if (!to_double(t, d)) return fail(name, ":", lines.line_no(), ": vertex ", i, ": ", quote(t), " is not a number");
          if (!std::isfinite(d)) return fail(name, ":", lines.line_no(), ": vertex ", i, ": coordinate ", quote(t), " is not finite");
          p[axis_of[k]] = d;
        }
      }
      if (is_vertex) pos.push_back(p);
    }
    if (is_vertex) vertices_done = true;
  }
  if (faces.empty()) return fail(name, ": no triangles (no 'face' element with vertex_indices)");
  return finish(name, pos, std::move(faces), std::move(rep));
}

std::vector<std::string> supported_extensions() {
  std::vector<std::string> out{".off", ".obj", ".ply"};
  Assimp::Importer importer;
  std::string list;
  importer.GetExtensionList(list);  // "*.3ds;*.obj;..."
  std::stringstream ss(list);
  for (std::string item; std::getline(ss, item, ';');) {
    if (item.size() > 1 && item[0] == '*') item = item.substr(1);
    if (std::find(out.begin(), out.end(), item) == out.end()) out.push_back(item);
  }
  return out;
}

Result<LoadedMesh> load_mesh(const std::string& path, const LoadOptions& options) {
  const auto t0 = std::chrono::steady_clock::now();
  Result<double> unit = unit_to_mm(options.units);
  if (!unit) return fail(path, ": ", unit.error());
  if (!std::isfinite(options.scale) || options.scale <= 0) return fail(path, ": scale ", options.scale, " must be finite and positive");
  std::ifstream probe(path);
  if (!probe) return fail(path, ": cannot open (", std::strerror(errno), ")");
  probe.close();
  const std::string ext = lower_ext(path);
  Result<LoadedMesh> r = Error{""};
  if (ext == ".off" || ext == ".obj" || ext == ".ply") {
    Result<std::string> text = slurp(path);
    if (!text) return Error{text.error()};
    const std::string_view t = text.value();
    if (ext == ".off") r = parse_off(t, path);
    else if (ext == ".obj") r = parse_obj(t, path);
    else if (t.substr(0, 200).find("format ascii") != std::string_view::npos) r = parse_ply_ascii(t, path);
    else r = load_with_assimp(path);  // binary PLY
  } else {
    Assimp::Importer importer;
    if (ext.empty() || !importer.IsExtensionSupported(ext))
      return fail(path, ": unknown mesh format '", ext, "' (expected .off, .obj, .ply, .stl, .gltf, .glb or another assimp format)");
    r = load_with_assimp(path);
  }
  if (!r) return r;
  const double s = unit.value() * options.scale;
  if (s != 1.0) {
    Mesh& m = r.value().mesh;
    m.scale(s);
    m.recentre();
    if (Status v = m.validate(); !v) return Error{v.error()};
  }
  r.value().report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return r;
}

Status write_off(const Mesh& mesh, const std::string& path) {
  std::string out;
  out.reserve(mesh.num_vertices() * 60 + mesh.num_faces() * 24 + 64);
  out += "OFF\n" + std::to_string(mesh.num_vertices()) + " " + std::to_string(mesh.num_faces()) + " 0\n";
  char buf[32];
  for (std::uint32_t i = 0; i < mesh.num_vertices(); ++i) {
    const Vec3 p = mesh.vertex(i);
    for (int k = 0; k < 3; ++k) {
      auto r = std::to_chars(buf, buf + sizeof buf, p[k]);  // shortest round-trip form
      out.append(buf, r.ptr);
      out += k < 2 ? ' ' : '\n';
    }
  }
  for (const Tri& f : mesh.faces) {
    out += "3";
    for (int k = 0; k < 3; ++k) {
      out += ' ';
      auto r = std::to_chars(buf, buf + sizeof buf, f[k]);
      out.append(buf, r.ptr);
    }
    out += '\n';
  }
  std::ofstream o(path, std::ios::binary);
  if (!o) return fail(path, ": cannot create (", std::strerror(errno), ")");
  o.write(out.data(), static_cast<std::streamsize>(out.size()));
  if (!o) return fail(path, ": write error");
  return Ok{};
}

}  // namespace st::geom
