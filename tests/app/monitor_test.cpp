// Tests src/app/cmd_monitor.cpp's refusals (a live session is watched in servo_process_test.cpp):
// a segment with a bad magic or another layout version gets a clear error, never a crash.
#include <fcntl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <fstream>
#include <iterator>
#include <thread>

#include "process_util.hpp"
#include "rt/shm_segment.hpp"
#include "test_util.hpp"

using namespace st::test;

TEST_CASE("monitor: refuses a segment with a bad magic or layout version, and a missing one") {
  const std::string name = "/spheretouch-test-mon-" + std::to_string(getpid());
  // Not ours: a segment of the right size full of zeros.
  {
    const int fd = shm_open(name.c_str(), O_RDWR | O_CREAT | O_EXCL, 0600);
    REQUIRE(fd >= 0);
    REQUIRE(ftruncate(fd, sizeof(st::rt::ShmLayout)) == 0);
    close(fd);
    const CommandResult r = run_command(spheretouch_exe() + " monitor --name " + name + " --count 1");
    INFO(r.output);
    CHECK(r.exit_code == 2);
    CHECK(contains(r.output, "bad magic"));
    shm_unlink(name.c_str());
  }
  // Ours, but another layout version.
  {
    auto seg = st::rt::ShmSegment::create(name);
    REQUIRE(seg.ok());
    const int fd = shm_open(name.c_str(), O_RDWR, 0);
    REQUIRE(fd >= 0);
    void* p = mmap(nullptr, sizeof(st::rt::ShmLayout), PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
    close(fd);
    REQUIRE(p != MAP_FAILED);
    static_cast<st::rt::ShmHeader*>(p)->layout_version = st::rt::kShmLayoutVersion + 7;
    const CommandResult r = run_command(spheretouch_exe() + " monitor --name " + name + " --count 1");
    INFO(r.output);
    CHECK(r.exit_code == 2);
    CHECK(contains(r.output, "layout version " + std::to_string(st::rt::kShmLayoutVersion + 7)));
    static_cast<st::rt::ShmHeader*>(p)->layout_version = st::rt::kShmLayoutVersion;
    // Restored: now it attaches and prints a line (no servo has ticked in it).
    const CommandResult ok = run_command(spheretouch_exe() + " monitor --name " + name + " --count 1");
    INFO(ok.output);
    CHECK(ok.exit_code == 0);
    CHECK(contains(ok.output, "no ticks yet"));
    munmap(p, sizeof(st::rt::ShmLayout));
  }
  const CommandResult missing = run_command(spheretouch_exe() + " monitor --name " + name + "-absent --count 1");
  CHECK(missing.exit_code == 2);
  CHECK(contains(missing.output, "cannot attach"));
}

TEST_CASE("monitor: a segment truncated under it is reported and stops it, not SIGBUS") {
  const std::string name = "/spheretouch-test-mon-trunc-" + std::to_string(getpid());
  auto seg = st::rt::ShmSegment::create(name);
  REQUIRE(seg.ok());
  TempDir d;
  const std::string log = d.file("monitor.log");
  const pid_t pid = spawn_spheretouch({"monitor", "--name", name, "--interval", "20", "--count", "1000"}, log);
  std::this_thread::sleep_for(std::chrono::milliseconds(400));  // it is printing lines by now
  const int fd = shm_open(name.c_str(), O_RDWR, 0);
  REQUIRE(fd >= 0);
  REQUIRE(ftruncate(fd, 0) == 0);  // what anyone who can write the segment can do
  close(fd);
  const int code = wait_for(pid, 20.0);
  std::ifstream in(log);
  const std::string out((std::istreambuf_iterator<char>(in)), {});
  INFO(out);
  CHECK(code == 1);  // not 128 + SIGBUS
  CHECK(contains(out, "the segment shrank under the monitor"));
  shm_unlink(name.c_str());
}
