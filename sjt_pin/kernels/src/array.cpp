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

// numpy's array for `object`: itself, or the array numpy makes in place of another object that
// exports a buffer (a memoryview; owned by `owned`); TypeError naming `name` for anything else
PyArrayObject* as_array(nb::handle object, const char* name, const char* what, nb::object& owned) {
  if (PyArray_Check(object.ptr())) return reinterpret_cast<PyArrayObject*>(object.ptr());
  if (PyObject_CheckBuffer(object.ptr()) && !PyBytes_Check(object.ptr()) &&
      !PyByteArray_Check(object.ptr())) {
    // (a buffer's array is a view of its memory: numpy never copies one)
    PyObject* array = PyArray_FromAny(object.ptr(), nullptr, 0, 0, 0, nullptr);
    if (!array) throw nb::python_error();
    owned = nb::steal(array);
    return reinterpret_cast<PyArrayObject*>(array);
  }
  std::ostringstream out;
  out << name << " must be " << what << ", got " << nb::type_name(object.type()).c_str();
  throw nb::type_error(out.str().c_str());
}

}  // namespace

Array::Array(nb::handle object, const char* name, int ndim, Access access, Order order)
    : name_(name) {
  const char* what = ndim == 1 ? "a 1-D numpy array of float64" : "a 2-D numpy array of float64";
  PyArrayObject* array = as_array(object, name, what, owned_);
  bool c_order = PyArray_IS_C_CONTIGUOUS(array);
  bool ok = PyArray_TYPE(array) == NPY_DOUBLE && PyArray_ISNOTSWAPPED(array) &&
            PyArray_NDIM(array) == ndim && PyArray_ISALIGNED(array) &&
            (c_order || (order == Order::any && PyArray_IS_F_CONTIGUOUS(array)));
  if (!ok) {
    std::ostringstream out;
    out << name << " must be " << (ndim == 1 ? "a 1-D" : "a 2-D")
        << (order == Order::any && ndim == 2 ? " C- or Fortran-contiguous" : " C-contiguous")
        << ", aligned float64 array, got " << describe(array);
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
  // (an array of one row or column is both C- and Fortran-contiguous: either steps read it)
  row_step_ = c_order ? cols_ : 1;
  col_step_ = c_order ? 1 : rows_;
}

bool plain_array(nb::handle object, int ndim, Order order) {
  if (!PyArray_Check(object.ptr())) return false;
  auto* array = reinterpret_cast<PyArrayObject*>(object.ptr());
  return PyArray_TYPE(array) == NPY_DOUBLE && PyArray_ISNOTSWAPPED(array) &&
         PyArray_NDIM(array) == ndim && PyArray_ISALIGNED(array) &&
         (PyArray_IS_C_CONTIGUOUS(array) ||
          (order == Order::any && PyArray_IS_F_CONTIGUOUS(array)));
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
  const char* what = ndim == 1 ? "a 1-D numpy array of int64" : "a 2-D numpy array of int64";
  if (!PyArray_Check(object.ptr())) {
    std::ostringstream out;
    out << name << " must be " << what << ", got " << nb::type_name(object.type()).c_str();
    throw nb::type_error(out.str().c_str());
  }
  auto* array = reinterpret_cast<PyArrayObject*>(object.ptr());
  bool ok = PyArray_TYPE(array) == NPY_INT64 && PyArray_ISNOTSWAPPED(array) &&
            PyArray_NDIM(array) == ndim && PyArray_ISALIGNED(array) &&
            PyArray_IS_C_CONTIGUOUS(array);
  if (!ok) {
    std::ostringstream out;
    out << name << " must be " << (ndim == 1 ? "a 1-D" : "a 2-D")
        << " C-contiguous, aligned int64 array, got " << describe(array);
    throw nb::type_error(out.str().c_str());
  }
  data_ = static_cast<const std::int64_t*>(PyArray_DATA(array));
  size_ = static_cast<Index>(PyArray_SIZE(array));
  rows_ = static_cast<Index>(PyArray_DIMS(array)[0]);
  cols_ = ndim == 2 ? static_cast<Index>(PyArray_DIMS(array)[1]) : 1;
  ndim_ = ndim;
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

namespace {

[[noreturn]] void no_such(const char* name, Index at, Index col, bool two_d, long long value,
                          const char* what, const char* of, Index bound) {
  std::ostringstream out;
  out << name << "[" << at;
  if (two_d) out << ", " << col;
  out << "] = " << value << " is no " << what << " (" << of << " " << bound << ")";
  fail(out.str());
}

}  // namespace

const IndexArray& IndexArray::below(Index bound, const char* what, const char* of) const {
  for (Index k = 0; k < size_; ++k)
    if (data_[k] < 0 || data_[k] >= bound)
      no_such(name_, k / cols_, k % cols_, ndim_ == 2, static_cast<long long>(data_[k]), what,
              of, bound);
  return *this;
}

std::vector<Index> index_list(nb::handle object, const char* name, Index bound, const char* what,
                              const char* of) {
  std::vector<Index> out;
  if (PyList_Check(object.ptr()) || PyTuple_Check(object.ptr())) {
    nb::sequence items = nb::borrow<nb::sequence>(object);
    Index n = static_cast<Index>(nb::len(items));
    out.reserve(static_cast<std::size_t>(n));
    for (Index i = 0; i < n; ++i) {
      nb::handle item = items[i];
      if (!PyLong_Check(item.ptr())) {
        std::ostringstream msg;
        msg << name << "[" << i << "] must be an int (an index), got "
            << nb::type_name(item.type()).c_str();
        throw nb::type_error(msg.str().c_str());
      }
      int overflow = 0;
      long long k = PyLong_AsLongLongAndOverflow(item.ptr(), &overflow);
      if (overflow || k < 0 || k >= bound)
        no_such(name, i, 0, false, overflow ? -1 : k, what, of, bound);
      out.push_back(static_cast<Index>(k));
    }
    return out;
  }
  if (!PyArray_Check(object.ptr())) {
    std::ostringstream msg;
    msg << name << " must be a list of ints or a 1-D numpy array of int64, got "
        << nb::type_name(object.type()).c_str();
    throw nb::type_error(msg.str().c_str());
  }
  IndexArray indices(object, name, 1);
  indices.below(bound, what, of);
  out.resize(static_cast<std::size_t>(indices.size()));
  for (Index i = 0; i < indices.size(); ++i) out[static_cast<std::size_t>(i)] = indices[i];
  return out;
}

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

NewArray new_array(Index rows, Index cols) {
  npy_intp shape[2] = {static_cast<npy_intp>(rows), static_cast<npy_intp>(cols < 0 ? 0 : cols)};
  PyObject* array = PyArray_SimpleNew(cols < 0 ? 1 : 2, shape, NPY_DOUBLE);
  if (!array) throw nb::python_error();
  return {nb::steal(array),
          static_cast<double*>(PyArray_DATA(reinterpret_cast<PyArrayObject*>(array)))};
}

void freeze(nb::handle array) {
  PyArray_CLEARFLAGS(reinterpret_cast<PyArrayObject*>(array.ptr()), NPY_ARRAY_WRITEABLE);
}

}  // namespace sjt
