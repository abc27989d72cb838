# SPDX-License-Identifier: BSD-3-Clause
"""Tests of the spheretouch Python module (run by `meson test --suite python`).

The module is checked against the project's own command line (`spheretouch query`, the exact
reference every other suite uses) on the real hand and elephant meshes, and on small generated
meshes whose answer is known. Prints '[python] test cases: N | P passed | F failed' at the end,
the line scripts/run_tests.sh sums.
"""
import math
import os
import subprocess
import sys
import tempfile
import traceback

import numpy as np

import spheretouch as st

SRC = os.environ.get("ST_SOURCE_ROOT", os.path.join(os.path.dirname(__file__), "..", ".."))
BUILD = os.environ.get("ST_BUILD_ROOT", os.path.join(SRC, "build"))
MODELS = os.environ.get("ST_MODEL_DIR", os.path.join(SRC, ".cache", "models"))


def box(size, centre=(0.0, 0.0, 0.0)):
    """A closed box mesh (12 faces, outward counter-clockwise), as numpy arrays."""
    sx, sy, sz = (s / 2 for s in size)
    v = np.array([[x, y, z] for x in (-sx, sx) for y in (-sy, sy) for z in (-sz, sz)]) + np.array(centre)
    f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    return v, f


def translation(x, y, z):
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


def rot_z(deg):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    m = np.eye(4)
    m[:2, :2] = [[c, -s], [s, c]]
    return m


def expect_error(fn, *words):
    try:
        fn()
    except ValueError as e:
        msg = str(e)
        for w in words:
            assert w in msg, f"error {msg!r} does not name {w!r}"
        return msg
    raise AssertionError("no ValueError raised")


def test_mesh_from_arrays_and_errors():
    v, f = box((10, 10, 10))
    m = st.Mesh(v, f, name="cube")
    assert m.num_vertices == 8 and m.num_faces == 12
    assert np.allclose(m.vertices, v) and (m.faces == f).all()
    expect_error(lambda: st.Mesh(v, np.array([[0, 1, 8]]), name="bad"), "bad", "face 0", "8")
    expect_error(lambda: st.Mesh(v[:, :2], f), "vertices")
    nan = v.copy()
    nan[3, 1] = float("nan")
    expect_error(lambda: st.Mesh(nan, f, name="nanmesh"), "nanmesh")


def test_boxes_touch_exactly_when_they_overlap():
    a = st.Body(st.Mesh(*box((10, 10, 10)), name="a"))
    b = st.Body(st.Mesh(*box((10, 10, 10)), name="b"))
    c = st.ComputeCollision(a, b)
    # Overlapping by 1 mm along x: the faces cross; 11 mm apart: nothing.
    r = c.query(translation(9, 0.5, 0.25))
    assert r.colliding and r.complete and len(r.pairs) > 0
    assert r.contacts == r.probe_faces + r.object_faces
    assert not c.query(translation(11, 0, 0)).colliding
    # Body frames: the same relative pose expressed as two world frames gives the same pairs.
    a.frame = translation(100, 200, 300) @ translation(9, 0.5, 0.25)
    b.frame = translation(100, 200, 300)
    c2 = st.ComputeCollision(a, b)
    assert (c2.query().pairs == r.pairs).all()
    # first pair only, and a cap.
    first = c.query(translation(9, 0.5, 0.25), max_pairs=1)
    assert len(first.pairs) == 1 and not first.complete
    assert tuple(first.pairs[0]) in {tuple(p) for p in r.pairs}
    capped = c.query(translation(9, 0.5, 0.25), max_pairs=3)
    assert len(capped.pairs) == min(3, len(r.pairs))
    expect_error(lambda: c.query(translation(9, 0, 0), max_pairs=0), "max_pairs")
    # Approximate mode reports a superset of the exact pairs.
    approx = c.query(translation(9, 0.5, 0.25), approximate_layer=st.LEAF_SPHERES)
    assert {tuple(p) for p in r.pairs} <= {tuple(p) for p in approx.pairs}


def test_bad_poses_are_refused_with_a_message():
    m = st.Mesh(*box((1, 1, 1)))
    c = st.ComputeCollision(st.Body(m), st.Body(m))
    bad = np.eye(4)
    bad[0, 0] = 2.0
    expect_error(lambda: c.query(bad), "pose", "orthonormal")
    refl = np.eye(4)
    refl[0, 0] = -1.0
    expect_error(lambda: c.query(refl), "reflection")
    nan = np.eye(4)
    nan[1, 3] = float("nan")
    expect_error(lambda: c.query(nan), "finite")
    expect_error(lambda: c.pairs(np.eye(3)), "4x4")
    expect_error(lambda: c.batch(np.stack([np.eye(4), bad])), "poses[1]")


def query_reference(probe, obj, poses):
    """Pairs per pose from `spheretouch query` (the CLI's exact query), as sets."""
    exe = os.path.join(BUILD, "spheretouch")
    with tempfile.NamedTemporaryFile("w", suffix=".txt", delete=False) as fh:
        for p in poses:
            fh.write(" ".join(repr(float(x)) for x in p.reshape(-1)) + "\n")
        path = fh.name
    try:
        out = subprocess.run([exe, "query", probe, obj, "--poses", path], check=True, capture_output=True,
                             text=True).stdout
    finally:
        os.unlink(path)
    result, cur = [], None
    for line in out.splitlines():
        w = line.split()
        if w and w[0] == "pose":
            cur = []
            result.append(cur)
        elif len(w) == 2 and cur is not None:
            cur.append((int(w[0]), int(w[1])))
    return result


def perf_poses():
    rows = []
    with open(os.path.join(SRC, "perf", "poses", "hand_elephant.txt")) as fh:
        for line in fh:
            line = line.split("#")[0].split()
            if len(line) == 16:
                rows.append(np.array([float(x) for x in line]).reshape(4, 4))
    return rows


def test_hand_elephant_pairs_match_the_command_line():
    hand = os.path.join(MODELS, "hand_L2.off")
    elephant = os.path.join(MODELS, "elephant.off")
    probe, obj = st.load_mesh(hand), st.load_mesh(elephant)
    assert probe.num_faces > 10000 and obj.num_faces > 10000
    c = st.ComputeCollision(st.Body(probe), st.Body(obj))
    poses = perf_poses()[::3]
    ref = query_reference(hand, elephant, poses)
    assert len(ref) == len(poses)
    batch = c.batch(np.stack(poses))
    touching = 0
    for i, p in enumerate(poses):
        one = c.pairs(p)
        assert [tuple(x) for x in one] == ref[i], f"pose {i}: {len(one)} pairs, the command line gives {len(ref[i])}"
        assert (batch[i] == one).all()
        touching += len(ref[i]) > 0
    assert touching > 0, "no perf pose touches: the check would prove nothing"


def test_coherent_queries_give_the_plain_pairs_along_a_slide():
    probe = st.load_mesh(os.path.join(MODELS, "hand_L2.off"))
    obj = st.load_mesh(os.path.join(MODELS, "elephant.off"))
    start = perf_poses()[1]
    # 0.01 mm a query along x and back, as a haptic loop moves (80 poses).
    steps = list(range(40)) + list(range(40, 0, -1))
    slide = np.stack([translation(0.01 * k, 0.0, 0.0) @ start for k in steps])
    plain = st.ComputeCollision(st.Body(probe), st.Body(obj))
    coherent = st.ComputeCollision(st.Body(probe), st.Body(obj))
    assert coherent.coherent_stats is None
    coherent.set_coherent(True, arbitrate=False)
    want, got = plain.batch(slide), coherent.batch(slide)
    assert sum(len(w) for w in want) > 0, "the slide touches nothing: the check would prove nothing"
    for i, (w, g) in enumerate(zip(want, got)):
        assert w.shape == g.shape and (w == g).all(), f"pose {i}: {len(g)} pairs, the plain query gives {len(w)}"
    stats = coherent.coherent_stats
    assert stats is not None and stats["rounds"] == len(slide)
    assert stats["reused"] > 0 and stats["plain_rounds"] < len(slide)
    assert 0 < stats["peak_bytes"] <= stats["bytes"]
    coherent.set_coherent(False)
    assert coherent.coherent_stats is None
    assert (coherent.pairs(slide[5]) == want[5]).all()
    expect_error(lambda: coherent.set_coherent(True, reach_mm=-1.0), "reach_mm", ">= 0")
    expect_error(lambda: coherent.set_coherent(True, max_step_mm=float("nan")), "max_step_mm")
    expect_error(lambda: coherent.set_coherent(True, max_bytes=0), "max_bytes")


def test_contact_model_and_force():
    # A 20 mm box pressed 2 mm into a 100 mm box's top face: FD = +z, PD = 2 mm (patch model).
    big = st.Mesh(*box((100, 100, 100)), name="object")
    small = st.Mesh(*box((20, 20, 20)), name="probe")
    c = st.ComputeCollision(st.Body(small), st.Body(big))
    pose = translation(3, -4, 50 + 10 - 2)
    pairs = c.pairs(pose)
    assert len(pairs) > 0
    builder = st.ContactBuilder()
    model = builder.build(small, big, pose, pairs)
    assert model.in_contact
    assert np.allclose(model.force_dir, [0, 0, 1], atol=1e-9), model.force_dir
    assert abs(model.penetration_mm - 2.0) < 1e-9, model.penetration_mm
    # The force acts at the pressed square's middle, on the top face: under the probe's centre.
    assert np.allclose(model.pressure_point, [3, -4, 50], atol=1e-9), model.pressure_point
    law = st.ForceLaw()
    f = law.force(model)
    assert np.allclose(f, law.magnitude(2.0) * np.array([0, 0, 1.0]))
    assert 0 < law.magnitude(2.0) <= law.magnitude(3.0)
    # The paper's model is selectable and gives the same face normal on a flat face.
    paper = st.ContactBuilder("paper").build(small, big, pose, pairs)
    assert paper.in_contact and np.allclose(paper.force_dir, [0, 0, 1])
    expect_error(lambda: st.ContactBuilder("nearest"), "nearest")
    # No pairs: no contact, zero force. Bad pair indices: finite, flagged, never a crash.
    none = st.ContactBuilder().build(small, big, pose, np.zeros((0, 2), dtype=np.uint32))
    assert not none.in_contact and (law.force(none) == 0).all()
    # Out-of-range pair indices: a clear error naming the row and the range (not a flagged model).
    expect_error(lambda: st.ContactBuilder().build(small, big, pose, np.array([[99999, 0]])),
                 "pairs: row 0: probe face 99999 out of range [0, 12)")
    expect_error(lambda: st.ContactBuilder().build(small, big, pose, np.array([[0, 0], [1, -1]])),
                 "pairs: row 1: object face -1 out of range")
    for pd in (float("nan"), -1.0, float("inf"), 1e300):
        assert 0 <= law.magnitude(pd) <= 3.3 + 1e-12


def test_file_errors_name_the_file():
    with tempfile.NamedTemporaryFile("w", suffix=".off", delete=False) as fh:
        fh.write("OFF\n3 1 0\n0 0 0\n1 0 0\n")
        path = fh.name
    try:
        expect_error(lambda: st.load_mesh(path), os.path.basename(path))
    finally:
        os.unlink(path)
    expect_error(lambda: st.load_mesh(path + ".missing.off"), "missing")


def test_names_version_and_constants_match_cpp():
    assert st.Collider is st.ComputeCollision  # the earlier name, kept as an alias
    parts = st.__version__.split(".")
    assert len(parts) == 3 and all(p.isdigit() for p in parts), st.__version__
    # ContactModel.flags bits, as in C++ (st::geom::kInContact = 1 << 0, ...).
    assert (st.IN_CONTACT, st.NORMALS_DISAGREE, st.REPLANED, st.DEGENERATE_SKIPPED, st.BAD_INPUT, st.HELD,
            st.NORMAL_FALLBACK, st.INSIDE_CAPPED, st.PLANES) == tuple(1 << i for i in range(9))
    v, f = box((10, 10, 10))
    m = st.Mesh(v, f)
    pose = translation(0, 0, 9.0)  # 1 mm deep on a 10 mm box against itself
    model = st.ContactBuilder().build(m, m, pose, st.ComputeCollision(st.Body(m), st.Body(m)).pairs(pose))
    assert model.flags & st.IN_CONTACT


def test_every_public_name_has_a_docstring():
    missing = []
    for name in st.__all__:
        obj = getattr(st, name)
        if isinstance(obj, (int, str)):
            continue
        if not (obj.__doc__ or "").strip():
            missing.append(name)
        if isinstance(obj, type):
            for attr, member in vars(obj).items():
                if attr.startswith("_"):
                    continue
                if not (getattr(member, "__doc__", None) or "").strip():
                    missing.append(f"{name}.{attr}")
    assert not missing, f"no docstring: {missing}"


def test_float_indices_and_bad_shapes_are_refused_briefly():
    v, f = box((10, 10, 10))
    expect_error(lambda: st.Mesh(v, f.astype(np.float64)), "faces: expected integer indices, got dtype float64")
    expect_error(lambda: st.Mesh(v, f[:, :2]), "faces: expected an (m, 3) array, got shape (12, 2)")
    m = st.Mesh(v, f)
    c = st.ComputeCollision(st.Body(m), st.Body(m))
    big = np.zeros(10000)
    msg = expect_error(lambda: c.pairs(big), "pose: expected a 4x4 array, got shape (10000,)")
    assert len(msg) < 120, msg  # the array is never printed
    expect_error(lambda: c.batch(np.zeros((2, 3, 4))), "poses: expected an (N, 4, 4) array, got shape (2, 3, 4)")
    expect_error(lambda: st.ContactBuilder().build(m, m, np.eye(4), np.array([[0.0, 1.0]])),
                 "pairs: expected integer indices, got dtype float64")


def test_one_object_from_two_threads_takes_turns():
    import threading
    v, f = box((10, 10, 10))
    m = st.Mesh(v, f)
    c = st.ComputeCollision(st.Body(m), st.Body(m))
    poses = [translation(0.1 * i, 0.05 * i, 9.5 - 0.01 * i) for i in range(40)]
    want = [c.pairs(p).tolist() for p in poses]
    wrong = []
    builder = st.ContactBuilder()

    def work(offset):
        for k in range(300):
            i = (k + offset) % len(poses)
            got = c.pairs(poses[i]).tolist()
            if got != want[i]:
                wrong.append(i)
            model = builder.build(m, m, poses[i], np.array(got, dtype=np.int64).reshape(-1, 2))
            if not np.isfinite(model.force_dir).all():
                wrong.append(-1)

    threads = [threading.Thread(target=work, args=(t * 7,)) for t in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not wrong, f"{len(wrong)} wrong answers from a shared ComputeCollision/ContactBuilder"


def test_a_world_of_several_objects_answers_per_object_as_single_colliders_do():
    # Three boxes placed by their frames; the probe box overlaps the first two at once, never the third.
    probe = st.Body(st.Mesh(*box((6, 6, 6)), name="probe"))
    objs = [st.Body(st.Mesh(*box((10, 10, 10)), name=f"o{k}"), frame=f)
            for k, f in enumerate([translation(-4, 0, 0), translation(4, 0, 0) @ rot_z(30), translation(500, 0, 0)])]
    w = st.World(probe, objs)
    assert len(w) == 3
    pose = translation(0, 0, 0)
    results = w.query(pose)
    assert len(results) == 3
    assert results[0].colliding and results[1].colliding and not results[2].colliding
    assert w.reached == [0, 1]  # the far box is out of the probe's reach: not collided at all
    # Each object's pairs are a single collider's at the relative pose (object frame^-1 . pose).
    for k, o in enumerate(objs):
        single = st.ComputeCollision(probe, st.Body(o.mesh)).pairs(np.linalg.inv(o.frame) @ pose)
        assert np.array_equal(results[k].pairs, single), k
    # The probe body's own frame when no pose is given.
    w2 = st.World(st.Body(probe.mesh, frame=translation(505, 0, 0)), objs)  # across the far box's face
    r2 = w2.query()
    assert [r.colliding for r in r2] == [False, False, True]
    expect_error(lambda: st.World(probe, []), "objects")


def test_a_clear_message_when_numpy_is_missing():
    code = "import sys; sys.modules['numpy'] = None\ntry:\n    import spheretouch\nexcept ImportError as e:\n    print(e)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=dict(os.environ))
    assert "spheretouch needs numpy" in out.stdout, out.stdout + out.stderr


def test_load_mesh_warns_when_the_size_is_implausible_for_its_units():
    import warnings
    with tempfile.NamedTemporaryFile("w", suffix=".off", delete=False) as fh:
        v, f = box((0.2, 0.2, 0.2))  # a 20 cm box written in metres
        fh.write(f"OFF\n{len(v)} {len(f)} 0\n")
        fh.writelines(f"{x} {y} {z}\n" for x, y, z in v)
        fh.writelines(f"3 {a} {b} {c}\n" for a, b, c in f)
        path = fh.name
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            st.load_mesh(path)
            st.load_mesh(path, units="m")
        msgs = [str(w.message) for w in caught]
        assert len(msgs) == 1 and "implausibly small" in msgs[0] and 'units = "m"' in msgs[0], msgs
    finally:
        os.unlink(path)


def test_load_mesh_winds_a_file_written_inside_out_outward_unless_told_not_to():
    with tempfile.NamedTemporaryFile("w", suffix=".off", delete=False) as fh:
        v, f = box((100.0, 100.0, 100.0))
        fh.write(f"OFF\n{len(v)} {len(f)} 0\n")
        fh.writelines(f"{x} {y} {z}\n" for x, y, z in v)
        fh.writelines(f"3 {a} {c} {b}\n" for a, b, c in f)  # every face wound clockwise from outside
        path = fh.name
    try:
        def signed_volume(mesh):
            p = mesh.vertices[mesh.faces.astype(np.int64)]
            return float(np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum()) / 6
        fixed, as_read = st.load_mesh(path), st.load_mesh(path, orient=False)
        assert math.isclose(signed_volume(fixed), 1e6, rel_tol=1e-9), signed_volume(fixed)
        assert math.isclose(signed_volume(as_read), -1e6, rel_tol=1e-9), signed_volume(as_read)
        assert np.array_equal(fixed.faces[:, 0], as_read.faces[:, 0])  # no face renumbered
    finally:
        os.unlink(path)


def main():
    tests = [(k, v) for k, v in sorted(globals().items()) if k.startswith("test_") and callable(v)]
    passed = failed = 0
    for name, fn in tests:
        try:
            fn()
            passed += 1
            print(f"ok   {name}")
        except Exception:  # noqa: BLE001 - report every failure, then fail the run
            failed += 1
            print(f"FAIL {name}")
            traceback.print_exc()
    print(f"[python] test cases: {len(tests)} | {passed} passed | {failed} failed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
