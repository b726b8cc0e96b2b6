// A step's rows of the collision limit in one call (sjt_pin/limits/collision.py, _rows): the
// geometries' placements, Pinocchio's exact distance queries of the listed pairs (called back
// through Python: pinocchio.computeDistance, or whatever the limit passes), their witness rows
// and the damper rows of them all.
#include <cmath>
#include <utility>
#include <limits>
#include <new>
#include <optional>
#include <sstream>

#include "collision.hpp"
#include "registry.hpp"

namespace sjt {

// What collision_rows reads and writes besides the step's (the limit's tables, built once; the
// arrays are changed in place only, and checked where collision_rows reads them).
struct CollisionTables {
  nb::object geometry, geometry_data, model, update;  // Pinocchio's, and its placements' update
  nb::object floor, margins, joints, rows;            // per pair; rows: the step's pair rows
  nb::object memory, state, owners;                   // the witnesses' (collision.hpp)
  nb::object support, mimic;                          // the damper rows' (mimic: None or (N, n))
  double keep, apart;                                 // the witnesses' bands (m)
  bool witnesses;                                     // whether witness rows follow the pairs'
};

namespace {

// Where a pair is apart by more than this (m) the normal is read off the points, (p_b - p_a) /
// |p_b - p_a|, as coal forms it (to 1e-14 on the bench's scenes): a vector read through Python
// costs per vector
constexpr double SEPARATED = 1e-6;
// coal's answer where it found no closest points (GJK/EPA deep in a penetration): a distance of
// -DBL_MAX and points near DBL_MAX, or no normal (two closest points that coincide)
constexpr double UNUSABLE = 1e300;

// coal's result's attribute and method names, interned once (they live as long as the process)
struct ResultNames {
  nb::handle distance, normal, point_a, point_b;
};

const ResultNames& result_names() {
  static const ResultNames names{PyUnicode_InternFromString("min_distance"),
                                 PyUnicode_InternFromString("normal"),
                                 PyUnicode_InternFromString("getNearestPoint1"),
                                 PyUnicode_InternFromString("getNearestPoint2")};
  if (!names.distance.ptr() || !names.normal.ptr() || !names.point_a.ptr() ||
      !names.point_b.ptr())
    throw std::bad_alloc();
  return names;
}

// result.name() (a method without arguments)
nb::object call_method(nb::handle result, nb::handle name) {
  PyObject* out = PyObject_CallMethodNoArgs(result.ptr(), name.ptr());
  if (!out) throw nb::python_error();
  return nb::steal(out);
}

double as_double(nb::handle value, const char* name) {
  double v = PyFloat_AsDouble(value.ptr());
  if (v == -1.0 && PyErr_Occurred()) {
    nb::python_error error;
    std::ostringstream out;
    out << name << " must be a number: " << error.what();
    throw nb::type_error(out.str().c_str());
  }
  return v;
}

// 3 numbers of coal's result (a normal or a closest point: a float64 array of 3)
void read3(nb::handle value, const char* name, double* out) {
  Array a(value, name, 1);
  a.length(3);
  Eigen::Map<Vector3> target(out);
  target = a.vector();
}

bool usable(const double* r) {
  for (Index c = row::normal; c < row::size; ++c)
    if (!(std::fabs(r[c]) < UNUSABLE)) return false;
  // a unit normal (not coal's zero one where the points coincide)
  return Eigen::Map<const Vector3>(r + row::normal).squaredNorm() > 0.25;
}

// The arrays of one collision_rows call, checked against each other before any is read
struct Checked {
  Array floor, margins, influence, rows, support;
  IndexArray joints;
  std::optional<Array> reach, mimic, memory, state, owners;
  Index npairs, njoints;
};

Checked check(const CollisionTables& t, nb::handle influence, nb::handle reach) {
  Checked c{Array(t.floor, "floor", 1, Access::write),
            Array(t.margins, "margins", 1),
            Array(influence, "influence", 1),
            Array(t.rows, "rows", 2, Access::write),
            Array(t.support, "support", 2),
            IndexArray(t.joints, "joints", 2),
            std::nullopt, std::nullopt, std::nullopt, std::nullopt, std::nullopt, 0, 0};
  c.npairs = c.floor.size();
  c.njoints = c.support.rows();
  if (!reach.is_none()) c.reach.emplace(reach, "reach", 1);
  if (!t.mimic.is_none()) c.mimic.emplace(t.mimic, "mimic", 2);
  if (c.margins.size() != c.npairs || c.influence.size() != c.npairs ||
      c.joints.rows() != c.npairs || c.joints.cols() != 2 || c.rows.cols() != row::size ||
      (c.reach && c.reach->size() != c.npairs) ||
      (c.mimic && c.mimic->rows() != c.support.cols())) {
    std::ostringstream out;
    out << "collision_rows: floor, margins, influence, reach (npairs,), joints (npairs, 2), "
        << "rows (N, 13), support (njoints, N) and mimic (N, n) do not fit (npairs " << c.npairs
        << ", joints (" << c.joints.rows() << ", " << c.joints.cols() << "), rows ("
        << c.rows.rows() << ", " << c.rows.cols() << "), support (" << c.njoints << ", "
        << c.support.cols() << "))";
    fail(out.str());
  }
  if (t.witnesses) {
    c.memory.emplace(t.memory, "memory", 2, Access::write);
    c.state.emplace(t.state, "state", 2, Access::write);
    c.owners.emplace(t.owners, "owners", 1, Access::write);
    if (c.state->rows() < c.npairs) {
      std::ostringstream out;
      out << "collision_rows: state (npairs, 2) does not fit: " << c.state->rows()
          << " rows for " << c.npairs << " pairs";
      fail(out.str());
    }
  }
  return c;
}

nb::object collision_rows(const CollisionTables& t, nb::handle near, nb::handle data_obj,
                          double rate, nb::handle influence_obj, double tick, nb::handle reach,
                          nb::handle compute) {
  Checked c = check(t, influence_obj, reach);
  std::vector<Index> listed = index_list(near, "near", c.npairs, "pair", "npairs");
  for (Index k : listed)  // (the joints of the pairs queried: a row names them)
    for (Index side = 0; side < 2; ++side)
      if (c.joints(k, side) < 0 || c.joints(k, side) >= c.njoints) {
        std::ostringstream out;
        out << "joints[" << k << ", " << side << "] = " << c.joints(k, side)
            << " is no joint (njoints " << c.njoints << ")";
        fail(out.str());
      }
  const Index N = c.rows.rows();
  // (every listed pair may get a row and, with witnesses, W more: room for them all)
  if (t.witnesses)
    witness_memory(*c.memory, *c.state, *c.owners, N, listed, "collision_rows", "near");
  else if (N < static_cast<Index>(listed.size()))
    fail("collision_rows: rows (N, 13) and near do not fit: fewer rows than pairs listed");
  // Pinocchio's data, or data views onto it (data, J, rotations, translations)
  const bool views = PyTuple_Check(data_obj.ptr());
  if (views) check_views(data_obj, "collision_rows");
  nb::handle data = views ? nb::handle(PyTuple_GET_ITEM(data_obj.ptr(), 0)) : data_obj;
  if (views && PyList_GET_SIZE(PyTuple_GET_ITEM(data_obj.ptr(), 2)) < c.njoints) {
    std::ostringstream out;
    out << "collision_rows: data views of " << PyList_GET_SIZE(PyTuple_GET_ITEM(data_obj.ptr(), 2))
        << " joints do not fit support (njoints " << c.njoints << ")";
    fail(out.str());
  }
  nb::object J_obj = views ? nb::borrow(PyTuple_GET_ITEM(data_obj.ptr(), 1)) : data.attr("J");
  const Array J(J_obj, "J", 2, Access::read, Order::any);
  if (J.rows() != 6 || J.cols() != c.support.cols()) {
    std::ostringstream out;
    out << "collision_rows: J (6, N) and support (njoints, N) do not fit: J (" << J.rows()
        << ", " << J.cols() << "), support (" << c.njoints << ", " << c.support.cols() << ")";
    fail(out.str());
  }
  std::vector<double> pose_store(static_cast<std::size_t>(16 * std::max<Index>(c.njoints, 1)));
  JointPoses poses(data_obj, views ? JointPoses::Source::views : JointPoses::Source::data,
                   c.njoints, pose_store.data());

  // 1. the geometries' placements (Pinocchio's updateGeometryPlacements)
  t.update(t.model, data, t.geometry, t.geometry_data);

  // 2. the exact distance queries: a floor for each pair, a row for each within influence
  // whose row can bind (reach: the fastest the speed limits close the pair)
  const ResultNames& names = result_names();
  double* floor = c.floor.data();
  const double* margins = c.margins.data();
  const double* influence = c.influence.data();
  double* rows = c.rows.data();
  nb::list within, found;
  std::vector<Index> found_k;
  Index count = 0, failures = 0;
  for (Index k : listed) {
    nb::int_ pair(k);
    nb::object result = compute(t.geometry, t.geometry_data, pair);
    double d = as_double(result.attr(names.distance), "min_distance");
    floor[k] = d > -UNUSABLE ? d : -kInf;  // (NaN, or no closest points: queried again)
    if (!(d > -kInf && d < influence[k])) continue;
    within.append(pair);
    if (c.reach && rate * (d - margins[k]) >= c.reach->data()[k]) continue;  // cannot bind
    if (count >= N) fail("collision_rows: more pairs within influence than rows");
    double* r = rows + row::size * count;
    const bool apart = d > SEPARATED;
    if (!apart) read3(result.attr(names.normal), "normal", r + row::normal);
    read3(call_method(result, names.point_a), "nearest point 1", r + row::point_a);
    read3(call_method(result, names.point_b), "nearest point 2", r + row::point_b);
    if (apart) {
      Vector3 u = Eigen::Map<const Vector3>(r + row::point_b) -
                  Eigen::Map<const Vector3>(r + row::point_a);
      Eigen::Map<Vector3>(r + row::normal) = u / u.norm();
    }
    r[row::distance] = d;
    if (!(d > -UNUSABLE) || !usable(r)) {  // no closest points: the caller forms the row
      r[row::distance] = -kInf;
      std::fill(r + row::normal, r + row::size, 0.0);
      ++failures;
    }
    r[row::margin] = margins[k];
    r[row::joint_a] = static_cast<double>(c.joints(k, 0));
    r[row::joint_b] = static_cast<double>(c.joints(k, 1));
    found.append(pair);
    found_k.push_back(k);
    ++count;
  }
  if (nb::len(within) == 0) return nb::none();
  if (count == 0 || failures > 0)
    return nb::make_tuple(within, found, nb::none(), nb::none(), 0);

  // 3. the witness rows after them (data.oMi read only for the pairs that remember)
  Index total = count;
  if (t.witnesses) {
    WitnessMemory w =
        witness_memory(*c.memory, *c.state, *c.owners, N, found_k, "collision_rows", "found");
    for (Index i = 0; i < count; ++i) {
      const double* r = rows + row::size * i;
      if (!remembers(r, w, found_k[static_cast<std::size_t>(i)], t.keep)) continue;
      poses.at(static_cast<Index>(r[row::joint_a]));
      poses.at(static_cast<Index>(r[row::joint_b]));
    }
    total = witness_rows_into(poses.data(), rows, found_k, w, tick, t.keep, t.apart);
  }

  // 4. the damper rows of them all, folded by the mimic map onto the velocity coordinates
  check_row_joints(rows, total, c.njoints, "rows", "support");
  const Index n = c.mimic ? c.mimic->cols() : J.cols();
  NewArray A = new_array(total, n), b = new_array(total);
  if (c.mimic) {
    RowMatrix X(total, J.cols());
    damper_rows_into(J.strided(), std::as_const(c.support).matrix(), rows, total, rate, X.data(), b.data);
    MatrixMap(A.data, total, n).noalias() = X * std::as_const(*c.mimic).matrix();
  } else {
    damper_rows_into(J.strided(), std::as_const(c.support).matrix(), rows, total, rate, A.data, b.data);
  }
  freeze(A.array);
  freeze(b.array);
  return nb::make_tuple(within, found, A.array, b.array, total - count);
}

}  // namespace

void register_collision_queries(nb::module_& m) {
  nb::class_<CollisionTables>(
      m, "CollisionTables",
      "What collision_rows reads and writes besides the step's, from the collision limit\n"
      "(limits/collision.py): Pinocchio's geometry model and data, its model and\n"
      "update(model, data, geometry, geometry_data) (pinocchio.updateGeometryPlacements); per\n"
      "pair (npairs of them) its floor (written: its last exact distance, m), margins, joints\n"
      "(npairs, 2) int64; rows (N, 13), the step's pair rows (written); the witnesses' memory\n"
      "(npairs W, 6), state (npairs, 2) and owners (>= npairs W,) (written; witness_rows);\n"
      "support (njoints, N) and mimic (None or (N, n)) for the damper rows; keep and apart, the\n"
      "witnesses' bands (m); witnesses, whether witness rows follow. Checked where\n"
      "collision_rows reads them.")
      .def(nb::init<nb::object, nb::object, nb::object, nb::object, nb::object, nb::object,
                    nb::object, nb::object, nb::object, nb::object, nb::object, nb::object,
                    nb::object, double, double, bool>(),
           nb::arg("geometry").none(), nb::arg("geometry_data").none(), nb::arg("model").none(),
           nb::arg("update"),
           nb::arg("floor"), nb::arg("margins"), nb::arg("joints"), nb::arg("rows"),
           nb::arg("memory"), nb::arg("state"), nb::arg("owners"), nb::arg("support"),
           nb::arg("mimic").none(), nb::arg("keep"), nb::arg("apart"), nb::arg("witnesses"))
      .def_ro("geometry", &CollisionTables::geometry)
      .def_ro("geometry_data", &CollisionTables::geometry_data)
      .def_ro("floor", &CollisionTables::floor)
      .def_ro("rows", &CollisionTables::rows)
      .def_ro("witnesses", &CollisionTables::witnesses);

  m.def("collision_rows", &collision_rows, nb::arg("tables"), nb::arg("near"),
        nb::arg("data").none(),
        nb::arg("rate"), nb::arg("influence"), nb::arg("tick"), nb::arg("reach").none(),
        nb::arg("compute"),
        "collision_rows(tables, near, data, rate, influence, tick, reach, compute) -> (within,\n"
        "found, A, b, witnesses) | None: a step's rows of the collision limit in one call\n"
        "(limits/collision.py, _rows), at the joint poses and WORLD joint Jacobians of\n"
        "Pinocchio's `data`, or of data views (data, data.J, rotations, translations): numpy\n"
        "views onto its J and each joint's data.oMi[j].rotation and .translation (lists).\n"
        "tables: the limit's CollisionTables.\n"
        "1. tables.update(model, data, geometry, geometry_data): the geometries' placements.\n"
        "2. For each pair k of `near` (a list of ints, or int64), result = compute(geometry,\n"
        "   geometry_data, k) (pinocchio.computeDistance), d = result.min_distance; floor[k] =\n"
        "   d (-inf for a failed query: d NaN or no closest points). A pair with d <\n"
        "   influence[k] (npairs,) is within influence; it gets the next row of rows (d,\n"
        "   margins[k], joints[k], the normal, the closest points) unless reach (npairs,; None:\n"
        "   every pair within influence) says the row cannot bind: rate (d - margin) >=\n"
        "   reach[k] (m/s). Where coal found no closest points the row holds d = -inf and\n"
        "   zeros, and A and b are None (the caller forms those rows first).\n"
        "3. With witnesses, witness_rows' rows after them (at `tick`), `witnesses` of them, and\n"
        "   damper_rows' A (k, N) and b (k,), both read-only, of all the rows at `rate` (1/s)\n"
        "   from data.J (6, N); A (k, n) = A G with a mimic map G (N, n).\n"
        "within: the pairs within influence, found those with a row (A and b None when there\n"
        "is none); None when no pair is within influence.");
}

}  // namespace sjt
