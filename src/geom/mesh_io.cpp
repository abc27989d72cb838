// Mesh import/export. Our own readers for the text formats keep the file's doubles exactly;
// assimp (float) reads the rest. See mesh_io.hpp for the face-numbering rule.
#include "geom/mesh_io.hpp"

#include <assimp/DefaultIOSystem.h>
#include <assimp/Importer.hpp>
#include <assimp/scene.h>
#include <fcntl.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
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
  /// Byte offset just past the last line returned (where a binary PLY body starts).
  std::size_t offset() const { return std::min(pos_, text_.size()); }

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

/// Welds exact-duplicate vertices (formats like STL repeat them per face), so closedness and
/// subdivision see the real topology; +0 and -0 weld together. Welding never reorders faces.
class Welder {
 public:
  /// Index of `q` among the distinct vertices so far, adding it if new.
  std::uint32_t add(const Vec3& q) {
    ++raw_;
    auto [slot, fresh] = index_of_.try_emplace(q, static_cast<std::uint32_t>(pos_.size()));
    if (fresh) pos_.push_back(q);
    return slot->second;
  }
  const std::vector<Vec3>& positions() const { return pos_; }  ///< distinct vertices, first-seen order
  std::size_t welded() const { return raw_ - pos_.size(); }     ///< duplicates merged

 private:
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
  std::unordered_map<Vec3, std::uint32_t, Hash> index_of_;
  std::vector<Vec3> pos_;
  std::size_t raw_ = 0;
};

/// What the importer child sends back: the welded positions, the faces and the report, or an error.
struct AssimpOut {
  std::string error;
  std::vector<Vec3> pos;
  std::vector<Tri> faces;
  LoadReport rep;
};

/// Assimp's file access, confined: the mesh file itself and, only when allowed, regular files
/// inside its directory (a glTF's .bin buffers). A URI that names any other file (../, an
/// absolute path, a symlink out) cannot be opened, so its bytes cannot come back as coordinates.
class ConfinedIO : public Assimp::DefaultIOSystem {
 public:
  ConfinedIO(const std::string& main, bool allow_dir) : allow_dir_(allow_dir) {
    std::error_code ec;
    main_ = std::filesystem::weakly_canonical(main, ec);
    dir_ = main_.parent_path();
  }
  bool Exists(const char* file) const override { return allowed(file) && DefaultIOSystem::Exists(file); }
  Assimp::IOStream* Open(const char* file, const char* mode = "rb") override {
    if (!mode || std::strpbrk(mode, "wa+") || !allowed(file)) {
      if (refused.empty()) refused = file ? file : "";
      return nullptr;
    }
    return DefaultIOSystem::Open(file, mode);
  }
  mutable std::string refused;  ///< the first file it refused to open

 private:
  bool allowed(const char* file) const {
    if (!file) return false;
    std::error_code ec;
    const std::filesystem::path p = std::filesystem::weakly_canonical(file, ec);
    if (ec) return false;
    if (p == main_) return true;
    if (!allow_dir_) return false;
    const std::filesystem::path rel = p.lexically_relative(dir_);
    if (rel.empty() || *rel.begin() == "..") return false;
    return std::filesystem::is_regular_file(p, ec);
  }
  std::filesystem::path main_, dir_;
  bool allow_dir_;
};

/// Reads `path` with assimp in this process (the importer child, load_with_assimp).
AssimpOut read_with_assimp(const std::string& path, bool allow_external) {
  AssimpOut out;
  Assimp::Importer importer;
  auto* io = new ConfinedIO(path, allow_external);  // the importer owns and deletes it
  importer.SetIOHandler(io);
  // No post-processing at all: every aiProcess step may reorder, split or merge faces.
  const aiScene* scene = importer.ReadFile(path, 0);
  if (!scene || !scene->mRootNode) {
    out.error = st::fail(path, ": assimp could not read it: ", importer.GetErrorString()).message;
    if (!io->refused.empty())
      out.error += st::fail(" (it refers to '", io->refused, "': files other than the mesh are not opened",
                            allow_external ? " outside its directory" : "; LoadOptions::allow_external_files opens those in its directory", ")").message;
    return out;
  }
  LoadReport rep;
  rep.reader = "assimp";
  rep.precision = "float (Debian's assimp has single-precision ai_real: ~7 significant digits)";
  Welder weld;
  std::vector<Tri> faces;
  std::vector<std::uint32_t> poly;
  // Depth-first over the node tree in child order: meshes in the order nodes reference them,
  // each with its accumulated node transform (applied in double).
  struct Item { const aiNode* node; Eigen::Matrix4d xf; };
  std::vector<Item> stack{{scene->mRootNode, Eigen::Matrix4d::Identity()}};
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
      for (unsigned v = 0; v < mesh->mNumVertices; ++v) {
        const aiVector3D& a = mesh->mVertices[v];
        const Eigen::Vector4d p = xf * Eigen::Vector4d(a.x, a.y, a.z, 1.0);
        remap[v] = weld.add(p.head<3>());
      }
      for (unsigned f = 0; f < mesh->mNumFaces; ++f) {
        const aiFace& face = mesh->mFaces[f];
        if (face.mNumIndices < 3) { ++rep.skipped_primitives; continue; }
        poly.clear();
        for (unsigned k = 0; k < face.mNumIndices; ++k) {
          if (face.mIndices[k] >= mesh->mNumVertices) {
            out.error = st::fail(path, ": mesh ", mi, " face ", f, ": vertex index ", face.mIndices[k], " out of range [0, ",
                                 mesh->mNumVertices, ")").message;
            return out;
          }
          poly.push_back(remap[face.mIndices[k]]);
        }
        fan(poly, faces, rep);
      }
    }
    for (unsigned c = it.node->mNumChildren; c-- > 0;) stack.push_back({it.node->mChildren[c], xf});
  }
  rep.welded_vertices = weld.welded();
  out.pos = weld.positions();
  out.faces = std::move(faces);
  out.rep = std::move(rep);
  return out;
}

// The child's answer on the pipe: u8 status (0 ok, 1 error), then either u64 length + error
// text, or u64 polygons, fanned, skipped, welded, u64 #positions, #faces, the positions
// (3 doubles each), the faces (3 u32 each).
bool write_all(int fd, const void* data, std::size_t n) {
  const char* p = static_cast<const char*>(data);
  while (n > 0) {
    const ssize_t w = ::write(fd, p, n);
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) return false;
    p += w;
    n -= std::size_t(w);
  }
  return true;
}
bool read_all(int fd, void* data, std::size_t n) {
  char* p = static_cast<char*>(data);
  while (n > 0) {
    const ssize_t r = ::read(fd, p, n);
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) return false;
    p += r;
    n -= std::size_t(r);
  }
  return true;
}

[[noreturn]] void importer_child(int fd, const std::string& path, const LoadOptions& o, std::uint64_t budget) {
  // Memory: the address space this process has now, plus the budget; CPU time: the limit.
  std::uint64_t vm_pages = 0;
  if (std::FILE* f = std::fopen("/proc/self/statm", "r")) {
    unsigned long long v = 0;
    if (std::fscanf(f, "%llu", &v) == 1) vm_pages = v;
    std::fclose(f);
  }
  const std::uint64_t as = vm_pages * std::uint64_t(::sysconf(_SC_PAGESIZE)) + budget;
  const rlimit mem{as, as};
  ::setrlimit(RLIMIT_AS, &mem);
  const rlimit cpu{o.assimp_cpu_seconds, o.assimp_cpu_seconds + 1};
  ::setrlimit(RLIMIT_CPU, &cpu);
  std::uint8_t status = 1;
  AssimpOut out;
  try {
    out = read_with_assimp(path, o.allow_external_files);
    status = out.error.empty() ? 0 : 1;
  } catch (const std::bad_alloc&) {
    out.error = "out of memory";
  } catch (const std::exception& e) {
    out.error = e.what();
  }
  bool ok = write_all(fd, &status, 1);
  if (status) {
    const std::uint64_t n = out.error.size();
    ok = ok && write_all(fd, &n, 8) && write_all(fd, out.error.data(), n);
  } else {
    const std::uint64_t head[6] = {out.rep.polygons, out.rep.fanned_polygons, out.rep.skipped_primitives,
                                   out.rep.welded_vertices, out.pos.size(), out.faces.size()};
    ok = ok && write_all(fd, head, sizeof head);
    for (const Vec3& v : out.pos) ok = ok && write_all(fd, v.data(), 3 * sizeof(double));
    ok = ok && write_all(fd, out.faces.data(), out.faces.size() * sizeof(Tri));
  }
  ::_exit(ok ? 0 : 3);
}

/// Reads `path` with assimp in a child process with a memory and CPU budget: a file that makes
/// assimp allocate gigabytes, loop or crash costs the child, never this process.
Result<LoadedMesh> load_with_assimp(const std::string& path, const LoadOptions& o) {
  static_assert(sizeof(Tri) == 12);
  std::error_code ec;
  const std::uint64_t file_bytes = std::filesystem::file_size(path, ec);
  std::uint64_t input = ec ? 0 : file_bytes;
  if (o.allow_external_files) {  // buffers beside it count towards what it may allocate
    for (const auto& e : std::filesystem::directory_iterator(std::filesystem::path(path).parent_path().empty()
                                                                  ? std::filesystem::path(".")
                                                                  : std::filesystem::path(path).parent_path(), ec))
      if (e.is_regular_file(ec)) input += e.file_size(ec);
  }
  const std::uint64_t budget = (std::uint64_t(o.assimp_memory_floor_mb) << 20) + o.assimp_memory_per_byte * input;
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0) return fail(path, ": cannot start the assimp reader: pipe: ", std::strerror(errno));
  const pid_t pid = ::fork();
  if (pid < 0) {
    const int err = errno;
    ::close(fds[0]);
    ::close(fds[1]);
    return fail(path, ": cannot start the assimp reader: fork: ", std::strerror(err));
  }
  if (pid == 0) {
    ::close(fds[0]);
    importer_child(fds[1], path, o, budget);
  }
  ::close(fds[1]);
  const int fd = fds[0];
  Result<LoadedMesh> result = Error{""};
  std::uint8_t status = 2;
  bool got = read_all(fd, &status, 1);
  if (got && status == 1) {
    std::uint64_t n = 0;
    std::string text;
    got = read_all(fd, &n, 8) && n <= 4096 && (text.resize(n), read_all(fd, text.data(), n));
    result = fail(got ? text : path + ": the assimp reader sent a malformed error");
  } else if (got && status == 0) {
    std::uint64_t head[6];
    got = read_all(fd, head, sizeof head);
    // Sizes the child claims are checked against what its budget could have held.
    if (got && (head[4] > budget / 24 || head[5] > budget / 12 || head[4] >= UINT32_MAX)) got = false;
    if (got) {
      LoadReport rep;
      rep.reader = "assimp";
      rep.precision = "float (Debian's assimp has single-precision ai_real: ~7 significant digits)";
      rep.polygons = head[0];
      rep.fanned_polygons = head[1];
      rep.skipped_primitives = head[2];
      rep.welded_vertices = head[3];
      std::vector<Vec3> pos(head[4]);
      std::vector<Tri> faces(head[5]);
      for (Vec3& v : pos) got = got && read_all(fd, v.data(), 3 * sizeof(double));
      got = got && read_all(fd, faces.data(), faces.size() * sizeof(Tri));
      if (got && faces.empty())
        result = fail(path, ": no triangles (", rep.skipped_primitives, " points/lines ignored)");
      else if (got)
        result = finish(path, pos, std::move(faces), std::move(rep));
    }
  }
  ::close(fd);
  int ws = 0;
  while (::waitpid(pid, &ws, 0) < 0 && errno == EINTR) {
  }
  if (WIFSIGNALED(ws)) {
    const int sig = WTERMSIG(ws);
    if (sig == SIGXCPU || sig == SIGKILL)
      return fail(path, ": assimp took more than ", o.assimp_cpu_seconds, " s of CPU reading it (LoadOptions::assimp_cpu_seconds)");
    if (sig == SIGABRT)  // assimp's own abort, or a sanitizer build's allocator refusing past the budget
      return fail(path, ": assimp aborted reading it (signal ", sig, ", ", strsignal(sig), "): the file is malformed or "
                  "hostile, or needed more than its budget of ", budget >> 20, " MiB (sanitizer builds abort there)");
    return fail(path, ": assimp crashed reading it (signal ", sig, ", ", strsignal(sig), "); the file is malformed or hostile");
  }
  if (result.ok() || status == 0 || !got) {
    if (!got || !WIFEXITED(ws) || WEXITSTATUS(ws) != 0)
      return fail(path, ": the assimp reader stopped without an answer (exit status ", WIFEXITED(ws) ? WEXITSTATUS(ws) : -1,
                  "): the file is malformed or hostile, or needed more than its budget of ", budget >> 20,
                  " MiB (a sanitizer build's allocator exits there)");
    return result;
  }
  if (result.error().find("out of memory") != std::string::npos || result.error().find("bad_alloc") != std::string::npos)
    return fail(path, ": assimp needed more than its budget of ", budget >> 20, " MiB reading a ", file_bytes,
                "-byte file (LoadOptions::assimp_memory_floor_mb + assimp_memory_per_byte x input bytes): refused");
  return result;
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
    case PlyType::I8: case PlyType::U8: return 1;
    case PlyType::I16: case PlyType::U16: return 2;
    case PlyType::I32: case PlyType::U32: case PlyType::F32: return 4;
    case PlyType::F64: return 8;
    case PlyType::Unknown: break;
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
      case PlyType::I8: { std::int8_t v; std::memcpy(&v, b, 1); out = v; break; }
      case PlyType::U8: out = b[0]; break;
      case PlyType::I16: { std::int16_t v; std::memcpy(&v, b, 2); out = v; break; }
      case PlyType::U16: { std::uint16_t v; std::memcpy(&v, b, 2); out = v; break; }
      case PlyType::I32: { std::int32_t v; std::memcpy(&v, b, 4); out = v; break; }
      case PlyType::U32: { std::uint32_t v; std::memcpy(&v, b, 4); out = v; break; }
      case PlyType::F32: { float v; std::memcpy(&v, b, 4); out = v; break; }
      case PlyType::F64: std::memcpy(&out, b, 8); break;
      case PlyType::Unknown: return false;
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
  struct Property { std::string name; bool list = false; PlyType type = PlyType::Unknown, count_type = PlyType::Unknown; };
  struct Element { std::string name; long long count = 0; std::vector<Property> props; };
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
      if (f == "ascii") format = Format::Ascii;
      else if (f == "binary_little_endian") format = Format::Little;
      else if (f == "binary_big_endian") format = Format::Big;
      else return fail(name, ":", lines.line_no(), ": format ", quote(f), " is not ascii, binary_little_endian or binary_big_endian");
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
      if (t == "list") {
        p.list = true;
        p.count_type = ply_type(token(rest));
        t = token(rest);
      }
      p.type = ply_type(t);
      p.name = std::string(token(rest));
      if (p.name.empty()) return fail(name, ":", lines.line_no(), ": property without a name");
      elements.back().props.push_back(p);
    } else {
      return fail(name, ":", lines.line_no(), ": unknown header line ", quote(line));
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
    return binary ? name + ": byte " + std::to_string(body_at + bin.offset()) : name + ":" + std::to_string(lines.line_no());
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
        return fail(where(), ": element '", e.name, "': ", e.count, " items of at least ", min_bytes, " bytes do not fit in the ",
                    bin.left(), " bytes left");
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
            return fail(where(), ": ", e.name, " ", i, ": list length ", why.empty() ? std::to_string(static_cast<long long>(d)) : why, " is not valid");
          const auto n = static_cast<std::size_t>(d);
          if (binary && n > bin.left() / ply_size(prop.type))
            return fail(where(), ": ", e.name, " ", i, ": list of ", n, " values does not fit in the ", bin.left(), " bytes left");
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
              return fail(where(), ": face ", i, ": vertex index ", static_cast<long long>(d), " out of range [0, ", pos.size(), ")");
            poly.push_back(static_cast<std::uint32_t>(d));
          }
          if (indices) {
            if (poly.size() < 3) return fail(where(), ": face ", i, ": has ", poly.size(), " corners (expected at least 3)");
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

std::vector<std::string> supported_extensions() {
  std::vector<std::string> out{".off", ".obj", ".ply", ".stl"};
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
          if (!q.allFinite()) return fail(name, ": facet ", f, " (byte ", 84 + 50 * std::size_t{f} + 12 + 12 * k, "): vertex ", k, " is not finite");
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
      return fail(name, ":", lines.line_no(), ": expected ", what, ", found ", quote(line));
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
        if (kw == "endsolid") { at = At::Outside; break; }
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
          if (poly.size() < 3) return fail(name, ":", lines.line_no(), ": facet ", facet, ": has ", poly.size(), " vertices (expected at least 3)");
          fan(poly, faces, rep);
          at = At::EndLoop;
          break;
        }
        if (kw != "vertex") return expected("'vertex X Y Z' or 'endloop'");
        {
          Vec3 q;
          for (int k = 0; k < 3; ++k) {
            const std::string_view t = token(rest);
            if (!to_double(t, q[k])) return fail(name, ":", lines.line_no(), ": facet ", facet, ": ", quote(t), " is not a number");
            if (!std::isfinite(q[k])) return fail(name, ":", lines.line_no(), ": facet ", facet, ": coordinate ", quote(t), " is not finite");
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

Result<LoadedMesh> parse_mesh(std::string_view bytes, const std::string& ext, const std::string& name) {
  if (ext == ".off") return parse_off(bytes, name);
  if (ext == ".obj") return parse_obj(bytes, name);
  if (ext == ".ply") return parse_ply(bytes, name);
  if (ext == ".stl") return parse_stl(bytes, name);
  return fail(name, ": parse_mesh reads .off, .obj, .ply and .stl, not '", ext, "'");
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
  if (ext == ".off" || ext == ".obj" || ext == ".ply" || ext == ".stl") {
    Result<std::string> text = slurp(path);
    if (!text) return Error{text.error()};
    r = parse_mesh(text.value(), ext, path);
  } else {
    Assimp::Importer importer;
    if (ext.empty() || !importer.IsExtensionSupported(ext))
      return fail(path, ": unknown mesh format '", ext, "' (expected .off, .obj, .ply, .stl, .gltf, .glb or another assimp format)");
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
