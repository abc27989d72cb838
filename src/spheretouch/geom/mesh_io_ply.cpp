// SPDX-License-Identifier: BSD-3-Clause
// The PLY reader, ASCII and binary (either byte order). Declared in mesh_io.hpp.
#include <spheretouch/geom/mesh_io.hpp>

#include <bit>
#include <cstring>
#include <string>
#include <vector>

#include <spheretouch/geom/mesh_io_detail.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {

using namespace detail;

namespace {

/// PLY scalar types (the PLY 1.0 names and their sized aliases); Unknown is accepted in ASCII
/// files only, where every value is just a token.
enum class PlyType { Unknown, I8, U8, I16, U16, I32, U32, F32, F64 };

PlyType ply_type(std::string_view t) {
  if (t == "char" || t == "int8") return PlyType::I8;
  if (t == "uchar" || t == "uint8") return PlyType::U8;
  if (t == "short" || t == "int16") return PlyType::I16;
  if (t == "ushort" || t == "uint16") return PlyType::U16;
  if (t == "int" || t == "int32") return PlyType::I32;
  if (t == "uint" || t == "uint32") return PlyType::U32;
  if (t == "float" || t == "float32") return PlyType::F32;
  if (t == "double" || t == "float64") return PlyType::F64;
  return PlyType::Unknown;
}

std::size_t ply_size(PlyType t) {
  switch (t) {
    case PlyType::I8:
    case PlyType::U8:
      return 1;
    case PlyType::I16:
    case PlyType::U16:
      return 2;
    case PlyType::I32:
    case PlyType::U32:
    case PlyType::F32:
      return 4;
    case PlyType::F64:
      return 8;
    case PlyType::Unknown:
      break;
  }
  return 0;
}

bool ply_integral(PlyType t) { return t != PlyType::F32 && t != PlyType::F64 && t != PlyType::Unknown; }

/// Reads binary PLY values of a declared type, in the file's byte order, never past the end.
class PlyBinary {
 public:
  PlyBinary(std::string_view body, bool big_endian) : d_(body), big_(big_endian) {}
  std::size_t left() const { return d_.size() - pos_; }  ///< bytes not yet read
  std::size_t offset() const { return pos_; }            ///< bytes read
  /// One value as a double (integers exactly); false at the end of the data.
  bool read(PlyType t, double& out) {
    const std::size_t n = ply_size(t);
    if (n == 0 || n > left()) return false;
    unsigned char b[8];
    std::memcpy(b, d_.data() + pos_, n);
    pos_ += n;
    static_assert(std::endian::native == std::endian::little, "PlyBinary swaps big-endian data only");
    if (big_) std::reverse(b, b + n);
    switch (t) {
      case PlyType::I8: {
        std::int8_t v;
        std::memcpy(&v, b, 1);
        out = v;
        break;
      }
      case PlyType::U8:
        out = b[0];
        break;
      case PlyType::I16: {
        std::int16_t v;
        std::memcpy(&v, b, 2);
        out = v;
        break;
      }
      case PlyType::U16: {
        std::uint16_t v;
        std::memcpy(&v, b, 2);
        out = v;
        break;
      }
      case PlyType::I32: {
        std::int32_t v;
        std::memcpy(&v, b, 4);
        out = v;
        break;
      }
      case PlyType::U32: {
        std::uint32_t v;
        std::memcpy(&v, b, 4);
        out = v;
        break;
      }
      case PlyType::F32: {
        float v;
        std::memcpy(&v, b, 4);
        out = v;
        break;
      }
      case PlyType::F64:
        std::memcpy(&out, b, 8);
        break;
      case PlyType::Unknown:
        return false;
    }
    return true;
  }

 private:
  std::string_view d_;
  bool big_;
  std::size_t pos_ = 0;
};

}  // namespace

Result<LoadedMesh> parse_ply(std::string_view text, const std::string& name) {
  // Header: element/property declarations; body: the values in element order, as
  // whitespace-separated tokens (ascii) or packed in the declared types (binary).
  Lines lines(text);
  std::string_view line;
  if (!lines.next(line, false) || line != "ply") return fail(name, ":1: expected the 'ply' magic line");
  struct Property {
    std::string name;
    bool list = false;
    PlyType type = PlyType::Unknown, count_type = PlyType::Unknown;
  };
  struct Element {
    std::string name;
    long long count = 0;
    std::vector<Property> props;
  };
  std::vector<Element> elements;
  enum class Format { None, Ascii, Little, Big } format = Format::None;
  for (;;) {
    if (!lines.next(line, false)) return fail(name, ": file ends inside the header (no 'end_header')");
    std::string_view rest = line;
    const std::string_view kw = token(rest);
    if (kw == "end_header") break;
    if (kw == "comment" || kw == "obj_info") continue;
    if (kw == "format") {
      const std::string_view f = token(rest);
      if (f == "ascii")
        format = Format::Ascii;
      else if (f == "binary_little_endian")
        format = Format::Little;
      else if (f == "binary_big_endian")
        format = Format::Big;
      else
        return fail_at_line(name, lines.line_no(), ": format ", quote(f),
                            " is not ascii, binary_little_endian or binary_big_endian");
    } else if (kw == "element") {
      Element e;
      e.name = std::string(token(rest));
      const std::string_view c = token(rest);
      if (!to_int(c, e.count) || e.count < 0)
        return fail_at_line(name, lines.line_no(), ": element '", e.name, "': count ", quote(c),
                            " is not a non-negative integer");
      if (std::size_t(e.count) > text.size())
        return fail_at_line(name, lines.line_no(), ": element '", e.name, "': count ", e.count,
                            " exceeds the file size");
      elements.push_back(std::move(e));
    } else if (kw == "property") {
      if (elements.empty()) return fail_at_line(name, lines.line_no(), ": property before any element");
      Property p;
      std::string_view t = token(rest);
      if (t == "list") {
        p.list = true;
        p.count_type = ply_type(token(rest));
        t = token(rest);
      }
      p.type = ply_type(t);
      p.name = std::string(token(rest));
      if (p.name.empty()) return fail_at_line(name, lines.line_no(), ": property without a name");
      elements.back().props.push_back(p);
    } else {
      return fail_at_line(name, lines.line_no(), ": unknown header line ", quote(line));
    }
  }
  if (format == Format::None) return fail(name, ": header has no 'format' line");
  const bool binary = format != Format::Ascii;
  if (binary)  // ASCII values are tokens whatever their type; binary ones need a size
    for (const Element& e : elements)
      for (const Property& p : e.props)
        if (p.type == PlyType::Unknown || (p.list && !ply_integral(p.count_type)))
          return fail(name, ": element '", e.name, "' property '", p.name, "': ", p.list ? "list types" : "type",
                      " must be one of char, uchar, short, ushort, int, uint, float, double (or int8 ... float64)",
                      p.list ? " with an integer count type" : "");
  LoadReport rep;
  rep.reader = binary ? "spheretouch PLY (binary) reader" : "spheretouch PLY (ascii) reader";
  rep.precision = binary ? "double (float properties widened exactly)" : "double (correctly rounded)";
  std::vector<Vec3> pos;
  std::vector<Tri> faces;
  std::vector<std::uint32_t> poly;
  // The ASCII body is a stream of tokens (line numbers tracked for messages); the binary body
  // starts right after the end_header line, its errors name the byte offset in the file.
  const std::size_t body_at = lines.offset();
  PlyBinary bin(text.substr(body_at), format == Format::Big);
  std::string_view rest;
  auto next_token = [&](std::string_view& t) -> bool {
    for (;;) {
      t = token(rest);
      if (!t.empty()) return true;
      if (!lines.next(line, false)) return false;
      rest = line;
    }
  };
  auto where = [&]() {
    return binary ? name + ": byte " + std::to_string(body_at + bin.offset())
                  : name + ":" + std::to_string(lines.line_no());
  };
  // Next value of type `type` as a double; for ASCII `integer` asks for an integer token.
  // Returns an empty string, or what went wrong.
  auto next_value = [&](PlyType type, bool integer, double& out) -> std::string {
    if (binary) return bin.read(type, out) ? std::string() : std::string("end");
    std::string_view t;
    if (!next_token(t)) return "end";
    if (integer) {
      long long v = 0;
      if (!to_int(t, v)) return quote(t) + " is not an integer";
      if (v < -(1ll << 53) || v > (1ll << 53)) return quote(t) + " is out of range";
      out = double(v);
      return {};
    }
    if (!to_double(t, out)) return quote(t) + " is not a number";
    return {};
  };
  bool vertices_done = false;
  for (const Element& e : elements) {
    if (e.props.empty()) continue;  // nothing to read, however many items it declares
    const bool is_vertex = e.name == "vertex", is_face = e.name == "face";
    int axis_of[64];
    for (std::size_t k = 0; k < e.props.size() && k < 64; ++k)
      axis_of[k] = e.props[k].name == "x" ? 0 : e.props[k].name == "y" ? 1 : e.props[k].name == "z" ? 2 : -1;
    if (is_vertex) {
      bool have[3] = {false, false, false};
      for (std::size_t k = 0; k < e.props.size() && k < 64; ++k)
        if (axis_of[k] >= 0) {
          if (e.props[k].list) return fail(name, ": element 'vertex': property '", e.props[k].name, "' is a list");
          if (have[axis_of[k]]) return fail(name, ": element 'vertex' declares property '", e.props[k].name, "' twice");
          have[axis_of[k]] = true;
        }
      if (!(have[0] && have[1] && have[2])) return fail(name, ": element 'vertex' lacks x, y and z properties");
    }
    if (binary) {  // every item takes at least one byte per property: refuse counts the data cannot hold
      std::size_t min_bytes = 0;
      for (const Property& p : e.props) min_bytes += p.list ? ply_size(p.count_type) : ply_size(p.type);
      if (std::size_t(e.count) > bin.left() / min_bytes)
        return fail(where(), ": element '", e.name, "': ", e.count, " items of at least ", min_bytes,
                    " bytes do not fit in the ", bin.left(), " bytes left");
    }
    if (is_vertex) pos.reserve(pos.size() + std::size_t(e.count));
    for (long long i = 0; i < e.count; ++i) {
      Vec3 p = Vec3::Zero();
      for (std::size_t k = 0; k < e.props.size(); ++k) {
        const Property& prop = e.props[k];
        double d = 0;
        if (prop.list) {
          std::string why = next_value(prop.count_type, true, d);
          if (why == "end") return fail(name, ": file ends inside element '", e.name, "' ", i, " of ", e.count);
          if (!why.empty() || d < 0 || d > double(text.size()))
            return fail(where(), ": ", e.name, " ", i, ": list length ",
                        why.empty() ? std::to_string(static_cast<long long>(d)) : why, " is not valid");
          const auto n = static_cast<std::size_t>(d);
          if (binary && n > bin.left() / ply_size(prop.type))
            return fail(where(), ": ", e.name, " ", i, ": list of ", n, " values does not fit in the ", bin.left(),
                        " bytes left");
          const bool indices = is_face && (prop.name == "vertex_indices" || prop.name == "vertex_index");
          if (binary && indices && !ply_integral(prop.type))
            return fail(where(), ": face ", i, ": vertex indices of a floating-point type");
          poly.clear();
          for (std::size_t j = 0; j < n; ++j) {
            why = next_value(prop.type, indices, d);
            if (why == "end") return fail(name, ": file ends inside ", e.name, " ", i);
            if (!indices) continue;
            if (!why.empty()) return fail(where(), ": face ", i, ": index ", why);
            if (!vertices_done || d < 0 || d >= static_cast<double>(pos.size()))
              return fail(where(), ": face ", i, ": vertex index ", static_cast<long long>(d), " out of range [0, ",
                          pos.size(), ")");
            poly.push_back(static_cast<std::uint32_t>(d));
          }
          if (indices) {
            if (poly.size() < 3)
              return fail(where(), ": face ", i, ": has ", poly.size(), " corners (expected at least 3)");
            fan(poly, faces, rep);
          }
        } else {
          const bool axis = is_vertex && k < 64 && axis_of[k] >= 0;
          std::string why = next_value(prop.type, false, d);
          if (why == "end") return fail(name, ": file ends inside element '", e.name, "' ", i, " of ", e.count);
          if (!axis) continue;  // other properties (colour, normal, ...) are skipped
          if (!why.empty()) return fail(where(), ": vertex ", i, ": ", why);
          if (!std::isfinite(d)) return fail(where(), ": vertex ", i, ": coordinate ", d, " is not finite");
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

}  // namespace st::geom
