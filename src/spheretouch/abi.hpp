// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// <spheretouch/abi.hpp>: the ABI namespace. Every header of the library includes this first and
/// opens its namespace as `namespace st::inline SPHERETOUCH_ABI::geom {`, so every name is declared
/// in st::SPHERETOUCH_ABI (an inline namespace: users write st::geom::Mesh).
//
// The explicit form, because compilers differ on `namespace st::geom {` once st::v0_a16::geom
// exists: GCC reopens the inline namespace's member (CWG 2061), Clang 14 makes a new st::geom
// (found by the CI's Clang fuzz build as a link error). tests/install checks the installed headers.
//
// Why. Eigen lays out its fixed-size vectorisable types (Isometry3d, Quaterniond, Vector4d) by
// EIGEN_MAX_STATIC_ALIGN_BYTES, which follows the compiler's -m flags (16 with SSE, 32 with AVX, 64
// with AVX-512). A program compiled with other flags than the library would pass a Pose with
// another layout across the boundary and crash. The library is therefore built with a fixed
// alignment (-DEIGEN_MAX_ALIGN_BYTES=16 -DEIGEN_MAX_STATIC_ALIGN_BYTES=16, in the pkg-config Cflags
// and the CMake targets, so a consumer built through them matches whatever its -march), and the
// namespace names the alignment a translation unit sees: a consumer that bypasses those flags
// references st::v0_a32::... (or _a64) and fails to link instead of crashing.
#pragma once
#include <Eigen/Core>

#include <spheretouch/version.hpp>

/// Pastes two tokens (SPHERETOUCH_ABI's helper; use SPHERETOUCH_ABI_CAT).
#define SPHERETOUCH_ABI_CAT2(a, b) a##b
/// Pastes two tokens after expanding them (builds SPHERETOUCH_ABI's name).
#define SPHERETOUCH_ABI_CAT(a, b) SPHERETOUCH_ABI_CAT2(a, b)
/// The inline namespace of this ABI: v<major>_a<Eigen static alignment in bytes>, e.g. v0_a16.
#define SPHERETOUCH_ABI                                                                           \
  SPHERETOUCH_ABI_CAT(SPHERETOUCH_ABI_CAT(SPHERETOUCH_ABI_CAT(v, SPHERETOUCH_VERSION_MAJOR), _a), \
                      EIGEN_MAX_STATIC_ALIGN_BYTES)

// The library's namespaces, declared inside the ABI namespace (each header opens its own as above).
/// spheretouch: haptic rendering of large meshes with exact collision detection. The public API
/// (Body, ComputeCollision, collide()) is in `<spheretouch/collide.hpp>`.
namespace st {
inline namespace SPHERETOUCH_ABI {
namespace detail {}
/// The collision core (pkg-config `spheretouch`): meshes, sphere trees, collide(), contact models;
/// mesh files in `spheretouch-meshio`.
namespace geom {}
/// The haptic side (`spheretouch-rt`): force laws, interpolation, passivity, the servo loop,
/// shared-memory exchange.
namespace rt {}
/// Distributed collision (`spheretouch-net`): the worker service, scatter-gather, the wire protocol.
namespace net {}
/// The main job of `spheretouch run`: the collision thread, scenes, run outputs (headers not installed).
namespace engine {}
/// The live view's web server (headers not installed).
namespace view {}
/// Checked reading of TOML scene and worker configs (headers not installed).
namespace config {}
}  // namespace SPHERETOUCH_ABI
}  // namespace st
