/* The compiled distance queries (distances.cpp, module sjt_pin.kernels._distances) as the C
 * kernels see them: coal's distance of a pair at given joint poses, without a Python call. A
 * capsule named DISTANCES_CAPSULE holds a pointer to a Distances (its first member). */

#ifndef SJT_PIN_DISTANCES_H
#define SJT_PIN_DISTANCES_H

#define PY_SSIZE_T_CLEAN
#include <Python.h>

#define DISTANCES_CAPSULE "sjt_pin.kernels._distances.Distances"

typedef struct Distances {
    /* Pair k's distance with its geometries placed at poses[joint] * placement (poses: njoints
     * row-major 4x4 world poses of the joints, Pinocchio's data.oMi, at least those of pair
     * k's geometries): out[0] the distance (m; signed where the request enables it),
     * out[1:4] coal's normal, out[4:7] and out[7:10] the closest points on the pair's first
     * and second geometry (world, m), as Pinocchio's computeDistance gives them. 0, or -1
     * with a Python error set (k or a joint out of range, or coal's exception). */
    int (*distance)(struct Distances *self, Py_ssize_t k, const double *poses,
                    Py_ssize_t njoints, double *out);
    Py_ssize_t npairs;
} Distances;

#endif
