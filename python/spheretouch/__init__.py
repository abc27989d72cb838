# SPDX-License-Identifier: BSD-3-Clause
"""spheretouch: exact face-level collision of large meshes, contact models and force law.

The C++ library's Python face (names as in C++: ComputeCollision, ContactBuilder, ForceLaw, ...).
Poses are 4x4 float64 rigid transforms in mm (probe frame -> object frame); face pairs are (k, 2)
uint32 arrays of (probe face, object face) file indices. Bad input raises ValueError with a short
message naming the file, field, row or index at fault.
"""
try:
    import numpy  # noqa: F401  (the C++ half exchanges numpy arrays)
except ImportError as e:  # pragma: no cover - exercised by the test with numpy hidden
    raise ImportError(
        "spheretouch needs numpy: apt-get install python3-numpy (Debian), or pip install numpy"
    ) from e

from ._core import (
    BAD_INPUT,
    DEGENERATE_SKIPPED,
    EXACT,
    HELD,
    IN_CONTACT,
    INSIDE_CAPPED,
    LEAF_SPHERES,
    NORMAL_FALLBACK,
    NORMALS_DISAGREE,
    PLANES,
    REPLANED,
    Body,
    Collider,
    CollisionResult,
    ComputeCollision,
    ContactBuilder,
    ContactModel,
    ForceLaw,
    Mesh,
    SphereTree,
    World,
    __version__,
    load_mesh,
)

__all__ = [
    "BAD_INPUT", "DEGENERATE_SKIPPED", "EXACT", "HELD", "IN_CONTACT", "INSIDE_CAPPED", "LEAF_SPHERES",
    "NORMAL_FALLBACK", "NORMALS_DISAGREE", "PLANES", "REPLANED", "Body", "Collider", "CollisionResult",
    "ComputeCollision", "ContactBuilder", "ContactModel", "ForceLaw", "Mesh", "SphereTree", "World", "__version__",
    "load_mesh",
]
