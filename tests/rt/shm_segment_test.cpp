// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/rt/shm_segment.*: two processes (fork) exchanging through a segment, header checks,
// and a segment left by a dead process being detected (attach refuses) and replaced (create).
#include <spheretouch/rt/shm_segment.hpp>

#include <doctest/doctest.h>

#include "rt_test_util.hpp"
#include <fcntl.h>
#include <sys/mman.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstring>
#include <string>

#include <spheretouch/rt/clock.hpp>

using namespace st::rt;

namespace {
std::string unique_name(const char* tag) {
  return "/spheretouch-test-" + std::string(tag) + "-" + std::to_string(getpid());
}
int wait_child(pid_t pid) {
  int status = 0;
  waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}
}  // namespace

TEST_CASE("ShmSegment: create, attach in a forked child, exchange both ways") {
  const std::string name = unique_name("xchg");
  auto seg = ShmSegment::create(name);
  REQUIRE_MESSAGE(seg.ok(), err_of(seg));
  CHECK(seg.value()->creator());
  CHECK(seg.value()->header().creator_pid == getpid());
  constexpr std::uint64_t kModels = 200'000;

  const pid_t child = fork();
  REQUIRE(child >= 0);
  if (child == 0) {
    // Child: the collision side. Attach by name (not the inherited mapping), publish models,
    // and check the poses it reads from the parent. Exit code = number of faults.
    int faults = 0;
    auto att = ShmSegment::attach(name);
    if (!att.ok()) _exit(100);
    ShmSegment& s = *att.value();
    std::uint64_t last_pose = 0;
    for (std::uint64_t i = 1; i <= kModels; ++i) {
      st::geom::ContactSet& set = s.models().input();
      set.count = 1;
      st::geom::ContactModel& m = set.models[0];
      m = st::geom::ContactModel{};
      m.seq = i;
      m.penetration_mm = static_cast<double>(i);
      m.pairs = static_cast<std::uint32_t>(i);
      m.published_ns = now_ns();
      s.models().publish();
      if (s.poses().update()) {
        const PoseSample& p = s.poses().output();
        if (p.seq < last_pose || p.pose.t[0] != static_cast<double>(p.seq)) ++faults;
        last_pose = p.seq;
      }
    }
    _exit(faults > 99 ? 99 : faults);
  }
  // Parent: the haptic side.
  ShmSegment& s = *seg.value();
  std::uint64_t last = 0, torn = 0, backwards = 0, pose_seq = 0;
  int child_status = -1;
  auto take = [&] {
    if (s.models().update()) {
      const auto& m = s.models().output().models[0];
      if (m.penetration_mm != static_cast<double>(m.seq) || m.pairs != static_cast<std::uint32_t>(m.seq)) ++torn;
      if (m.seq <= last) ++backwards;
      last = m.seq;
    }
  };
  while (last < kModels && child_status < 0) {
    PoseSample ps;
    ps.seq = ++pose_seq;
    ps.sampled_ns = now_ns();
    ps.pose.t[0] = static_cast<double>(ps.seq);
    s.poses().write(ps);
    take();
    int status = 0;
    if (waitpid(child, &status, WNOHANG) == child) {
      child_status = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
      take();  // the child's last model was published before it exited
    }
  }
  if (child_status < 0) child_status = wait_child(child);
  CHECK(child_status == 0);
  CHECK(torn == 0);
  CHECK(backwards == 0);
  CHECK(last == kModels);
}

TEST_CASE("ShmSegment: a live creator's segment is refused by create, accepted by attach") {
  const std::string name = unique_name("live");
  auto a = ShmSegment::create(name);
  REQUIRE(a.ok());
  auto b = ShmSegment::create(name);
  REQUIRE_FALSE(b.ok());
  CHECK_MESSAGE(b.error().find("in use") != std::string::npos, b.error());
  auto c = ShmSegment::attach(name);
  CHECK(c.ok());
}

TEST_CASE("ShmSegment: a segment left by a dead process is refused by attach and replaced by create") {
  const std::string name = unique_name("dead");
  const pid_t child = fork();
  REQUIRE(child >= 0);
  if (child == 0) {
    auto seg = ShmSegment::create(name);
    if (!seg.ok()) _exit(1);
    (void)seg.value().release();  // leak the mapping: die without unlinking, like a crash
    _exit(0);
  }
  REQUIRE(wait_child(child) == 0);
  auto att = ShmSegment::attach(name);
  REQUIRE_FALSE(att.ok());
  CHECK_MESSAGE(att.error().find("dead") != std::string::npos, att.error());
  auto seg = ShmSegment::create(name);
  REQUIRE_MESSAGE(seg.ok(), err_of(seg));
  CHECK(seg.value()->header().creator_pid == getpid());
  CHECK(ShmSegment::attach(name).ok());
}

TEST_CASE("ShmSegment: header mismatches are refused with a clear error") {
  const std::string name = unique_name("hdr");
  auto seg = ShmSegment::create(name);
  REQUIRE(seg.ok());
  const int fd = shm_open(name.c_str(), O_RDWR, 0);
  REQUIRE(fd >= 0);
  void* p = mmap(nullptr, sizeof(ShmLayout), PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
  close(fd);
  REQUIRE(p != MAP_FAILED);
  auto* h = static_cast<ShmHeader*>(p);

  h->layout_version = kShmLayoutVersion + 1;
  auto r = ShmSegment::attach(name);
  REQUIRE_FALSE(r.ok());
  CHECK_MESSAGE(r.error().find("layout version") != std::string::npos, r.error());
  h->layout_version = kShmLayoutVersion;

  h->model_size += 8;
  r = ShmSegment::attach(name);
  REQUIRE_FALSE(r.ok());
  CHECK_MESSAGE(r.error().find("layout mismatch") != std::string::npos, r.error());
  h->model_size -= 8;

  h->magic ^= 1;
  r = ShmSegment::attach(name);
  REQUIRE_FALSE(r.ok());
  CHECK_MESSAGE(r.error().find("magic") != std::string::npos, r.error());
  h->magic ^= 1;

  CHECK(ShmSegment::attach(name).ok());
  munmap(p, sizeof(ShmLayout));
}

TEST_CASE("ShmSegment: foreign segments are not replaced; bad names refused") {
  const std::string name = unique_name("foreign");
  const int fd = shm_open(name.c_str(), O_RDWR | O_CREAT | O_EXCL, 0600);
  REQUIRE(fd >= 0);
  const char junk[256] = "not a spheretouch segment";
  REQUIRE(ftruncate(fd, sizeof junk) == 0);
  REQUIRE(pwrite(fd, junk, sizeof junk, 0) == static_cast<ssize_t>(sizeof junk));
  close(fd);
  auto c = ShmSegment::create(name);
  REQUIRE_FALSE(c.ok());
  CHECK_MESSAGE(c.error().find("not a spheretouch segment") != std::string::npos, c.error());
  auto a = ShmSegment::attach(name);
  REQUIRE_FALSE(a.ok());
  CHECK(ShmSegment::remove(name).ok());
  CHECK_FALSE(ShmSegment::attach("/no-such-spheretouch-segment-xyz").ok());
  CHECK_FALSE(ShmSegment::create("/a/b").ok());
  CHECK_FALSE(ShmSegment::create("").ok());
}

TEST_CASE("process_alive: self alive, pid reuse detected") {
  const auto start = process_start_ticks(getpid());
  CHECK(start > 0);
  CHECK(process_alive(getpid(), start));
  CHECK_FALSE(process_alive(getpid(), start + 1));
  CHECK_FALSE(process_alive(-1, 0));
}

TEST_CASE("ShmSegment: read-only attach sees the status area, survives its creator, checks the header") {
  const std::string name = unique_name("ro");
  auto seg = ShmSegment::create(name);
  REQUIRE_MESSAGE(seg.ok(), err_of(seg));
  ServoStatus sv;
  sv.ticks = 42;
  seg.value()->status().servo.store(sv);
  seg.value()->status().servo_state.store(static_cast<std::uint32_t>(ServoState::running));
  auto ro = ShmSegment::attach_read_only(name);
  REQUIRE_MESSAGE(ro.ok(), err_of(ro));
  ServoStatus got;
  REQUIRE(ro.value()->status().servo.load(got));
  CHECK(got.ticks == 42);
  CHECK(ro.value()->creator_alive());
  CHECK_FALSE(ro.value()->unlink_if_orphaned());  // creator alive: not ours to remove
  auto ro2 = ShmSegment::attach_read_only(name);  // any number of read-only attachers
  CHECK(ro2.ok());

  // Wrong magic: refused with a clear error.
  const int fd = shm_open(name.c_str(), O_RDWR, 0);
  REQUIRE(fd >= 0);
  void* p = mmap(nullptr, sizeof(ShmLayout), PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
  close(fd);
  REQUIRE(p != MAP_FAILED);
  auto* h = static_cast<ShmHeader*>(p);
  h->magic ^= 1;
  auto bad = ShmSegment::attach_read_only(name);
  REQUIRE_FALSE(bad.ok());
  CHECK_MESSAGE(bad.error().find("magic") != std::string::npos, bad.error());
  h->magic ^= 1;
  munmap(p, sizeof(ShmLayout));

  // A dead creator's segment: attach refuses it, read-only attach still shows it.
  const std::string dead = unique_name("ro-dead");
  const pid_t child = fork();
  REQUIRE(child >= 0);
  if (child == 0) {
    auto s = ShmSegment::create(dead);
    if (!s.ok()) _exit(1);
    (void)s.value().release();
    _exit(0);
  }
  REQUIRE(wait_child(child) == 0);
  auto rd = ShmSegment::attach_read_only(dead);
  REQUIRE_MESSAGE(rd.ok(), err_of(rd));
  CHECK_FALSE(rd.value()->creator_alive());
  CHECK(rd.value()->unlink_if_orphaned());  // a survivor tidies up the name
  CHECK_FALSE(ShmSegment::attach_read_only(dead).ok());
}

TEST_CASE("ShmSegment: another user's segment is never attached nor replaced (a squatter, or a colleague's run)") {
  // Making a segment another user owns needs CAP_CHOWN: CI runs the suites as root.
  if (geteuid() != 0) {
    MESSAGE("skipped: not root (cannot give a segment to another user)");
    return;
  }
  const std::string name = "/spheretouch-test-foreign-owner-" + std::to_string(getpid());
  auto seg = st::rt::ShmSegment::create(name);
  REQUIRE(seg.ok());
  const int fd = shm_open(name.c_str(), O_RDWR, 0);
  REQUIRE(fd >= 0);
  REQUIRE(fchown(fd, 65534, 65534) == 0);  // nobody's now, a valid segment with a live creator
  close(fd);
  auto rw = st::rt::ShmSegment::attach(name);
  REQUIRE_FALSE(rw.ok());
  CHECK(rw.error().find("belongs to uid 65534, not to this user") != std::string::npos);
  auto ro = st::rt::ShmSegment::attach_read_only(name);
  REQUIRE_FALSE(ro.ok());
  CHECK(ro.error().find("refusing another user's segment") != std::string::npos);
  seg.value().reset();  // our creator goes: the name is a squatter's now
  const int again = shm_open(name.c_str(), O_RDWR | O_CREAT | O_EXCL, 0644);
  REQUIRE(again >= 0);
  REQUIRE(fchown(again, 65534, 65534) == 0);
  close(again);
  auto squatted = st::rt::ShmSegment::create(name);
  REQUIRE_FALSE(squatted.ok());
  CHECK(squatted.error().find("belongs to uid 65534 (another user's, or squatted)") != std::string::npos);
  shm_unlink(name.c_str());
}
