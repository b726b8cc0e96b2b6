// What the collision limit's kernel files share (sjt_pin/limits/collision.py): the columns of
// its pair rows, the joint poses read from Pinocchio's data, and the damper and witness rows
// that both their own entries and collision_rows make.
#pragma once

#include <nanobind/nanobind.h>

#include <Eigen/Core>
#include <Eigen/Geometry>  // (cross products)
#include <vector>

#include "array.hpp"

namespace sjt {

// A pair row (rows (k, 13), as damper_rows reads them): the distance d (m), the margin, the
// joints of the pair's two geometries (a, b), the unit normal n from a to b (coal's) and the
// closest points p_a, p_b (world, m)
namespace row {
constexpr Index distance = 0, margin = 1, joint_a = 2, joint_b = 3, normal = 4, point_a = 7,
                point_b = 10, size = 13;
}

using Pose = Eigen::Matrix<double, 4, 4, Eigen::RowMajor>;  // a joint's 4x4 world pose
using PoseMap = Eigen::Map<Pose>;
using ConstPoseMap = Eigen::Map<const Pose>;
using Vector3 = Eigen::Vector3d;

// ValueError unless every row of rows (k, 13) names two joints (columns joint_a and joint_b)
// that are whole numbers in [0, njoints): "<name>[i] names joint j; <of> has njoints"
void check_row_joints(const double* rows, Index count, Index njoints, const char* name,
                      const char* of);

// The world poses of the joints a kernel needs (njoints x 16, row-major, into `out`; joint 0
// the identity), each read once a call when first asked: from data views (a tuple (data, J,
// rotations, translations), the last two lists of numpy views onto each joint's
// data.oMi[j].rotation and .translation), from Pinocchio's data (its oMi), or from its oMi.
class JointPoses {
 public:
  enum class Source { views, data, oMi };
  JointPoses(nb::handle source, Source kind, Index njoints, double* out);

  // joint j's pose; ValueError unless 0 <= j < njoints, or the source's error
  ConstPoseMap at(Index j);
  const double* data() const { return out_; }
  Index njoints() const { return njoints_; }

 private:
  nb::handle source_;
  nb::object oMi_;
  Source kind_;
  Index njoints_;
  double* out_;
  std::vector<char> fetched_;
};

// TypeError unless views is a tuple (data, J, rotations, translations), the last two lists
// of one array per joint (`who`: the kernel's name)
void check_views(nb::handle views, const char* who);

// (m per unit of q_dot) a damper row whose norm is at most this is rounding (coal's points
// times Jacobian columns), not a lever
constexpr double kRoundingLever = 1e-12;
// (m per unit of q_dot) the least lever |A_i| with which a row inside its margin pushes its
// pair out: below it a centimetre's push takes more than a radian of joint motion, over which
// no linearisation of the distance holds, and the row only keeps the pair from closing
constexpr double kPushLever = 0.01;

// damper_rows into A (k, N) and b (k,) from the first k rows of `rows` (rows' joints checked
// against support's rows already): row i, A_i = (u_a^T J) support[a] - (u_b^T J) support[b]
// with u_x = [n; p_x x n] (0 where |A_i| <= kRoundingLever), b_i = rate (d - margin), or 0
// where that is negative and |A_i| < kPushLever. J (6, N) in either order.
void damper_rows_into(const StridedMatrixMap& J, const ConstMatrixMap& support, const double* rows,
                      Index k, double rate, double* A, double* b);

// The witness rows' memory: per pair W remembered closest points (memory (npairs W, 6)), their
// count and the tick of the last call that saw the pair (state (npairs, 2)); the owners of the
// witness rows (>= count W,)
struct WitnessMemory {
  double* memory;
  double* state;
  double* owners;
  Index W;
};

// WitnessMemory of these arrays, checked against the step's rows (N, 13) and the pairs `found`
// (count of them, each < npairs): memory (npairs W, 6) with 1 <= W <= 64, state (npairs, 2)
// whose counts are -1 (never remembers) or whole numbers in [0, W], owners (>= count W,), and
// N >= count (1 + W). ValueError naming what does not fit (`who`: the kernel, `listed`: the
// name of its list of pairs).
WitnessMemory witness_memory(Array& memory, Array& state, Array& owners, Index rows,
                             const std::vector<Index>& found, const char* who,
                             const char* listed);

// Whether pair row `r` of a pair in `found` keeps witnesses this call (its d - margin under
// keep, its state not -1): the poses a witness_rows call reads
bool remembers(const double* row, const WitnessMemory& w, Index pair, double keep);

// witness_rows' rows after the count rows of the pairs `found` (rows (N, 13)), at the joint
// poses (njoints x 16); the number of rows
Index witness_rows_into(const double* poses, double* rows, const std::vector<Index>& found,
                        const WitnessMemory& w, double tick, double keep, double apart);

}  // namespace sjt
