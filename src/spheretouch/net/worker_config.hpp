// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// Configuration of the spheretouch-worker daemon (TOML, `--config FILE`) and its bind policy:
/// safe by default — a worker binds loopback (or ipc://) unless told otherwise, and binding any
/// other address needs CURVE keys or an explicit `insecure = true` / `--insecure`.
#pragma once
#include <spheretouch/abi.hpp>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include <spheretouch/geom/result.hpp>
#include <spheretouch/net/curve_keys.hpp>

namespace st::inline SPHERETOUCH_ABI::net {

/// Everything a worker daemon is configured with; defaults are safe.
struct DaemonConfig {
  std::string bind = "tcp://127.0.0.1:5555";  ///< endpoint: tcp://HOST:PORT or ipc://PATH
  std::uint32_t worker_id = 0;                ///< reported in Hello and Result
  std::string log_level = "info";             ///< error, warning, info or debug
  bool insecure = false;                      ///< allow a non-loopback bind without CURVE
  std::uint32_t max_sets = 3;                 ///< block sets kept in memory (LRU)
  std::uint32_t idle_set_s = 30;              ///< drop a set not queried for this long (0 = never; not the newest)
  /// Largest block set accepted, MiB (memory bound: about 6.5x this for the build, 6x per held
  /// set; 256 MiB is ~9 M faces and fits the unit's MemoryMax=8G with the other defaults).
  std::uint64_t max_blockset_mb = 256;
  std::uint32_t max_sets_per_client = 0;  ///< block sets one client may hold (0: max_sets)
  std::uint64_t max_client_mb = 0;        ///< encoded MiB one client may hold (0: max_sets x max_blockset_mb)
  /// Answer queries through the coherent collider (tree_backend_factory(): certificates carried
  /// between a client's rounds, the same pairs); false answers each from scratch.
  bool coherent = true;
  std::vector<std::uint32_t> ipc_allowed_uids;           ///< ipc://: users besides the worker's own that may connect
  std::string curve_secret_key_file;                     ///< [curve] secret_key_file (Z85), empty: no CURVE
  std::vector<std::string> curve_allowed_clients;        ///< [curve] allowed_clients (Z85 public keys)
  std::vector<std::string> curve_allowed_clients_files;  ///< [curve] allowed_clients_files (PREFIX.pub paths)
};

/// Default configuration (loopback, worker 0).
inline DaemonConfig DefaultDaemonConfig() { return DaemonConfig{}; }

/// Parses TOML text over `base`; unknown keys and wrong types are errors naming the key and line.
Result<DaemonConfig> parse_daemon_config(std::string_view text, const std::string& source, DaemonConfig base = {});
/// Reads and parses a config file; relative key file paths are taken relative to its directory.
Result<DaemonConfig> load_daemon_config(const std::string& path, DaemonConfig base = {});

/// True for tcp:// on 127.0.0.0/8, [::1] or localhost, and for ipc:// and inproc:// (not on a network).
/// An endpoint as libzmq takes it: in "tcp://localhost:PORT" libzmq's bind() reads "localhost"
/// as a network interface name ("No such device"), so it becomes 127.0.0.1; others are unchanged.
std::string zmq_endpoint(const std::string& endpoint);
/// True for a tcp endpoint with a bracketed IPv6 host ("tcp://[::1]:5550"): its socket needs
/// ZMQ_IPV6 set before bind() or connect().
bool needs_ipv6(const std::string& endpoint);
/// True for an endpoint only this host can reach: inproc://, ipc://, or tcp:// on a loopback address.
bool is_local_endpoint(const std::string& endpoint);
/// Refuses a non-local bind unless CURVE (secret key file and allowed clients) is configured or
/// `insecure` is set; checks log_level, the endpoint scheme and the client keys.
Status check_daemon_config(const DaemonConfig& c);
/// The admitted client public keys: allowed_clients, then the key of each allowed_clients_files
/// entry (read_public_key; errors name the file).
Result<std::vector<std::string>> allowed_client_keys(const DaemonConfig& c);

/// Syslog priority of a log level name (3 error, 4 warning, 6 info, 7 debug), or -1.
int log_priority(const std::string& level);

}  // namespace st::net
