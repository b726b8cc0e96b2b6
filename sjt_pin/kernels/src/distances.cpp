/* sjt_pin.kernels._distances: coal's distance queries of a collision limit's pairs, called from
 * the C kernels (distances.h) without a Python call: what Pinocchio's updateGeometryPlacements
 * and computeDistance do (each geometry at its joint's pose times its placement, then
 * coal::ComputeDistance on the pair's shapes), the shapes taken from coal's own Python objects
 * through Boost.Python's registry. Built against the libcoal its build found; the module
 * refuses to load beside another coal (a C++ ABI), and sjt_pin.limits.collision then queries
 * through Pinocchio's Python bindings instead. */

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

struct Queries {
    Distances api;  /* first: the C kernels see a Queries * as a Distances * */
    std::vector<std::unique_ptr<coal::ComputeDistance>> functors;
    std::vector<coal::DistanceRequest> requests;
    std::vector<coal::DistanceResult> results;
    std::vector<std::pair<Py_ssize_t, Py_ssize_t>> pairs;
    std::vector<Py_ssize_t> joints;  /* each geometry's parent joint */
    const double *placements = nullptr;  /* (ngeoms, 4, 4) row-major, read at each query */
    PyObject *keep = nullptr;  /* the shapes and the placements' array */

    /* geometry g's world pose: its joint's (4x4 row-major in poses) times its placement */
    coal::Transform3s transform(const double *poses, Py_ssize_t g) const
    {
        const double *H = poses + 16 * joints[g], *M = placements + 16 * g;
        coal::Matrix3s rotation;
        coal::Vec3s translation;
        for (int r = 0; r < 3; r++) {
            for (int c = 0; c < 3; c++)
                rotation(r, c) = H[4 * r] * M[c] + H[4 * r + 1] * M[4 + c]
                                 + H[4 * r + 2] * M[8 + c];
            translation(r) = H[4 * r] * M[3] + H[4 * r + 1] * M[7] + H[4 * r + 2] * M[11]
                             + H[4 * r + 3];
        }
        return coal::Transform3s(rotation, translation);
    }
};

int distance(Distances *self, Py_ssize_t k, const double *poses, Py_ssize_t njoints,
             double *out)
{
    Queries *Q = reinterpret_cast<Queries *>(self);
    if (k < 0 || k >= self->npairs) {
        PyErr_Format(PyExc_IndexError, "pair %zd out of range (%zd pairs)", k, self->npairs);
        return -1;
    }
    const auto &pair = Q->pairs[k];
    if (Q->joints[pair.first] >= njoints || Q->joints[pair.second] >= njoints) {
        PyErr_Format(PyExc_ValueError, "pair %zd: its joints are not among the %zd poses", k,
                     njoints);
        return -1;
    }
    coal::DistanceResult &result = Q->results[k];
    result.clear();
    try {
        (*Q->functors[k])(Q->transform(poses, pair.first), Q->transform(poses, pair.second),
                          Q->requests[k], result);
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

/* queries(shapes, pairs, requests, joints, placements) -> capsule: shapes (coal's shapes, one
 * per geometry), pairs ((first, second) geometry indices), requests (coal DistanceRequests, one
 * per pair, copied), joints (each geometry's parent joint) and placements (a C-contiguous
 * float64 array (ngeoms, 4, 4): each geometry's pose in its joint's frame, read at each query,
 * so that moving an obstacle is writing its placement) */
PyObject *py_queries(PyObject *, PyObject *args)
{
    PyObject *shapes, *pairs, *requests, *joints, *placements;
    if (!PyArg_ParseTuple(args, "OOOOO:queries", &shapes, &pairs, &requests, &joints,
                          &placements))
        return nullptr;
    std::unique_ptr<Queries> Q(new Queries());
    Py_buffer view;
    if (PyObject_GetBuffer(placements, &view, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0)
        return nullptr;
    bool ok = view.format && std::strcmp(view.format, "d") == 0 && view.ndim == 3
              && view.shape[1] == 4 && view.shape[2] == 4;
    Py_ssize_t ngeoms = ok ? view.shape[0] : 0;
    Q->placements = static_cast<const double *>(view.buf);
    PyBuffer_Release(&view);  /* (the array is kept alive with the capsule) */
    if (!ok) {
        PyErr_SetString(PyExc_ValueError, "placements must be a C-contiguous float64 array of "
                        "shape (ngeoms, 4, 4)");
        return nullptr;
    }
    PyObject *seq[4] = {PySequence_Fast(shapes, "shapes must be a sequence"),
                        PySequence_Fast(pairs, "pairs must be a sequence"),
                        PySequence_Fast(requests, "requests must be a sequence"),
                        PySequence_Fast(joints, "joints must be a sequence")};
    try {
        ok = seq[0] && seq[1] && seq[2] && seq[3];
        Py_ssize_t npairs = ok ? PySequence_Fast_GET_SIZE(seq[1]) : 0;
        if (ok && (PySequence_Fast_GET_SIZE(seq[0]) != ngeoms
                   || PySequence_Fast_GET_SIZE(seq[3]) != ngeoms
                   || PySequence_Fast_GET_SIZE(seq[2]) != npairs)) {
            PyErr_SetString(PyExc_ValueError, "queries: one shape, joint and placement per "
                            "geometry and one request per pair");
            ok = false;
        }
        std::vector<const coal::CollisionGeometry *> geometry;
        for (Py_ssize_t g = 0; ok && g < ngeoms; g++) {
            auto *shape = extract_pointer<coal::CollisionGeometry>(
                PySequence_Fast_GET_ITEM(seq[0], g), "shape", g);
            Py_ssize_t j = shape ? PyLong_AsSsize_t(PySequence_Fast_GET_ITEM(seq[3], g)) : -1;
            if (shape && j < 0) {
                if (!PyErr_Occurred())
                    PyErr_Format(PyExc_ValueError, "geometry %zd's joint is negative", g);
            }
            ok = shape && j >= 0;
            geometry.push_back(shape);
            Q->joints.push_back(j);
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
            if (PyErr_Occurred()) {
                ok = false;
            } else if (!(0 <= a && a < ngeoms && 0 <= b && b < ngeoms)) {
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
        if (ok) {
            Q->results.resize(Q->pairs.size());
            Q->api.distance = distance;
            Q->api.npairs = npairs;
        }
    } catch (const bp::error_already_set &) {
        ok = false;
    } catch (const std::exception &exc) {
        PyErr_Format(PyExc_RuntimeError, "coal: %s", exc.what());
        ok = false;
    }
    for (PyObject *item : seq) Py_XDECREF(item);
    if (!ok || !(Q->keep = Py_BuildValue("(OO)", shapes, placements))) return nullptr;
    PyObject *capsule = PyCapsule_New(Q.get(), DISTANCES_CAPSULE, free_queries);
    if (capsule) Q.release();
    return capsule;
}

/* distance(capsule, k, poses) -> (d, normal, p1, p2): Distances.distance from Python (tests);
 * poses (njoints, 16) float64, C-contiguous */
PyObject *py_distance(PyObject *, PyObject *args)
{
    PyObject *capsule, *poses;
    Py_ssize_t k;
    if (!PyArg_ParseTuple(args, "OnO:distance", &capsule, &k, &poses)) return nullptr;
    auto *D = static_cast<Distances *>(PyCapsule_GetPointer(capsule, DISTANCES_CAPSULE));
    if (!D) return nullptr;
    Py_buffer view;
    if (PyObject_GetBuffer(poses, &view, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) return nullptr;
    double out[10];
    int bad = 0;
    if (!(view.format && std::strcmp(view.format, "d") == 0 && view.ndim == 2
          && view.shape[1] == 16)) {
        PyErr_SetString(PyExc_ValueError, "poses must be a float64 array (njoints, 16)");
        bad = 1;
    } else {
        bad = D->distance(D, k, static_cast<const double *>(view.buf), view.shape[0], out);
    }
    PyBuffer_Release(&view);
    if (bad) return nullptr;
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
