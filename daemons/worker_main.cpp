// spheretouch-worker: the worker daemon (distribution issue). Minimal main for now.
#include <CLI/CLI.hpp>
#include <cstdio>

int main(int argc, char** argv) {
  CLI::App app{"spheretouch-worker: holds sphere blocks in memory and answers collision queries"};
  std::string bind = "tcp://127.0.0.1:5555";
  app.add_option("--bind", bind, "endpoint to bind (tcp://, ipc://)");
  CLI11_PARSE(app, argc, argv);
  std::fprintf(stderr, "spheretouch-worker: not implemented yet (bind %s)\n", bind.c_str());
  return 1;
}
