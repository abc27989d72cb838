// SPDX-License-Identifier: BSD-3-Clause
// Run outputs: see run_outputs.hpp.
#include <spheretouch/engine/run_outputs.hpp>

#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <spheretouch/geom/collide.hpp>

namespace st::inline SPHERETOUCH_ABI::engine {

Status write_contact_ply(const std::string& path, const geom::Mesh& probe, const geom::Mesh& object,
                         const geom::Pose& pose, const std::vector<geom::FacePair>& pairs) {
  std::vector<char> hit_o(object.num_faces(), 0), hit_p(probe.num_faces(), 0);
  for (const geom::FacePair& p : pairs) {
    if (p.object < hit_o.size()) hit_o[p.object] = 1;
    if (p.probe < hit_p.size()) hit_p[p.probe] = 1;
  }
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (!f) return fail(path, ": cannot create");
  const std::size_t nv = object.num_vertices() + probe.num_vertices(), nf = object.num_faces() + probe.num_faces();
  std::fprintf(f,
               "ply\nformat ascii 1.0\ncomment spheretouch contact state: object faces first, then the probe's; "
               "colliding faces red\nelement vertex %zu\nproperty double x\nproperty double y\nproperty double z\n"
               "element face %zu\nproperty list uchar int vertex_indices\nproperty uchar red\nproperty uchar green\n"
               "property uchar blue\nend_header\n",
               nv, nf);
  for (std::uint32_t i = 0; i < object.num_vertices(); ++i) {
    const geom::Vec3 v = object.vertex(i);
    std::fprintf(f, "%.17g %.17g %.17g\n", v.x(), v.y(), v.z());
  }
  for (std::uint32_t i = 0; i < probe.num_vertices(); ++i) {
    const geom::Vec3 v = pose * probe.vertex(i);
    std::fprintf(f, "%.17g %.17g %.17g\n", v.x(), v.y(), v.z());
  }
  for (std::uint32_t i = 0; i < object.num_faces(); ++i) {
    const geom::Tri& t = object.faces[i];
    std::fprintf(f, "3 %u %u %u %s\n", t[0], t[1], t[2], hit_o[i] ? "230 30 30" : "180 180 180");
  }
  const auto off = static_cast<std::uint32_t>(object.num_vertices());
  for (std::uint32_t i = 0; i < probe.num_faces(); ++i) {
    const geom::Tri& t = probe.faces[i];
    std::fprintf(f, "3 %u %u %u %s\n", t[0] + off, t[1] + off, t[2] + off, hit_p[i] ? "230 30 30" : "150 190 230");
  }
  const bool ok = std::ferror(f) == 0;
  if (std::fclose(f) != 0 || !ok) return fail(path, ": write error");
  return Ok{};
}

namespace {

/// Reads the comma-separated numbers of one CSV line into `v`; false for headers and comments.
bool csv_numbers(const std::string& line, std::vector<double>& v) {
  if (line.empty() || !std::isdigit(static_cast<unsigned char>(line[0]))) return false;
  v.clear();
  const char* p = line.data();
  const char* end = p + line.size();
  while (p < end) {
    double d = 0;
    auto r = std::from_chars(p, end, d);
    if (r.ec != std::errc()) break;
    v.push_back(d);
    p = r.ptr + (r.ptr < end ? 1 : 0);
  }
  return true;
}

}  // namespace

Status write_trace_json(const std::string& path, const std::string& tick_csv, const std::string& rounds_csv) {
  // Only regular files are read back: a trace that is a device (/dev/full, /dev/zero) would be
  // read without end.
  for (const std::string* p : {&tick_csv, &rounds_csv}) {
    std::error_code ec;
    if (!std::filesystem::is_regular_file(*p, ec)) return fail(*p, ": not a regular file: trace.json not written");
  }
  std::ifstream in(tick_csv);
  if (!in) return fail(tick_csv, ": cannot read the per-tick trace");
  std::ifstream rin(rounds_csv);
  if (!rin) return fail(rounds_csv, ": cannot read the per-round trace");
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (!f) return fail(path, ": cannot create");
  std::fprintf(f, "{\"displayTimeUnit\":\"ms\",\"traceEvents\":[\n");
  std::fprintf(f, "{\"name\":\"process_name\",\"ph\":\"M\",\"pid\":1,\"args\":{\"name\":\"spheretouch run\"}},\n");
  std::fprintf(f,
               "{\"name\":\"thread_name\",\"ph\":\"M\",\"pid\":1,\"tid\":1,\"args\":{\"name\":\"haptic 1 kHz\"}},\n");
  std::fprintf(f, "{\"name\":\"thread_name\",\"ph\":\"M\",\"pid\":1,\"tid\":2,\"args\":{\"name\":\"collision\"}}");
  // Timestamps are CLOCK_MONOTONIC in microseconds, shared by both threads' events.
  auto us = [](double ns) { return ns / 1000.0; };
  std::string line;
  std::vector<double> v;
  while (std::getline(in, line)) {
    if (!csv_numbers(line, v) || v.size() < 17) continue;
    const double force = std::sqrt(v[9] * v[9] + v[10] * v[10] + v[11] * v[11]);
    std::fprintf(f,
                 ",\n{\"name\":\"tick\",\"ph\":\"X\",\"pid\":1,\"tid\":1,\"ts\":%.3f,\"dur\":1,"
                 "\"args\":{\"tick\":%.0f,\"latency_us\":%.3f,\"model\":%.0f,\"pd_mm\":%.4g}}",
                 us(v[1]), v[0], v[2] / 1000.0, v[4], v[12]);
    std::fprintf(f, ",\n{\"name\":\"force_N\",\"ph\":\"C\",\"pid\":1,\"ts\":%.3f,\"args\":{\"force\":%.5g}}", us(v[1]),
                 force);
  }
  // rounds.csv: start_ns,end_ns,pose_seq,pairs,contacts,pd_mm,complete
  while (std::getline(rin, line)) {
    if (!csv_numbers(line, v) || v.size() < 7) continue;
    std::fprintf(f,
                 ",\n{\"name\":\"round\",\"ph\":\"X\",\"pid\":1,\"tid\":2,\"ts\":%.3f,\"dur\":%.3f,"
                 "\"args\":{\"pose\":%.0f,\"pairs\":%.0f,\"contacts\":%.0f,\"pd_mm\":%.4g,\"complete\":%s}}",
                 us(v[0]), us(v[1] - v[0]), v[2], v[3], v[4], v[5], v[6] != 0 ? "true" : "false");
  }
  std::fprintf(f, "\n]}\n");
  const bool ok = std::ferror(f) == 0;
  if (std::fclose(f) != 0 || !ok) return fail(path, ": write error");
  return Ok{};
}

}  // namespace st::engine
