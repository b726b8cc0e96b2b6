// The collision limit's broad phase and its skip (sjt_pin/limits/collision.py, _near, _aged
// and _rows): the gaps between the pairs' bounding spheres, the pairs a step must query, and
// the candidates and floors after a new broad phase.
//
// A pair's bound lever_k |q - q0| (m; lever (npairs, n)) is summed in one order everywhere
// (lever_sum): near_pairs answers the same with and without its prefilter, to the last bit.
#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <sstream>

#include "collision.hpp"
#include "registry.hpp"

namespace sjt {

namespace {

// lever_k . moved, summed in index order
double lever_sum(const ConstMatrixMap& lever, Index k, const double* moved) {
  double acc = 0.0;
  const double* l = lever.data() + k * lever.cols();
  for (Index j = 0; j < lever.cols(); ++j) acc += l[j] * moved[j];
  return acc;
}

// Whether q lies in the box lower <= q <= upper the levers hold in
bool inside(const Array& q, const Array& lower, const Array& upper) {
  for (Index j = 0; j < q.size(); ++j)
    if (!(q.data()[j] >= lower.data()[j] && q.data()[j] <= upper.data()[j])) return false;
  return true;
}

// ValueError naming the arrays that do not fit (n: joints, npairs: pairs)
[[noreturn]] void do_not_fit(const char* what, Index n, Index npairs) {
  std::ostringstream out;
  out << what << " do not fit (n " << n << ", npairs " << npairs << ")";
  fail(out.str());
}

}  // namespace

// near_pairs' state (collision.py's skip): the last broad phase at `reference` (n,), the box
// lower <= q <= upper (n,) its levers hold in, lever (npairs, n), each pair's gap (npairs,) at
// the reference, its candidates `near` (int64), each pair's floor (npairs,) at floor_q (n,),
// and an optional prefilter (1 + 3 npairs,) that orders the lever test.
struct Skip {
  nb::object reference, lower, upper, lever, gap, near, floor, floor_q, prefilter;
};

namespace {

// The prefilter (1 + 3 npairs: a flag, then thresholds, pairs and the influence they were made
// for): each pair's r_k = s_k / |lever_k| with its slack s_k = gap_k - influence_k less 1e-12
// (1 + |gap_k| + |influence_k|) (inf where the gap is; -inf where s_k is not > 0 or the lever's
// norm is 0 or not finite), ascending. As lever_k . m <= |lever_k| |m| (Cauchy-Schwarz), a pair
// with r_k (1 - 1e-9) > |m| meets the test at m, beyond the rounding of either side; the pairs
// are tested from the smallest r_k on, until one exceeds |m|: after a broad phase most pairs
// lie far beyond their influence and none of them is summed.
void build_prefilter(const ConstMatrixMap& lever, const double* gap, const double* influence,
                     double* P) {
  const Index m = lever.rows();
  std::vector<std::pair<double, Index>> order(static_cast<std::size_t>(m));
  for (Index k = 0; k < m; ++k) {
    double norm = lever.row(k).norm();
    double slack = gap[k] - influence[k] - 1e-12 * (1.0 + std::fabs(gap[k]) +
                                                    std::fabs(influence[k]));
    double r = -kInf;
    if (std::isinf(gap[k]) && gap[k] > 0 && std::isfinite(influence[k]) && std::isfinite(norm))
      r = kInf;
    else if (slack > 0.0 && norm > 0.0 && std::isfinite(norm))
      r = slack / norm;
    order[static_cast<std::size_t>(k)] = {r, k};
  }
  std::sort(order.begin(), order.end(),
            [](const auto& a, const auto& b) { return a.first < b.first; });
  for (Index i = 0; i < m; ++i) {
    P[1 + i] = order[static_cast<std::size_t>(i)].first;
    P[1 + m + i] = static_cast<double>(order[static_cast<std::size_t>(i)].second);
    P[1 + 2 * m + i] = influence[i];
  }
  P[0] = 1.0;
}

// Whether every pair's bound lever |q - reference| plus its influence stays under its gap (else
// the broad phase must run again); with a prefilter (built here first where P[0] < 0) only the
// pairs whose threshold does not clear |q - reference| are summed, which answers the same.
// moved: n numbers of scratch.
bool levers_hold(const Array& q, const Array& reference, const ConstMatrixMap& lever,
                 const double* gap, const double* influence, double* P, double* moved) {
  const Index n = q.size(), m = lever.rows();
  double norm = 0.0;
  for (Index j = 0; j < n; ++j) {
    moved[j] = std::fabs(q.data()[j] - reference.data()[j]);
    norm += moved[j] * moved[j];
  }
  auto holds = [&](Index k) { return lever_sum(lever, k, moved) + influence[k] < gap[k]; };
  if (P) {
    if (P[0] < 0.0) build_prefilter(lever, gap, influence, P);
    bool same = true;  // (made for these influences: near_pairs' callers pass one array)
    for (Index k = 0; k < m && same; ++k) same = P[1 + 2 * m + k] == influence[k];
    if (same) {
      norm = std::sqrt(norm);
      for (Index i = 0; i < m && !(P[1 + i] * (1.0 - 1e-9) > norm); ++i) {
        double k = P[1 + m + i];  // (a pair index the prefilter was built with)
        if (!(k >= 0.0 && k < static_cast<double>(m))) fail("prefilter: no pair index");
        if (!holds(static_cast<Index>(k))) return false;
      }
      return true;
    }
  }
  for (Index k = 0; k < m; ++k)
    if (!holds(k)) return false;
  return true;
}

// The moves |q - from| (n,; 0 without `from`) into moved
void moves(const Array& q, const double* from, double* moved) {
  for (Index j = 0; j < q.size(); ++j) moved[j] = from ? std::fabs(q.data()[j] - from[j]) : 0.0;
}

nb::object near_pairs(nb::handle q_obj, const Skip& skip, nb::handle influence_obj) {
  Array q(q_obj, "q", 1);
  Array reference(skip.reference, "reference", 1);
  Array lower(skip.lower, "lower", 1);
  Array upper(skip.upper, "upper", 1);
  const Array lever(skip.lever, "lever", 2);
  Array gap(skip.gap, "gap", 1);
  Array floor(skip.floor, "floor", 1, Access::write);
  Array floor_q(skip.floor_q, "floor_q", 1, Access::write);
  Array influence(influence_obj, "influence", 1);
  std::optional<Array> prefilter;
  if (!skip.prefilter.is_none()) prefilter.emplace(skip.prefilter, "prefilter", 1, Access::write);
  const Index n = q.size(), npairs = lever.rows();
  if (reference.size() != n || lower.size() != n || upper.size() != n || lever.cols() != n ||
      floor_q.size() != n || gap.size() != npairs || floor.size() != npairs ||
      influence.size() != npairs || (prefilter && prefilter->size() != 1 + 3 * npairs))
    do_not_fit("near_pairs: q, reference, lower, upper, floor_q (n,), lever (npairs, n), gap, "
               "floor and influence (npairs,), prefilter (1 + 3 npairs,)", n, npairs);
  // the candidates: an int64 array read in place (the limit's), or a list of ints
  std::optional<IndexArray> near_array;
  std::vector<Index> near_list;
  if (PyList_Check(skip.near.ptr()) || PyTuple_Check(skip.near.ptr())) {
    near_list = index_list(skip.near, "near", npairs, "pair", "npairs");
  } else {
    near_array.emplace(skip.near, "near", 1);
    near_array->below(npairs, "pair", "npairs");
  }
  const Index count = near_array ? near_array->size() : static_cast<Index>(near_list.size());
  const auto L = lever.matrix();
  std::vector<double> moved(static_cast<std::size_t>(2 * n));  // (from the reference, floor_q)
  if (!inside(q, lower, upper) ||
      !levers_hold(q, reference, L, gap.data(), influence.data(),
                   prefilter ? prefilter->data() : nullptr, moved.data()))
    return nb::none();
  // the pairs of near whose floor, aged from floor_q to q, is not above their influence
  double* aged = moved.data() + n;
  moves(q, floor_q.data(), aged);
  nb::list out;
  for (Index i = 0; i < count; ++i) {
    Index k = near_array ? (*near_array)[i] : near_list[static_cast<std::size_t>(i)];
    floor.data()[k] -= lever_sum(L, k, aged);
    if (!(floor.data()[k] > influence.data()[k])) out.append(nb::int_(k));
  }
  floor_q.vector() = q.vector();
  return std::move(out);
}

nb::object refresh_pairs(nb::handle q_obj, nb::handle lower_obj, nb::handle upper_obj,
                         nb::handle gap_obj, nb::handle influence_obj, double skin,
                         nb::handle floor_obj, nb::handle kept_obj, nb::handle floor_q_obj,
                         nb::handle lever_obj) {
  Array q(q_obj, "q", 1);
  Array lower(lower_obj, "lower", 1);
  Array upper(upper_obj, "upper", 1);
  Array gap(gap_obj, "gap", 1, Access::write);
  Array influence(influence_obj, "influence", 1);
  Array floor(floor_obj, "floor", 1, Access::write);
  std::optional<Array> floor_q;
  if (!floor_q_obj.is_none()) floor_q.emplace(floor_q_obj, "floor_q", 1, Access::write);
  const Array lever(lever_obj, "lever", 2);
  const Index n = q.size(), npairs = lever.rows();
  if (lower.size() != n || upper.size() != n || lever.cols() != n ||
      (floor_q && floor_q->size() != n) || gap.size() != npairs || floor.size() != npairs ||
      influence.size() != npairs)
    do_not_fit("refresh_pairs: q, lower, upper, floor_q (n,), lever (npairs, n), gap, floor "
               "and influence (npairs,)", n, npairs);
  std::vector<char> keep(static_cast<std::size_t>(npairs), 0);
  if (!kept_obj.is_none())
    for (Index k : index_list(kept_obj, "kept", npairs, "pair", "npairs"))
      keep[static_cast<std::size_t>(k)] = 1;
  if (!inside(q, lower, upper)) return nb::none();  // (nothing changed)
  double* f = floor.data();
  for (Index k = 0; k < npairs; ++k)
    if (!keep[static_cast<std::size_t>(k)]) f[k] = -kInf;  // no bound known
  const auto L = lever.matrix();
  std::vector<double> moved(static_cast<std::size_t>(n));
  moves(q, floor_q ? floor_q->data() : nullptr, moved.data());
  nb::list near, listed;
  for (Index k = 0; k < npairs; ++k) {
    if (!(gap.data()[k] < influence.data()[k] + skin)) continue;
    gap.data()[k] = kInf;  // a candidate stays one
    near.append(nb::int_(k));
    if (floor_q) f[k] -= lever_sum(L, k, moved.data());
    if (!floor_q || !(f[k] > influence.data()[k])) listed.append(nb::int_(k));
  }
  if (floor_q) floor_q->vector() = q.vector();
  return nb::make_tuple(near, listed);
}

void sphere_gaps(nb::handle views, nb::handle joints_obj, nb::handle centres_obj,
                 nb::handle pairs_obj, nb::handle span_obj, nb::handle gap_obj) {
  check_views(views, "sphere_gaps");
  IndexArray joints(joints_obj, "joints", 1);
  const Array centres(centres_obj, "centres", 2);
  IndexArray pairs(pairs_obj, "pairs", 2);
  Array span(span_obj, "span", 1);
  Array gap(gap_obj, "gap", 1, Access::write);
  const Index n = joints.size(), npairs = pairs.rows();
  const Index njoints = static_cast<Index>(PyList_GET_SIZE(PyTuple_GET_ITEM(views.ptr(), 2)));
  if (centres.rows() != n || centres.cols() != 4 || pairs.cols() != 2 ||
      span.size() != npairs || gap.size() != npairs)
    do_not_fit("sphere_gaps: joints (ngeoms,), centres (ngeoms, 4), pairs (npairs, 2), span "
               "and gap (npairs,)", n, npairs);
  joints.below(njoints, "joint", "njoints");
  pairs.below(n, "geometry", "ngeoms");
  std::vector<double> poses(static_cast<std::size_t>(16 * std::max<Index>(njoints, 1)));
  JointPoses P(views, JointPoses::Source::views, njoints, poses.data());
  // each sphere's centre in the world: its joint's pose times its centre in the joint's frame
  Eigen::Matrix<double, 3, Eigen::Dynamic> world(3, n);
  const auto C = centres.matrix();
  for (Index g = 0; g < n; ++g) {
    ConstPoseMap H = P.at(joints[g]);
    world.col(g) = H.topLeftCorner<3, 3>() * C.row(g).head<3>().transpose() +
                   H.topRightCorner<3, 1>();
  }
  for (Index k = 0; k < npairs; ++k)
    gap.data()[k] = (world.col(pairs(k, 0)) - world.col(pairs(k, 1))).norm() - span.data()[k];
}

}  // namespace

void register_broad_phase(nb::module_& m) {
  nb::class_<Skip>(m, "Skip",
                   "near_pairs' state of the collision limit's skip (limits/collision.py): the\n"
                   "last broad phase at `reference` (n,), the box lower <= q <= upper (n,) its\n"
                   "levers hold in, lever (npairs, n: m per unit of |dq| each pair's distance\n"
                   "changes at most), each pair's gap (npairs,) at the reference, its candidates\n"
                   "`near` (int64 pair indices, or a list of ints), each pair's floor (npairs,; a\n"
                   "lower bound of its distance at floor_q (n,), m), and optionally a writable\n"
                   "prefilter (1 + 3 npairs,; its first number < 0 until near_pairs builds it\n"
                   "for this gap). Checked where near_pairs reads them.")
      .def(nb::init<nb::object, nb::object, nb::object, nb::object, nb::object, nb::object,
                    nb::object, nb::object, nb::object>(),
           nb::arg("reference"), nb::arg("lower"), nb::arg("upper"), nb::arg("lever"),
           nb::arg("gap"), nb::arg("near"), nb::arg("floor"), nb::arg("floor_q"),
           nb::arg("prefilter").none() = nb::none())
      .def_ro("reference", &Skip::reference)
      .def_ro("lower", &Skip::lower)
      .def_ro("upper", &Skip::upper)
      .def_ro("lever", &Skip::lever)
      .def_ro("gap", &Skip::gap)
      .def_ro("near", &Skip::near)
      .def_ro("floor", &Skip::floor)
      .def_ro("floor_q", &Skip::floor_q)
      .def_ro("prefilter", &Skip::prefilter);

  m.def("near_pairs", &near_pairs, nb::arg("q"), nb::arg("skip"), nb::arg("influence"),
        "near_pairs(q, skip, influence) -> list | None: the collision limit's skip of its broad\n"
        "phase and of its queries (limits/collision.py, _near and _rows) for q in its own\n"
        "tangent space (revolute and prismatic joints); skip: a Skip. None when q leaves the\n"
        "box lower <= q <= upper, or when some pair's bound lever |q - reference| plus its\n"
        "influence (npairs,) reaches the gap its bounding volumes had at the reference (the\n"
        "broad phase must run again); else the pairs of `near` whose floor, aged to q (floor_k\n"
        "-= lever_k |q - floor_q|), is not above their influence (those to query), floor_q then\n"
        "q. A prefilter orders the lever test so that the pairs far beyond reach are not summed\n"
        "(the same answer).");

  m.def("refresh_pairs", &refresh_pairs, nb::arg("q"), nb::arg("lower"), nb::arg("upper"),
        nb::arg("gap"), nb::arg("influence"), nb::arg("skin"), nb::arg("floor"),
        nb::arg("kept").none(), nb::arg("floor_q").none(), nb::arg("lever"),
        "refresh_pairs(q, lower, upper, gap, influence, skin, floor, kept, floor_q, lever) ->\n"
        "(near, listed) | None: the collision limit's new candidate list after a broad phase\n"
        "(limits/collision.py, _near and _aged, in one call): None, changing nothing, when q\n"
        "leaves the box lower <= q <= upper (n,) the levers hold in; else near, the pairs whose\n"
        "bounding volumes' gap (npairs,; m, from sphere_gaps) is below their influence\n"
        "(npairs,) plus skin (m), their gaps set to inf (a candidate stays one); every floor\n"
        "(npairs,) but those of the pairs `kept` (int64 or a list of ints; None: none) becomes\n"
        "-inf; with floor_q (n,; None: not yet) the floors of near aged from floor_q to q by\n"
        "lever (npairs, n) |q - floor_q|, floor_q then q, and listed the pairs of near whose\n"
        "floor is not above their influence (without floor_q: near).");

  m.def("sphere_gaps", &sphere_gaps, nb::arg("views"), nb::arg("joints"), nb::arg("centres"),
        nb::arg("pairs"), nb::arg("span"), nb::arg("gap"),
        "sphere_gaps(views, joints, centres, pairs, span, gap): the broad phase's test of every\n"
        "pair's bounding spheres (limits/collision.py, _broad_phase): gap[k] = |c_a - c_b| -\n"
        "span[k] (m), c_g = oMi[joints[g]] centres[g] the world centre of geometry g's sphere\n"
        "from its centre in its joint's frame (centres (ngeoms, 4), homogeneous; joints\n"
        "(ngeoms,) int64, joint 0 the world), joint poses read from collision_rows' data views,\n"
        "pairs (npairs, 2) int64 geometry indices.");
}

}  // namespace sjt
