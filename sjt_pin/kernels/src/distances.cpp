/* sjt_pin.kernels._distances: coal's distance queries of a collision limit's pairs, called from
 * the C kernels (distances.h) without a Python call: what Pinocchio's computeDistance does
 * (coal::ComputeDistance on the pair's shapes at GeometryData.oMg's placements), the shapes
 * taken from coal's own Python objects through Boost.Python's registry. Built against the
 * libcoal its build found; the module refuses to load beside another coal (a C++ ABI), and
 * sjt_pin.limits.collision then queries through Pinocchio's Python bindings instead. */

#include "distances.h"

#include <boost/python.hpp>
#include <coal/collision_data.h>
#include <coal/config.hh>
#include <coal/distance.h>

#include <cstring>
#include <exception>
#include <memory>
#include <vector>

namespace bp = boost::python;

namespace {

/* a 3x3 rotation and a 3-vector translation in memory another object owns (numpy views onto
 * Pinocchio's GeometryData.oMg), read with their strides (bytes) */
struct Placement {
    const char *R;
    Py_ssize_t r0, r1;
    const char *t;
    Py_ssize_t t0;

    coal::Transform3s transform() const
    {
        coal::Matrix3s rotation;
        coal::Vec3s translation;
        for (int r = 0; r < 3; r++) {
            for (int c = 0; c < 3; c++)
                rotation(r, c) = *reinterpret_cast<const double *>(R + r * r0 + c * r1);
            translation(r) = *reinterpret_cast<const double *>(t + r * t0);
        }
        return coal::Transform3s(rotation, translation);
    }
};

struct Queries {
    Distances api;  /* first: the C kernels see a Queries * as a Distances * */
    std::vector<std::unique_ptr<coal::ComputeDistance>> functors;
    std::vector<coal::DistanceRequest> requests;
    std::vector<coal::DistanceResult> results;
    std::vector<std::pair<Py_ssize_t, Py_ssize_t>> pairs;
    std::vector<Placement> placements;
    PyObject *keep = nullptr;  /* the shapes, the placements' arrays and what they view */
};

int distance(Distances *self, Py_ssize_t k, double *out)
{
    Queries *Q = reinterpret_cast<Queries *>(self);
    if (k < 0 || k >= self->npairs) {
        PyErr_Format(PyExc_IndexError, "pair %zd out of range (%zd pairs)", k, self->npairs);
        return -1;
    }
    const auto &pair = Q->pairs[k];
    coal::DistanceResult &result = Q->results[k];
    result.clear();
    try {
        (*Q->functors[k])(Q->placements[pair.first].transform(),
                          Q->placements[pair.second].transform(), Q->requests[k], result);
    } catch (const std::exception &exc) {
        PyErr_Format(PyExc_RuntimeError, "coal: %s", exc.what());
        return -1;
    }
    out[0] = result.min_distance;
    for (int c = 0; c < 3; c++) {
        out[1 + c] = result.normal(c);
        out[4 + c] = result.nearest_points[0](c);
        out[7 + c] = result.nearest_points[1](c);
    }
    return 0;
}

void free_queries(PyObject *capsule)
{
    Queries *Q = static_cast<Queries *>(PyCapsule_GetPointer(capsule, DISTANCES_CAPSULE));
    if (!Q) return;
    Py_XDECREF(Q->keep);
    delete Q;
}

/* the float64 array's data pointer and strides, checked to hold `n` by `m` (m 0: a vector of
 * n); false with a Python error set */
bool placement_part(PyObject *array, Py_ssize_t n, Py_ssize_t m, const char **data,
                    Py_ssize_t *s0, Py_ssize_t *s1)
{
    Py_buffer view;
    if (PyObject_GetBuffer(array, &view, PyBUF_STRIDES | PyBUF_FORMAT) < 0) return false;
    bool ok = view.format && std::strcmp(view.format, "d") == 0
              && view.ndim == (m ? 2 : 1) && view.shape[0] == n && (!m || view.shape[1] == m);
    if (ok) {
        *data = static_cast<const char *>(view.buf);
        *s0 = view.strides[0];
        *s1 = m ? view.strides[1] : 0;
    } else {
        PyErr_Format(PyExc_ValueError, "a placement's %s must be a float64 array of shape %s",
                     m ? "rotation" : "translation", m ? "(3, 3)" : "(3,)");
    }
    PyBuffer_Release(&view);
    return ok;
}

template <typename T>
T *extract_pointer(PyObject *obj, const char *what, Py_ssize_t i)
{
    bp::extract<T *> get{bp::object(bp::handle<>(bp::borrowed(obj)))};
    if (!get.check()) {
        PyErr_Format(PyExc_TypeError, "%s %zd is not a coal %s", what, i, what);
        return nullptr;
    }
    return get();
}

/* queries(shapes, pairs, requests, rotations, translations, keep) -> capsule: shapes (coal's
 * shapes, one per geometry), pairs ((first, second) geometry indices), requests (coal
 * DistanceRequests, one per pair, copied), rotations and translations (one per geometry: the
 * (3, 3) and (3,) float64 arrays whose memory holds its placement, read at each query), keep
 * (the object that owns that memory where the arrays are views onto it; kept alive with the
 * shapes and the arrays) */
PyObject *py_queries(PyObject *, PyObject *args)
{
    PyObject *shapes, *pairs, *requests, *rotations, *translations, *keep;
    if (!PyArg_ParseTuple(args, "OOOOOO:queries", &shapes, &pairs, &requests, &rotations,
                          &translations, &keep))
        return nullptr;
    std::unique_ptr<Queries> Q(new Queries());
    try {
        PyObject *seq[4] = {PySequence_Fast(shapes, "shapes must be a sequence"),
                            PySequence_Fast(pairs, "pairs must be a sequence"),
                            PySequence_Fast(requests, "requests must be a sequence"), nullptr};
        bool ok = seq[0] && seq[1] && seq[2];
        Py_ssize_t ngeoms = ok ? PySequence_Fast_GET_SIZE(seq[0]) : 0;
        Py_ssize_t npairs = ok ? PySequence_Fast_GET_SIZE(seq[1]) : 0;
        if (ok && (PySequence_Size(rotations) != ngeoms || PySequence_Size(translations) != ngeoms
                   || PySequence_Fast_GET_SIZE(seq[2]) != npairs)) {
            PyErr_SetString(PyExc_ValueError, "queries: one rotation and translation per shape "
                            "and one request per pair");
            ok = false;
        }
        std::vector<const coal::CollisionGeometry *> geometry;
        for (Py_ssize_t g = 0; ok && g < ngeoms; g++) {
            auto *shape = extract_pointer<coal::CollisionGeometry>(
                PySequence_Fast_GET_ITEM(seq[0], g), "shape", g);
            Placement p{};
            Py_ssize_t unused;
            PyObject *R = shape ? PySequence_GetItem(rotations, g) : nullptr;
            PyObject *t = R ? PySequence_GetItem(translations, g) : nullptr;
            ok = t && placement_part(R, 3, 3, &p.R, &p.r0, &p.r1)
                 && placement_part(t, 3, 0, &p.t, &p.t0, &unused);
            Py_XDECREF(R);
            Py_XDECREF(t);
            geometry.push_back(shape);
            Q->placements.push_back(p);
        }
        for (Py_ssize_t k = 0; ok && k < npairs; k++) {
            PyObject *item = PySequence_Fast(PySequence_Fast_GET_ITEM(seq[1], k),
                                             "a pair must be a sequence of two indices");
            Py_ssize_t a = -1, b = -1;
            ok = item && PySequence_Fast_GET_SIZE(item) == 2;
            if (ok) {
                a = PyLong_AsSsize_t(PySequence_Fast_GET_ITEM(item, 0));
                b = PyLong_AsSsize_t(PySequence_Fast_GET_ITEM(item, 1));
            }
            Py_XDECREF(item);
            if (PyErr_Occurred()) ok = false;
            else if (!(0 <= a && a < ngeoms && 0 <= b && b < ngeoms)) {
                PyErr_Format(PyExc_ValueError, "pair %zd names no shape", k);
                ok = false;
            }
            auto *request = ok ? extract_pointer<coal::DistanceRequest>(
                                     PySequence_Fast_GET_ITEM(seq[2], k), "DistanceRequest", k)
                               : nullptr;
            if (!request) {
                ok = false;
                break;
            }
            Q->pairs.emplace_back(a, b);
            Q->requests.push_back(*request);
            Q->functors.emplace_back(new coal::ComputeDistance(geometry[a], geometry[b]));
        }
        for (PyObject *s : seq) Py_XDECREF(s);
        if (!ok) return nullptr;
        Q->results.resize(Q->pairs.size());
        Q->api.distance = distance;
        Q->api.npairs = npairs;
    } catch (const bp::error_already_set &) {
        return nullptr;
    } catch (const std::exception &exc) {
        PyErr_Format(PyExc_RuntimeError, "coal: %s", exc.what());
        return nullptr;
    }
    Q->keep = Py_BuildValue("(OOOO)", shapes, rotations, translations, keep);
    if (!Q->keep) return nullptr;
    PyObject *capsule = PyCapsule_New(Q.get(), DISTANCES_CAPSULE, free_queries);
    if (capsule) Q.release();
    return capsule;
}

/* distance(capsule, k) -> (d, normal, p1, p2): Distances.distance from Python (tests) */
PyObject *py_distance(PyObject *, PyObject *args)
{
    PyObject *capsule;
    Py_ssize_t k;
    if (!PyArg_ParseTuple(args, "On:distance", &capsule, &k)) return nullptr;
    auto *D = static_cast<Distances *>(PyCapsule_GetPointer(capsule, DISTANCES_CAPSULE));
    double out[10];
    if (!D || D->distance(D, k, out)) return nullptr;
    return Py_BuildValue("(d(ddd)(ddd)(ddd))", out[0], out[1], out[2], out[3], out[4], out[5],
                         out[6], out[7], out[8], out[9]);
}

PyMethodDef methods[] = {
    {"queries", py_queries, METH_VARARGS, "The compiled distance queries of a limit's pairs."},
    {"distance", py_distance, METH_VARARGS, "One pair's (d, normal, p1, p2) (tests)."},
    {nullptr, nullptr, 0, nullptr}};

PyModuleDef module = {PyModuleDef_HEAD_INIT, "_distances",
                      "coal's distance queries without a Python call (distances.h)", -1,
                      methods};

}  // namespace

/* refuses to load beside a coal other than the one it was built against (an ImportError) */
PyMODINIT_FUNC PyInit__distances(void)
{
    PyObject *coal_module = PyImport_ImportModule("coal");
    if (!coal_module) return nullptr;
    PyObject *version = PyObject_GetAttrString(coal_module, "__version__");
    Py_DECREF(coal_module);
    const char *text = version ? PyUnicode_AsUTF8(version) : nullptr;
    if (!text) {
        Py_XDECREF(version);
        return nullptr;
    }
    if (std::strcmp(text, COAL_VERSION) != 0) {
        PyErr_Format(PyExc_ImportError, "built against coal %s, found coal %s", COAL_VERSION,
                     text);
        Py_DECREF(version);
        return nullptr;
    }
    Py_DECREF(version);
    return PyModule_Create(&module);
}
