// SPDX-License-Identifier: BSD-3-Clause
// A program that uses the installed collision core, nothing else of spheretouch:
//   c++ -std=c++20 touch_boxes.cpp $(pkg-config --cflags --libs spheretouch) -o touch_boxes
// Two boxes are slid into each other; each step prints whether they touch, how many face pairs
// collide and the first pair (the request that stops at the first pair).
#include <cstdio>
#include <vector>

#include <spheretouch/collide.hpp>
#include <spheretouch/geom/primitives.hpp>

int main() {
  st::Result<st::Body> probe = st::Body::make(st::geom::make_box({10, 10, 10}));
  st::Result<st::Body> object = st::Body::make(st::geom::make_box({40, 40, 40}));
  if (!probe || !object) {
    std::fprintf(stderr, "touch_boxes: %s\n", (!probe ? probe.error() : object.error()).c_str());
    return 1;
  }
  st::ComputeCollision pair(probe.value(), object.value());
  st::CollisionResult all, first;
  int touching = 0;
  for (int step = 0; step <= 4; ++step) {
    const double x = 26.5 - step;  // centres 26.5 mm apart: a 1.5 mm gap; 22.5 mm: 2.5 mm overlap
    st::Pose frame = st::Pose::Identity();
    frame.translation() = st::Vec3(x, 0.5, 0.25);
    pair.probe().set_frame(frame);
    pair(st::CollisionRequest::all_pairs(), all);
    pair(st::CollisionRequest::first_pair(), first);
    std::printf("x %.1f mm: colliding %d, pairs %zu, contacts %u", x, all.colliding() ? 1 : 0, all.pairs.size(),
                all.contacts());
    if (first.colliding()) std::printf(", first pair (%u, %u)", first.pairs[0].probe, first.pairs[0].object);
    std::printf("\n");
    if (all.colliding() != first.colliding()) return 1;  // the two requests must agree on "touching"
    touching += all.colliding() ? 1 : 0;
  }
  return touching == 3 ? 0 : 1;  // x = 24.5, 23.5 and 22.5 touch; 26.5 and 25.5 do not
}
