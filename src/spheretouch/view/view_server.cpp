// SPDX-License-Identifier: BSD-3-Clause
// ViewServer: see view_server.hpp.
#include <spheretouch/view/view_server.hpp>

#include <civetweb.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string_view>

#include <spheretouch/engine/text.hpp>
#include <spheretouch/net/wire.hpp>
#include <spheretouch/rt/clock.hpp>

namespace st::inline SPHERETOUCH_ABI::view {

namespace assets {
extern const std::string_view view_html;
extern const std::string_view view_js;
}  // namespace assets

namespace {

constexpr std::size_t kMaxSnapshotBytes = 16u << 20;  // a PNG of a page's canvas
constexpr std::size_t kMaxTextBytes = 4096;           // a page's stats report

Result<std::string> slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return fail(path, ": cannot read (install Debian's libjs-three)");
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

const char* reason_of(int code) {
  switch (code) {
    case 200:
      return "OK";
    case 403:
      return "Forbidden";
    case 503:
      return "Service Unavailable";
    default:
      return "Not Found";
  }
}

int send_text(mg_connection* conn, int code, const char* type, std::string_view body) {
  mg_printf(conn,
            "HTTP/1.1 %d %s\r\nContent-Type: %s\r\nContent-Length: %zu\r\nCache-Control: no-store\r\n"
            "X-Content-Type-Options: nosniff\r\nConnection: close\r\n\r\n",
            code, reason_of(code), type, body.size());
  mg_write(conn, body.data(), body.size());
  return code;
}

/// The host part of a Host header or an Origin's authority ("[::1]:8080" -> "[::1]", "a:80" -> "a").
std::string host_part(std::string_view authority) {
  if (!authority.empty() && authority.front() == '[') return std::string(authority.substr(0, authority.find(']') + 1));
  return std::string(authority.substr(0, authority.find(':')));
}

/// An IP literal or "localhost": what a browser sends for this machine; a DNS name is what a
/// rebinding attack sends (the attacker's name, now resolving to us).
bool is_address_or_localhost(const std::string& host) {
  if (host == "localhost") return true;
  if (host.size() > 2 && host.front() == '[' && host.back() == ']')
    return host.find_first_not_of("0123456789abcdefABCDEF:.", 1) == host.size() - 1;
  if (host.empty() || host.find_first_not_of("0123456789.") != std::string::npos) return false;
  int dots = 0;
  for (char c : host) dots += c == '.';
  return dots == 3;
}

/// Equal in time independent of where they differ (the token).
bool same_secret(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  unsigned char d = 0;
  for (std::size_t i = 0; i < a.size(); ++i) d |= static_cast<unsigned char>(a[i] ^ b[i]);
  return d == 0;
}

// C trampolines.
int on_request(mg_connection* c, void* self) { return static_cast<ViewServer*>(self)->serve(c); }
int on_ws_connect(const mg_connection* c, void* self) { return static_cast<ViewServer*>(self)->admit(c); }
void on_ws_ready(mg_connection* c, void* self) { static_cast<ViewServer*>(self)->ready(c); }
int on_ws_data(mg_connection* c, int bits, char* data, std::size_t len, void* self) {
  return static_cast<ViewServer*>(self)->data(c, bits, data, len);
}
void on_ws_close(const mg_connection* c, void* self) { static_cast<ViewServer*>(self)->closed(c); }
int on_log(const mg_connection*, const char*) { return 1; }  // civetweb's own log lines: not on our terminal

}  // namespace

std::string check_listen(const std::string& listen) {
  const auto colon = listen.rfind(':');
  if (colon == std::string::npos || colon == 0 || colon + 1 == listen.size() || colon + 6 < listen.size() ||
      listen.find_first_not_of("0123456789", colon + 1) != std::string::npos || std::stoi(listen.substr(colon + 1)) > 65535)
    return "--view: '" + listen + "': expected ADDR:PORT (e.g. 127.0.0.1:8080)";
  return "";
}

Result<std::unique_ptr<ViewServer>> ViewServer::start(const ViewServerConfig& c, const geom::Mesh& probe,
                                                      const geom::Mesh& object, const rt::SeqLock<rt::ViewFrame>& frames,
                                                      const rt::ShmStatus& status, rt::PoseFeedDevice* device) {
  if (const std::string bad = check_listen(c.listen); !bad.empty()) return fail(bad);
  const auto colon = c.listen.rfind(':');
  if (!(c.rate_hz > 0 && c.rate_hz <= 240)) return fail("--view: rate must be in (0, 240] frames per second");
  if (c.max_pages < 1 || c.max_pages > 64) return fail("--view: max_pages must be in [1, 64]");
  std::unique_ptr<ViewServer> s(new ViewServer(c, probe, object, frames, status, device));
  Result<std::string> three = slurp(c.three_dir + "/three.min.js");
  if (!three) return Error{three.error()};
  Result<std::string> controls = slurp(c.three_dir + "/examples/js/controls/OrbitControls.js");
  if (!controls) return Error{controls.error()};
  s->three_js_ = std::move(three).value();
  s->controls_js_ = std::move(controls).value();

  // The meshes, once: local coordinates (f32 is exact enough near each body's origin) and origins.
  if (!c.objects.empty() && c.objects.front().mesh != &object)
    return fail("view: ViewServerConfig::objects must start with the object given to start()");
  const geom::Pose place0 = c.objects.empty() ? geom::Pose::Identity() : c.objects.front().placement;
  const geom::Vec3 scene_origin = place0 * object.origin;  // the page draws world minus this
  net::Writer m(s->mesh_msg_);
  m.raw("STVM", 4);
  m.u32(2);
  for (int i = 0; i < 3; ++i) m.f64(scene_origin[i]);
  for (int i = 0; i < 3; ++i) m.f64(probe.origin[i]);
  m.u32(std::uint32_t(probe.local.size()));
  m.u32(std::uint32_t(probe.faces.size()));
  m.u32(std::uint32_t(object.local.size()));
  m.u32(std::uint32_t(object.faces.size()));
  for (const geom::Mesh* b : {&probe, &object}) {
    for (const geom::Vec3& v : b->local)
      for (int i = 0; i < 3; ++i) {
        const float f = float(v[i]);
        m.raw(&f, 4);
      }
    for (const geom::Tri& t : b->faces)
      for (std::uint32_t v : t) m.u32(v);
  }
  // Version 2: the first object's rotation, then every other object placed in the page's frame.
  for (int r = 0; r < 3; ++r)
    for (int k = 0; k < 3; ++k) m.f64(place0.linear()(r, k));
  m.u32(c.objects.empty() ? 0u : std::uint32_t(c.objects.size() - 1));
  for (std::size_t i = 1; i < c.objects.size(); ++i) {
    const geom::Mesh& b = *c.objects[i].mesh;
    const geom::Pose& p = c.objects[i].placement;
    const geom::Vec3 t = p * b.origin - scene_origin;  // its local coordinates → the page's frame
    for (int r = 0; r < 3; ++r) {
      for (int k = 0; k < 3; ++k) m.f64(p.linear()(r, k));
      m.f64(t[r]);
    }
    m.u32(std::uint32_t(b.local.size()));
    m.u32(std::uint32_t(b.faces.size()));
    for (const geom::Vec3& v : b.local)
      for (int k = 0; k < 3; ++k) {
        const float f = float(v[k]);
        m.raw(&f, 4);
      }
    for (const geom::Tri& tri : b.faces)
      for (std::uint32_t v : tri) m.u32(v);
  }

  if (s->config_.token.empty()) s->config_.token = engine::random_hex(16);
  mg_init_library(0);
  s->library_ = true;
  const std::string port_opt = c.listen;
  // A WebSocket holds one of civetweb's threads while it is open: max_pages of them, and four for
  // plain requests (the page, its scripts, a refused page's 503). A request or a write that
  // stalls for 3 s fails; a page that sends nothing for 10 s (the page reports every second) closes.
  const std::string threads = std::to_string(c.max_pages + 4);
  const char* options[] = {"listening_ports",
                           port_opt.c_str(),
                           "num_threads",
                           threads.c_str(),
                           "enable_keep_alive",
                           "no",
                           "request_timeout_ms",
                           "3000",
                           "websocket_timeout_ms",
                           "10000",
                           nullptr};
  mg_callbacks cb{};
  cb.log_message = on_log;
  s->ctx_ = mg_start(&cb, s.get(), options);
  if (!s->ctx_) return fail("--view: cannot listen on ", c.listen, " (in use, or not an address of this machine)");
  mg_set_request_handler(s->ctx_, "/", on_request, s.get());
  mg_set_websocket_handler(s->ctx_, "/ws", on_ws_connect, on_ws_ready, on_ws_data, on_ws_close, s.get());
  mg_server_port ports[4];
  const int n = mg_get_server_ports(s->ctx_, 4, ports);
  const int port = n > 0 ? ports[0].port : 0;
  s->url_ = "http://" + c.listen.substr(0, colon) + ":" + std::to_string(port) + "/?t=" + s->config_.token;
  s->pusher_ = std::thread([p = s.get()] { p->push(); });
  return s;
}

ViewServer::ViewServer(const ViewServerConfig& c, const geom::Mesh& probe, const geom::Mesh& object,
                       const rt::SeqLock<rt::ViewFrame>& frames, const rt::ShmStatus& status, rt::PoseFeedDevice* device)
    : config_(c), probe_(probe), object_(object), frames_(frames), status_(status), device_(device) {}

/// A page: its connection, its sender thread and a mailbox of one frame (the newest).
struct ViewServer::Page {
  mg_connection* conn = nullptr;
  std::mutex mu;
  std::condition_variable cv;
  std::shared_ptr<const std::vector<std::uint8_t>> next;  // the newest frame not yet written
  bool closing = false;                                   // the connection is closing: stop
  bool dead = false;                                      // a write failed: no more frames
  std::thread sender;
};

ViewServer::~ViewServer() {
  stop_.store(true);
  if (pusher_.joinable()) pusher_.join();
  if (ctx_) mg_stop(ctx_);  // closes every connection (close handlers run, senders joined) and joins civetweb's threads
  if (library_) mg_exit_library();
}

std::string ViewServer::refuse_why(const mg_connection* conn, bool websocket) const {
  const char* host = mg_get_header(conn, "Host");
  if (!host || !is_address_or_localhost(host_part(host)))
    return "the Host header must name this machine by address or as localhost";
  if (!websocket) return "";
  const mg_request_info* ri = mg_get_request_info(conn);
  std::string_view query = ri && ri->query_string ? ri->query_string : "";
  std::string_view token;
  for (std::size_t at = 0; at <= query.size();) {
    const std::size_t end = std::min(query.find('&', at), query.size());
    if (query.substr(at, 2) == "t=") token = query.substr(at + 2, end - at - 2);
    at = end + 1;
  }
  if (!same_secret(token, config_.token)) return "no or a wrong token (open the URL the run printed)";
  // A browser names the page that opens the socket: it must be this server's own page.
  if (const char* origin = mg_get_header(conn, "Origin")) {
    const std::string_view o = origin;
    if (o.substr(0, 7) != "http://" || o.substr(7) != std::string_view(host))
      return "a page of another origin may not open the view's socket";
  }
  return "";
}

int ViewServer::admit(const mg_connection* conn) {
  auto* c = const_cast<mg_connection*>(conn);  // civetweb hands the handshake's connection as const
  if (const std::string why = refuse_why(conn, true); !why.empty()) {
    {
      std::lock_guard<std::mutex> l(mu_);
      ++stats_.forbidden;
    }
    send_text(c, 403, "text/plain", "forbidden: " + why + "\n");
    return 1;
  }
  std::lock_guard<std::mutex> l(mu_);
  const std::int64_t now = rt::now_ns();
  std::erase_if(admitted_, [now](const auto& a) { return now - a.second > 10'000'000'000; });
  admitted_.erase(conn);  // this thread's connection object, reused: not a page yet
  if (pages_.size() + admitted_.size() >= config_.max_pages) {
    ++stats_.busy;
    send_text(c, 503, "text/plain",
              "the live view already serves " + std::to_string(config_.max_pages) + " pages; close one and retry\n");
    return 1;
  }
  admitted_[conn] = now;
  return 0;
}

int ViewServer::serve(mg_connection* conn) {
  if (const std::string why = refuse_why(conn, false); !why.empty()) {
    {
      std::lock_guard<std::mutex> l(mu_);
      ++stats_.forbidden;
    }
    return send_text(conn, 403, "text/plain", "forbidden: " + why + "\n");
  }
  const mg_request_info* ri = mg_get_request_info(conn);
  const std::string uri = ri && ri->local_uri ? ri->local_uri : "";
  if (uri == "/" || uri == "/index.html") return send_text(conn, 200, "text/html; charset=utf-8", assets::view_html);
  if (uri == "/view.js") return send_text(conn, 200, "text/javascript; charset=utf-8", assets::view_js);
  if (uri == "/three.min.js") return send_text(conn, 200, "text/javascript; charset=utf-8", three_js_);
  if (uri == "/OrbitControls.js") return send_text(conn, 200, "text/javascript; charset=utf-8", controls_js_);
  return send_text(conn, 404, "text/plain", "not found\n");
}

void ViewServer::ready(mg_connection* conn) {
  mg_lock_connection(conn);
  int w = mg_websocket_write(conn, MG_WEBSOCKET_OPCODE_BINARY, reinterpret_cast<const char*>(mesh_msg_.data()),
                             mesh_msg_.size());
  if (w > 0 && device_) {  // the page is the device: where its tip starts
    char text[256];
    const Eigen::Vector3d h = device_->home() + object_.origin;
    const int n =
        std::snprintf(text, sizeof text, "{\"device\": \"browser\", \"home\": [%.9g, %.9g, %.9g]}", h.x(), h.y(), h.z());
    w = mg_websocket_write(conn, MG_WEBSOCKET_OPCODE_TEXT, text, std::size_t(n));
  }
  mg_unlock_connection(conn);
  std::lock_guard<std::mutex> l(mu_);
  admitted_.erase(conn);
  ++stats_.clients;
  if (w > 0) {
    stats_.bytes += mesh_msg_.size();
    auto page = std::make_unique<Page>();
    page->conn = conn;
    Page* p = page.get();
    p->sender = std::thread([this, p] { send_loop(p); });
    pages_.push_back(std::move(page));
  }
}

void ViewServer::send_loop(Page* p) {
  for (;;) {
    std::shared_ptr<const std::vector<std::uint8_t>> msg;
    {
      std::unique_lock<std::mutex> l(p->mu);
      p->cv.wait(l, [p] { return p->closing || (p->next && !p->dead); });
      if (p->closing) return;
      msg.swap(p->next);
    }
    // Only this thread writes frames to this page, and under no lock of the server's: a page
    // that stops reading blocks here (until the write times out), no one else.
    mg_lock_connection(p->conn);
    const int n =
        mg_websocket_write(p->conn, MG_WEBSOCKET_OPCODE_BINARY, reinterpret_cast<const char*>(msg->data()), msg->size());
    mg_unlock_connection(p->conn);
    std::lock_guard<std::mutex> l(mu_);
    if (n > 0) {
      ++stats_.frames;
      stats_.bytes += msg->size();
    } else {
      ++stats_.write_failures;
      std::lock_guard<std::mutex> pl(p->mu);
      p->dead = true;
    }
  }
}

void ViewServer::note_bad(const std::string& why) {
  std::lock_guard<std::mutex> l(mu_);
  if (stats_.bad_messages++ == 0)
    std::fprintf(stderr, "view: a page sent a bad message (%s); further ones are counted\n", why.c_str());
}

void ViewServer::note_bad_frame(const char* why) {
  std::lock_guard<std::mutex> l(mu_);
  if (stats_.bad_frames++ == 0)
    std::fprintf(stderr, "view: a frame failed its checks (%s): not sent; further ones are counted\n", why);
}

int ViewServer::data(mg_connection* conn, int bits, const char* data, std::size_t len) {
  const int opcode = bits & 0x0f;
  if (opcode == MG_WEBSOCKET_OPCODE_CONNECTION_CLOSE) return 0;
  if (opcode == MG_WEBSOCKET_OPCODE_PING || opcode == MG_WEBSOCKET_OPCODE_PONG) return 1;
  // A message may come in fragments (browsers split large ones, e.g. a snapshot, at 128 KiB):
  // collect them per page, bounded, and handle the whole message.
  const bool fin = (bits & 0x80) != 0;
  if (opcode == MG_WEBSOCKET_OPCODE_CONTINUATION || !fin) {
    std::string whole;
    int whole_opcode = 0;
    const char* bad = nullptr;
    {
      std::lock_guard<std::mutex> l(mu_);
      Partial& p = partial_[conn];
      if (opcode != MG_WEBSOCKET_OPCODE_CONTINUATION) {
        p.opcode = opcode;
        p.data.clear();
      }
      if (p.opcode == 0) {
        bad = "a continuation frame without a first frame";
      } else if (p.data.size() + len > kMaxSnapshotBytes + 16) {
        bad = "a fragmented message over 16 MiB";
      } else {
        p.data.append(data, len);
        if (!fin) return 1;
        whole.swap(p.data);
        whole_opcode = p.opcode;
      }
      partial_.erase(conn);
    }
    if (bad) {
      note_bad(bad);
      return 1;
    }
    return handle(conn, whole_opcode, whole.data(), whole.size());
  }
  return handle(conn, opcode, data, len);
}

int ViewServer::handle(mg_connection* conn, int opcode, const char* data, std::size_t len) {
  if (opcode == MG_WEBSOCKET_OPCODE_TEXT) {
    // The page's report, a JSON object {"fps": F, "frames": N[, "seconds": S]} of numbers in
    // [0, 1e12); anything else (not JSON, another shape, a key inside a string) is refused.
    const nlohmann::json j = len > kMaxTextBytes
                                 ? nlohmann::json()
                                 : nlohmann::json::parse(data, data + len, nullptr, /*allow_exceptions=*/false);
    auto number = [&](const char* key, double& out) {
      if (!j.is_object() || !j.contains(key) || !j[key].is_number()) return false;
      out = j[key].get<double>();
      return std::isfinite(out) && out >= 0 && out < 1e12;
    };
    double fps = 0, frames = 0, seconds = 0;
    if (len > kMaxTextBytes || !number("fps", fps) || !number("frames", frames)) {
      note_bad(len > kMaxTextBytes ? "text message too long" : "expected {\"fps\": F, \"frames\": N}");
      return 1;
    }
    if (!number("seconds", seconds)) seconds = 0;
    std::lock_guard<std::mutex> l(mu_);
    stats_.page_fps = fps;
    stats_.page_frames = std::uint64_t(frames);
    stats_.page_seconds = seconds;
    ++stats_.page_reports;
    return 1;
  }
  if (opcode == MG_WEBSOCKET_OPCODE_BINARY && len >= 4 && std::memcmp(data, "STVP", 4) == 0) {
    if (!device_ || len != 64) {
      note_bad(device_ ? "a pose message is 64 bytes"
                       : "a pose, but this view drives no device (the run's device is not the browser, or this "
                         "is a monitor's read-only view)");
      return 1;
    }
    bool mine = false;
    {
      std::lock_guard<std::mutex> l(mu_);
      if (!driver_) driver_ = conn;  // the first page to send a pose drives
      mine = driver_ == conn;
    }
    if (!mine) {
      note_bad("another page is driving the device");
      return 1;
    }
    double v[7];
    std::memcpy(v, data + 8, sizeof v);
    const Eigen::Vector3d tip = Eigen::Vector3d(v[0], v[1], v[2]) - object_.origin;
    if (!device_->offer(tip, Eigen::Quaterniond(v[3], v[4], v[5], v[6]), rt::now_ns())) {
      note_bad("a pose with a NaN, infinite or out-of-range number, or a quaternion that is not unit");
      return 1;
    }
    std::lock_guard<std::mutex> l(mu_);
    ++stats_.poses;
    return 1;
  }
  if (opcode == MG_WEBSOCKET_OPCODE_BINARY) {
    static constexpr unsigned char kPng[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
    if (len < 12 || len > kMaxSnapshotBytes || std::memcmp(data, "STVS", 4) != 0 || std::memcmp(data + 4, kPng, 8) != 0) {
      note_bad("expected \"STVS\" and a PNG of at most 16 MiB");
      return 1;
    }
    if (config_.out_dir.empty()) return 1;
    const std::string path = config_.out_dir + "/view.png";
    std::ofstream o(path + ".tmp", std::ios::binary);
    o.write(data + 4, std::streamsize(len - 4));
    o.close();
    if (o && std::rename((path + ".tmp").c_str(), path.c_str()) == 0) {
      std::lock_guard<std::mutex> l(mu_);
      ++stats_.snapshots;
    } else {
      std::remove((path + ".tmp").c_str());
      note_bad(path + ": cannot write the snapshot");
    }
    return 1;
  }
  note_bad("unexpected WebSocket opcode");
  return 1;
}

void ViewServer::closed(const mg_connection* conn) {
  std::unique_ptr<Page> page;
  {
    std::lock_guard<std::mutex> l(mu_);
    partial_.erase(conn);
    admitted_.erase(conn);
    if (driver_ == conn) driver_ = nullptr;  // another page may drive now
    const auto it = std::find_if(pages_.begin(), pages_.end(), [conn](const auto& p) { return p->conn == conn; });
    if (it == pages_.end()) return;
    page = std::move(*it);
    pages_.erase(it);
  }
  // The sender stops before civetweb frees the connection (a write in progress ends at its timeout).
  {
    std::lock_guard<std::mutex> l(page->mu);
    page->closing = true;
  }
  page->cv.notify_one();
  page->sender.join();
}

void ViewServer::push() {
  // The frame sent (the newest good one) and the one being read; 128 KiB each, not on the stack.
  auto frame = std::make_unique<rt::ViewFrame>(), next = std::make_unique<rt::ViewFrame>();
  frame->n_probe = frame->n_object = 0;
  // A scene of several objects lists every object's colliding faces, object k's offset by the
  // faces of the objects before it: ids below the faces of all of them.
  std::uint64_t all_faces = object_.faces.size();
  for (std::size_t k = 1; k < config_.objects.size(); ++k) all_faces += config_.objects[k].mesh->faces.size();
  const auto probe_faces = std::uint32_t(probe_.faces.size());
  const auto object_faces = std::uint32_t(std::min<std::uint64_t>(all_faces, UINT32_MAX));
  std::uint64_t seen = 0;  // the frames' SeqLock version last read
  const std::int64_t t0 = rt::now_ns();
  const auto period = std::chrono::nanoseconds(std::int64_t(1e9 / config_.rate_hz));
  auto next_at = std::chrono::steady_clock::now();
  while (!stop_.load(std::memory_order_relaxed)) {
    next_at += period;
    std::this_thread::sleep_until(next_at);
    if (std::chrono::steady_clock::now() - next_at > 4 * period) next_at = std::chrono::steady_clock::now();
    {
      std::lock_guard<std::mutex> l(mu_);
      if (pages_.empty()) continue;
    }
    // The newest frame if one came (a few tries: a writer that keeps the SeqLock busy costs this
    // thread little), checked; else the last good one again.
    if (const std::uint64_t v = frames_.version(); v != seen) {
      seen = v;
      const char* why = "";
      if (frames_.load(*next, 8)) {
        if (rt::sanitize_view_frame(*next, probe_faces, object_faces, &why))
          std::swap(frame, next);
        else
          note_bad_frame(why);
      }
    }
    rt::ServoStatus servo{};
    status_.servo.load(servo);
    rt::CollisionStatus col{};
    status_.collision.load(col);
    // "STVF" layout: 0 magic, 4 u32 flags, 8 u64 round, 16 f64 pose[12], 112 f64 force_dir[3],
    // 136 f64 contact_point[3], 160 f64 penetration_mm, 168 f64 round_ms, 176 f64 force_N[3]
    // (the servo's, this tick), 200 u64 servo ticks, 208 u64 misses, 216 u64 collision rounds,
    // 224 f64 seconds since the view started, 232 u32 contacts, 236 u32 n_probe, 240 u32 n_object,
    // 244 u32 reserved, 248 f64 torque_Nm[3] (the servo's, about the tool centre point), 272 u32
    // probe faces[n_probe], then u32 object faces[n_object].
    auto msg = std::make_shared<std::vector<std::uint8_t>>();  // built once, shared by every page's mailbox
    net::Writer w(*msg);
    w.raw("STVF", 4);
    w.u32(frame->flags);
    w.u64(frame->round);
    for (double v : frame->pose) w.f64(v);
    for (double v : frame->force_dir) w.f64(v);
    for (double v : frame->contact_point) w.f64(v);
    w.f64(frame->penetration_mm);
    w.f64(frame->round_ms);
    for (double v : servo.force_N) w.f64(std::isfinite(v) ? v : 0.0);
    w.u64(servo.ticks);
    w.u64(servo.misses);
    w.u64(col.rounds);
    w.f64(double(rt::now_ns() - t0) * 1e-9);
    w.u32(frame->contacts);
    w.u32(frame->n_probe);
    w.u32(frame->n_object);
    w.u32(0);
    for (double v : servo.torque_Nm) w.f64(std::isfinite(v) ? v : 0.0);
    w.raw(frame->faces, 4 * (std::size_t(frame->n_probe) + frame->n_object));
    // Into every page's mailbox; a frame its page has not taken yet is replaced (dropped).
    const std::shared_ptr<const std::vector<std::uint8_t>> frame_msg = std::move(msg);
    std::lock_guard<std::mutex> l(mu_);
    for (const auto& p : pages_) {
      {
        std::lock_guard<std::mutex> pl(p->mu);
        if (p->dead) continue;
        if (p->next) ++stats_.dropped;
        p->next = frame_msg;
      }
      p->cv.notify_one();
    }
  }
}

ViewStats ViewServer::stats() const {
  std::lock_guard<std::mutex> l(mu_);
  return stats_;
}

std::string ViewServer::summary() const {
  const ViewStats s = stats();
  char line[512];
  std::snprintf(line, sizeof line,
                "%s: %llu page(s), %llu frames sent (%.1f MB); page drew %.1f fps (last second; %llu frames in %.1f s, "
                "%.1f fps)%s%s",
                url_.c_str(), static_cast<unsigned long long>(s.clients), static_cast<unsigned long long>(s.frames),
                double(s.bytes) / 1e6, s.page_fps, static_cast<unsigned long long>(s.page_frames), s.page_seconds,
                s.page_seconds > 0 ? double(s.page_frames) / s.page_seconds : 0.0, s.snapshots ? ", snapshot view.png" : "",
                s.bad_messages ? (", " + std::to_string(s.bad_messages) + " bad messages refused").c_str() : "");
  std::string out = line;
  if (s.bad_frames) out += ", " + std::to_string(s.bad_frames) + " bad frames not sent";
  if (s.dropped || s.write_failures)
    out += ", " + std::to_string(s.dropped) + " frames dropped for slow pages, " + std::to_string(s.write_failures) +
           " writes failed";
  if (s.forbidden || s.busy)
    out += "; refused: " + std::to_string(s.forbidden) + " forbidden (Host, Origin or token), " +
           std::to_string(s.busy) + " over the page limit";
  if (device_) out += "; browser device: " + std::to_string(s.poses) + " poses taken";
  return out;
}

}  // namespace st::view
