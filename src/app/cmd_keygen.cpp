// SPDX-License-Identifier: BSD-3-Clause
// spheretouch keygen --out PREFIX [--force]: a CURVE key pair for a worker fleet or a client:
// PREFIX.key (the Z85 secret key, one line, mode 0600) and PREFIX.pub (the Z85 public key, one
// line). The workers' .key goes in their [curve] secret_key_file, their .pub to every client
// (server_key); a client's .pub goes in the workers' allow-list (docs/user-guide/security.md, "Securing a fleet").
// spheretouch keygen --bridge --out FILE [--force]: a UDP device bridge key (32 random bytes as
// 64 hex digits, mode 0600) for [device] key_file and the driver (docs/user-guide/devices.md).
#include <cstdio>

#include "app/commands.hpp"
#include <spheretouch/net/curve_keys.hpp>
#include <spheretouch/rt/udp_device.hpp>

namespace st::app {

void add_keygen(CLI::App& app) {
  struct Args {
    std::string out;
    bool force = false;
    bool bridge = false;
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "keygen",
      "Make a CURVE key pair: PREFIX.key (secret, mode 0600, created so that no one else can ever read it)\n"
      "and PREFIX.pub (public). Workers use theirs in [curve] secret_key_file; clients give theirs with\n"
      "--client-key PREFIX (or [workers] client_key) and list the workers' PREFIX.pub as server_key.\n"
      "With --bridge: a key for the UDP device bridge instead, in the file --out names (mode 0600),\n"
      "for the scene's [device] key_file and the driver program.");
  cmd->add_option("--out", a->out, "write PREFIX.key and PREFIX.pub (a trailing .key or .pub is dropped)")
      ->type_name("PREFIX")
      ->required();
  cmd->add_flag("--force", a->force, "replace an existing pair (the new PREFIX.key is still mode 0600)");
  cmd->add_flag("--bridge", a->bridge,
                "make a UDP device bridge key (HMAC-SHA256, 64 hex digits) in the file --out names");
  cmd->callback([a] {
    if (a->bridge) {
      Result<rt::BridgeKey> key = rt::random_bridge_key();
      if (!key) {
        std::fprintf(stderr, "spheretouch: %s\n", key.error().c_str());
        throw CLI::RuntimeError(1);
      }
      if (Status s = rt::write_bridge_key(a->out, key.value(), a->force); !s) {
        std::fprintf(stderr, "spheretouch: %s\n", s.error().c_str());
        throw CLI::RuntimeError(2);
      }
      std::printf("wrote %s (bridge key, mode 0600: give it to the scene's [device] key_file and the driver)\n",
                  a->out.c_str());
      return;
    }
    Result<net::CurveKeyPair> keys = net::generate_curve_key_pair();
    if (!keys) {
      std::fprintf(stderr, "spheretouch: %s\n", keys.error().c_str());
      throw CLI::RuntimeError(1);
    }
    if (Status s = net::write_key_pair(a->out, keys.value(), a->force); !s) {
      std::fprintf(stderr, "spheretouch: %s\n", s.error().c_str());
      throw CLI::RuntimeError(2);
    }
    const net::KeyFiles f = net::key_files(a->out);
    std::printf("wrote %s (secret key, mode 0600: keep it private)\nwrote %s (public key)\npublic key: %s\n",
                f.secret_file.c_str(), f.public_file.c_str(), keys.value().public_z85.c_str());
  });
}

}  // namespace st::app
