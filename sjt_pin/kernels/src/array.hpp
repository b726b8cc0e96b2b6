// The kernels' boundary: every array a kernel reads or writes is checked here, before any read.
//
// An argument is accepted only as a numpy array of float64 (native byte order), of the expected
// number of dimensions, C-contiguous, aligned, and writable when the kernel writes it. Anything
// else (a record array's field, a stride-12 view, a Fortran or reversed matrix, float32, a list)
// raises TypeError or ValueError naming the argument and what it should be: nothing is read
// through a stride the kernel does not expect. The public door (sjt_pin's Python API) makes q,
// targets and limit rows contiguous float64 once; the kernels check again, since they are
// callable on their own.
#pragma once

#include <nanobind/nanobind.h>

#include <Eigen/Core>
#include <cstddef>
#include <string>

namespace sjt {

namespace nb = nanobind;

using Index = Eigen::Index;
using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using Vector = Eigen::VectorXd;
using MatrixMap = Eigen::Map<RowMatrix>;
using ConstMatrixMap = Eigen::Map<const RowMatrix>;
using VectorMap = Eigen::Map<Eigen::VectorXd>;
using ConstVectorMap = Eigen::Map<const Eigen::VectorXd>;

// Which arrays a kernel takes: read-only or written in place.
enum class Access { read, write };

// A checked float64 numpy array (see the file's comment). It borrows the array: the Python
// object outlives the kernel call that made it.
class Array {
 public:
  Array(nb::handle object, const char* name, int ndim, Access access = Access::read);

  Index size() const { return size_; }
  Index rows() const { return rows_; }
  Index cols() const { return cols_; }
  const char* name() const { return name_; }
  double* data() { return data_; }
  const double* data() const { return data_; }

  ConstVectorMap vector() const { return ConstVectorMap(data_, size_); }
  VectorMap vector() { return VectorMap(data_, size_); }
  ConstMatrixMap matrix() const { return ConstMatrixMap(data_, rows_, cols_); }
  MatrixMap matrix() { return MatrixMap(data_, rows_, cols_); }

  // ValueError unless the array has `n` entries (1-D) / this shape (2-D)
  const Array& length(Index n) const;
  const Array& shape(Index rows, Index cols) const;
  // ValueError if an entry is NaN (inf allowed: "no bound") / not finite
  const Array& no_nan() const;
  const Array& finite() const;

 private:
  const char* name_;
  double* data_ = nullptr;
  Index size_ = 0, rows_ = 0, cols_ = 0;
};

// ValueError with a formatted message (throws)
[[noreturn]] void fail(const std::string& message);

// the numpy C API of the module (called once, from the module's init)
void import_numpy();

}  // namespace sjt
