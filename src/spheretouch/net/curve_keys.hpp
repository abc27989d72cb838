// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// CURVE key files (CurveZMQ, RFC 26): a key pair is PREFIX.key, the Z85 secret key on one line
/// (mode 0600), and PREFIX.pub, the Z85 public key on one line. The one implementation of making,
/// writing and reading them: `spheretouch keygen`, `spheretouch-worker --keygen`, the worker's
/// [curve] config and the app's client keys all go through here.
#pragma once
#include <spheretouch/abi.hpp>
#include <string>

#include <spheretouch/geom/result.hpp>

namespace st::inline SPHERETOUCH_ABI::net {

/// Overwrites a string's characters with zeros (sodium_memzero: not optimised away) and empties
/// it; for every copy of a secret key once it has been handed to libzmq. Copies made by earlier
/// reallocations are out of reach: code that holds a secret does not grow the string.
void wipe_secret(std::string& s);

/// A CURVE key pair, Z85 (40 characters each). The secret is wiped when the pair is destroyed.
struct CurveKeyPair {
  std::string public_z85;  ///< handed out: workers' allow-lists, the clients' server_key
  std::string secret_z85;  ///< stays in its owner's PREFIX.key
  ~CurveKeyPair() { wipe_secret(secret_z85); }
};

/// The two files of a key pair.
struct KeyFiles {
  std::string secret_file;  ///< PREFIX.key
  std::string public_file;  ///< PREFIX.pub
};

/// Checks a Z85 CURVE key (40 characters that decode to 32 bytes); the error names `what`.
Status check_z85_key(const std::string& z85, const std::string& what);
/// The public key of a Z85 secret key, Z85.
Result<std::string> curve_public_of(const std::string& secret_z85);
/// A new key pair from libzmq (libsodium's random source).
Result<CurveKeyPair> generate_curve_key_pair();

/// PREFIX.key and PREFIX.pub; a trailing ".key" or ".pub" on `prefix` is dropped first, so
/// "client", "client.key" and "client.pub" name the same pair.
KeyFiles key_files(const std::string& prefix);
/// Writes the pair: PREFIX.key created with O_CREAT|O_EXCL and mode 0600 (never readable by
/// others, whatever the umask) and PREFIX.pub with mode 0644. Existing files are refused unless
/// `force`; then each file is written to a new 0600 temporary beside it and renamed over the old
/// one, so the key ends 0600 even if the old file was not. Errors name the file.
Status write_key_pair(const std::string& prefix, const CurveKeyPair& keys, bool force);

/// Expands a leading "$CREDENTIALS_DIRECTORY" (systemd LoadCredential=) in a key file path.
Result<std::string> expand_credentials_path(const std::string& path);
/// Reads a Z85 secret key from the first line of `path` (credentials path expanded). Refuses
/// anything but a regular file, and files readable or writable by group or others (chmod 600).
Result<std::string> read_secret_key(const std::string& path);
/// Reads a Z85 public key from the first line of `path` (a PREFIX.pub). Refuses a path ending in
/// ".key": a secret key must never be handed out in place of a public one.
Result<std::string> read_public_key(const std::string& path);
/// Reads PREFIX.key (as read_secret_key) and, if it exists, PREFIX.pub, which must match the
/// public key derived from the secret one; without PREFIX.pub the public key is derived.
Result<CurveKeyPair> read_key_pair(const std::string& prefix);

}  // namespace st::net
