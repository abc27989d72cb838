// SPDX-License-Identifier: BSD-3-Clause
// What `spheretouch run` leaves in its run directory besides the per-tick CSV: the contact
// state as a coloured PLY (paper Fig. 5) and a trace-event JSON for Perfetto / chrome://tracing.
#pragma once
#include <spheretouch/abi.hpp>
#include <string>
#include <vector>

#include <spheretouch/engine/collision_loop.hpp>
#include <spheretouch/geom/mesh.hpp>

namespace st::inline SPHERETOUCH_ABI::engine {

/// Writes both bodies in the object's frame (probe placed by `pose`) as one ASCII PLY with
/// per-face colours: colliding faces red, the rest grey (object) or light blue (probe). Faces
/// 0..F_object-1 are the object's, then the probe's, each in file order.
Status write_contact_ply(const std::string& path, const geom::Mesh& probe, const geom::Mesh& object,
                         const geom::Pose& pose, const std::vector<geom::FacePair>& pairs);

/// Writes a Chrome trace-event JSON: one complete event per haptic tick (from the per-tick CSV),
/// a force counter track, and one complete event per collision round (from the per-round CSV of
/// CollisionLoop::write_rounds_csv). Both files are streamed: memory does not grow with the run.
Status write_trace_json(const std::string& path, const std::string& tick_csv, const std::string& rounds_csv);

}  // namespace st::engine
