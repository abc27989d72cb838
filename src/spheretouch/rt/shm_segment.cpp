// SPDX-License-Identifier: BSD-3-Clause
#include <spheretouch/rt/shm_segment.hpp>

#include <fcntl.h>
#include <signal.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <climits>
#include <csignal>
#include <cstring>
#include <ctime>
#include <fstream>
#include <mutex>
#include <new>
#include <sstream>

#include <spheretouch/rt/clock.hpp>

namespace st::inline SPHERETOUCH_ABI::rt {

static_assert(offsetof(ShmHeader, creator_pid) == 32 && offsetof(ShmHeader, creator_start_ticks) == 40,
              "these offsets are frozen across layout versions (liveness check of old segments)");
static_assert(std::atomic<std::uint32_t>::is_always_lock_free, "state word must be address-free");

std::uint64_t process_start_ticks(int pid) {
  std::ifstream f("/proc/" + std::to_string(pid) + "/stat");
  std::string s;
  if (!std::getline(f, s)) return 0;
  // Field 2 (comm) may contain spaces and ')': parse after the last ')'.
  const auto close = s.rfind(')');
  if (close == std::string::npos) return 0;
  std::istringstream rest(s.substr(close + 1));
  std::string field;
  for (int i = 3; i <= 22; ++i) {  // fields 3..22
    if (!(rest >> field)) return 0;
  }
  try {
    return std::stoull(field);
  } catch (...) { return 0; }
}

std::uint64_t resident_bytes(int pid) {
  std::ifstream f(pid > 0 ? "/proc/" + std::to_string(pid) + "/statm" : std::string("/proc/self/statm"));
  std::uint64_t size = 0, resident = 0;
  if (!(f >> size >> resident)) return 0;
  return resident * static_cast<std::uint64_t>(::sysconf(_SC_PAGESIZE));
}

bool process_alive(int pid, std::uint64_t start_ticks) {
  if (pid <= 0) return false;
  if (kill(pid, 0) != 0 && errno != EPERM) return false;  // ESRCH: gone
  const std::uint64_t now_start = process_start_ticks(pid);
  if (now_start == 0) return false;  // zombie or vanished meanwhile
  return now_start == start_ticks;   // else: pid reused by another process
}

namespace {

Result<std::string> normalise(const std::string& name) {
  std::string n = (!name.empty() && name[0] == '/') ? name : "/" + name;
  if (n.size() < 2 || n.size() > NAME_MAX || n.find('/', 1) != std::string::npos)
    return fail("shm segment name '", name, "': expected 1..", NAME_MAX - 1, " characters without '/' after the first");
  return n;
}

std::string describe_creator(const ShmHeader& h) {
  std::ostringstream os;
  os << "pid " << h.creator_pid << " (started at tick " << h.creator_start_ticks << ")";
  return os.str();
}

// Reads the header of an open segment into `out` (a copy; no mapping is kept). Returns the file
// size, or -1 with errno set.
long read_header(int fd, ShmHeader& out) {
  struct stat st {};
  if (fstat(fd, &st) != 0) return -1;
  if (static_cast<std::size_t>(st.st_size) < sizeof(ShmHeader)) return st.st_size;
  void* p = mmap(nullptr, sizeof(ShmHeader), PROT_READ, MAP_SHARED, fd, 0);
  if (p == MAP_FAILED) return -1;
  std::memcpy(static_cast<void*>(&out), p, sizeof(ShmHeader));  // state read non-atomically: a snapshot
  munmap(p, sizeof(ShmHeader));
  return st.st_size;
}

std::string sys_error(const std::string& what) { return what + ": " + std::strerror(errno); }

}  // namespace

Status ShmSegment::remove(const std::string& name) {
  auto n = normalise(name);
  if (!n) return Error{n.error()};
  if (shm_unlink(n.value().c_str()) != 0 && errno != ENOENT) return Error{sys_error("shm_unlink " + n.value())};
  return Ok{};
}

Result<std::unique_ptr<ShmSegment>> ShmSegment::create(const std::string& name) {
  auto nn = normalise(name);
  if (!nn) return Error{nn.error()};
  const std::string& n = nn.value();
  for (int attempt = 0; attempt < 2; ++attempt) {
    int fd = shm_open(n.c_str(), O_RDWR | O_CREAT | O_EXCL, 0600);
    if (fd < 0 && errno == EEXIST) {
      // Someone's segment: judge it, never trust it.
      fd = shm_open(n.c_str(), O_RDONLY, 0);
      if (fd < 0) {
        if (errno == ENOENT) continue;  // removed meanwhile: retry
        return Error{sys_error("shm " + n + ": exists but cannot be opened to check it")};
      }
      ShmHeader h{};
      struct stat st {};
      const long size = read_header(fd, h);
      const bool have_stat = fstat(fd, &st) == 0;
      close(fd);
      if (size < 0) return Error{sys_error("shm " + n + ": exists but its header cannot be read")};
      if (have_stat && st.st_uid != geteuid())
        return Error{"shm " + n + ": exists and belongs to uid " + std::to_string(st.st_uid) +
                     " (another user's, or squatted); refusing it: choose another name"};
      if (static_cast<std::size_t>(size) < sizeof(ShmHeader) || h.magic != kShmMagic) {
        const bool empty_and_old = size == 0 && have_stat && time(nullptr) - st.st_ctime > 2;
        if (!empty_and_old) {
          return Error{"shm " + n + ": exists and is not a spheretouch segment (size " + std::to_string(size) +
                       ", no magic); refusing to replace it — remove it (rm /dev/shm" + n + ") if it is stale"};
        }
      } else if (process_alive(h.creator_pid, h.creator_start_ticks)) {
        return Error{"shm " + n + ": in use, created by live " + describe_creator(h) + " (layout version " +
                     std::to_string(h.layout_version) + ")"};
      }
      // Creator dead (or an abandoned empty segment): replace it.
      if (shm_unlink(n.c_str()) != 0 && errno != ENOENT) return Error{sys_error("shm_unlink stale " + n)};
      continue;
    }
    if (fd < 0) return Error{sys_error("shm_open " + n)};
    if (ftruncate(fd, sizeof(ShmLayout)) != 0) {
      const std::string e = sys_error("ftruncate " + n);
      close(fd);
      shm_unlink(n.c_str());
      return Error{e};
    }
    void* p = mmap(nullptr, sizeof(ShmLayout), PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
    close(fd);
    if (p == MAP_FAILED) {
      const std::string e = sys_error("mmap " + n);
      shm_unlink(n.c_str());
      return Error{e};
    }
    auto* layout = new (p) ShmLayout{};
    ShmHeader& h = layout->header;
    h.magic = kShmMagic;
    h.layout_version = kShmLayoutVersion;
    h.header_size = sizeof(ShmHeader);
    h.total_size = sizeof(ShmLayout);
    h.pose_size = sizeof(PoseSample);
    h.model_size = sizeof(geom::ContactSet);
    h.creator_pid = getpid();
    h.creator_start_ticks = process_start_ticks(getpid());
    h.created_ns = now_ns();
    h.state.store(1, std::memory_order_release);
    return std::unique_ptr<ShmSegment>(new ShmSegment(n, layout, true));
  }
  return Error{"shm " + n + ": another process keeps re-creating it; giving up"};
}

namespace {

// Opens `n` and checks its header against this build; returns the open fd (caller closes) and
// the header copy, or the reason to refuse it. `need_live_creator`: refuse a dead creator's.
Result<int> open_checked(const std::string& n, int oflag, bool need_live_creator, ShmHeader& h) {
  const int fd = shm_open(n.c_str(), oflag, 0);
  if (fd < 0) return Error{sys_error("shm " + n + ": cannot attach")};
  auto refuse = [&](const std::string& why) -> Result<int> {
    close(fd);
    return Error{"shm " + n + ": " + why};
  };
  // Only our own segments: another user's (a squatter's, or a colleague's run) is never read,
  // and its scene never loaded.
  struct stat st {};
  if (fstat(fd, &st) != 0) return refuse(sys_error("cannot stat"));
  if (st.st_uid != geteuid())
    return refuse("belongs to uid " + std::to_string(st.st_uid) + ", not to this user (uid " +
                  std::to_string(geteuid()) + "): refusing another user's segment");
  const long size = read_header(fd, h);
  if (size < 0) return refuse(sys_error("header unreadable"));
  if (static_cast<std::size_t>(size) < sizeof(ShmHeader))
    return refuse("size " + std::to_string(size) + " bytes, smaller than the header (" +
                  std::to_string(sizeof(ShmHeader)) + "): not initialised or not ours");
  if (h.magic != kShmMagic) return refuse("bad magic: not a spheretouch real-time segment");
  if (h.layout_version != kShmLayoutVersion)
    return refuse("layout version " + std::to_string(h.layout_version) + ", this build speaks " +
                  std::to_string(kShmLayoutVersion) + " (created by " + describe_creator(h) + ")");
  if (h.header_size != sizeof(ShmHeader) || h.total_size != sizeof(ShmLayout) ||
      static_cast<std::size_t>(size) != sizeof(ShmLayout) || h.pose_size != sizeof(PoseSample) ||
      h.model_size != sizeof(geom::ContactSet))
    return refuse("layout mismatch: header/total/pose/model sizes " + std::to_string(h.header_size) + "/" +
                  std::to_string(h.total_size) + "/" + std::to_string(h.pose_size) + "/" +
                  std::to_string(h.model_size) + " (file " + std::to_string(size) + "), expected " +
                  std::to_string(sizeof(ShmHeader)) + "/" + std::to_string(sizeof(ShmLayout)) + "/" +
                  std::to_string(sizeof(PoseSample)) + "/" + std::to_string(sizeof(geom::ContactSet)));
  if (need_live_creator && !process_alive(h.creator_pid, h.creator_start_ticks))
    return refuse("stale: its creator " + describe_creator(h) + " is dead; the creator must create it anew");
  return fd;
}

}  // namespace

Result<std::unique_ptr<ShmSegment>> ShmSegment::attach(const std::string& name) {
  auto nn = normalise(name);
  if (!nn) return Error{nn.error()};
  const std::string& n = nn.value();
  ShmHeader h{};
  Result<int> fd = open_checked(n, O_RDWR, true, h);
  if (!fd) return Error{fd.error()};
  void* p = mmap(nullptr, sizeof(ShmLayout), PROT_READ | PROT_WRITE, MAP_SHARED, fd.value(), 0);
  close(fd.value());
  if (p == MAP_FAILED) return Error{sys_error("mmap " + n)};
  auto* layout = std::launder(static_cast<ShmLayout*>(p));
  if (layout->header.state.load(std::memory_order_acquire) != 1) {
    munmap(p, sizeof(ShmLayout));
    return Error{"shm " + n + ": still being initialised by " + describe_creator(h) + "; try again"};
  }
  return std::unique_ptr<ShmSegment>(new ShmSegment(n, layout, false));
}

Result<std::unique_ptr<const ShmSegment>> ShmSegment::attach_read_only(const std::string& name) {
  auto nn = normalise(name);
  if (!nn) return Error{nn.error()};
  const std::string& n = nn.value();
  ShmHeader h{};
  Result<int> fd = open_checked(n, O_RDONLY, false, h);
  if (!fd) return Error{fd.error()};
  void* p = mmap(nullptr, sizeof(ShmLayout), PROT_READ, MAP_SHARED, fd.value(), 0);
  close(fd.value());
  if (p == MAP_FAILED) return Error{sys_error("mmap " + n)};
  auto* layout = std::launder(static_cast<ShmLayout*>(p));
  if (layout->header.state.load(std::memory_order_acquire) != 1) {
    munmap(p, sizeof(ShmLayout));
    return Error{"shm " + n + ": still being initialised by " + describe_creator(h) + "; try again"};
  }
  return std::unique_ptr<const ShmSegment>(new ShmSegment(n, layout, false));
}

namespace {

// The guarded mappings (address, length), written before the handler can need them, and the flag.
struct GuardedMapping {
  std::atomic<std::uintptr_t> addr{0};
  std::atomic<std::size_t> len{0};
};
GuardedMapping g_guarded[4];
std::atomic<bool> g_truncated{false};

void on_sigbus(int sig, siginfo_t* info, void*) {
  const auto at = reinterpret_cast<std::uintptr_t>(info ? info->si_addr : nullptr);
  for (GuardedMapping& g : g_guarded) {
    const std::uintptr_t a = g.addr.load(std::memory_order_acquire);
    const std::size_t n = g.len.load(std::memory_order_acquire);
    if (a && at >= a && at < a + n) {
      // The file behind the mapping shrank: put private zero pages in its place (mmap is a plain
      // system call on Linux, safe here though POSIX does not list it), so the faulting access
      // retries and reads zeros.
      mmap(reinterpret_cast<void*>(a), n, PROT_READ | PROT_WRITE, MAP_FIXED | MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
      g_truncated.store(true, std::memory_order_release);
      return;
    }
  }
  // Not ours: the default action (the access retries and the process ends with SIGBUS, as before).
  signal(sig, SIG_DFL);
}

}  // namespace

void ShmSegment::guard_truncation() {
  static std::once_flag installed;
  std::call_once(installed, [] {
    struct sigaction sa {};
    sa.sa_sigaction = on_sigbus;
    sa.sa_flags = SA_SIGINFO;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGBUS, &sa, nullptr);
  });
  for (GuardedMapping& g : g_guarded) {
    std::uintptr_t expected = 0;
    if (g.addr.load() == 0) {
      g.len.store(sizeof(ShmLayout), std::memory_order_release);
      if (g.addr.compare_exchange_strong(expected, reinterpret_cast<std::uintptr_t>(layout_))) return;
    }
  }
}

bool ShmSegment::truncated() noexcept { return g_truncated.load(std::memory_order_acquire); }

bool ShmSegment::creator_alive() const {
  return process_alive(layout_->header.creator_pid, layout_->header.creator_start_ticks);
}

bool ShmSegment::names_this() const {
  const int fd = shm_open(name_.c_str(), O_RDONLY, 0);
  if (fd < 0) return false;
  ShmHeader h{};
  const bool same = read_header(fd, h) >= static_cast<long>(sizeof(ShmHeader)) && h.magic == kShmMagic &&
                    h.creator_pid == layout_->header.creator_pid && h.created_ns == layout_->header.created_ns;
  close(fd);
  return same;
}

bool ShmSegment::unlink_if_orphaned() const {
  if (creator_alive() || !names_this()) return false;
  return shm_unlink(name_.c_str()) == 0;
}

ShmSegment::~ShmSegment() {
  // Unlink only if the name still refers to our segment (not a replacement by someone else).
  if (creator_ && names_this()) shm_unlink(name_.c_str());
  for (GuardedMapping& g : g_guarded) {
    std::uintptr_t mine = reinterpret_cast<std::uintptr_t>(layout_);
    g.addr.compare_exchange_strong(mine, 0);
  }
  munmap(layout_, sizeof(ShmLayout));
}

}  // namespace st::rt
