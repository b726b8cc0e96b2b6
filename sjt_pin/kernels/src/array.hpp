// The kernels' boundary: every array a kernel reads or writes is checked here, before any read.
//
// An argument is accepted only as a numpy array of float64 (native byte order), of the expected
// number of dimensions, C-contiguous, aligned, and writable when the kernel writes it. Anything
// else (a record array's field, a stride-12 view, a Fortran or reversed matrix, float32, a list)
// raises TypeError or ValueError naming the argument and what it should be: nothing is read
// through a stride the kernel does not expect. Another object that exports a buffer (a
// memoryview) is seen as the numpy array numpy makes of it in place (no copy), under the same
// rules. A kernel that reads Pinocchio's matrices through numpy (data.J, a joint's rotation:
// Eigen's column-major storage, Fortran-ordered arrays) takes them with Order::any, C or
// Fortran order, and reads them through strided(). Index tables (pairs, joints) are int64
// arrays under the same rules (IndexArray), each entry checked against its bound before any is
// used. The public door (sjt_pin's Python API) makes q,
// targets and limit rows contiguous float64 once; the kernels check again, since they are
// callable on their own.
#pragma once

#include <nanobind/nanobind.h>

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

namespace sjt {

namespace nb = nanobind;

using Index = Eigen::Index;
using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using Vector = Eigen::VectorXd;
using MatrixMap = Eigen::Map<RowMatrix>;
using ConstMatrixMap = Eigen::Map<const RowMatrix>;
using VectorMap = Eigen::Map<Eigen::VectorXd>;
using ConstVectorMap = Eigen::Map<const Eigen::VectorXd>;

inline constexpr double kInf = std::numeric_limits<double>::infinity();

// Which arrays a kernel takes: read-only or written in place.
enum class Access { read, write };

// How a 2-D array's entries may lie: C order only, or C or Fortran order (read through
// Array::strided(); a 1-D array is both)
enum class Order { c, any };

// a 2-D array of either order read through its strides (in entries: both orders are contiguous)
using StridedMatrixMap =
    Eigen::Map<const RowMatrix, 0, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>>;

// A checked float64 numpy array (see the file's comment). It borrows the array: the Python
// object outlives the kernel call that made it.
class Array {
 public:
  Array(nb::handle object, const char* name, int ndim, Access access = Access::read,
        Order order = Order::c);

  Index size() const { return size_; }
  Index rows() const { return rows_; }
  Index cols() const { return cols_; }
  const char* name() const { return name_; }
  double* data() { return data_; }
  const double* data() const { return data_; }

  ConstVectorMap vector() const { return ConstVectorMap(data_, size_); }
  VectorMap vector() { return VectorMap(data_, size_); }
  // (C order; an array taken with Order::any is read through strided())
  ConstMatrixMap matrix() const { return ConstMatrixMap(data_, rows_, cols_); }
  MatrixMap matrix() { return MatrixMap(data_, rows_, cols_); }
  StridedMatrixMap strided() const {
    return StridedMatrixMap(data_, rows_, cols_,
                            Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>(row_step_, col_step_));
  }
  double operator()(Index r, Index c) const { return data_[r * row_step_ + c * col_step_]; }
  // whether matrix() reads it (C order), not only strided()
  bool row_major() const { return col_step_ == 1 && row_step_ == cols_; }

  // ValueError unless the array has `n` entries (1-D) / this shape (2-D)
  const Array& length(Index n) const;
  const Array& shape(Index rows, Index cols) const;
  // ValueError if an entry is NaN (inf allowed: "no bound") / not finite
  const Array& no_nan() const;
  const Array& finite() const;

 private:
  const char* name_;
  nb::object owned_;  // the numpy array made of another buffer (a memoryview), if any
  double* data_ = nullptr;
  Index size_ = 0, rows_ = 0, cols_ = 0;
  Index row_step_ = 0, col_step_ = 1;  // entries between rows, between columns
};

// A checked int64 numpy array of indices (pairs, geometries, joints, blocks of q), under
// Array's rules: a numpy array of native int64, of the expected number of dimensions,
// C-contiguous, aligned (TypeError otherwise); read only. below() and within() check every
// entry against the range a kernel indexes with before any is used.
class IndexArray {
 public:
  IndexArray(nb::handle object, const char* name, int ndim);

  Index size() const { return size_; }
  Index rows() const { return rows_; }
  Index cols() const { return cols_; }
  const char* name() const { return name_; }
  const std::int64_t* data() const { return data_; }
  Index operator[](Index i) const { return static_cast<Index>(data_[i]); }
  Index operator()(Index r, Index c) const { return static_cast<Index>(data_[r * cols_ + c]); }

  // ValueError unless the array has `n` entries (1-D) / this shape (2-D)
  const IndexArray& length(Index n) const;
  const IndexArray& shape(Index rows, Index cols) const;
  // ValueError unless every entry is in [0, bound): "name[i] = v is no <what> (<of> bound)"
  const IndexArray& below(Index bound, const char* what, const char* of) const;
  // ValueError unless every entry is in [lower, upper)
  const IndexArray& within(std::int64_t lower, std::int64_t upper) const;

 private:
  const char* name_;
  const std::int64_t* data_ = nullptr;
  Index size_ = 0, rows_ = 0, cols_ = 0;
  int ndim_ = 1;
};

// The indices of a list or tuple of Python ints, or of a 1-D IndexArray (TypeError naming
// `name` otherwise); each checked as IndexArray::below does.
std::vector<Index> index_list(nb::handle object, const char* name, Index bound, const char* what,
                              const char* of);

// A new C-contiguous float64 numpy array (1-D when cols < 0) and its data; freeze() makes an
// array read-only
struct NewArray {
  nb::object array;
  double* data;
};
NewArray new_array(Index rows, Index cols = -1);
void freeze(nb::handle array);

// Whether Array(object, name, ndim, Access::read, order) takes `object` as it is: a numpy array
// of native, aligned float64, of ndim dimensions and that order (a kernel that converts what
// it may, as numpy.ascontiguousarray does, converts only the rest).
bool plain_array(nb::handle object, int ndim, Order order);

// The number of dimensions of a numpy array, -1 for any other object (for a kernel that
// takes a vector or a matrix in one place).
int ndim_of(nb::handle object);

// A numpy array (C-contiguous float64: (rows,) for cols < 0, else (rows, cols)) on
// memory that `owner` holds and never reallocates: the array keeps owner alive; read-only
// unless access is Access::write.
nb::object numpy_view(double* data, Index rows, Index cols, nb::handle owner, Access access);

// ValueError with a formatted message (throws)
[[noreturn]] void fail(const std::string& message);

// the numpy C API of the module (called once, from the module's init)
void import_numpy();

}  // namespace sjt
