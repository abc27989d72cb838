// SPDX-License-Identifier: BSD-3-Clause
// spheretouch-bench load MESH: time to load a mesh (median of N runs), e.g. the 832,000-face
// armadillo, loaded in under 2 s.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

#include "bench.hpp"
#include "bench_json.hpp"
#include <spheretouch/geom/mesh_io.hpp>

namespace st::bench {

void add_load(CLI::App& app) {
  struct Args {
    std::vector<std::string> paths;
    int runs = 5;
    bool json = false;
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand("load", "Median wall time to load each mesh (read, parse, validate, recentre)");
  cmd->add_option("meshes", a->paths, "mesh files")->required()->check(CLI::ExistingFile);
  cmd->add_option("--runs", a->runs, "loads per mesh")->check(CLI::Range(1, 100))->capture_default_str();
  cmd->add_flag("--json", a->json, "print one JSON object");
  cmd->callback([a] {
    Json out = {{"load", Json::array()}};
    for (std::size_t i = 0; i < a->paths.size(); ++i) {
      std::vector<double> s;
      std::size_t faces = 0;
      for (int r = 0; r < a->runs; ++r) {
        const auto t0 = std::chrono::steady_clock::now();
        Result<geom::LoadedMesh> m = geom::load_mesh(a->paths[i]);
        s.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
        if (!m) {
          std::fprintf(stderr, "%s\n", m.error().c_str());
          throw CLI::RuntimeError(2);
        }
        faces = m.value().mesh.num_faces();
      }
      std::sort(s.begin(), s.end());
      const double med = s[s.size() / 2], fastest = s.front();
      if (a->json)
        out["load"].push_back(
            {{"mesh", a->paths[i]}, {"faces", faces}, {"median_s", round_to(med, 4)}, {"min_s", round_to(fastest, 4)}});
      else
        std::printf("%-50s %9zu faces  median %.3f s  min %.3f s  (%d runs)\n", a->paths[i].c_str(), faces, med,
                    fastest, a->runs);
    }
    if (a->json) print_json(out);
  });
}

}  // namespace st::bench
