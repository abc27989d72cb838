# SPDX-License-Identifier: BSD-3-Clause
"""A ball pressed into a box: the contact model (FD, PD) and the force the law gives.

Run from a build tree: PYTHONPATH=build/python python3 python/examples/contact_force.py
"""
import numpy as np
import numpy.typing as npt

import spheretouch as st


def main() -> int:
    ball = st.Mesh(*unit_ball(), name="ball")
    h = 20.0
    v = np.array([[x, y, z] for x in (-h, h) for y in (-h, h) for z in (-h, h)], dtype=np.float64)
    f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]], dtype=np.int64)
    block = st.Mesh(v, f, name="block")
    pair = st.ComputeCollision(st.Body(ball), st.Body(block))
    builder = st.ContactBuilder("patch")
    law = st.ForceLaw("linear", spring_N_per_mm=0.5)
    for depth in (0.5, 1.0, 2.0):
        pose = np.eye(4)
        pose[:3, 3] = (0.0, 0.0, h + 5.0 - depth)  # ball radius 5 mm, resting on the top face
        pairs = pair.pairs(pose)
        model = builder.build(ball, block, pose, pairs)
        force = law.force(model)
        flags = [name for name, bit in (("in contact", st.IN_CONTACT), ("planes", st.PLANES)) if model.flags & bit]
        print(f"pressed {depth} mm: PD {model.penetration_mm:.3f} mm, FD {np.round(model.force_dir, 3)}, "
              f"|F| {float(np.linalg.norm(force)):.3f} N, flags {flags}")
    return 0


def unit_ball() -> "tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]":
    """An icosphere of radius 5 mm (frequency 2: 80 faces), vertices and faces."""
    t = (1 + 5 ** 0.5) / 2
    v = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
         (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
             (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11),
             (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    verts = [np.array(p, dtype=np.float64) / np.linalg.norm(p) for p in v]
    out: "list[tuple[int, int, int]]" = []
    cache: "dict[tuple[int, int], int]" = {}

    def mid(a: int, b: int) -> int:
        key = (min(a, b), max(a, b))
        if key not in cache:
            m = verts[a] + verts[b]
            verts.append(m / np.linalg.norm(m))
            cache[key] = len(verts) - 1
        return cache[key]

    for a, b, c in faces:
        ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
        out += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
    return np.array(verts) * 5.0, np.array(out, dtype=np.int64)


if __name__ == "__main__":
    raise SystemExit(main())
