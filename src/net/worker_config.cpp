// Worker daemon configuration (worker_config.hpp).
#include "net/worker_config.hpp"

#include <filesystem>
#include <fstream>
#include <sstream>
#include <toml++/toml.h>

#include <cctype>
#include <cstdlib>

#include "net/worker_service.hpp"

namespace st::net {

namespace {

std::string where(const std::string& source, const toml::node& n) {
  return source + ":" + std::to_string(n.source().begin.line);
}

template <class T>
Status get_int(const toml::node& n, const std::string& key, const std::string& source, T lo, T hi, T& out) {
  auto v = n.value<std::int64_t>();
  if (!n.is_integer() || !v) return fail(where(source, n), ": ", key, ": expected an integer");
  if (*v < static_cast<std::int64_t>(lo) || *v > static_cast<std::int64_t>(hi))
    return fail(where(source, n), ": ", key, ": ", *v, " outside [", lo, ", ", hi, "]");
  out = static_cast<T>(*v);
  return Ok{};
}

Status get_string(const toml::node& n, const std::string& key, const std::string& source, std::string& out) {
  if (!n.is_string()) return fail(where(source, n), ": ", key, ": expected a string");
  out = *n.value<std::string>();
  return Ok{};
}

}  // namespace

Result<DaemonConfig> parse_daemon_config(std::string_view text, const std::string& source, DaemonConfig c) {
  toml::table t;
  try {
    t = toml::parse(text, source);
  } catch (const toml::parse_error& e) {
    return fail(source, ":", e.source().begin.line, ":", e.source().begin.column, ": ", e.description());
  }
  for (auto&& [k, node] : t) {
    const std::string key(k.str());
    Status s = Ok{};
    if (key == "bind")
      s = get_string(node, key, source, c.bind);
    else if (key == "worker_id")
      s = get_int<std::uint32_t>(node, key, source, 0, 1u << 20, c.worker_id);
    else if (key == "log_level")
      s = get_string(node, key, source, c.log_level);
    else if (key == "max_sets")
      s = get_int<std::uint32_t>(node, key, source, 1, 64, c.max_sets);
    else if (key == "idle_set_s")
      s = get_int<std::uint32_t>(node, key, source, 0, 86400, c.idle_set_s);
    else if (key == "max_blockset_mb")
      s = get_int<std::uint64_t>(node, key, source, 1, 1u << 20, c.max_blockset_mb);
    else if (key == "ipc_allowed_uids") {
      const toml::array* a = node.as_array();
      if (!a) return fail(where(source, node), ": ipc_allowed_uids: expected an array of user ids");
      c.ipc_allowed_uids.clear();
      for (const toml::node& u : *a) {
        std::uint32_t uid = 0;
        if (Status su = get_int<std::uint32_t>(u, "ipc_allowed_uids", source, 0, 0x7fffffffu, uid); !su)
          return Error{su.error()};
        c.ipc_allowed_uids.push_back(uid);
      }
    } else if (key == "insecure") {
      if (!node.is_boolean()) return fail(where(source, node), ": insecure: expected true or false");
      c.insecure = *node.value<bool>();
    } else if (key == "curve") {
      const toml::table* ct = node.as_table();
      if (!ct) return fail(where(source, node), ": curve: expected a table [curve]");
      for (auto&& [ck, cn] : *ct) {
        const std::string ckey = "curve." + std::string(ck.str());
        if (ckey == "curve.secret_key_file")
          s = get_string(cn, ckey, source, c.curve_secret_key_file);
        else if (ckey == "curve.allowed_clients") {
          const toml::array* a = cn.as_array();
          if (!a) return fail(where(source, cn), ": ", ckey, ": expected an array of Z85 public keys");
          c.curve_allowed_clients.clear();
          for (const toml::node& e : *a) {
            if (!e.is_string() || e.value<std::string>()->size() != 40)
              return fail(where(source, e), ": ", ckey, ": expected 40-character Z85 public keys");
            c.curve_allowed_clients.push_back(*e.value<std::string>());
          }
        } else if (ckey == "curve.allowed_clients_files") {
          const toml::array* a = cn.as_array();
          if (!a) return fail(where(source, cn), ": ", ckey, ": expected an array of public key file paths");
          c.curve_allowed_clients_files.clear();
          for (const toml::node& e : *a) {
            if (!e.is_string() || e.value<std::string>()->empty())
              return fail(where(source, e), ": ", ckey, ": expected public key file paths (PREFIX.pub)");
            c.curve_allowed_clients_files.push_back(*e.value<std::string>());
          }
        } else
          return fail(where(source, cn), ": unknown key '", ckey,
                      "' (known: secret_key_file, allowed_clients, allowed_clients_files)");
        if (!s) return Error{s.error()};
      }
    } else {
      return fail(where(source, node), ": unknown key '", key,
                  "' (known: bind, worker_id, log_level, insecure, max_sets, idle_set_s, max_blockset_mb, "
                  "ipc_allowed_uids, [curve])");
    }
    if (!s) return Error{s.error()};
  }
  return c;
}

Result<DaemonConfig> load_daemon_config(const std::string& path, DaemonConfig base) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return fail(path, ": cannot open");
  std::ostringstream ss;
  ss << in.rdbuf();
  Result<DaemonConfig> c = parse_daemon_config(ss.str(), path, std::move(base));
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
