// SPDX-License-Identifier: BSD-3-Clause
// ViewServer: the live view of a run (spheretouch run --view, spheretouch monitor --view). An
// embedded HTTP/WebSocket server (civetweb) serves a page (web/view.html, web/view.js, three.js
// from Debian's libjs-three) that draws the object and the probe as shaded meshes, the colliding
// faces in red, the force as an arrow, the status figures and a plot of |F| over the last seconds.
//
// Data path: every run's collision thread stores a frame (rt::ViewFrame, at most 60 a second)
// into its shared-memory status area (ShmStatus::view, a SeqLock) next to the servo's and its
// own status. This server's thread reads the frames (a new one when the SeqLock's version moved)
// and the status and writes each frame to every connected page; neither real-time thread ever
// waits for it, and a slow page only slows its own connection. `run --view` hands it the run's
// own status area; `monitor --view` a process-local copy that its main thread refreshes from the
// read-only mapping (so only that thread, with its SIGBUS guard armed, touches the mapping).
// A frame is checked before it is sent (rt::sanitize_view_frame: counts within the frame, face
// ids within the meshes, numbers finite): one that fails is not sent and is counted.
//
// WebSocket /ws, binary messages, little-endian (web/view.js reads them):
//   server -> page, once: "STVM" u32 version (2), f64 scene origin[3], f64 probe origin[3],
//     u32 probe vertices, u32 probe faces, u32 object vertices, u32 object faces,
//     f32 probe local vertices (x y z), u32 probe faces (a b c), f32 object local vertices, u32 object faces,
//     then (version 2) f64 the object's rotation (3x3, rows), u32 more objects, and for each: f64 its
//     placement in the page's frame (rows of [R | t], 12), u32 vertices, u32 faces, f32 local
//     vertices, u32 faces. The page draws in world coordinates minus the scene origin (the first
//     object's placed origin: f32 stays exact near it); frames' poses and points are world
//     coordinates (a scene of one unplaced object: its file coordinates, as in version 1); a
//     frame's object faces are every object's, object k's ids offset by the faces of the objects
//     before it (in the order above: the first object, then the others).
//   server -> page, every frame: "STVF" (layout in view_server.cpp, write_frame)
//   page -> server: text {"fps": F, "frames": N, "seconds": S, "red": R} once a second; binary "STVS" + a PNG
//     of the canvas (saved as view.png in the run directory) when the page was opened with
//     ?snapshot=1 and it has drawn colliding faces.
// Who may connect: every request must name this machine in its Host header (an IP address or
// "localhost": a DNS name is what a DNS-rebinding page sends), and /ws needs the per-server
// random token the printed URL carries (?t=...) and, from a browser, an Origin of that same host
// (a page on another site cannot open it: cross-site WebSocket hijacking). Refusals are 403s,
// counted. At most max_pages pages at once (one more gets a 503); each page has its own sender
// thread with a one-frame mailbox, so a page that stops reading loses frames (counted) and slows
// no one: nothing is written under the server's lock, and a write that stalls for the request
// timeout (3 s) fails and that page gets no more frames. A page that sends nothing for 10 s
// (the real one reports every second) is closed.
//   With [device] kind = "browser": server -> page text {"device": "browser", "home": [x, y, z]}
//   after the meshes; page -> server binary "STVP" u32 0, f64 tip x y z (object file mm), f64 qw qx
//   qy qz, 64 bytes, at the page's frame rate; the first page to send one drives, others are refused.
#pragma once
#include <spheretouch/abi.hpp>
#include <atomic>
#include <cstdint>
#include <condition_variable>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <spheretouch/geom/mesh.hpp>
#include <spheretouch/geom/result.hpp>
#include <spheretouch/rt/pose_feed_device.hpp>
#include <spheretouch/rt/seqlock.hpp>
#include <spheretouch/rt/shm_status.hpp>
#include <spheretouch/rt/view_frame.hpp>

struct mg_context;
struct mg_connection;

namespace st::inline SPHERETOUCH_ABI::view {

/// A mesh placed in the world (a scene's object and its placement).
struct PlacedMesh {
  const geom::Mesh* mesh = nullptr;               ///< outlives the server
  geom::Pose placement = geom::Pose::Identity();  ///< its file coordinates → world
};

struct ViewServerConfig {
  std::string listen = "127.0.0.1:8080";                  ///< ADDR:PORT (port 0: any free port)
  double rate_hz = 60;                                    ///< frames per second sent to each page
  std::string three_dir = "/usr/share/javascript/three";  ///< Debian's libjs-three
  std::string out_dir;                                    ///< where snapshots go (view.png); "" = none
  std::size_t max_pages = 4;                              ///< pages at once; one more gets a 503
  std::string token;  ///< the WebSocket's token ("" = a random one per server: the URL carries it)
  /// A scene of several objects: every object with its placement, the first being start()'s
  /// `object` (empty: that object alone, unplaced).
  std::vector<PlacedMesh> objects;
};

struct ViewStats {
  std::uint64_t clients = 0;       ///< pages that connected
  std::uint64_t frames = 0;        ///< frames written (all pages)
  std::uint64_t bytes = 0;         ///< bytes written (all pages)
  double page_fps = 0;             ///< the last rate a page reported drawing at (its last second)
  std::uint64_t page_frames = 0;   ///< frames it had drawn by then
  double page_seconds = 0;         ///< over this many seconds since it loaded
  std::uint64_t page_reports = 0;  ///< reports received
  std::uint64_t snapshots = 0;     ///< view.png written
  std::uint64_t bad_messages = 0;  ///< messages from a page that were refused
  std::uint64_t bad_frames = 0;    ///< frames that failed their checks (rt::sanitize_view_frame), not sent
  std::uint64_t poses = 0;         ///< browser device: poses a page sent that were taken
  std::uint64_t forbidden = 0;  ///< requests refused (403): a Host that is not an address, a foreign Origin, no token
  std::uint64_t busy = 0;       ///< pages refused (503): max_pages already open
  std::uint64_t dropped = 0;    ///< frames a slow page never got (its next frame replaced it)
  std::uint64_t write_failures = 0;  ///< frame writes that failed or timed out (that page gets no more)
};

/// "" when `listen` has the ADDR:PORT form --view takes, else the error (checked before a run
/// loads anything; start() checks it again).
std::string check_listen(const std::string& listen);

class ViewServer {
 public:
  /// Starts serving. The meshes, frames and status must outlive the server; the frames' face ids
  /// refer to these meshes. `device` (may be null): the run's browser device, which the first
  /// page to send a pose drives (a monitor's view passes null: the run owns its device).
  static Result<std::unique_ptr<ViewServer>> start(const ViewServerConfig& config, const geom::Mesh& probe,
                                                   const geom::Mesh& object, const rt::SeqLock<rt::ViewFrame>& frames,
                                                   const rt::ShmStatus& status, rt::PoseFeedDevice* device = nullptr);
  ~ViewServer();
  ViewServer(const ViewServer&) = delete;
  ViewServer& operator=(const ViewServer&) = delete;
  std::string url() const {
    return url_;
  }  ///< http://ADDR:PORT/?t=TOKEN (the token is the key: share the URL with care)
  ViewStats stats() const;
  /// One line for the run's summary.
  std::string summary() const;

  // civetweb callbacks (public for the C trampolines).
  int serve(mg_connection* conn);
  int admit(const mg_connection* conn);  // the WebSocket handshake: 0 admits, else a 403/503 was sent
  void ready(mg_connection* conn);
  int data(mg_connection* conn, int bits, const char* data, std::size_t len);
  void closed(const mg_connection* conn);
  int handle(mg_connection* conn, int opcode, const char* data, std::size_t len);  // a whole message

 private:
  ViewServer(const ViewServerConfig& c, const geom::Mesh& probe, const geom::Mesh& object,
             const rt::SeqLock<rt::ViewFrame>& frames, const rt::ShmStatus& status, rt::PoseFeedDevice* device);
  struct Page;
  void push();              // the frame thread: builds each frame once, hands it to every page's mailbox
  void send_loop(Page* p);  // a page's sender thread
  /// "" when the request may be served, else why not (403).
  std::string refuse_why(const mg_connection* conn, bool websocket) const;
  void note_bad(const std::string& why);
  void note_bad_frame(const char* why);

  ViewServerConfig config_;
  const geom::Mesh& probe_;
  const geom::Mesh& object_;
  const rt::SeqLock<rt::ViewFrame>& frames_;
  const rt::ShmStatus& status_;
  rt::PoseFeedDevice* device_;             // the browser device, or null
  const mg_connection* driver_ = nullptr;  // the page driving it (under mu_)
  std::string url_;
  std::string three_js_, controls_js_;  // read once at start
  std::vector<std::uint8_t> mesh_msg_;  // the "STVM" message, built once
  mg_context* ctx_ = nullptr;
  bool library_ = false;   // mg_init_library called (mg_exit_library in the destructor)
  mutable std::mutex mu_;  // pages_, stats_, partial_, driver_ (never held while writing to a page)
  std::vector<std::unique_ptr<Page>> pages_;
  /// Connections admitted whose page is not listed yet (the meshes are being written), with when:
  /// they count toward max_pages. civetweb reuses a thread's connection object, and one whose
  /// handshake failed never closes: an entry older than 10 s is forgotten.
  std::map<const mg_connection*, std::int64_t> admitted_;
  struct Partial {
    int opcode = 0;
    std::string data;
  };
  std::map<const mg_connection*, Partial> partial_;  // fragmented messages being collected, per page
  ViewStats stats_;
  std::atomic<bool> stop_{false};
  std::thread pusher_;
};

}  // namespace st::view
