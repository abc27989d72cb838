// SPDX-License-Identifier: BSD-3-Clause
// A WebSocket client of the live view for the app suites (civetweb's client API): collects the
// binary messages ("STVM" meshes, "STVF" frames) a view sends, and reads their fields.
#pragma once
#include <arpa/inet.h>
#include <civetweb.h>
#include <doctest/doctest.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <mutex>
#include <string>
#include <vector>

#include "view_raw.hpp"

namespace st::test {

/// Binary messages received, in order (civetweb's client thread appends).
struct ViewMessages {
  std::mutex mu;
  std::vector<std::string> binary;
};

/// civetweb data handler: pass a ViewMessages* as the user data.
inline int view_on_data(mg_connection*, int bits, char* data, std::size_t len, void* user) {
  auto* m = static_cast<ViewMessages*>(user);
  if ((bits & 0x0f) == MG_WEBSOCKET_OPCODE_BINARY) {
    std::lock_guard<std::mutex> l(m->mu);
    m->binary.emplace_back(data, len);
  }
  return 1;
}

/// The token in the view URL a run or monitor printed to `log` ("view: http://ADDR:PORT/?t=TOKEN"); "" if none.
inline std::string view_token(const std::string& log) {
  const auto at = log.find("view: http://");
  if (at == std::string::npos) return "";
  const auto t = log.find("/?t=", at);
  if (t == std::string::npos) return "";
  const auto end = log.find_first_not_of("0123456789abcdef", t + 4);
  return log.substr(t + 4, end == std::string::npos ? std::string::npos : end - t - 4);
}

/// Connects to ws://127.0.0.1:port/ws?t=TOKEN collecting into `msgs`; null on failure (`err` says why).
inline mg_connection* view_connect(int port, ViewMessages& msgs, char (&err)[256], const std::string& token) {
  const std::string path = "/ws?t=" + token;
  return mg_connect_websocket_client("127.0.0.1", port, 0, err, sizeof err, path.c_str(), nullptr, view_on_data,
                                     nullptr, &msgs);
}

/// A little-endian field of a message.
template <class T>
T view_at(const std::string& s, std::size_t off) {
  T v;
  std::memcpy(&v, s.data() + off, sizeof v);
  return v;
}

/// The counts in a "STVM" message (the meshes), checked against its size.
struct ViewMeshCounts {
  std::uint32_t probe_vertices = 0, probe_faces = 0, object_vertices = 0, object_faces = 0;
  double rotation[9] = {};  ///< the first object's placement's rotation (version 2)
  /// The scene's other objects: placement in the page's frame (rows of [R | t]), vertices, faces.
  struct More {
    double place[12];
    std::uint32_t vertices, faces;
  };
  std::vector<More> more;
};
/// Parses an "STVM" message (version 2), checking its size against its counts.
inline ViewMeshCounts view_mesh_counts(const std::string& mesh) {
  REQUIRE(mesh.size() >= 72);
  CHECK(mesh.compare(0, 4, "STVM") == 0);
  CHECK(view_at<std::uint32_t>(mesh, 4) == 2);
  ViewMeshCounts c;
  c.probe_vertices = view_at<std::uint32_t>(mesh, 56);
  c.probe_faces = view_at<std::uint32_t>(mesh, 60);
  c.object_vertices = view_at<std::uint32_t>(mesh, 64);
  c.object_faces = view_at<std::uint32_t>(mesh, 68);
  std::size_t at = 72 + 12 * (std::size_t(c.probe_vertices) + c.probe_faces + c.object_vertices + c.object_faces);
  REQUIRE(mesh.size() >= at + 76);
  for (int i = 0; i < 9; ++i) c.rotation[i] = view_at<double>(mesh, at + 8 * std::size_t(i));
  at += 72;
  const std::uint32_t n = view_at<std::uint32_t>(mesh, at);
  at += 4;
  for (std::uint32_t k = 0; k < n; ++k) {
    REQUIRE(mesh.size() >= at + 104);
    ViewMeshCounts::More m{};
    for (int i = 0; i < 12; ++i) m.place[i] = view_at<double>(mesh, at + 8 * std::size_t(i));
    m.vertices = view_at<std::uint32_t>(mesh, at + 96);
    m.faces = view_at<std::uint32_t>(mesh, at + 100);
    at += 104 + 12 * (std::size_t(m.vertices) + m.faces);
    c.more.push_back(m);
  }
  CHECK(mesh.size() == at);
  return c;
}

/// What a stream of frames showed.
struct ViewFrameCounts {
  std::size_t frames = 0;      ///< "STVF" messages
  std::size_t with_faces = 0;  ///< of which listed colliding object faces
};

/// Checks every "STVF" message in `binary` from index `first` on against meshes of `probe_faces`
/// and `object_faces` faces: its size matches its face counts; face ids in range, object ids
/// distinct and ascending; a frame listing object faces is in contact and its contacts (paper
/// §3.5) are the faces it lists.
/// Where an "STVF" frame's face lists start (after the torque at 248).
inline constexpr std::size_t kFacesAt = 272;

inline ViewFrameCounts view_check_frames(const std::vector<std::string>& binary, std::size_t first,
                                         std::uint32_t probe_faces, std::uint32_t object_faces) {
  ViewFrameCounts c;
  for (std::size_t i = first; i < binary.size(); ++i) {
    const std::string& f = binary[i];
    REQUIRE(f.size() >= kFacesAt);
    REQUIRE(f.compare(0, 4, "STVF") == 0);
    ++c.frames;
    const std::uint32_t np = view_at<std::uint32_t>(f, 236), no = view_at<std::uint32_t>(f, 240);
    REQUIRE(f.size() == kFacesAt + 4 * std::size_t(np + no));
    for (int k = 0; k < 3; ++k) CHECK(std::isfinite(view_at<double>(f, 248 + 8 * k)));  // the torque
    const std::uint32_t flags = view_at<std::uint32_t>(f, 4);
    if (no > 0) {
      ++c.with_faces;
      CHECK((flags & 1) != 0);                           // in contact
      CHECK(view_at<std::uint32_t>(f, 232) == np + no);  // contacts = distinct colliding faces
    }
    for (std::uint32_t k = 0; k < np; ++k) CHECK(view_at<std::uint32_t>(f, kFacesAt + 4 * k) < probe_faces);
    for (std::uint32_t k = 1; k < no; ++k)
      CHECK(view_at<std::uint32_t>(f, kFacesAt + 4 * (np + k - 1)) < view_at<std::uint32_t>(f, kFacesAt + 4 * (np + k)));
    for (std::uint32_t k = 0; k < no; ++k) CHECK(view_at<std::uint32_t>(f, kFacesAt + 4 * (np + k)) < object_faces);
  }
  return c;
}

}  // namespace st::test
