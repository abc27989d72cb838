// SPDX-License-Identifier: BSD-3-Clause
// Worker daemon configuration (worker_config.hpp).
#include <spheretouch/net/worker_config.hpp>
#include <spheretouch/geom/text_file.hpp>

#include <filesystem>
#include <fstream>
#include <sstream>

#include <cctype>
#include <cstdlib>

#include <spheretouch/config/toml_reader.hpp>
#include <spheretouch/net/worker_service.hpp>

namespace st::inline SPHERETOUCH_ABI::net {

Result<DaemonConfig> parse_daemon_config(std::string_view text, const std::string& source, DaemonConfig c) {
  Result<toml::table> parsed = config::parse_toml(text, source);
  if (!parsed) return Error{parsed.error()};
  const toml::table& t = parsed.value();
  config::TomlReader r(&t, "", source);
  r.string("bind", c.bind);
  r.integer("worker_id", c.worker_id, 0, 1 << 20);
  r.string("log_level", c.log_level);
  r.boolean("insecure", c.insecure);
  r.integer("max_sets", c.max_sets, 1, 64);
  r.integer("idle_set_s", c.idle_set_s, 0, 86400);
  r.integer("max_blockset_mb", c.max_blockset_mb, 1, 1 << 20);
  r.integer("max_sets_per_client", c.max_sets_per_client, 0, 64);
  r.integer("max_client_mb", c.max_client_mb, 0, 1 << 26);
  r.boolean("coherent", c.coherent);
  r.integers("ipc_allowed_uids", c.ipc_allowed_uids, 0, 0x7fffffff);
  const toml::table* curve = r.table("curve");
  if (Status s = r.finish(); !s) return Error{s.error()};

  config::TomlReader cr(curve, "curve", source);
  cr.string("secret_key_file", c.curve_secret_key_file);
  cr.strings("allowed_clients", c.curve_allowed_clients);
  for (const std::string& k : c.curve_allowed_clients)
    if (k.size() != 40) cr.error("allowed_clients", "expected 40-character Z85 public keys (found '" + k + "')");
  cr.strings("allowed_clients_files", c.curve_allowed_clients_files);
  for (const std::string& f : c.curve_allowed_clients_files)
    if (f.empty()) cr.error("allowed_clients_files", "expected public key file paths (PREFIX.pub), found ''");
  if (Status s = cr.finish(); !s) return Error{s.error()};
  return c;
}

Result<DaemonConfig> load_daemon_config(const std::string& path, DaemonConfig base) {
  // A config is a small text file: a FIFO or /dev/zero named here is refused, not read forever.
  Result<std::string> text = geom::read_text_file(path, 1u << 20, "worker config");
  if (!text) return Error{text.error()};
  Result<DaemonConfig> c = parse_daemon_config(text.value(), path, std::move(base));
  if (!c) return c;
  // Key files named relative to the config (not to whatever directory the daemon starts in).
  const std::filesystem::path dir = std::filesystem::path(path).parent_path();
  auto resolve = [&](std::string& f) {
    if (!f.empty() && f[0] != '$' && std::filesystem::path(f).is_relative()) f = (dir / f).string();
  };
  resolve(c.value().curve_secret_key_file);
  for (std::string& f : c.value().curve_allowed_clients_files) resolve(f);
  return c;
}

std::string zmq_endpoint(const std::string& ep) {
  const std::string prefix = "tcp://localhost:";
  if (ep.rfind(prefix, 0) == 0) return "tcp://127.0.0.1:" + ep.substr(prefix.size());
  return ep;
}

bool needs_ipv6(const std::string& ep) { return ep.rfind("tcp://[", 0) == 0; }

bool is_local_endpoint(const std::string& ep) {
  if (ep.rfind("ipc://", 0) == 0 || ep.rfind("inproc://", 0) == 0) return true;
  if (ep.rfind("tcp://", 0) != 0) return false;
  std::string host = ep.substr(6);
  if (host.find(';') != std::string::npos) return false;  // "src;dst" forms: refuse to guess
  const auto colon = host.rfind(':');
  if (colon == std::string::npos) return false;
  host = host.substr(0, colon);
  if (host == "localhost" || host == "[::1]") return true;
  // 127.0.0.0/8 in dotted-quad form only.
  unsigned a, b, cc, d;
  char tail;
  if (std::sscanf(host.c_str(), "%u.%u.%u.%u%c", &a, &b, &cc, &d, &tail) == 4)
    return a == 127 && b < 256 && cc < 256 && d < 256;
  return false;
}

Status check_daemon_config(const DaemonConfig& c) {
  if (log_priority(c.log_level) < 0)
    return fail("log_level: '", c.log_level, "' is not one of error, warning, info, debug");
  if (c.bind.rfind("tcp://", 0) != 0 && c.bind.rfind("ipc://", 0) != 0)
    return fail("bind: '", c.bind, "': expected tcp://HOST:PORT or ipc://PATH");
  const bool curve = !c.curve_secret_key_file.empty();
  const bool clients = !c.curve_allowed_clients.empty() || !c.curve_allowed_clients_files.empty();
  if (curve && !clients)
    return fail(
        "[curve]: secret_key_file is set but allowed_clients and allowed_clients_files are empty: "
        "no client could connect");
  if (!curve && clients) return fail("[curve]: allowed clients are set but secret_key_file is not");
  for (const std::string& k : c.curve_allowed_clients)
    if (Status s = check_z85_key(k, "[curve] allowed_clients: '" + k + "'"); !s) return s;
  if (!is_local_endpoint(c.bind) && !c.insecure && !curve)
    return fail("bind: '", c.bind,
                "' is not a loopback address; refusing to serve unauthenticated on a network. "
                "Configure [curve] keys, or pass --insecure (insecure = true) on a trusted network");
  return Ok{};
}

Result<std::vector<std::string>> allowed_client_keys(const DaemonConfig& c) {
  std::vector<std::string> keys = c.curve_allowed_clients;
  for (const std::string& f : c.curve_allowed_clients_files) {
    Result<std::string> k = read_public_key(f);
    if (!k) return fail("[curve] allowed_clients_files: ", k.error());
    keys.push_back(std::move(k).value());
  }
  return keys;
}

int log_priority(const std::string& level) {
  if (level == "error") return 3;
  if (level == "warning") return 4;
  if (level == "info") return 6;
  if (level == "debug") return 7;
  return -1;
}

}  // namespace st::net
