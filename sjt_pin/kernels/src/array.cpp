// The checked arrays of array.hpp: numpy's arrays read in place through its C API.
#include "array.hpp"

#define PY_ARRAY_UNIQUE_SYMBOL SJT_PIN_ARRAY_API
#include <numpy/arrayobject.h>

#include <cmath>
#include <sstream>

namespace sjt {

void import_numpy() {
  if (_import_array() < 0) throw nb::python_error();
}

[[noreturn]] void fail(const std::string& message) { throw nb::value_error(message.c_str()); }

namespace {

std::string describe(PyArrayObject* array) {
  std::ostringstream out;
  out << "an array of dtype " << nb::str(nb::handle((PyObject*)PyArray_DESCR(array))).c_str()
      << " and shape (";
  for (int k = 0; k < PyArray_NDIM(array); ++k)
    out << (k ? ", " : "") << PyArray_DIMS(array)[k];
  out << (PyArray_NDIM(array) == 1 ? ",)" : ")") << " with strides (";
  for (int k = 0; k < PyArray_NDIM(array); ++k)
    out << (k ? ", " : "") << PyArray_STRIDES(array)[k];
  out << (PyArray_NDIM(array) == 1 ? ",)" : ")");
  return out.str();
}

}  // namespace

Array::Array(nb::handle object, const char* name, int ndim, Access access) : name_(name) {
  const char* what = ndim == 1 ? "a 1-D" : "a 2-D";
  if (!PyArray_Check(object.ptr())) {
    std::ostringstream out;
    out << name << " must be " << what << " numpy array of float64, got "
        << nb::type_name(object.type()).c_str();
    throw nb::type_error(out.str().c_str());
  }
  auto* array = reinterpret_cast<PyArrayObject*>(object.ptr());
  bool ok = PyArray_TYPE(array) == NPY_DOUBLE && PyArray_ISNOTSWAPPED(array) &&
            PyArray_NDIM(array) == ndim && PyArray_ISALIGNED(array) &&
            PyArray_IS_C_CONTIGUOUS(array);
  if (!ok) {
    std::ostringstream out;
    out << name << " must be " << what << " C-contiguous, aligned float64 array, got "
        << describe(array);
    throw nb::type_error(out.str().c_str());
  }
  if (access == Access::write && !PyArray_ISWRITEABLE(array)) {
    std::ostringstream out;
    out << name << " must be writable (the kernel writes its result into it)";
    throw nb::value_error(out.str().c_str());
  }
  data_ = static_cast<double*>(PyArray_DATA(array));
  size_ = static_cast<Index>(PyArray_SIZE(array));
  rows_ = static_cast<Index>(PyArray_DIMS(array)[0]);
  cols_ = ndim == 2 ? static_cast<Index>(PyArray_DIMS(array)[1]) : 1;
}

const Array& Array::length(Index n) const {
  if (size_ != n) {
    std::ostringstream out;
    out << name_ << " must have length " << n << ", got " << size_;
    fail(out.str());
  }
  return *this;
}

const Array& Array::shape(Index rows, Index cols) const {
  if (rows_ != rows || cols_ != cols) {
    std::ostringstream out;
    out << name_ << " must have shape (" << rows << ", " << cols << "), got (" << rows_ << ", "
        << cols_ << ")";
    fail(out.str());
  }
  return *this;
}

const Array& Array::no_nan() const {
  for (Index k = 0; k < size_; ++k)
    if (std::isnan(data_[k])) fail(std::string(name_) + " contains NaN");
  return *this;
}

const Array& Array::finite() const {
  for (Index k = 0; k < size_; ++k)
    if (!std::isfinite(data_[k])) fail(std::string(name_) + " contains NaN or inf");
  return *this;
}

}  // namespace sjt
