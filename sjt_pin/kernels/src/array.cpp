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

// The numpy array `object` if it is one of `ndim` dimensions and numpy type `type` (native
// byte order), aligned and C-contiguous; TypeError naming `name` and what it got otherwise.
PyArrayObject* checked(nb::handle object, const char* name, int ndim, int type,
                       const char* type_name) {
  const char* what = ndim == 1 ? "a 1-D" : "a 2-D";
  if (!PyArray_Check(object.ptr())) {
    std::ostringstream out;
    out << name << " must be " << what << " numpy array of " << type_name << ", got "
        << nb::type_name(object.type()).c_str();
    throw nb::type_error(out.str().c_str());
  }
  auto* array = reinterpret_cast<PyArrayObject*>(object.ptr());
  bool ok = PyArray_TYPE(array) == type && PyArray_ISNOTSWAPPED(array) &&
            PyArray_NDIM(array) == ndim && PyArray_ISALIGNED(array) &&
            PyArray_IS_C_CONTIGUOUS(array);
  if (!ok) {
    std::ostringstream out;
    out << name << " must be " << what << " C-contiguous, aligned " << type_name
        << " array, got " << describe(array);
    throw nb::type_error(out.str().c_str());
  }
  return array;
}

}  // namespace

int ndim_of(nb::handle object) {
  if (!PyArray_Check(object.ptr())) return -1;
  return PyArray_NDIM(reinterpret_cast<PyArrayObject*>(object.ptr()));
}

nb::object numpy_view(double* data, Index rows, Index cols, nb::handle owner, Access access) {
  static double empty = 0.0;  // (numpy reads nothing of an empty array, but wants a pointer)
  npy_intp dims[2] = {static_cast<npy_intp>(rows), static_cast<npy_intp>(cols)};
  int flags = NPY_ARRAY_C_CONTIGUOUS | NPY_ARRAY_ALIGNED;
  if (access == Access::write) flags |= NPY_ARRAY_WRITEABLE;
  PyObject* array = PyArray_New(&PyArray_Type, cols < 0 ? 1 : 2, dims, NPY_DOUBLE, nullptr,
                                data ? data : &empty, 0, flags, nullptr);
  if (!array) throw nb::python_error();
  owner.inc_ref();  // (stolen by PyArray_SetBaseObject)
  if (PyArray_SetBaseObject(reinterpret_cast<PyArrayObject*>(array), owner.ptr()) < 0) {
    Py_DECREF(array);
    throw nb::python_error();
  }
  return nb::steal(array);
}

Array::Array(nb::handle object, const char* name, int ndim, Access access) : name_(name) {
  PyArrayObject* array = checked(object, name, ndim, NPY_DOUBLE, "float64");
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

IndexArray::IndexArray(nb::handle object, const char* name, int ndim) : name_(name) {
  static_assert(sizeof(npy_int64) == sizeof(std::int64_t), "int64");
  PyArrayObject* array = checked(object, name, ndim, NPY_INT64, "int64");
  data_ = static_cast<const std::int64_t*>(PyArray_DATA(array));
  size_ = static_cast<Index>(PyArray_SIZE(array));
  rows_ = static_cast<Index>(PyArray_DIMS(array)[0]);
  cols_ = ndim == 2 ? static_cast<Index>(PyArray_DIMS(array)[1]) : 1;
}

const IndexArray& IndexArray::length(Index n) const {
  if (size_ != n) {
    std::ostringstream out;
    out << name_ << " must have length " << n << ", got " << size_;
    fail(out.str());
  }
  return *this;
}

const IndexArray& IndexArray::shape(Index rows, Index cols) const {
  if (rows_ != rows || cols_ != cols) {
    std::ostringstream out;
    out << name_ << " must have shape (" << rows << ", " << cols << "), got (" << rows_ << ", "
        << cols_ << ")";
    fail(out.str());
  }
  return *this;
}

const IndexArray& IndexArray::within(std::int64_t lower, std::int64_t upper) const {
  for (Index k = 0; k < size_; ++k)
    if (data_[k] < lower || data_[k] >= upper) {
      std::ostringstream out;
      out << name_ << ": entry " << k << " is " << data_[k] << ", outside [" << lower << ", "
          << upper << ")";
      fail(out.str());
    }
  return *this;
}

}  // namespace sjt
