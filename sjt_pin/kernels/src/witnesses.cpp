// The collision limit's witness rows (sjt_pin/limits/collision.py, "Witnesses"): each pair's
// recent closest points, fixed to their geometries, as rows of their own on its current normal.
#include <sstream>

#include "collision.hpp"
#include "registry.hpp"

namespace sjt {

namespace {

constexpr Index MOST_WITNESSES = 64;

}  // namespace

WitnessMemory witness_memory(Array& memory, Array& state, Array& owners, Index rows,
                             const std::vector<Index>& found, const char* who,
                             const char* listed) {
  const Index npairs = state.rows(), count = static_cast<Index>(found.size());
  const Index W = npairs > 0 ? memory.rows() / npairs : 0;
  if (memory.cols() != 6 || state.cols() != 2 || W < 1 || W > MOST_WITNESSES ||
      memory.rows() != W * npairs || rows < count * (1 + W) || owners.size() < count * W) {
    std::ostringstream out;
    out << who << ": rows (>= count (1 + W), 13), memory (npairs W, 6) with 1 <= W <= "
        << MOST_WITNESSES << ", state (npairs, 2) and owners (>= count W,) do not fit the "
        << count << " pairs of " << listed << " (count " << count << ", rows " << rows << ", memory (" << memory.rows() << ", " << memory.cols()
        << "), state (" << npairs << ", " << state.cols() << "), owners " << owners.size() << ")";
    fail(out.str());
  }
  for (std::size_t i = 0; i < found.size(); ++i) {
    Index k = found[i];
    if (k >= npairs) {
      std::ostringstream out;
      out << listed << "[" << i << "] = " << k << " is no pair (npairs " << npairs << ")";
      fail(out.str());
    }
    // a count of witnesses: -1 (never remembers) or a whole number up to W
    double c = state.data()[2 * k];
    if (!(c < 0.0 || (c <= static_cast<double>(W) && c == static_cast<double>(
                                                                static_cast<Index>(c))))) {
      std::ostringstream out;
      out << "state[" << k << ", 0] = " << c << " is no count of witnesses (-1 or 0 to " << W
          << ")";
      fail(out.str());
    }
  }
  return {memory.data(), state.data(), owners.data(), W};
}

bool remembers(const double* row, const WitnessMemory& w, Index pair, double keep) {
  return row[row::distance] - row[row::margin] < keep && !(w.state[2 * pair] < 0.0);
}

Index witness_rows_into(const double* poses, double* rows, const std::vector<Index>& found,
                        const WitnessMemory& w, double tick, double keep, double apart) {
  using Point6 = Eigen::Matrix<double, 6, 1>;
  const Index count = static_cast<Index>(found.size()), W = w.W;
  Index total = count;
  for (Index i = 0; i < count; ++i) {
    const Index k = found[static_cast<std::size_t>(i)];
    double* r = rows + row::size * i;
    double* st = w.state + 2 * k;
    double* mem = w.memory + 6 * W * k;
    if (st[0] < 0.0) continue;  // a pair whose closest points are unique
    ConstPoseMap H[2] = {ConstPoseMap(poses + 16 * static_cast<Index>(r[row::joint_a])),
                         ConstPoseMap(poses + 16 * static_cast<Index>(r[row::joint_b]))};
    Index filled = st[1] == tick - 1.0 ? static_cast<Index>(st[0]) : 0;
    st[1] = tick;
    if (!(r[row::distance] - r[row::margin] < keep)) {  // far from its margin: binds nothing
      st[0] = 0.0;
      continue;
    }
    Eigen::Map<const Vector3> n(r + row::normal);
    Point6 now;  // this step's closest points, each in its joint's frame: R^T (p - t)
    for (int side = 0; side < 2; ++side) {
      Eigen::Map<const Vector3> p(r + (side ? row::point_b : row::point_a));
      now.segment<3>(3 * side) = H[side].topLeftCorner<3, 3>().transpose() *
                                 (p - H[side].topRightCorner<3, 1>());
    }
    Point6 kept[MOST_WITNESSES];
    Index nk = 0;
    for (Index m = 0; m < filled; ++m) {
      Eigen::Map<const Point6> local(mem + 6 * m);
      double far = 0.0;
      for (Index c = 0; c < 6; ++c) {
        double d = std::fabs(local[c] - now[c]);
        far = far > d ? far : d;
      }
      if (!(far > apart)) continue;  // this step's own points
      Point6 world;
      for (int side = 0; side < 2; ++side)
        world.segment<3>(3 * side) = H[side].topLeftCorner<3, 3>() * local.segment<3>(3 * side) +
                                     H[side].topRightCorner<3, 1>();
      // the separation along this step's normal (>= d: the plane separates the hulls)
      double s = n.dot(world.tail<3>() - world.head<3>());
      if (!(s - r[row::distance] < keep)) continue;
      double* out = rows + row::size * total;
      std::copy(r, r + row::size, out);
      out[row::distance] = s;
      Eigen::Map<Point6>(out + row::point_a) = world;
      w.owners[total - count] = static_cast<double>(k);
      ++total;
      kept[nk++] = local;  // (nk <= filled <= W <= MOST_WITNESSES)
    }
    // the pair remembers the last W - 1 kept and this step's points
    Index start = nk > W - 1 ? nk - (W - 1) : 0, held = 0;
    for (Index m = start; m < nk; ++m, ++held) Eigen::Map<Point6>(mem + 6 * held) = kept[m];
    Eigen::Map<Point6>(mem + 6 * held) = now;
    st[0] = static_cast<double>(held + 1);
  }
  return total;
}

void register_witnesses(nb::module_& m) {
  m.def(
      "witness_rows",
      [](nb::handle oMi, nb::handle poses_obj, nb::handle rows_obj, nb::handle found_obj,
         nb::handle memory_obj, nb::handle state_obj, double tick, double keep, double apart,
         nb::handle owners_obj) {
        const bool fetch = !oMi.is_none();
        Array poses(poses_obj, "poses", 2, fetch ? Access::write : Access::read);
        Array rows(rows_obj, "rows", 2, Access::write);
        Array memory(memory_obj, "memory", 2, Access::write);
        Array state(state_obj, "state", 2, Access::write);
        Array owners(owners_obj, "owners", 1, Access::write);
        if (poses.cols() != 16 || rows.cols() != row::size) {
          std::ostringstream out;
          out << "witness_rows: poses (njoints, 16) and rows (N, 13) do not fit: poses ("
              << poses.rows() << ", " << poses.cols() << "), rows (" << rows.rows() << ", "
              << rows.cols() << ")";
          fail(out.str());
        }
        std::vector<Index> found =
            index_list(found_obj, "found", state.rows(), "pair", "npairs");
        WitnessMemory w =
            witness_memory(memory, state, owners, rows.rows(), found, "witness_rows", "found");
        const Index count = static_cast<Index>(found.size());
        check_row_joints(rows.data(), count, poses.rows(), "rows", "poses");
        if (fetch) {  // the poses of the joints of the pairs that remember, from data.oMi
          JointPoses P(oMi, JointPoses::Source::oMi, poses.rows(), poses.data());
          for (Index i = 0; i < count; ++i) {
            const double* r = rows.data() + row::size * i;
            if (!remembers(r, w, found[static_cast<std::size_t>(i)], keep)) continue;
            P.at(static_cast<Index>(r[row::joint_a]));
            P.at(static_cast<Index>(r[row::joint_b]));
          }
        }
        return witness_rows_into(poses.data(), rows.data(), found, w, tick, keep, apart);
      },
      nb::arg("oMi").none(), nb::arg("poses"), nb::arg("rows"), nb::arg("found"),
      nb::arg("memory"), nb::arg("state"), nb::arg("tick"), nb::arg("keep"), nb::arg("apart"),
      nb::arg("owners"),
      "witness_rows(oMi, poses, rows, found, memory, state, tick, keep, apart, owners) -> int:\n"
      "the collision limit's witness rows (limits/collision.py, \"Witnesses\"). rows (N, 13)\n"
      "holds the step's exact rows of the pairs `found` (a list of ints, count of them) in its\n"
      "first count rows (as damper_rows reads them); poses (njoints, 16): the 4x4 world pose\n"
      "of each joint the rows name (row-major), taken here from Pinocchio's data.oMi (joint 0:\n"
      "the identity) unless oMi is None. A pair whose d - margin is not under keep remembers\n"
      "nothing. memory (npairs W, 6): per pair up to W remembered closest points, each in its\n"
      "joint's frame (p_a, p_b); state (npairs, 2): how many are remembered (-1: a pair that\n"
      "never remembers) and the tick of the call that last saw the pair within influence (a\n"
      "pair missed by the previous call, tick - 1, forgets them). Each remembered pair of\n"
      "points that lies farther than `apart` from this step's and whose separation s = n^T\n"
      "(p_b - p_a) along this step's normal is under d + keep becomes a row after the exact\n"
      "ones (d = s, the points in the world), its pair written to owners; the pair then\n"
      "remembers those (the last W - 1) and this step's points. Returns the number of rows.");
}

}  // namespace sjt
