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
#include <cstdint>
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

// A checked int64 numpy array of indices (an index table: joints' coordinates, blocks of q),
// read-only: native int64, of the expected number of dimensions, C-contiguous and aligned, as
// Array; within() checks every entry against the range a kernel indexes with it. It borrows
// the array as Array does.
class IndexArray {
 public:
  IndexArray(nb::handle object, const char* name, int ndim);

  Index size() const { return size_; }
  Index rows() const { return rows_; }
  Index cols() const { return cols_; }
  const char* name() const { return name_; }
  const std::int64_t* data() const { return data_; }
  std::int64_t operator[](Index k) const { return data_[k]; }
  std::int64_t operator()(Index row, Index col) const { return data_[row * cols_ + col]; }

  // ValueError unless the array has `n` entries (1-D) / this shape (2-D)
  const IndexArray& length(Index n) const;
  const IndexArray& shape(Index rows, Index cols) const;
  // ValueError unless every entry is in [lower, upper)
  const IndexArray& within(std::int64_t lower, std::int64_t upper) const;

 private:
  const char* name_;
  const std::int64_t* data_ = nullptr;
  Index size_ = 0, rows_ = 0, cols_ = 0;
};

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
