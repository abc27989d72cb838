# SPDX-License-Identifier: BSD-3-Clause
"""Two boxes slid into each other: at each step, do they touch, and which face pairs collide.

Run from a build tree: PYTHONPATH=build/python python3 python/examples/touch_boxes.py
(checked with `mypy --strict` in CI, so it is also the typed example of the API).
"""
import numpy as np
import numpy.typing as npt

import spheretouch as st


def box(size: float) -> st.Mesh:
    """A closed cube of edge `size` mm centred at the origin (12 faces)."""
    h = size / 2
    v = np.array([[x, y, z] for x in (-h, h) for y in (-h, h) for z in (-h, h)], dtype=np.float64)
    f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]], dtype=np.int64)
    return st.Mesh(v, f, name=f"box{size:g}")


def at(x: float) -> npt.NDArray[np.float64]:
    """The probe's pose: translated by x mm along x (and a little off-axis)."""
    pose = np.eye(4)
    pose[:3, 3] = (x, 0.5, 0.25)
    return pose


def main() -> int:
    pair = st.ComputeCollision(st.Body(box(10.0)), st.Body(box(40.0)))
    touching = 0
    for step in range(5):
        x = 26.5 - step  # centres 26.5 mm apart: a 1.5 mm gap; 22.5 mm: 2.5 mm overlap
        result = pair.query(at(x))
        print(f"x {x:.1f} mm: colliding {int(result.colliding)}, pairs {len(result.pairs)}, contacts {result.contacts}")
        touching += int(result.colliding)
    return 0 if touching == 3 else 1


if __name__ == "__main__":
    raise SystemExit(main())
