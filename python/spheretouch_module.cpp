// SPDX-License-Identifier: BSD-3-Clause
// spheretouch._core, the C++ half of the `spheretouch` Python package (pybind11, numpy): meshes
// from arrays or files, sphere trees, exact collision queries for one pose or a batch, the contact
// models and the force law, named as in C++ (ComputeCollision, ContactBuilder, ...).
// Conventions: arrays are numpy; poses are 4x4 float64 rigid transforms (probe frame -> object
// frame, mm); face pairs are (k, 2) uint32 arrays of (probe face, object face) file indices.
// Errors raise ValueError with a short message (the file, field, row or index at fault; never the
// array). Threads: queries release the GIL; an object used from two threads at once serialises
// on its own lock (a ComputeCollision or ContactBuilder keeps scratch between calls).
#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cmath>
#include <memory>
#include <mutex>
#include <sstream>
#include <string>
#include <vector>

#include <spheretouch/geom/contact.hpp>
#include <spheretouch/geom/mesh_io.hpp>
#include <spheretouch/geom/pose_io.hpp>
#include <spheretouch/rt/force_law.hpp>
#include <spheretouch/collide.hpp>
#include <spheretouch/version.hpp>

namespace py = pybind11;
using namespace st;

namespace {

template <class T>
T take(Result<T> r) {
  if (!r.ok()) throw py::value_error(r.error());
  return std::move(r).value();
}

using Array3d = py::array_t<double, py::array::c_style | py::array::forcecast>;
using IndexArray = py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>;

// "(3,)", "(2, 4, 4)": an array's shape for a message (the array itself is never printed).
std::string shape_of(const py::array& a) {
  std::ostringstream os;
  os << '(';
  for (py::ssize_t i = 0; i < a.ndim(); ++i) os << (i ? ", " : "") << a.shape(i);
  os << (a.ndim() == 1 ? ",)" : ")");
  return os.str();
}

// Indices must come as integers: a float array would be truncated silently by the cast.
IndexArray index_array(const py::handle& h, const std::string& what) {
  const py::array a = py::array::ensure(h);
  if (!a) throw py::value_error(what + ": expected an integer array");
  const char kind = a.dtype().kind();
  if (a.size() > 0 && kind != 'i' && kind != 'u')
    throw py::value_error(what + ": expected integer indices, got dtype " + std::string(py::str(a.dtype())));
  return IndexArray::ensure(a);
}

Pose to_pose(const Array3d& a, const char* what) {
  if (a.ndim() != 2 || a.shape(0) != 4 || a.shape(1) != 4)
    throw py::value_error(std::string(what) + ": expected a 4x4 array, got shape " + shape_of(a));
  Eigen::Matrix4d m;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) m(r, c) = a.at(r, c);
  if (const std::string why = geom::check_rigid(m); !why.empty()) throw py::value_error(std::string(what) + ": " + why);
  Pose p;
  p.matrix() = m;
  return p;
}

py::array_t<double> to_array(const Pose& p) {
  py::array_t<double> a({4, 4});
  auto w = a.mutable_unchecked<2>();
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) w(r, c) = p.matrix()(r, c);
  return a;
}

py::array_t<double> to_array(const Vec3& v) {
  py::array_t<double> a(3);
  auto w = a.mutable_unchecked<1>();
  for (int i = 0; i < 3; ++i) w(i) = v[i];
  return a;
}

py::array_t<std::uint32_t> pairs_array(const std::vector<FacePair>& pairs) {
  py::array_t<std::uint32_t> a({static_cast<py::ssize_t>(pairs.size()), py::ssize_t{2}});
  auto w = a.mutable_unchecked<2>();
  for (std::size_t i = 0; i < pairs.size(); ++i) {
    w(static_cast<py::ssize_t>(i), 0) = pairs[i].probe;
    w(static_cast<py::ssize_t>(i), 1) = pairs[i].object;
  }
  return a;
}

// (k, 2) integer pairs (probe face, object face), each index checked against its mesh.
std::vector<FacePair> pairs_from(const py::handle& h, std::size_t probe_faces, std::size_t object_faces) {
  const IndexArray a = index_array(h, "pairs");
  if (a.ndim() != 2 || (a.shape(1) != 2 && a.shape(0) != 0))
    throw py::value_error("pairs: expected a (k, 2) array, got shape " + shape_of(a));
  std::vector<FacePair> out;
  out.reserve(static_cast<std::size_t>(a.shape(0)));
  auto r = a.unchecked<2>();
  for (py::ssize_t i = 0; i < a.shape(0); ++i) {
    const std::int64_t p = r(i, 0), o = r(i, 1);
    if (p < 0 || static_cast<std::uint64_t>(p) >= probe_faces)
      throw py::value_error("pairs: row " + std::to_string(i) + ": probe face " + std::to_string(p) +
                            " out of range [0, " + std::to_string(probe_faces) + ")");
    if (o < 0 || static_cast<std::uint64_t>(o) >= object_faces)
      throw py::value_error("pairs: row " + std::to_string(i) + ": object face " + std::to_string(o) +
                            " out of range [0, " + std::to_string(object_faces) + ")");
    out.push_back({static_cast<std::uint32_t>(p), static_cast<std::uint32_t>(o)});
  }
  return out;
}

std::shared_ptr<Mesh> mesh_from_arrays(const Array3d& vertices, const py::handle& face_array, const std::string& name) {
  if (vertices.ndim() != 2 || vertices.shape(1) != 3)
    throw py::value_error(name + ": vertices: expected an (n, 3) array, got shape " + shape_of(vertices));
  const IndexArray faces = index_array(face_array, name + ": faces");
  if (faces.ndim() != 2 || faces.shape(1) != 3)
    throw py::value_error(name + ": faces: expected an (m, 3) array, got shape " + shape_of(faces));
  std::vector<Vec3> pos(static_cast<std::size_t>(vertices.shape(0)));
  auto v = vertices.unchecked<2>();
  for (py::ssize_t i = 0; i < vertices.shape(0); ++i)
    pos[static_cast<std::size_t>(i)] = Vec3(v(i, 0), v(i, 1), v(i, 2));
  std::vector<geom::Tri> tris(static_cast<std::size_t>(faces.shape(0)));
  auto f = faces.unchecked<2>();
  for (py::ssize_t i = 0; i < faces.shape(0); ++i)
    for (int k = 0; k < 3; ++k) {
      const std::int64_t x = f(i, k);
      if (x < 0 || x >= vertices.shape(0))
        throw py::value_error(name + ": face " + std::to_string(i) + ": vertex index " + std::to_string(x) +
                              " out of range [0, " + std::to_string(vertices.shape(0)) + ")");
      tris[static_cast<std::size_t>(i)][static_cast<std::size_t>(k)] = static_cast<std::uint32_t>(x);
    }
  auto mesh = std::make_shared<Mesh>(geom::make_mesh(name, pos, std::move(tris)));
  if (Status s = mesh->validate(); !s.ok()) throw py::value_error(name + ": " + s.error());
  return mesh;
}

py::array_t<double> vertices_array(const Mesh& m) {
  py::array_t<double> a({static_cast<py::ssize_t>(m.num_vertices()), py::ssize_t{3}});
  auto w = a.mutable_unchecked<2>();
  for (std::size_t i = 0; i < m.num_vertices(); ++i) {
    const Vec3 p = m.vertex(static_cast<std::uint32_t>(i));
    for (int k = 0; k < 3; ++k) w(static_cast<py::ssize_t>(i), k) = p[k];
  }
  return a;
}

py::array_t<std::uint32_t> faces_array(const Mesh& m) {
  py::array_t<std::uint32_t> a({static_cast<py::ssize_t>(m.num_faces()), py::ssize_t{3}});
  auto w = a.mutable_unchecked<2>();
  for (std::size_t i = 0; i < m.num_faces(); ++i)
    for (int k = 0; k < 3; ++k) w(static_cast<py::ssize_t>(i), k) = m.faces[i][static_cast<std::size_t>(k)];
  return a;
}

CollisionRequest make_request(std::optional<std::size_t> max_pairs, std::optional<int> approximate_layer, bool sort) {
  CollisionRequest r = DefaultCollisionRequest();
  if (max_pairs) r.max_pairs = *max_pairs;
  if (approximate_layer) r.approximate_layer = *approximate_layer;
  r.sort_pairs = sort;
  if (const std::string why = check(r); !why.empty()) throw py::value_error(why);
  return r;
}

py::dict stats_dict(const CollideStats& s) {
  py::dict d;
  d["node_pairs"] = s.node_pairs;
  d["leaf_pairs"] = s.leaf_pairs;
  d["tri_pairs"] = s.tri_pairs;
  d["tri_exact"] = s.tri_exact;
  d["sphere_pairs"] = s.sphere_pairs;
  d["probe_leaves"] = s.probe_leaves;
  d["truncated"] = s.truncated;
  d["pair_limit_hit"] = s.pair_limit_hit;
  d["work_limit_hit"] = s.work_limit_hit;
  return d;
}

// A ComputeCollision or ContactBuilder with the lock that serialises its users: calls release
// the GIL, so two Python threads could otherwise run one object's scratch at once.
struct PyComputeCollision {
  ComputeCollision c;
  std::mutex mu;
};
struct PyContactBuilder {
  geom::ContactBuilder b;
  std::mutex mu;
};
// A probe among several objects: one collider per object (made on its first reach), each object's
// bounding sphere in the world tested first. Serialised like the others.
struct PyWorld {
  Body probe;
  std::vector<Body> objects;
  std::vector<std::optional<ComputeCollision>> colliders;
  std::vector<std::uint32_t> reached;  ///< the last query's objects within reach
  std::mutex mu;
};

}  // namespace

PYBIND11_MODULE(_core, m) {
  m.doc() =
      "spheretouch: exact face-level collision of large meshes (layered boundary spheres), contact models "
      "and force law. Poses are 4x4 rigid transforms in mm (probe frame -> object frame).";
  m.attr("__version__") = SPHERETOUCH_VERSION_STRING;
  m.attr("EXACT") = geom::kExact;
  m.attr("LEAF_SPHERES") = geom::kLeafSpheres;
  // ContactModel.flags bits (C++: st::geom::kInContact, ...).
  m.attr("IN_CONTACT") = std::uint32_t{geom::kInContact};
  m.attr("NORMALS_DISAGREE") = std::uint32_t{geom::kNormalsDisagree};
  m.attr("REPLANED") = std::uint32_t{geom::kReplaned};
  m.attr("DEGENERATE_SKIPPED") = std::uint32_t{geom::kDegenerateSkipped};
  m.attr("BAD_INPUT") = std::uint32_t{geom::kBadInput};
  m.attr("HELD") = std::uint32_t{geom::kHeld};
  m.attr("NORMAL_FALLBACK") = std::uint32_t{geom::kNormalFallback};
  m.attr("INSIDE_CAPPED") = std::uint32_t{geom::kInsideCapped};
  m.attr("PLANES") = std::uint32_t{geom::kPlanes};

  py::class_<Mesh, std::shared_ptr<Mesh>>(m, "Mesh",
                                          "An indexed triangle mesh (mm); face i is the file's i-th triangle.")
      .def(py::init(&mesh_from_arrays), py::arg("vertices"), py::arg("faces"), py::arg("name") = "array",
           "From an (n, 3) float array of vertices and an (m, 3) int array of faces (counter-clockwise from outside).")
      .def_property_readonly("vertices", &vertices_array, "(n, 3) float64 copy of the vertices, body frame, mm")
      .def_property_readonly("faces", &faces_array, "(m, 3) uint32 copy of the faces")
      .def_property_readonly("num_vertices", &Mesh::num_vertices, "number of vertices")
      .def_property_readonly("num_faces", &Mesh::num_faces, "number of triangles")
      .def_readonly("name", &Mesh::name, "the mesh's name (its file, or the name given)")
      .def("__repr__", [](const Mesh& me) {
        return "<spheretouch.Mesh '" + me.name + "' " + std::to_string(me.num_vertices()) + " vertices, " +
               std::to_string(me.num_faces()) + " faces>";
      });

  m.def(
      "load_mesh",
      [](const std::string& path, const std::string& units, double scale, bool orient) {
        geom::LoadConfig o;
        o.units = units;
        o.scale = scale;
        o.orient = orient;
        geom::LoadedMesh lm = take(geom::load_mesh(path, o));
        if (!lm.report.size_warning.empty() && PyErr_WarnEx(PyExc_UserWarning, lm.report.size_warning.c_str(), 1) < 0)
          throw py::error_already_set();  // warnings turned into errors
        return std::make_shared<Mesh>(std::move(lm.mesh));
      },
      py::arg("path"), py::arg("units") = "mm", py::arg("scale") = 1.0, py::arg("orient") = true,
      "Reads a mesh file (OFF, OBJ, PLY, STL; other formats through assimp). units: um, mm, cm, m, in. orient: "
      "make the faces' winding consistent and outward, as the force needs (False keeps the file's). Warns "
      "(UserWarning) when the object's size is implausible in those units (a mesh in metres read as mm).");

  py::class_<SphereTree, std::shared_ptr<SphereTree>>(m, "SphereTree", "Layered boundary spheres over one mesh.")
      .def(py::init([](const Mesh& mesh, std::uint32_t leaf_faces) {
             TreeConfig p = geom::DefaultTreeConfig();
             p.leaf_faces = leaf_faces;
             return std::make_shared<SphereTree>(take(SphereTree::build(mesh, p)));
           }),
           py::arg("mesh"), py::arg("leaf_faces") = geom::DefaultTreeConfig().leaf_faces,
           "Builds the tree; every leaf holds at most leaf_faces (1..64) faces.")
      .def_property_readonly("num_nodes", &SphereTree::num_nodes, "spheres in the tree")
      .def_property_readonly("num_leaves", &SphereTree::num_leaves, "leaf spheres (each holds a few faces)")
      .def_property_readonly(
          "num_layers", [](const SphereTree& t) { return t.num_depths; }, "layers, root = 0")
      .def_property_readonly("num_faces", &SphereTree::num_faces, "faces under the tree");

  py::class_<Body>(m, "Body", "A mesh, its tree and its frame (body frame -> world, 4x4).")
      .def(py::init([](std::shared_ptr<Mesh> mesh, std::shared_ptr<SphereTree> tree, const Array3d& frame) {
             if (!mesh) throw py::value_error("Body: mesh is None");
             if (!tree) {
               tree = std::make_shared<SphereTree>(take(SphereTree::build(*mesh, geom::DefaultTreeConfig())));
             }
             return take(Body::make(std::move(mesh), std::move(tree), to_pose(frame, "frame")));
           }),
           py::arg("mesh"), py::arg("tree") = nullptr, py::arg("frame") = py::array_t<double>(to_array(Pose::Identity())),
           "A body; the tree is built with the default leaf size when not given.")
      .def_property(
          "frame", [](const Body& b) { return to_array(b.frame()); },
          [](Body& b, const Array3d& f) { b.set_frame(to_pose(f, "frame")); }, "body frame -> world, 4x4")
      .def_property_readonly(
          "mesh", [](const Body& b) { return std::const_pointer_cast<Mesh>(b.shared_mesh()); }, "the body's mesh");

  py::class_<CollisionResult>(m, "CollisionResult", "What one query found.")
      .def_property_readonly(
          "pairs", [](const CollisionResult& r) { return pairs_array(r.pairs); },
          "(k, 2) uint32: (probe face, object face)")
      .def_property_readonly("colliding", &CollisionResult::colliding, "True when any pair was found")
      .def_property_readonly("contacts", &CollisionResult::contacts, "distinct probe faces + distinct object faces")
      .def_readonly("probe_faces", &CollisionResult::probe_faces, "distinct probe faces in pairs")
      .def_readonly("object_faces", &CollisionResult::object_faces, "distinct object faces in pairs")
      .def_readonly("complete", &CollisionResult::complete, "False when the query stopped at max_pairs")
      .def_property_readonly(
          "stats", [](const CollisionResult& r) { return stats_dict(r.stats); },
          "traversal counters: node_pairs, leaf_pairs, tri_pairs, tri_exact, sphere_pairs, probe_leaves, truncated, "
          "pair_limit_hit, work_limit_hit");

  py::class_<PyComputeCollision>(
      m, "ComputeCollision",
      "Collision of one (probe, object) pair with its scratch kept between queries. Calls "
      "from several threads on one object take turns; use one per thread to run in parallel.")
      .def(py::init([](Body probe, Body object) {
             return std::unique_ptr<PyComputeCollision>(
                 new PyComputeCollision{ComputeCollision(std::move(probe), std::move(object)), {}});
           }),
           py::arg("probe"), py::arg("object"), "The pair to collide; the caches are sized on the first query.")
      .def(
          "query",
          [](PyComputeCollision& c, const std::optional<Array3d>& pose, std::optional<std::size_t> max_pairs,
             std::optional<int> approximate_layer, bool sort) {
            const CollisionRequest req = make_request(max_pairs, approximate_layer, sort);
            CollisionResult r;
            const std::optional<Pose> p = pose ? std::optional<Pose>(to_pose(*pose, "pose")) : std::nullopt;
            py::gil_scoped_release unlock;
            std::lock_guard<std::mutex> lock(c.mu);
            if (p)
              c.c.at_relative(*p, req, r);
            else
              c.c(req, r);
            return r;
          },
          py::arg("pose") = py::none(), py::arg("max_pairs") = py::none(), py::arg("approximate_layer") = py::none(),
          py::arg("sort") = true,
          "Collides at `pose` (probe frame -> object frame), or at the bodies' frames when pose is None.")
      .def(
          "pairs",
          [](PyComputeCollision& c, const Array3d& pose, std::optional<std::size_t> max_pairs) {
            const CollisionRequest req = make_request(max_pairs, std::nullopt, true);
            const Pose p = to_pose(pose, "pose");
            CollisionResult r;
            {
              py::gil_scoped_release unlock;
              std::lock_guard<std::mutex> lock(c.mu);
              c.c.at_relative(p, req, r);
            }
            return pairs_array(r.pairs);
          },
          py::arg("pose"), py::arg("max_pairs") = py::none(), "The sorted colliding pairs at one pose, (k, 2) uint32.")
      .def(
          "batch",
          [](PyComputeCollision& c, const py::array_t<double, py::array::c_style | py::array::forcecast>& poses,
             std::optional<std::size_t> max_pairs) {
            if (poses.ndim() != 3 || poses.shape(1) != 4 || poses.shape(2) != 4)
              throw py::value_error("poses: expected an (N, 4, 4) array, got shape " + shape_of(poses));
            const CollisionRequest req = make_request(max_pairs, std::nullopt, true);
            std::vector<Pose> ps(static_cast<std::size_t>(poses.shape(0)));
            auto a = poses.unchecked<3>();
            for (py::ssize_t i = 0; i < poses.shape(0); ++i) {
              Eigen::Matrix4d mm;
              for (int r = 0; r < 4; ++r)
                for (int k = 0; k < 4; ++k) mm(r, k) = a(i, r, k);
              if (const std::string why = geom::check_rigid(mm); !why.empty())
                throw py::value_error("poses[" + std::to_string(i) + "]: " + why);
              ps[static_cast<std::size_t>(i)].matrix() = mm;
            }
            std::vector<std::vector<FacePair>> out(ps.size());
            {
              py::gil_scoped_release unlock;
              std::lock_guard<std::mutex> lock(c.mu);
              CollisionResult r;
              for (std::size_t i = 0; i < ps.size(); ++i) {
                c.c.at_relative(ps[i], req, r);
                out[i] = r.pairs;
              }
            }
            py::list l;
            for (const auto& p : out) l.append(pairs_array(p));
            return l;
          },
          py::arg("poses"), py::arg("max_pairs") = py::none(),
          "Sorted pairs for each of N poses ((N, 4, 4) array): a list of (k, 2) uint32 arrays.")
      .def(
          "set_coherent",
          [](PyComputeCollision& c, bool on, double reach_mm, double max_step_mm, std::size_t max_bytes, bool arbitrate) {
            auto distance = [](double v, const char* name) {
              if (!std::isfinite(v) || v < 0)
                throw py::value_error(std::string(name) + ": expected a finite distance >= 0 (0 = automatic), got " +
                                      std::to_string(v));
            };
            distance(reach_mm, "reach_mm");
            distance(max_step_mm, "max_step_mm");
            if (max_bytes == 0) throw py::value_error("max_bytes: expected at least 1");
            geom::CoherentConfig cfg;
            cfg.reach = reach_mm, cfg.max_step = max_step_mm, cfg.max_bytes = max_bytes, cfg.arbitrate = arbitrate;
            std::lock_guard<std::mutex> lock(c.mu);
            c.c.set_coherent(on, cfg);
          },
          py::arg("on") = true, py::arg("reach_mm") = 0.0, py::arg("max_step_mm") = 0.0,
          py::arg("max_bytes") = std::size_t(64) << 20, py::arg("arbitrate") = true,
          "Carry certificates between queries (the coherent collider): the same pairs, fewer tests "
          "while the probe moves a little between them (a haptic loop, a batch along a trajectory). "
          "reach_mm and max_step_mm: 0 = chosen from the probe's leaf size and the motion; max_bytes "
          "bounds its cache; arbitrate: time itself against the plain query and give way when slower.")
      .def_property_readonly(
          "coherent_stats",
          [](PyComputeCollision& c) -> py::object {
            std::lock_guard<std::mutex> lock(c.mu);
            const geom::CoherentCollider* k = c.c.coherent();
            if (!k) return py::none();
            const geom::CoherentStats& s = k->stats();
            py::dict d;
            d["rounds"] = s.rounds, d["plain_rounds"] = s.plain_rounds, d["rebuilds"] = s.rebuilds;
            d["reroots"] = s.reroots, d["expansions"] = s.expansions, d["refreshes"] = s.refreshes;
            d["deferred"] = s.deferred, d["reused"] = s.reused, d["retested"] = s.retested;
            d["overflows"] = s.overflows, d["gave_way"] = s.gave_way, d["entries"] = s.entries;
            d["candidates"] = s.candidates, d["peak_bytes"] = s.peak_bytes, d["bytes"] = k->bytes();
            return d;
          },
          "the coherent collider's counters (None when it is off): rounds, plain_rounds, rebuilds, reroots, "
          "expansions, refreshes, deferred, reused, retested, overflows, gave_way, entries, candidates, "
          "peak_bytes, bytes")
      .def_property_readonly(
          "probe", [](PyComputeCollision& c) { return c.c.probe(); }, "a copy of the probe body")
      .def_property_readonly(
          "object", [](PyComputeCollision& c) { return c.c.object(); }, "a copy of the object body");
  // The name of earlier releases, kept so existing scripts run: the same class.
  m.attr("Collider") = m.attr("ComputeCollision");

  py::class_<PyWorld>(
      m, "World",
      "A probe among several objects, each placed by its Body frame (object -> world): one query answers for "
      "every object, testing each object's bounding sphere first so objects out of reach cost one test. "
      "Calls from several threads take turns.")
      .def(py::init([](Body probe, std::vector<Body> objects) {
             if (objects.empty()) throw py::value_error("objects: expected at least one Body");
             auto w = std::unique_ptr<PyWorld>(new PyWorld{std::move(probe), std::move(objects), {}, {}, {}});
             w->colliders.resize(w->objects.size());
             return w;
           }),
           py::arg("probe"), py::arg("objects"), "The probe and the objects (their frames place them in the world).")
      .def(
          "query",
          [](PyWorld& w, const std::optional<Array3d>& pose, std::optional<std::size_t> max_pairs, bool sort) {
            const CollisionRequest req = make_request(max_pairs, std::nullopt, sort);
            const Pose p = pose ? to_pose(*pose, "pose") : w.probe.frame();
            std::vector<CollisionResult> out(w.objects.size());
            {
              py::gil_scoped_release unlock;
              std::lock_guard<std::mutex> lock(w.mu);
              w.reached.clear();
              const BoundingSphere probe = w.probe.bounding_sphere().moved(p);
              for (std::size_t k = 0; k < w.objects.size(); ++k) {
                if (!probe.meets(w.objects[k].bounding_sphere().moved(w.objects[k].frame()))) continue;
                w.reached.push_back(std::uint32_t(k));
                if (!w.colliders[k]) w.colliders[k].emplace(w.probe, w.objects[k]);
                w.colliders[k]->at_relative(w.objects[k].frame().inverse() * p, req, out[k]);
              }
            }
            return out;
          },
          py::arg("pose") = py::none(), py::arg("max_pairs") = py::none(), py::arg("sort") = true,
          "One CollisionResult per object (object face indices in its own file's order) for the probe at `pose` "
          "(probe frame -> world, 4x4; None: the probe body's frame). An object out of reach gets an empty result.")
      .def_property_readonly(
          "reached",
          [](PyWorld& w) {
            std::lock_guard<std::mutex> lock(w.mu);
            return w.reached;
          },
          "indices of the objects the last query's probe could reach (collided)")
      .def(
          "__len__", [](const PyWorld& w) { return w.objects.size(); }, "the number of objects");

  py::class_<geom::ContactModel>(m, "ContactModel", "FD, PD and the local contact plane of one round (object frame).")
      .def_property_readonly("in_contact", &geom::ContactModel::in_contact, "FD, PD and the plane are meaningful")
      .def_property_readonly(
          "force_dir", [](const geom::ContactModel& c) { return to_array(geom::to_eigen(c.force_dir)); },
          "FD: unit force direction, object frame")
      .def_readonly("penetration_mm", &geom::ContactModel::penetration_mm, "PD: penetration depth, mm")
      .def_property_readonly(
          "contact_point", [](const geom::ContactModel& c) { return to_array(geom::to_eigen(c.contact_point)); },
          "a point of the contact, object frame, mm")
      .def_property_readonly(
          "plane_point", [](const geom::ContactModel& c) { return to_array(geom::to_eigen(c.plane_point)); },
          "a point of the local contact plane (normal FD), object frame, mm")
      .def_property_readonly(
          "probe_point", [](const geom::ContactModel& c) { return to_array(geom::to_eigen(c.probe_point)); },
          "deepest probe point, probe frame")
      .def_property_readonly(
          "pressure_point", [](const geom::ContactModel& c) { return to_array(geom::to_eigen(c.pressure_point)); },
          "where the force acts, for its torque: the patch's centre on the contact plane, object frame, mm")
      .def_property_readonly(
          "proxy_offset", [](const geom::ContactModel& c) { return to_array(c.proxy_offset()); },
          "PD · FD: where the probe would rest outside the object, relative to its pose, mm")
      .def_readonly("flags", &geom::ContactModel::flags, "IN_CONTACT | HELD | PLANES | ... (module constants)")
      .def_readonly("contacts", &geom::ContactModel::contacts, "distinct probe faces + distinct object faces")
      .def_readonly("object_faces", &geom::ContactModel::object_faces, "distinct colliding object faces")
      .def_readonly("probe_faces", &geom::ContactModel::probe_faces, "distinct colliding probe faces");

  py::class_<PyContactBuilder>(m, "ContactBuilder",
                               "Builds contact models, keeping the model's history between rounds. Calls from several "
                               "threads on one builder take turns.")
      .def(py::init([](const std::string& model) {
             geom::ContactConfig c = geom::DefaultContactConfig();
             c.model = take(geom::parse_contact_model(model));
             return std::unique_ptr<PyContactBuilder>(new PyContactBuilder{geom::ContactBuilder(c), {}});
           }),
           py::arg("model") = "patch", "model: 'patch' (default) or 'paper' (paper §3.6)")
      .def(
          "build",
          [](PyContactBuilder& b, const Mesh& probe, const Mesh& object, const Array3d& pose, const py::handle& pairs) {
            const Pose p = to_pose(pose, "pose");
            const std::vector<FacePair> ps = pairs_from(pairs, probe.num_faces(), object.num_faces());
            py::gil_scoped_release unlock;
            std::lock_guard<std::mutex> lock(b.mu);
            return b.b.build(probe, object, p, ps);
          },
          py::arg("probe"), py::arg("object"), py::arg("pose"), py::arg("pairs"),
          "The contact model for the pairs found at pose (probe frame -> object frame).")
      .def(
          "reset",
          [](PyContactBuilder& b) {
            std::lock_guard<std::mutex> lock(b.mu);
            b.b.reset();
          },
          "Forgets the history (as if contact had ended).");

  py::class_<rt::ForceLaw>(m, "ForceLaw", "Force magnitude (N) from penetration depth (mm): paper eq. (1) or a spring.")
      .def(py::init([](const std::string& kind, std::optional<double> spring_N_per_mm, std::optional<double> max_force_N) {
             rt::ForceLawConfig c = rt::DefaultForceLawConfig();
             if (kind == "linear")
               c.kind = rt::LawKind::linear;
             else if (kind != "log")
               throw py::value_error("kind: expected 'log' or 'linear', got '" + kind + "'");
             if (spring_N_per_mm) c.spring_N_per_mm = *spring_N_per_mm;
             if (max_force_N) c.max_force_N = *max_force_N;
             return take(rt::ForceLaw::make(c));
           }),
           py::arg("kind") = "log", py::arg("spring_N_per_mm") = py::none(), py::arg("max_force_N") = py::none(),
           "kind: 'log' (paper eq. 1) or 'linear' (a spring of spring_N_per_mm); max_force_N caps it")
      .def("magnitude", &rt::ForceLaw::magnitude_N, py::arg("pd_mm"), "N, finite, in [0, max_force_N] for any input")
      .def(
          "force",
          [](const rt::ForceLaw& law, const geom::ContactModel& c) {
            if (!c.in_contact()) return to_array(Vec3::Zero());
            return to_array(law.magnitude_N(c.penetration_mm) * geom::to_eigen(c.force_dir));
          },
          py::arg("contact"), "The force vector at the model's own pose, N, object frame: magnitude(PD) · FD.")
      .def_property_readonly("max_stiffness_N_per_mm", &rt::ForceLaw::max_stiffness_N_per_mm,
                             "the law's largest slope, N/mm (sizes damping and passivity)");
}
