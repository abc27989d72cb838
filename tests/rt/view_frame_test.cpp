// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/rt/view_frame.*: a frame's used prefix, and the checks a frame read from shared
// memory gets before a view sends it (counts, face ids, non-finite numbers, flags); a frame
// published through a SeqLock prefix store reads back whole.
#include <spheretouch/rt/view_frame.hpp>

#include <doctest/doctest.h>

#include <cmath>
#include <limits>
#include <memory>

#include <spheretouch/rt/seqlock.hpp>

using namespace st::rt;

namespace {
std::unique_ptr<ViewFrame> frame_with(std::uint32_t np, std::uint32_t no) {
  auto f = std::make_unique<ViewFrame>();
  f->n_probe = np;
  f->n_object = no;
  for (std::uint32_t i = 0; i < np; ++i) f->faces[i] = i;
  for (std::uint32_t i = 0; i < no; ++i) f->faces[np + i] = 2 * i;
  return f;
}
}  // namespace

TEST_CASE("ViewFrame: the used prefix ends with the face lists; counts beyond the frame are clamped") {
  auto f = frame_with(3, 5);
  CHECK(f->used_bytes() == 200 + 4 * 8);
  f->n_object = 0xffffffffu;
  f->n_probe = 0xffffffffu;
  CHECK(f->used_bytes() == sizeof(ViewFrame));
}

TEST_CASE("sanitize_view_frame: a good frame passes untouched; non-finite numbers become 0, unknown flags go") {
  auto f = frame_with(3, 5);
  f->flags = ViewFrame::kInContact;
  f->penetration_mm = 1.5;
  const char* why = nullptr;
  CHECK(sanitize_view_frame(*f, 3, 9, &why));
  CHECK(why == nullptr);
  CHECK(f->penetration_mm == 1.5);
  CHECK(f->flags == ViewFrame::kInContact);
  f->pose[7] = std::nan("");
  f->force_dir[1] = std::numeric_limits<double>::infinity();
  f->contact_point[2] = -std::numeric_limits<double>::infinity();
  f->penetration_mm = std::nan("");
  f->round_ms = std::nan("");
  f->flags = 0xffffffffu;
  CHECK(sanitize_view_frame(*f, 3, 9));
  CHECK(f->pose[7] == 0);
  CHECK(f->pose[0] == 1);
  CHECK(f->force_dir[1] == 0);
  CHECK(f->contact_point[2] == 0);
  CHECK(f->penetration_mm == 0);
  CHECK(f->round_ms == 0);
  CHECK(f->flags == (ViewFrame::kInContact | ViewFrame::kTruncated));
}

TEST_CASE("sanitize_view_frame: counts beyond the frame and face ids beyond the meshes refuse the frame") {
  const char* why = nullptr;
  auto f = frame_with(3, 5);
  CHECK_FALSE(sanitize_view_frame(*f, 2, 9, &why));  // probe id 2 of a 2-face probe
  CHECK(std::string(why).find("probe face id") != std::string::npos);
  CHECK_FALSE(sanitize_view_frame(*f, 3, 8, &why));  // object id 8 of an 8-face object
  CHECK(std::string(why).find("object face id") != std::string::npos);
  f->n_object = kViewMaxFaces + 1;
  CHECK_FALSE(sanitize_view_frame(*f, 3, 0xffffffffu, &why));
  CHECK(std::string(why).find("face count") != std::string::npos);
  f->n_object = 0;
  f->n_probe = 0xffffffffu;
  CHECK_FALSE(sanitize_view_frame(*f, 0xffffffffu, 0xffffffffu));
  auto full = frame_with(kViewMaxFaces, kViewMaxFaces);  // a full frame is fine
  CHECK(sanitize_view_frame(*full, kViewMaxFaces, 2 * kViewMaxFaces));
}

TEST_CASE("ViewFrame through a SeqLock: a prefix store publishes the face lists; the reader gets them") {
  auto lock = std::make_unique<SeqLock<ViewFrame>>();
  auto out = std::make_unique<ViewFrame>();
  CHECK_FALSE(lock->load(*out));
  auto big = frame_with(100, 200);
  big->round = 1;
  lock->store(*big, big->used_bytes());
  auto small = frame_with(1, 2);
  small->faces[1] = 77;
  small->round = 2;
  lock->store(*small, small->used_bytes());
  REQUIRE(lock->load(*out));
  CHECK(lock->version() == 2);
  CHECK(out->round == 2);
  CHECK(out->n_probe == 1);
  CHECK(out->n_object == 2);
  CHECK(out->faces[0] == 0);
  CHECK(out->faces[1] == 77);
  CHECK(out->faces[2] == 2);
  CHECK(out->faces[5] == big->faces[5]);  // beyond the prefix (whole words): what the earlier store left
}
