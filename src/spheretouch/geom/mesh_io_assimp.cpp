// SPDX-License-Identifier: BSD-3-Clause
// Formats other than OFF/OBJ/PLY/STL through assimp (float), read in a forked child process with
// a memory and CPU budget and file access confined to the mesh (and, if allowed, its directory).
#include <spheretouch/geom/mesh_io.hpp>

#include <assimp/DefaultIOSystem.h>
#include <assimp/Importer.hpp>
#include <assimp/scene.h>
#include <fcntl.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include <spheretouch/geom/mesh_io_detail.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {

using namespace detail;

namespace {

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
                            allow_external ? " outside its directory"
                                           : "; LoadConfig::allow_external_files opens those in its directory",
                            ")")
                       .message;
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
  struct Item {
    const aiNode* node;
    Eigen::Matrix4d xf;
  };
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
        if (face.mNumIndices < 3) {
          ++rep.skipped_primitives;
          continue;
        }
        poly.clear();
        for (unsigned k = 0; k < face.mNumIndices; ++k) {
          if (face.mIndices[k] >= mesh->mNumVertices) {
            out.error = st::fail(path, ": mesh ", mi, " face ", f, ": vertex index ", face.mIndices[k],
                                 " out of range [0, ", mesh->mNumVertices, ")")
                            .message;
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

[[noreturn]] void importer_child(int fd, const std::string& path, const LoadConfig& o, std::uint64_t budget) {
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
  } catch (const std::bad_alloc&) { out.error = "out of memory"; } catch (const std::exception& e) {
    out.error = e.what();
  }
  bool ok = write_all(fd, &status, 1);
  if (status) {
    const std::uint64_t n = out.error.size();
    ok = ok && write_all(fd, &n, 8) && write_all(fd, out.error.data(), n);
  } else {
    const std::uint64_t head[6] = {out.rep.polygons,        out.rep.fanned_polygons, out.rep.skipped_primitives,
                                   out.rep.welded_vertices, out.pos.size(),          out.faces.size()};
    ok = ok && write_all(fd, head, sizeof head);
    for (const Vec3& v : out.pos) ok = ok && write_all(fd, v.data(), 3 * sizeof(double));
    ok = ok && write_all(fd, out.faces.data(), out.faces.size() * sizeof(Tri));
  }
  ::_exit(ok ? 0 : 3);
}

}  // namespace

/// Reads `path` with assimp in a child process with a memory and CPU budget: a file that makes
/// assimp allocate gigabytes, loop or crash costs the child, never this process.
Result<LoadedMesh> detail::load_with_assimp(const std::string& path, const LoadConfig& o) {
  static_assert(sizeof(Tri) == 12);
  std::error_code ec;
  const std::uint64_t file_bytes = std::filesystem::file_size(path, ec);
  std::uint64_t input = ec ? 0 : file_bytes;
  if (o.allow_external_files) {  // buffers beside it count towards what it may allocate
    for (const auto& e : std::filesystem::directory_iterator(std::filesystem::path(path).parent_path().empty()
                                                                 ? std::filesystem::path(".")
                                                                 : std::filesystem::path(path).parent_path(),
                                                             ec))
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
  while (::waitpid(pid, &ws, 0) < 0 && errno == EINTR) {}
  if (WIFSIGNALED(ws)) {
    const int sig = WTERMSIG(ws);
    if (sig == SIGXCPU || sig == SIGKILL)
      return fail(path, ": assimp took more than ", o.assimp_cpu_seconds,
                  " s of CPU reading it (LoadConfig::assimp_cpu_seconds)");
    if (sig == SIGABRT)  // assimp's own abort, or a sanitizer build's allocator refusing past the budget
      return fail(path, ": assimp aborted reading it (signal ", sig, ", ", strsignal(sig),
                  "): the file is malformed or "
                  "hostile, or needed more than its budget of ",
                  budget >> 20, " MiB (sanitizer builds abort there)");
    return fail(path, ": assimp crashed reading it (signal ", sig, ", ", strsignal(sig),
                "); the file is malformed or hostile");
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
                "-byte file (LoadConfig::assimp_memory_floor_mb + assimp_memory_per_byte x input bytes): refused");
  return result;
}

bool detail::assimp_reads(const std::string& ext) {
  Assimp::Importer importer;
  return importer.IsExtensionSupported(ext);
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

}  // namespace st::geom
