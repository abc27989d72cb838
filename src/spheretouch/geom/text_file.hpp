// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// <spheretouch/geom/text_file.hpp>: reading a small text file (a scene, a worker config, a pose
/// or trajectory file) whole, bounded: only a regular file, at most a given size, opened so that a
/// FIFO or a device cannot hang or exhaust the reader (/dev/zero, a named pipe nobody writes).
#pragma once
#include <spheretouch/abi.hpp>
#include <cstdint>
#include <string>

#include <spheretouch/geom/result.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {

/// The whole file at `path`: a regular file of at most `max_bytes` bytes and, with `owner_only`
/// (a secret), that group and others cannot access. Errors name the path, `what` it should be
/// ("scene file") and what is wrong (missing, a directory, a FIFO, too big, readable by others).
Result<std::string> read_text_file(const std::string& path, std::uint64_t max_bytes, const std::string& what,
                                   bool owner_only = false);

}  // namespace st::geom
