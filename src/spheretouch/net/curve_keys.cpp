// SPDX-License-Identifier: BSD-3-Clause
// CURVE key files (curve_keys.hpp).
#include <spheretouch/net/curve_keys.hpp>

#include <sodium.h>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zmq.h>

#include <cctype>
#include <cerrno>
#include <cstdint>
#include <cstdlib>
#include <cstring>

namespace st::inline SPHERETOUCH_ABI::net {

namespace {

/// A key file is one short line; anything bigger is not a key file (and is not read whole).
constexpr std::size_t kMaxKeyFileBytes = 4096;

bool ends_with(const std::string& s, const std::string& tail) {
  return s.size() >= tail.size() && s.compare(s.size() - tail.size(), tail.size(), tail) == 0;
}

std::string errno_text() { return std::strerror(errno); }

/// Closes a descriptor on scope exit.
struct Fd {
  int fd = -1;
  ~Fd() {
    if (fd >= 0) ::close(fd);
  }
};

Status write_all(int fd, const std::string& data, const std::string& path) {
  for (std::size_t off = 0; off < data.size();) {
    const ssize_t n = ::write(fd, data.data() + off, data.size() - off);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) return fail(path, ": write failed: ", errno_text());
    off += std::size_t(n);
  }
  if (::fsync(fd) != 0) return fail(path, ": fsync failed: ", errno_text());
  return Ok{};
}

/// Writes `line` + '\n' to a file that must not exist yet, with exactly `mode` (fchmod: the
/// umask may only have taken bits away). On failure the new file is removed.
Status create_exclusive(const std::string& path, const std::string& line, mode_t mode) {
  // O_EXCL: never replace a file, and never follow a symlink planted at the path.
  Fd f{::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC | O_NOCTTY, 0600 & mode)};
  if (f.fd < 0) {
    if (errno == EEXIST) return fail(path, ": already exists; refusing to overwrite a key file (--force replaces it)");
    return fail(path, ": cannot create: ", errno_text());
  }
  Status s = ::fchmod(f.fd, mode) == 0 ? write_all(f.fd, line + "\n", path) : fail(path, ": fchmod: ", errno_text());
  if (!s) ::unlink(path.c_str());
  return s;
}

/// Writes `line` + '\n' to a new 0600 temporary file beside `path` (mkostemp: O_CREAT|O_EXCL),
/// sets `mode`, and returns the temporary's name; the caller renames it over `path`.
Result<std::string> write_temporary(const std::string& path, const std::string& line, mode_t mode) {
  std::string tmp = path + ".tmp-XXXXXX";
  Fd f{::mkostemp(tmp.data(), O_CLOEXEC)};
  if (f.fd < 0) return fail(path, ": cannot create a temporary file beside it: ", errno_text());
  Status s = ::fchmod(f.fd, mode) == 0 ? write_all(f.fd, line + "\n", tmp) : fail(tmp, ": fchmod: ", errno_text());
  if (!s) {
    ::unlink(tmp.c_str());
    return Error{s.error()};
  }
  return tmp;
}

/// The first line of a small regular file, trimmed; `secret` refuses group/other permissions.
Result<std::string> read_key_line(const std::string& path_in, const char* what, bool secret) {
  Result<std::string> p = expand_credentials_path(path_in);
  if (!p) return p;
  const std::string& path = p.value();
  // O_NONBLOCK: a FIFO at the path must not hang us; fstat on the open file, not stat then open.
  Fd f{::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NOCTTY | O_NONBLOCK)};
  if (f.fd < 0) return fail(path, ": cannot open the ", what, ": ", errno_text());
  struct stat st {};
  if (::fstat(f.fd, &st) != 0) return fail(path, ": cannot stat the ", what, ": ", errno_text());
  if (!S_ISREG(st.st_mode)) return fail(path, ": the ", what, " is not a regular file");
  if (secret && (st.st_mode & 077))
    return fail(path, ": the ", what, " is accessible by group or others (mode ", std::oct, (st.st_mode & 0777),
                "); refusing to use it (chmod 600 ", path, ")");
  if (std::size_t(st.st_size) > kMaxKeyFileBytes)
    return fail(path, ": ", st.st_size, " bytes: too big for a ", what, " (one 40-character line)");
  char buf[kMaxKeyFileBytes];
  std::size_t n = 0;
  while (n < sizeof buf) {
    const ssize_t r = ::read(f.fd, buf + n, sizeof buf - n);
    if (r < 0 && errno == EINTR) continue;
    if (r < 0) return fail(path, ": cannot read the ", what, ": ", errno_text());
    if (r == 0) break;
    n += std::size_t(r);
  }
  std::string line(buf, n);
  std::memset(buf, 0, sizeof buf);
  line.resize(std::min(line.size(), line.find('\n')));  // in place: no unwiped copy of the key
  while (!line.empty() && std::isspace(static_cast<unsigned char>(line.back()))) line.pop_back();
  std::size_t lead = 0;
  while (lead < line.size() && std::isspace(static_cast<unsigned char>(line[lead]))) ++lead;
  line.erase(0, lead);
  if (line.empty()) return fail(path, ": the ", what, " is empty (expected a 40-character Z85 key on the first line)");
  if (Status s = check_z85_key(line, path + ": first line"); !s) {
    wipe_secret(line);
    return Error{s.error()};
  }
  return line;
}

}  // namespace

Status check_z85_key(const std::string& z85, const std::string& what) {
  std::uint8_t raw[32];
  const bool ok = z85.size() == 40 && zmq_z85_decode(raw, z85.c_str());
  sodium_memzero(raw, sizeof raw);  // the key may be a secret one
  if (!ok) return fail(what, ": not a 40-character Z85 CURVE key");
  return Ok{};
}

void wipe_secret(std::string& s) {
  if (!s.empty()) sodium_memzero(s.data(), s.size());
  s.clear();
}

Result<std::string> curve_public_of(const std::string& secret_z85) {
  if (Status s = check_z85_key(secret_z85, "secret key"); !s) return Error{s.error()};
  char pub[41] = {};
  if (zmq_curve_public(pub, secret_z85.c_str()) != 0) return fail("secret key: libzmq has no CURVE support");
  return std::string(pub);
}

Result<CurveKeyPair> generate_curve_key_pair() {
  char pub[41] = {}, sec[41] = {};
  if (zmq_curve_keypair(pub, sec) != 0) return fail("libzmq has no CURVE support (built without libsodium?)");
  CurveKeyPair k{pub, sec};
  std::memset(sec, 0, sizeof sec);
  return k;
}

KeyFiles key_files(const std::string& prefix) {
  std::string base = prefix;
  if (ends_with(base, ".key") || ends_with(base, ".pub")) base.resize(base.size() - 4);
  return {base + ".key", base + ".pub"};
}

Status write_key_pair(const std::string& prefix, const CurveKeyPair& keys, bool force) {
  Result<std::string> derived = curve_public_of(keys.secret_z85);
  if (!derived) return Error{derived.error()};
  if (derived.value() != keys.public_z85)
    return fail("write_key_pair: the public key does not belong to the secret key");
  const KeyFiles f = key_files(prefix);
  if (prefix.empty() || f.secret_file == ".key") return fail("key file prefix is empty");
  if (!force) {
    if (Status s = create_exclusive(f.secret_file, keys.secret_z85, 0600); !s) return s;
    if (Status s = create_exclusive(f.public_file, keys.public_z85, 0644); !s) {
      ::unlink(f.secret_file.c_str());  // no half pair left behind
      return s;
    }
    return Ok{};
  }
  // --force: rename() replaces the old file by a new inode that was 0600 from its creation.
  Result<std::string> ts = write_temporary(f.secret_file, keys.secret_z85, 0600);
  if (!ts) return Error{ts.error()};
  Result<std::string> tp = write_temporary(f.public_file, keys.public_z85, 0644);
  if (!tp) {
    ::unlink(ts.value().c_str());
    return Error{tp.error()};
  }
  if (::rename(ts.value().c_str(), f.secret_file.c_str()) != 0) {
    const std::string why = errno_text();
    ::unlink(ts.value().c_str());
    ::unlink(tp.value().c_str());
    return fail(f.secret_file, ": cannot replace: ", why);
  }
  if (::rename(tp.value().c_str(), f.public_file.c_str()) != 0) {
    const std::string why = errno_text();
    ::unlink(tp.value().c_str());
    return fail(f.public_file, ": cannot replace: ", why, " (", f.secret_file, " was replaced: run again with --force)");
  }
  return Ok{};
}

Result<std::string> expand_credentials_path(const std::string& path) {
  const std::string var = "$CREDENTIALS_DIRECTORY";
  if (path.rfind(var, 0) != 0) return path;
  const char* dir = std::getenv("CREDENTIALS_DIRECTORY");
  if (!dir) return fail(path, ": $CREDENTIALS_DIRECTORY is not set (use LoadCredential= in the unit)");
  return dir + path.substr(var.size());
}

Result<std::string> read_secret_key(const std::string& path) {
  return read_key_line(path, "CURVE secret key file", true);
}

Result<std::string> read_public_key(const std::string& path) {
  if (ends_with(path, ".key"))
    return fail(path,
                ": expected a public key file (PREFIX.pub), not a secret key file (PREFIX.key): "
                "secret keys never leave their owner");
  return read_key_line(path, "CURVE public key file", false);
}

Result<CurveKeyPair> read_key_pair(const std::string& prefix) {
  const KeyFiles f = key_files(prefix);
  Result<std::string> sec = read_secret_key(f.secret_file);
  if (!sec) return Error{sec.error()};
  Result<std::string> derived = curve_public_of(sec.value());
  if (!derived) return fail(f.secret_file, ": ", derived.error());
  Result<std::string> pub_path = expand_credentials_path(f.public_file);
  if (!pub_path) return Error{pub_path.error()};
  struct stat st {};
  if (::stat(pub_path.value().c_str(), &st) == 0) {
    Result<std::string> pub = read_public_key(f.public_file);
    if (!pub) return Error{pub.error()};
    if (pub.value() != derived.value())
      return fail(f.public_file, ": does not match ", f.secret_file, " (its public key is ", derived.value(),
                  "); the two files are not one pair");
  }
  return CurveKeyPair{derived.value(), sec.value()};
}

}  // namespace st::net
