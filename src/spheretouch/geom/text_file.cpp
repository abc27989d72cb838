// SPDX-License-Identifier: BSD-3-Clause
// read_text_file: see text_file.hpp.
#include <spheretouch/geom/text_file.hpp>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace st::inline SPHERETOUCH_ABI::geom {

Result<std::string> read_text_file(const std::string& path, std::uint64_t max_bytes, const std::string& what,
                                   bool owner_only) {
  // O_NONBLOCK: opening a FIFO must not wait for a writer; fstat the open file (no stat-then-open race).
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NOCTTY | O_NONBLOCK);
  if (fd < 0) return fail(path, ": cannot open ", what, ": ", std::strerror(errno));
  struct Closer {
    int fd;
    ~Closer() { ::close(fd); }
  } closer{fd};
  struct stat st {};
  if (::fstat(fd, &st) != 0) return fail(path, ": cannot stat ", what, ": ", std::strerror(errno));
  if (S_ISDIR(st.st_mode)) return fail(path, ": is a directory, not a ", what);
  if (!S_ISREG(st.st_mode)) return fail(path, ": not a regular file (a ", what, " is a text file)");
  if (owner_only && (st.st_mode & 077))
    return fail(path, ": the ", what, " is accessible by group or others (mode ", std::oct, (st.st_mode & 0777),
                "); refusing to use it (chmod 600 ", path, ")");
  if (std::uint64_t(st.st_size) > max_bytes)
    return fail(path, ": ", std::uint64_t(st.st_size), " bytes, more than the ", max_bytes, "-byte limit for a ", what);
  std::string text(std::size_t(st.st_size), '\0');
  std::size_t n = 0;
  while (n < text.size()) {
    const ssize_t r = ::read(fd, text.data() + n, text.size() - n);
    if (r < 0 && errno == EINTR) continue;
    if (r < 0) return fail(path, ": read error in ", what, ": ", std::strerror(errno));
    if (r == 0) break;  // shrank while we read: take what is there
    n += std::size_t(r);
  }
  text.resize(n);
  return text;
}

}  // namespace st::geom
