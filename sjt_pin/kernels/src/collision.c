/* The collision limit's compiled parts: velocity-damper and witness rows, Pinocchio's
 * distance queries, the broad phase's skip. */

#include "kernels.h"
#include "distances.h"

/* -- collision dampers (sjt_pin/limits/collision.py) ------------------------------------------ */

/* damper_rows(J, support, pairs, gain_rate, A, b): one velocity-damper row per pair. J (6, N):
 * Pinocchio's WORLD joint Jacobians (data.J, rows linear then angular); support (njoints, N):
 * 1 where a column moves a joint's frame; pairs (k, 13): distance d, margin, the joints of
 * the two geometries (a, b), the unit normal n from a to b (coal's), the closest points p_a
 * and p_b (world). Row i: A_i = (u_a^T J) support[a] - (u_b^T J) support[b] with
 * u_x = [n; p_x x n], and b_i = gain_rate (d - margin); A (k, N) and b (k,) are written. */
static void damper_rows_c(Mat J, Mat support, Mat pairs, double rate, double *A, double *b)
{
    Py_ssize_t N = J.n;
    for (Py_ssize_t i = 0; i < pairs.m; i++) {
        double u[2][6];
        Py_ssize_t joint[2];
        double nx = AT(pairs, i, 4), ny = AT(pairs, i, 5), nz = AT(pairs, i, 6);
        for (int side = 0; side < 2; side++) {
            double px = AT(pairs, i, 7 + 3 * side), py = AT(pairs, i, 8 + 3 * side);
            double pz = AT(pairs, i, 9 + 3 * side);
            u[side][0] = nx;
            u[side][1] = ny;
            u[side][2] = nz;
            u[side][3] = py * nz - pz * ny;
            u[side][4] = pz * nx - px * nz;
            u[side][5] = px * ny - py * nx;
            joint[side] = (Py_ssize_t)AT(pairs, i, 2 + side);
        }
        for (Py_ssize_t c = 0; c < N; c++) {
            double va = 0.0, vb = 0.0;
            for (int r = 0; r < 6; r++) {
                va += u[0][r] * AT(J, r, c);
                vb += u[1][r] * AT(J, r, c);
            }
            A[i * N + c] = va * AT(support, joint[0], c) - vb * AT(support, joint[1], c);
        }
        b[i] = rate * (AT(pairs, i, 0) - AT(pairs, i, 1));
    }
}

/* Whether every row of P (k, 13) names two joints (columns 2 and 3) below njoints; sets
 * ValueError naming the row otherwise (`what`: the rows' name) */
static int rows_name_joints(Mat P, Py_ssize_t njoints, const char *what)
{
    for (Py_ssize_t i = 0; i < P.m; i++)
        for (int side = 0; side < 2; side++) {
            double j = AT(P, i, 2 + side);
            if (!(j >= 0.0 && j < (double)njoints)) {
                PyErr_Format(PyExc_ValueError, "%s[%zd] names joint %zd; support has %zd", what,
                             i, (Py_ssize_t)j, njoints);
                return 0;
            }
        }
    return 1;
}

PyObject *py_damper_rows(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!nargs_ok(nargs, 6, "damper_rows")) return NULL;
    double rate = PyFloat_AsDouble(args[3]);
    if (rate == -1.0 && PyErr_Occurred()) return NULL;
    Arg J = {0}, sup = {0}, pairs = {0}, A = {0}, b = {0};
    PyObject *result = NULL;
    if (acquire(args[0], &J, 0, 2, "J") || acquire(args[1], &sup, 0, 2, "support")
        || acquire(args[2], &pairs, 0, 2, "pairs") || acquire(args[4], &A, 1, 2, "A")
        || acquire(args[5], &b, 1, 1, "b"))
        goto done;
    Mat Jm = mat(&J), Sm = mat(&sup), Pm = mat(&pairs);
    double *Av = out_mat(&A, "A"), *bv = out_vec(&b, "b");
    if (!Av || !bv) goto done;
    if (Jm.m != 6 || Sm.n != Jm.n || Pm.n != 13 || A.view.shape[0] != Pm.m
        || A.view.shape[1] != Jm.n || length(&b) != Pm.m) {
        PyErr_Format(PyExc_ValueError, "J (6, N), support (njoints, N), pairs (k, 13), A (k, N) "
                     "and b (k,) do not fit: J (%zd, %zd), support (%zd, %zd), pairs (%zd, %zd)",
                     Jm.m, Jm.n, Sm.m, Sm.n, Pm.m, Pm.n);
        goto done;
    }
    if (!rows_name_joints(Pm, Sm.m, "pairs")) goto done;
    damper_rows_c(Jm, Sm, Pm, rate, Av, bv);
    result = Py_None;
    Py_INCREF(result);
done:
    release(&J); release(&sup); release(&pairs); release(&A); release(&b);
    return result;
}

/* The closing speed v >= 0 a row can hold for tau and still brake to rest at a within the
 * excess h (m): v tau + v^2 / (2 a) = |h|, signed as h (a row inside its margin separates). */
static double stoppable_speed(double h, double a, double tau)
{
    double v = sqrt(a * tau * a * tau + 2.0 * a * fabs(h)) - a * tau;
    return h >= 0.0 ? v : -v;
}

/* stoppable_rows(A, b, dq, ddq, accelerations, jerks, rate, dt, share, slack): the damper
 * rows' bounds (in place) made ones an arm with acceleration (and jerk) limits can keep. Along
 * row i the closing speed s_i = A_i q_dot changes at up to a_i = sum_j |A_ij| accelerations_j
 * (m/s^2), and that rate changes at up to j_i = sum_j |A_ij| jerks_j (m/s^3; jerks None: no
 * limit). With h = b_i / rate the row's excess over its margin (m; rate = gain / dt):
 *   - b_i = min(b_i, v(h)), v the closing speed that, held for tau = dt + a / j and then
 *     braked at a = share a_i (j = share j_i), covers h: v tau + v^2 / (2 a) = h (a row inside
 *     its margin separates no faster than v(|h|)). The other part of each joint's
 *     acceleration is the task's and the other rows';
 *   - b_i = max(b_i, min(s_i + r dt, V(h + slack))), s_i = A_i dq and the rate of change
 *     r = max(-a, A_i ddq - j dt) from the previous step's velocity dq and acceleration ddq,
 *     V as v at the whole a_i: a row whose closing speed jumps (a contact's closest points
 *     slide onto another feature, a row appears) asks it to drop no faster than its share of
 *     the limits allows, while its pair, braking at a_i, stays at least margin - slack apart.
 * A (k, N), b (k,), dq, ddq, accelerations and jerks (N,). */
static void stoppable_rows_c(Mat A, double *b, const double *dq, const double *ddq,
                             const double *acc, const double *jerk, double rate, double dt,
                             double share, double slack)
{
    for (Py_ssize_t i = 0; i < A.m; i++) {
        double a = 0.0, j = 0.0, s = 0.0, sd = 0.0;
        for (Py_ssize_t c = 0; c < A.n; c++) {
            double w = AT(A, i, c);
            a += fabs(w) * acc[c];
            if (jerk) j += fabs(w) * jerk[c];
            s += w * dq[c];
            sd += w * ddq[c];
        }
        if (!(a > 0.0) || !isfinite(a)) continue;  /* a row no joint moves, or no limit */
        double ramp = jerk && j > 0.0 && isfinite(j) ? a / j : 0.0;  /* s to reach a */
        double h = b[i] / rate, v = stoppable_speed(h, share * a, dt + ramp);
        double r = jerk && isfinite(j) ? fmax(-share * a, sd - share * j * dt) : -share * a;
        b[i] = h >= 0.0 ? fmin(b[i], v) : fmax(b[i], v);
        b[i] = fmax(b[i], fmin(s + r * dt, stoppable_speed(h + slack, a, dt + ramp)));
    }
}

PyObject *py_stoppable_rows(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!nargs_ok(nargs, 10, "stoppable_rows")) return NULL;
    double rate = PyFloat_AsDouble(args[6]), dt = PyFloat_AsDouble(args[7]);
    double share = PyFloat_AsDouble(args[8]), slack = PyFloat_AsDouble(args[9]);
    if (PyErr_Occurred()) return NULL;
    if (!(rate > 0.0 && dt > 0.0 && share > 0.0 && share <= 1.0 && slack >= 0.0)) {
        PyErr_SetString(PyExc_ValueError, "stoppable_rows: rate and dt must be > 0, share in "
                        "(0, 1], slack >= 0");
        return NULL;
    }
    Arg A = {0}, b = {0}, dq = {0}, ddq = {0}, acc = {0}, jerk = {0};
    PyObject *result = NULL;
    int has_jerk = args[5] != Py_None;
    if (acquire(args[0], &A, 0, 2, "A") || acquire(args[1], &b, 1, 1, "b")
        || acquire(args[2], &dq, 0, 1, "dq") || acquire(args[3], &ddq, 0, 1, "ddq")
        || acquire(args[4], &acc, 0, 1, "accelerations")
        || (has_jerk && acquire(args[5], &jerk, 0, 1, "jerks")))
        goto done;
    Mat Am = mat(&A);
    double *bv = out_vec(&b, "b");
    const double *dv = vec(&dq, "dq"), *ddv = vec(&ddq, "ddq");
    const double *av = vec(&acc, "accelerations");
    const double *jv = has_jerk ? vec(&jerk, "jerks") : NULL;
    if (!bv || !dv || !ddv || !av || (has_jerk && !jv)) goto done;
    if (length(&b) != Am.m || length(&dq) != Am.n || length(&ddq) != Am.n
        || length(&acc) != Am.n || (has_jerk && length(&jerk) != Am.n)) {
        PyErr_Format(PyExc_ValueError, "stoppable_rows: A (k, N), b (k,), dq, ddq, "
                     "accelerations and jerks (N,) do not fit: A (%zd, %zd)", Am.m, Am.n);
        goto done;
    }
    stoppable_rows_c(Am, bv, dv, ddv, av, jv, rate, dt, share, slack);
    result = Py_None;
    Py_INCREF(result);
done:
    release(&A); release(&b); release(&dq); release(&ddq); release(&acc); release(&jerk);
    return result;
}

/* witness_rows(oMi, poses, rows, found, memory, state, tick, keep, apart, owners) -> int: the
 * collision limit's witness rows (limits/collision.py, "Witnesses"). rows (N, 13) holds the
 * step's exact rows of the pairs `found` (count,) in its first count rows (as damper_rows
 * reads them); poses (njoints, 16): the 4x4 world pose of each joint the rows name (row-major),
 * taken here from Pinocchio's data.oMi (joint 0: the identity) unless oMi is None. A pair
 * whose d - margin is not under keep remembers nothing. memory (npairs * W, 6): per pair up to
 * W remembered closest points, each in its joint's frame (p_a, p_b); state (npairs, 2): how
 * many are remembered (-1: a pair that never remembers, its closest points being unique) and
 * the tick of the call that last saw the pair within influence (a pair missed by the previous
 * call, tick - 1, forgets them). Each remembered pair of points that lies farther than `apart`
 * (either point, its frame) from this step's and whose separation s = n^T (p_b - p_a) along
 * this step's normal is under d + keep becomes a row after the exact ones (d = s, the points
 * in the world, the rest as its pair's row), its pair written to owners; the pair then
 * remembers those (the last W - 1) and this step's points. Returns the number of rows. */
static Py_ssize_t witness_rows_c(const double *poses, double *rows, const double *found,
                                 Py_ssize_t count, double *memory, Py_ssize_t W, double *state,
                                 double tick, double keep, double apart, double *owners)
{
    Py_ssize_t total = count;
    for (Py_ssize_t i = 0; i < count; i++) {
        Py_ssize_t k = (Py_ssize_t)found[i];
        double *row = rows + 13 * i, *st = state + 2 * k, *mem = memory + 6 * W * k;
        if (st[0] < 0.0) continue;  /* a pair whose closest points are unique */
        const double *H[2] = {poses + 16 * (Py_ssize_t)row[2], poses + 16 * (Py_ssize_t)row[3]};
        Py_ssize_t filled = st[1] == tick - 1.0 ? (Py_ssize_t)st[0] : 0;
        st[1] = tick;
        if (!(row[0] - row[1] < keep)) {  /* far from its margin: its row binds nothing */
            st[0] = 0.0;
            continue;
        }
        double now[6];
        for (int side = 0; side < 2; side++) {
            const double *M = H[side], *p = row + 7 + 3 * side;
            double dx = p[0] - M[3], dy = p[1] - M[7], dz = p[2] - M[11];
            for (int c = 0; c < 3; c++)  /* R^T (p - t) */
                now[3 * side + c] = M[c] * dx + M[4 + c] * dy + M[8 + c] * dz;
        }
        double kept[64][6];
        Py_ssize_t nk = 0;
        for (Py_ssize_t w = 0; w < filled; w++) {
            const double *m = mem + 6 * w;
            double far = 0.0, world[6];
            for (int c = 0; c < 6; c++) far = dmax(far, fabs(m[c] - now[c]));
            if (!(far > apart)) continue;
            for (int side = 0; side < 2; side++) {
                const double *M = H[side], *l = m + 3 * side;
                for (int r = 0; r < 3; r++)
                    world[3 * side + r] = M[4 * r] * l[0] + M[4 * r + 1] * l[1]
                                          + M[4 * r + 2] * l[2] + M[4 * r + 3];
            }
            double s = row[4] * (world[3] - world[0]) + row[5] * (world[4] - world[1])
                       + row[6] * (world[5] - world[2]);
            if (!(s - row[0] < keep)) continue;
            double *out = rows + 13 * total;
            for (int c = 0; c < 13; c++) out[c] = row[c];
            out[0] = s;
            for (int c = 0; c < 6; c++) out[7 + c] = world[c];
            owners[total - count] = (double)k;
            total++;
            if (nk < 64) {
                for (int c = 0; c < 6; c++) kept[nk][c] = m[c];
                nk++;
            }
        }
        Py_ssize_t start = nk > W - 1 ? nk - (W - 1) : 0, n = 0;
        for (Py_ssize_t w = start; w < nk; w++, n++)
            for (int c = 0; c < 6; c++) mem[6 * n + c] = kept[w][c];
        for (int c = 0; c < 6; c++) mem[6 * n + c] = now[c];
        st[0] = (double)(n + 1);
    }
    return total;
}

/* the 4x4 world pose of joint j (Pinocchio's data.oMi[j].homogeneous) into out (row-major) */
static int fetch_pose(PyObject *oMi, Py_ssize_t j, double *out)
{
    static PyObject *s_homogeneous = NULL;
    if (!s_homogeneous && !(s_homogeneous = PyUnicode_InternFromString("homogeneous")))
        return -1;
    PyObject *index = PyLong_FromSsize_t(j);
    PyObject *M = index ? PyObject_GetItem(oMi, index) : NULL;
    Py_XDECREF(index);
    PyObject *H = M ? PyObject_GetAttr(M, s_homogeneous) : NULL;
    Py_XDECREF(M);
    if (!H) return -1;
    Arg a = {0};
    int bad = acquire(H, &a, 0, 2, "oMi[j].homogeneous");
    if (!bad) {
        Mat Hm = mat(&a);
        if (Hm.m != 4 || Hm.n != 4) {
            PyErr_SetString(PyExc_ValueError, "oMi[j].homogeneous must be 4x4");
            bad = 1;
        } else {
            for (int r = 0; r < 4; r++)
                for (int c = 0; c < 4; c++) out[4 * r + c] = AT(Hm, r, c);
        }
        release(&a);
    }
    Py_DECREF(H);
    return bad ? -1 : 0;
}

/* Whether views (a tuple) are collision_rows' data views: (data, J, rotations, translations),
 * the last two lists of one array per joint; TypeError naming `who` otherwise */
static int views_ok(PyObject *views, const char *who)
{
    if (PyTuple_GET_SIZE(views) == 4 && PyList_Check(PyTuple_GET_ITEM(views, 2))
        && PyList_Check(PyTuple_GET_ITEM(views, 3))
        && PyList_GET_SIZE(PyTuple_GET_ITEM(views, 2))
               == PyList_GET_SIZE(PyTuple_GET_ITEM(views, 3)))
        return 1;
    PyErr_Format(PyExc_TypeError, "%s: data views must be (data, J, rotations, translations), "
                 "the last two lists of one array per joint", who);
    return 0;
}

/* the 4x4 world pose of joint j into out (row-major) from data views (collision_rows): its
 * rotation (3, 3) and translation (3,) arrays, numpy views onto Pinocchio's data.oMi[j] */
static int view_pose(PyObject *views, Py_ssize_t j, double *out)
{
    if (j >= PyList_GET_SIZE(PyTuple_GET_ITEM(views, 2))) {
        PyErr_Format(PyExc_ValueError, "collision_rows: no view of joint %zd's pose", j);
        return -1;
    }
    PyObject *R = PyList_GET_ITEM(PyTuple_GET_ITEM(views, 2), j);
    PyObject *t = PyList_GET_ITEM(PyTuple_GET_ITEM(views, 3), j);
    Arg a = {0}, b = {0};
    int bad = acquire(R, &a, 0, 2, "a rotation") || acquire(t, &b, 0, 1, "a translation");
    if (!bad && (a.view.shape[0] != 3 || a.view.shape[1] != 3 || length(&b) != 3)) {
        PyErr_SetString(PyExc_ValueError, "a joint's rotation must be (3, 3), its translation "
                        "(3,)");
        bad = 1;
    }
    if (!bad) {
        Mat Rm = mat(&a), tm = mat(&b);
        for (int r = 0; r < 3; r++) {
            for (int c = 0; c < 3; c++) out[4 * r + c] = AT(Rm, r, c);
            out[4 * r + 3] = tm.p[r * tm.s0];
            out[12 + r] = 0.0;
        }
        out[15] = 1.0;
    }
    release(&a);
    release(&b);
    return bad ? -1 : 0;
}

/* The pair indices of the sequence `found` as doubles in *out (malloc'ed, count of them); -1
 * with a Python error set */
static int pair_indices(PyObject *found, double **out, Py_ssize_t *count)
{
    PyObject *seq = PySequence_Fast(found, "found must be a sequence of pair indices");
    if (!seq) return -1;
    Py_ssize_t n = *count = PySequence_Fast_GET_SIZE(seq);
    double *fv = *out = (double *)malloc((size_t)(n > 0 ? n : 1) * sizeof(double));
    int bad = 0;
    if (!fv) {
        PyErr_NoMemory();
        bad = 1;
    }
    for (Py_ssize_t i = 0; i < n && !bad; i++) {
        fv[i] = PyFloat_AsDouble(PySequence_Fast_GET_ITEM(seq, i));
        bad = fv[i] == -1.0 && PyErr_Occurred();
    }
    Py_DECREF(seq);
    return bad ? -1 : 0;
}

/* Whether witness_rows' arrays fit each other, its pairs are pairs and its rows name joints
 * of poses; sets ValueError otherwise. *W: the witnesses per pair. */
static int witness_args_fit(const Arg *poses, const Arg *rows, const Arg *memory,
                            const Arg *state, const Arg *owners, const double *fv,
                            Py_ssize_t count, Py_ssize_t *W)
{
    Py_ssize_t N = rows->view.shape[0], npairs = state->view.shape[0];
    const double *rv = (const double *)rows->view.buf;
    *W = npairs > 0 ? memory->view.shape[0] / npairs : 0;
    if (poses->view.shape[1] != 16 || rows->view.shape[1] != 13
        || memory->view.shape[1] != 6 || state->view.shape[1] != 2 || *W < 1 || *W > 64
        || memory->view.shape[0] != *W * npairs || N < count * (1 + *W)
        || length(owners) < count * *W) {
        PyErr_Format(PyExc_ValueError, "witness_rows: poses (njoints, 16), rows (>= count (1 + W), "
                     "13), memory (npairs W, 6) with 1 <= W <= 64, state (npairs, 2) and owners "
                     "(>= count W,) do not fit (count %zd, rows %zd, npairs %zd)", count, N,
                     npairs);
        return 0;
    }
    for (Py_ssize_t i = 0; i < count; i++) {
        if (!(fv[i] >= 0.0 && fv[i] < (double)npairs)) {
            PyErr_Format(PyExc_ValueError, "found[%zd] is no pair (npairs %zd)", i, npairs);
            return 0;
        }
        for (int side = 0; side < 2; side++) {
            double j = rv[13 * i + 2 + side];
            if (!(j >= 0.0 && j < (double)poses->view.shape[0])) {
                PyErr_Format(PyExc_ValueError, "rows[%zd] names joint %zd; poses has %zd", i,
                             (Py_ssize_t)j, poses->view.shape[0]);
                return 0;
            }
        }
    }
    return 1;
}

/* Joint world poses read on demand into P (njoints x 16, row-major; joint 0 the identity),
 * each once a call: from collision_rows' data views (of 2), Pinocchio's data (of 1: its oMi
 * read when a pose is first needed) or its oMi (of 0) */
typedef struct {
    PyObject *source, *oMi;
    int of;
    double *P;
    char *fetched;
    Py_ssize_t nj;
} Poses;

static int poses_init(Poses *S, PyObject *source, int of, double *P, Py_ssize_t nj)
{
    S->source = source;
    S->oMi = of == 0 ? source : NULL;
    S->of = of;
    S->P = P;
    S->nj = nj;
    if (!(S->fetched = (char *)calloc((size_t)nj + 1, 1))) {
        PyErr_NoMemory();
        return -1;
    }
    for (int c = 0; c < 16; c++) P[c] = c % 5 == 0 ? 1.0 : 0.0;
    S->fetched[0] = 1;
    return 0;
}

/* joint j's pose in S->P (fetched if not yet); -1 with a Python error set */
static int pose_at(Poses *S, Py_ssize_t j)
{
    if (j < 0 || j >= S->nj) {
        PyErr_Format(PyExc_ValueError, "joint %zd: poses has %zd", j, S->nj);
        return -1;
    }
    if (S->fetched[j]) return 0;
    int bad;
    if (S->of == 2) {
        bad = view_pose(S->source, j, S->P + 16 * j);
    } else {
        if (!S->oMi && !(S->oMi = PyObject_GetAttrString(S->source, "oMi"))) return -1;
        bad = fetch_pose(S->oMi, j, S->P + 16 * j);
    }
    S->fetched[j] = !bad;
    return bad ? -1 : 0;
}

static void poses_free(Poses *S)
{
    if (S->of == 1) Py_XDECREF(S->oMi);
    S->oMi = NULL;
    free(S->fetched);
    S->fetched = NULL;
}

/* The poses (S) of the joints of the rows whose pairs remember (d - margin under keep, state
 * not -1: found, state as witness_rows_c's); -1 with a Python error set */
static int witness_poses(Poses *S, const double *rv, const double *found, const double *state,
                         Py_ssize_t count, double keep)
{
    for (Py_ssize_t i = 0; i < count; i++) {
        const double *row = rv + 13 * i;
        if (!(row[0] - row[1] < keep) || state[2 * (Py_ssize_t)found[i]] < 0.0) continue;
        for (int side = 0; side < 2; side++)
            if (pose_at(S, (Py_ssize_t)row[2 + side])) return -1;
    }
    return 0;
}

PyObject *py_witness_rows(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!nargs_ok(nargs, 10, "witness_rows")) return NULL;
    PyObject *oMi = args[0];
    args++;  /* the rest as without oMi */
    double tick = PyFloat_AsDouble(args[5]), keep = PyFloat_AsDouble(args[6]);
    double apart = PyFloat_AsDouble(args[7]);
    if (PyErr_Occurred()) return NULL;
    Arg poses = {0}, rows = {0}, memory = {0}, state = {0}, owners = {0};
    PyObject *result = NULL;
    double *fv = NULL;
    Py_ssize_t count = 0, W;
    if (acquire(args[0], &poses, oMi != Py_None, 2, "poses")
        || acquire(args[1], &rows, 1, 2, "rows")
        || acquire(args[3], &memory, 1, 2, "memory") || acquire(args[4], &state, 1, 2, "state")
        || acquire(args[8], &owners, 1, 1, "owners"))
        goto done;
    double *pv = out_mat(&poses, "poses"), *rv = out_mat(&rows, "rows");
    double *mv = out_mat(&memory, "memory");
    double *sv = out_mat(&state, "state"), *ov = out_vec(&owners, "owners");
    if (!pv || !rv || !mv || !sv || !ov || pair_indices(args[2], &fv, &count)
        || !witness_args_fit(&poses, &rows, &memory, &state, &owners, fv, count, &W))
        goto done;
    if (oMi != Py_None) {
        Poses S;
        if (poses_init(&S, oMi, 0, pv, poses.view.shape[0])) goto done;
        int bad = witness_poses(&S, rv, fv, sv, count, keep);
        poses_free(&S);
        if (bad) goto done;
    }
    result = PyLong_FromSsize_t(witness_rows_c(pv, rv, fv, count, mv, W, sv, tick, keep, apart,
                                               ov));
done:
    free(fv);
    release(&poses); release(&rows); release(&memory); release(&state); release(&owners);
    return result;
}

/* 3 doubles from a float64 array-like (coal's vectors) */
static int read3(PyObject *obj, double *out, const char *name)
{
    Arg a = {0};
    if (acquire(obj, &a, 0, 1, name)) return -1;
    double *v = length(&a) == 3 ? vec(&a, name) : NULL;
    if (!v) {
        if (!PyErr_Occurred())
            PyErr_Format(PyExc_ValueError, "%s must hold 3 numbers", name);
        release(&a);
        return -1;
    }
    out[0] = v[0];
    out[1] = v[1];
    out[2] = v[2];
    release(&a);
    return 0;
}

/* coal's result attributes, interned once */
static PyObject *s_distance, *s_normal, *s_p1, *s_p2;

static int query_names(void)
{
    if (s_distance) return 0;
    s_distance = PyUnicode_InternFromString("min_distance");
    s_normal = PyUnicode_InternFromString("normal");
    s_p1 = PyUnicode_InternFromString("getNearestPoint1");
    s_p2 = PyUnicode_InternFromString("getNearestPoint2");
    return s_distance && s_normal && s_p1 && s_p2 ? 0 : -1;
}

/* the queries: compute(geometry, geometry_data, k) (Pinocchio's computeDistance), each pair's
 * floor, margin and influence, its two joints, the joints' poses (S, read on demand) and the
 * rows written; and, when a pair's row may be left out where it cannot bind, its reach (the
 * closing speed, m/s, the joints' speed limits can give it at most) and the damper's rate
 * (1/s) */
typedef struct {
    PyObject *compute, *geometry, *geometry_data;
    Distances *direct;  /* the compiled queries (compute a capsule of them), or NULL */
    Arg floor_, margins, influence, joints, rows, failures, reach, poses;
    Poses S;
    double *fv, *mv, *iv, *rv, *failed;
    const double *reach_v;
    double rate;
    Mat Jm;
    Py_ssize_t npairs, N;
} Queries;

/* Acquire and check the queries' arrays from collision_rows' fixed (F) and influence; -1 with
 * a Python error set */
static int query_args(PyObject *const *F, PyObject *influence, Queries *Q)
{
    if (acquire(F[2], &Q->floor_, 1, 1, "floor")
        || acquire(F[3], &Q->margins, 0, 1, "margins")
        || acquire(F[4], &Q->joints, 0, 2, "joints")
        || acquire(influence, &Q->influence, 0, 1, "influence")
        || acquire(F[5], &Q->rows, 1, 2, "rows")
        || acquire(F[6], &Q->failures, 1, 1, "failures")
        || acquire(F[7], &Q->poses, 1, 2, "poses") || !out_mat(&Q->poses, "poses"))
        return -1;
    Q->geometry = F[0];
    Q->geometry_data = F[1];
    Q->fv = out_vec(&Q->floor_, "floor");
    Q->mv = vec(&Q->margins, "margins");
    Q->iv = vec(&Q->influence, "influence");
    Q->rv = out_mat(&Q->rows, "rows");
    Q->failed = out_vec(&Q->failures, "failures");
    if (!Q->fv || !Q->mv || !Q->iv || !Q->rv || !Q->failed) return -1;
    if (length(&Q->failures) != 1) {
        PyErr_SetString(PyExc_ValueError, "collision_rows: failures must hold one number");
        return -1;
    }
    Q->failed[0] = 0.0;
    Q->Jm = mat(&Q->joints);
    Q->npairs = length(&Q->floor_);
    Q->N = Q->rows.view.shape[0];
    if (length(&Q->margins) != Q->npairs || length(&Q->influence) != Q->npairs
        || Q->Jm.m != Q->npairs || Q->Jm.n != 2 || Q->rows.view.shape[1] != 13
        || Q->poses.view.shape[1] != 16) {
        PyErr_Format(PyExc_ValueError, "collision_rows: floor, margins, influence (npairs,), "
                     "joints (npairs, 2), rows (N, 13) and poses (njoints, 16) do not fit "
                     "(npairs %zd)", Q->npairs);
        return -1;
    }
    return 0;
}

/* The row of pair k from its result res: d, its margin, its joints, the normal and the
 * closest points. Where the pair is apart by more than SEPARATED (m) the normal is read off the
 * points, (p_b - p_a) / |p_b - p_a|, as coal forms it (to 1e-14 on the bench's scenes), not
 * from coal (a result read through Python costs per vector); -1 with a Python error set */
#define SEPARATED 1e-6
/* coal's answer where it found no closest points (GJK/EPA deep in a penetration): a distance
 * of -DBL_MAX and points near DBL_MAX, or no normal (two closest points that coincide, a sphere
 * at the centre of a cylinder) */
#define UNUSABLE 1e300
static int usable(const double *row)
{
    for (int c = 4; c < 13; c++)
        if (!(fabs(row[c]) < UNUSABLE)) return 0;
    double n2 = row[4] * row[4] + row[5] * row[5] + row[6] * row[6];
    return n2 > 0.25;  /* a unit normal (not coal's zero one where the points coincide) */
}

/* coal's normal (unless apart) and closest points of a result read through Python into
 * out[1:10] (as Distances.distance gives them); -1 with a Python error set */
static int python_points(PyObject *res, int apart, double *out)
{
    PyObject *normal = apart ? NULL : PyObject_GetAttr(res, s_normal);
    PyObject *p1 = apart || normal ? PyObject_CallMethodNoArgs(res, s_p1) : NULL;
    PyObject *p2 = p1 ? PyObject_CallMethodNoArgs(res, s_p2) : NULL;
    int bad = !p2 || (!apart && read3(normal, out + 1, "normal"))
              || read3(p1, out + 4, "nearest point 1") || read3(p2, out + 7, "nearest point 2");
    Py_XDECREF(normal);
    Py_XDECREF(p1);
    Py_XDECREF(p2);
    return bad ? -1 : 0;
}

/* The row of pair k from its query's out (d, normal, p_a, p_b; the normal unread where
 * apart): d, its margin, its joints, the normal and the closest points */
static void query_row(const Queries *Q, Py_ssize_t k, const double *out, int apart, double *row)
{
    double d = out[0];
    for (int c = 0; c < 9; c++) row[4 + c] = out[1 + c];
    if (apart) {
        double u[3] = {row[10] - row[7], row[11] - row[8], row[12] - row[9]};
        double norm = sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
        for (int c = 0; c < 3; c++) row[4 + c] = u[c] / norm;
    }
    row[0] = d;
    if (!(d > -UNUSABLE) || !usable(row)) {  /* no closest points: the caller forms the row */
        row[0] = -INFINITY;
        for (int c = 4; c < 13; c++) row[c] = 0.0;
        Q->failed[0] += 1.0;
    }
    row[1] = Q->mv[k];
    row[2] = AT(Q->Jm, k, 0);
    row[3] = AT(Q->Jm, k, 1);
}

/* Pair `item` (index k) queried (compiled, Q->direct, or through Q's compute): its floor, and
 * when it is within influence (*within then 1) its row at *count (which grows) unless its
 * damper's bound rate (d - margin) is not below its reach (no joint speed within the limits
 * closes it that fast: the row could never bind); -1 with a Python error set */
static int query_pair(Queries *Q, PyObject *item, Py_ssize_t k, Py_ssize_t *count,
                      int *within)
{
    double out[10];
    PyObject *res = NULL;
    if (Q->direct) {
        if (pose_at(&Q->S, (Py_ssize_t)AT(Q->Jm, k, 0))
            || pose_at(&Q->S, (Py_ssize_t)AT(Q->Jm, k, 1))
            || Q->direct->distance(Q->direct, k, Q->S.P, Q->S.nj, out))
            return -1;
    } else {
        PyObject *call[3] = {Q->geometry, Q->geometry_data, item};
        if (!(res = PyObject_Vectorcall(Q->compute, call, 3, NULL))) return -1;
        PyObject *dobj = PyObject_GetAttr(res, s_distance);
        out[0] = dobj ? PyFloat_AsDouble(dobj) : -1.0;
        Py_XDECREF(dobj);
        if (!dobj || (out[0] == -1.0 && PyErr_Occurred())) {
            Py_DECREF(res);
            return -1;
        }
    }
    double d = out[0];
    int bad = 0;
    /* NaN, or no closest points: -inf (queried again) */
    Q->fv[k] = d > -UNUSABLE ? d : -INFINITY;
    *within = d > -INFINITY && d < Q->iv[k];
    if (*within && !(Q->reach_v && Q->rate * (d - Q->mv[k]) >= Q->reach_v[k])) {
        int apart = d > SEPARATED;
        if (*count >= Q->N) {
            PyErr_SetString(PyExc_ValueError,
                            "collision_rows: more pairs within influence than rows");
            bad = 1;
        } else if (!(bad = res && python_points(res, apart, out))) {
            query_row(Q, k, out, apart, Q->rv + 13 * *count);
            *count += 1;
        }
    }
    Py_XDECREF(res);
    return bad ? -1 : 0;
}

/* the queries' loop: each pair of the sequence `listed` queried (query_pair); the list of
 * those with a row, their rows the first *count of Q->rows, and in *within the list of those
 * within influence (a new reference); NULL with a Python error set */
static PyObject *run_queries(PyObject *listed, Queries *Q, Py_ssize_t *count, PyObject **within)
{
    PyObject *near = PySequence_Fast(listed, "near must be a sequence of pair indices");
    PyObject *found = near ? PyList_New(0) : NULL;
    *within = found ? PyList_New(0) : NULL;
    *count = 0;
    if (!*within) goto fail;
    Py_ssize_t m = PySequence_Fast_GET_SIZE(near);
    PyObject **items = PySequence_Fast_ITEMS(near);
    for (Py_ssize_t i = 0; i < m; i++) {
        Py_ssize_t k = PyLong_AsSsize_t(items[i]), before = *count;
        if (k == -1 && PyErr_Occurred()) goto fail;
        if (k < 0 || k >= Q->npairs) {
            PyErr_Format(PyExc_ValueError, "near[%zd] = %zd is no pair (npairs %zd)", i, k,
                         Q->npairs);
            goto fail;
        }
        int close;
        if (query_pair(Q, items[i], k, count, &close)
            || (close && PyList_Append(*within, items[i]) < 0)
            || (*count > before && PyList_Append(found, items[i]) < 0))
            goto fail;
    }
    goto done;
fail:
    Py_CLEAR(found);
    Py_CLEAR(*within);
done:
    Py_XDECREF(near);
    return found;
}

static void release_queries(Queries *Q)
{
    release(&Q->floor_); release(&Q->margins); release(&Q->influence);
    release(&Q->joints); release(&Q->rows); release(&Q->failures); release(&Q->reach);
    release(&Q->poses);
    poses_free(&Q->S);
}

/* collision_rows' witness rows after the `count` rows of Q's pairs `found` (witness_rows with
 * the arrays of fixed); the number of rows, -1 with a Python error set */
static Py_ssize_t witnesses_of(PyObject *const *F, Queries *Q, PyObject *found,
                               Py_ssize_t count, double tick)
{
    double keep = PyFloat_AsDouble(F[10]), apart = PyFloat_AsDouble(F[11]);
    if (PyErr_Occurred()) return -1;
    Arg memory = {0}, state = {0}, owners = {0};
    Py_ssize_t total = -1, W;
    double *fv = NULL;
    if (acquire(F[8], &memory, 1, 2, "memory") || acquire(F[9], &state, 1, 2, "state")
        || acquire(F[12], &owners, 1, 1, "owners"))
        goto done;
    double *mv = out_mat(&memory, "memory");
    double *sv = out_mat(&state, "state"), *ov = out_vec(&owners, "owners");
    Py_ssize_t n;
    if (!mv || !sv || !ov || pair_indices(found, &fv, &n)
        || !witness_args_fit(&Q->poses, &Q->rows, &memory, &state, &owners, fv, count, &W)
        || witness_poses(&Q->S, Q->rv, fv, sv, count, keep))
        goto done;
    total = witness_rows_c(Q->S.P, Q->rv, fv, count, mv, W, sv, tick, keep, apart, ov);
done:
    free(fv);
    release(&memory); release(&state); release(&owners);
    return total;
}

/* A (k, n) = X (k, N) G (N, n): the damper rows folded onto the velocity coordinates by the
 * map G from every joint coordinate's velocity, mimic joints' included (a mimic joint's column
 * adds, times its multiplier, to the one it follows) */
static void fold_columns(const double *X, Py_ssize_t k, Py_ssize_t N, Mat G, double *A)
{
    for (Py_ssize_t i = 0; i < k; i++)
        for (Py_ssize_t v = 0; v < G.n; v++) {
            double acc = 0.0;
            for (Py_ssize_t c = 0; c < N; c++) acc += X[i * N + c] * AT(G, c, v);
            A[i * G.n + v] = acc;
        }
}

/* collision_rows' A and b from the first `total` rows of Q (damper_rows at `rate`, 1/s), A
 * folded by the mimic map (fixed's last; None: none) onto the velocity coordinates, into
 * out[0] (A, read-only) and out[1] (b, read-only); -1 with a Python error set */
static int dampers_of(PyObject *const *F, PyObject *data, PyObject *views, const Queries *Q,
                      Py_ssize_t total, double rate, PyObject **out)
{
    Arg J = {0}, sup = {0}, map = {0};
    int bad = 1, folds = F[17] != Py_None;
    double *X = NULL;
    PyObject *J_obj = views ? PyTuple_GET_ITEM(views, 1) : PyObject_GetAttrString(data, "J");
    Py_XINCREF(views ? J_obj : NULL);
    if (!J_obj || acquire(J_obj, &J, 0, 2, "J") || acquire(F[13], &sup, 0, 2, "support")
        || (folds && acquire(F[17], &map, 0, 2, "mimic")))
        goto done;
    Mat Jm = mat(&J), Sm = mat(&sup), Pm = {Q->rv, total, 13, 13, 1}, G = {NULL, 0, 0, 0, 0};
    if (folds) G = mat(&map);
    if (Jm.m != 6 || Sm.n != Jm.n || (folds && G.m != Jm.n)) {
        PyErr_Format(PyExc_ValueError, "collision_rows: J (6, N), support (njoints, N) and the "
                     "mimic map (N, n) do not fit: J (%zd, %zd), support (%zd, %zd)", Jm.m, Jm.n,
                     Sm.m, Sm.n);
        goto done;
    }
    if (!rows_name_joints(Pm, Sm.m, "rows")) goto done;
    Py_ssize_t dims[2] = {total, folds ? G.n : Jm.n};
    double *Av, *bv;
    if (!(out[0] = new_array(2, dims, &Av)) || !(out[1] = new_array(1, dims, &bv))) goto done;
    if (folds && !(X = (double *)malloc((size_t)(total * Jm.n + 1) * sizeof(double)))) {
        PyErr_NoMemory();
        goto done;
    }
    damper_rows_c(Jm, Sm, Pm, rate, folds ? X : Av, bv);
    if (folds) fold_columns(X, total, Jm.n, G, Av);
    freeze_array(out[0]);
    freeze_array(out[1]);
    bad = 0;
done:
    free(X);
    release(&J); release(&sup); release(&map);
    Py_XDECREF(J_obj);
    return bad ? -1 : 0;
}

/* collision_rows(fixed, near, data, rate, influence, tick, reach, compute) -> (within, found,
 * A, b, witnesses) | None: a step's rows of the collision limit in one call
 * (limits/collision.py, _rows), at the joint poses and WORLD joint Jacobians of Pinocchio's
 * `data`, or of data views (data, data.J, rotations, translations): data and numpy views onto
 * its J and each joint's data.oMi[j].rotation and .translation (lists), read without Python.
 * fixed: the limit's (geometry, geometry_data, floor, margins, joints, rows, failures, poses,
 * memory, state, keep, apart, owners, support, update, model, witnesses, mimic).
 * 1. Where compute is Pinocchio's computeDistance, the geometries' placements: update(model,
 *    data, geometry, geometry_data) (Pinocchio's updateGeometryPlacements).
 * 2. The exact distance queries: for each pair k of the list `near`, res = compute(geometry,
 *    geometry_data, k), d = res.min_distance; or, where compute is a capsule of the compiled
 *    queries (distances.h), the same without a Python call, at the poses (njoints, 16) of the
 *    pair's joints, read into `poses` once a call. floor[k] = d (-inf for a failed query: d
 *    NaN or no closest points). A pair with d < influence[k] (npairs,)
 *    is within influence; it gets the next row of rows (N, 13) as damper_rows reads it (d,
 *    margins[k], joints[k] (npairs, 2), the normal, res.getNearestPoint1(),
 *    res.getNearestPoint2()) unless reach (npairs,; None: every pair within influence) says
 *    the row cannot bind: rate (d - margin) >= reach[k], the largest closing speed (m/s) the
 *    joints' speed limits can give the pair. Where coal found no closest points (deep in a
 *    penetration: d -DBL_MAX) the row holds d = -inf and zeros and failures (1,) counts it.
 * 3. Unless a query failed (then A and b are None: the caller forms those rows first, then
 *    the rest with witness_rows and damper_rows), when `witnesses` is true, witness_rows' rows
 *    after them (at `tick`; data.oMi read only for pairs that remember), `witnesses` of them,
 *    and damper_rows' A (k, N) and b (k,), both read-only, of all the rows at `rate` (1/s) from
 *    data.J (6, N); A (k, n) = A G with a mimic map G (N, n) (mimic None: N = n).
 * within: the pairs within influence, found those with a row (A and b None when there is
 * none); None when no pair is within influence. */
PyObject *py_collision_rows(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!nargs_ok(nargs, 8, "collision_rows") || query_names()) return NULL;
    if (!PyTuple_Check(args[0]) || PyTuple_GET_SIZE(args[0]) != 18) {
        PyErr_SetString(PyExc_TypeError, "collision_rows: fixed must be a tuple of 18");
        return NULL;
    }
    PyObject *const *F = &PyTuple_GET_ITEM(args[0], 0), *data = args[2], *views = NULL;
    if (PyTuple_Check(data)) {  /* (data, J, rotations, translations): views onto its arrays */
        if (!views_ok(data, "collision_rows")) return NULL;
        views = data;
        data = PyTuple_GET_ITEM(views, 0);
    }
    double rate = PyFloat_AsDouble(args[3]), tick = PyFloat_AsDouble(args[5]);
    int witnesses = PyObject_IsTrue(F[16]);
    if (PyErr_Occurred() || witnesses < 0) return NULL;
    PyObject *update[4] = {F[15], data, F[0], F[1]};  /* (the queries through Python's) */
    Queries Q;
    memset(&Q, 0, sizeof Q);
    Py_ssize_t count = 0, total;
    PyObject *found = NULL, *within = NULL, *result = NULL, *placed = NULL;
    PyObject *AB[2] = {NULL, NULL};
    if (query_args(F, args[4], &Q)
        || poses_init(&Q.S, views ? views : data, views ? 2 : 1, (double *)Q.poses.view.buf,
                      Q.poses.view.shape[0]))
        goto done;
    Q.compute = args[7];
    if (PyCapsule_CheckExact(Q.compute)) {
        Q.direct = (Distances *)PyCapsule_GetPointer(Q.compute, DISTANCES_CAPSULE);
        if (!Q.direct) goto done;
        if (Q.direct->npairs != Q.npairs) {
            PyErr_Format(PyExc_ValueError, "collision_rows: the compiled queries hold %zd "
                         "pairs, floor %zd", Q.direct->npairs, Q.npairs);
            goto done;
        }
    }
    Q.rate = rate;
    if (args[6] != Py_None) {
        if (acquire(args[6], &Q.reach, 0, 1, "reach") || !(Q.reach_v = vec(&Q.reach, "reach")))
            goto done;
        if (length(&Q.reach) != Q.npairs) {
            PyErr_Format(PyExc_ValueError, "collision_rows: reach must hold one speed per pair "
                         "(%zd), got %zd", Q.npairs, length(&Q.reach));
            goto done;
        }
    }
    if ((!Q.direct && !(placed = PyObject_Vectorcall(F[14], update, 4, NULL)))
        || !(found = run_queries(args[1], &Q, &count, &within)))
        goto done;
    if (PyList_GET_SIZE(within) == 0) {
        result = Py_None;
        Py_INCREF(result);
        goto done;
    }
    if (count == 0 || Q.failed[0] > 0.0) {
        result = Py_BuildValue("(OOOOn)", within, found, Py_None, Py_None, (Py_ssize_t)0);
        goto done;
    }
    total = witnesses ? witnesses_of(F, &Q, found, count, tick) : count;
    if (total < 0 || dampers_of(F, data, views, &Q, total, rate, AB)) goto done;
    result = Py_BuildValue("(OOOOn)", within, found, AB[0], AB[1], total - count);
done:
    Py_XDECREF(placed);
    Py_XDECREF(found);
    Py_XDECREF(within);
    Py_XDECREF(AB[0]);
    Py_XDECREF(AB[1]);
    release_queries(&Q);
    return result;
}

/* sphere_gaps(views, joints, centres, pairs, span, gap): the broad phase's test of every
 * pair's bounding spheres (limits/collision.py, _broad_phase): gap[k] = |c_a - c_b| - span[k]
 * (m), c_g = oMi[joints[g]] centres[g] the world centre of geometry g's sphere from its centre
 * in its joint's frame (centres (n, 4), homogeneous; joint 0 the world), joint poses read from
 * collision_rows' data views (views), pairs (npairs, 2) geometry indices. */
PyObject *py_sphere_gaps(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!nargs_ok(nargs, 6, "sphere_gaps")) return NULL;
    PyObject *views = args[0];
    if (!PyTuple_Check(views) || !views_ok(views, "sphere_gaps")) return NULL;
    Arg joints = {0}, centres = {0}, pairs = {0}, span = {0}, gap = {0};
    PyObject *result = NULL;
    double *world = NULL, *poses = NULL;
    Poses S = {0};
    if (acquire(args[1], &joints, 0, 1, "joints") || acquire(args[2], &centres, 0, 2, "centres")
        || acquire(args[3], &pairs, 0, 2, "pairs") || acquire(args[4], &span, 0, 1, "span")
        || acquire(args[5], &gap, 1, 1, "gap"))
        goto done;
    const double *jv = vec(&joints, "joints"), *sv = vec(&span, "span");
    double *gv = out_vec(&gap, "gap");
    if (!jv || !sv || !gv) goto done;
    Mat C = mat(&centres), P = mat(&pairs);
    Py_ssize_t n = length(&joints), npairs = P.m;
    Py_ssize_t nj = PyList_GET_SIZE(PyTuple_GET_ITEM(views, 2));
    if (C.m != n || C.n != 4 || P.n != 2 || length(&span) != npairs || length(&gap) != npairs) {
        PyErr_Format(PyExc_ValueError, "sphere_gaps: joints (n,), centres (n, 4), pairs "
                     "(npairs, 2), span and gap (npairs,) do not fit (n %zd, npairs %zd)", n,
                     npairs);
        goto done;
    }
    world = (double *)malloc((size_t)(3 * n + 1) * sizeof(double));
    poses = (double *)malloc((size_t)(16 * nj + 16) * sizeof(double));
    if (!world || !poses) {
        PyErr_NoMemory();
        goto done;
    }
    if (poses_init(&S, views, 2, poses, nj)) goto done;
    for (Py_ssize_t g = 0; g < n; g++) {
        double jf = jv[g];
        if (!(jf >= 0.0 && jf < (double)nj)) {
            PyErr_Format(PyExc_ValueError, "sphere_gaps: geometry %zd's joint is not one of "
                         "the %zd joints", g, nj);
            goto done;
        }
        Py_ssize_t j = (Py_ssize_t)jf;
        const double *c = C.p + g * C.s0;
        double *w = world + 3 * g;
        if (pose_at(&S, j)) goto done;  /* (joint 0, the world: the identity) */
        const double *H = poses + 16 * j;
        for (int r = 0; r < 3; r++)
            w[r] = H[4 * r] * c[0] + H[4 * r + 1] * c[C.s1] + H[4 * r + 2] * c[2 * C.s1]
                   + H[4 * r + 3];
    }
    for (Py_ssize_t k = 0; k < npairs; k++) {
        double a = AT(P, k, 0), b = AT(P, k, 1);
        if (!(a >= 0.0 && a < (double)n && b >= 0.0 && b < (double)n)) {
            PyErr_Format(PyExc_ValueError, "sphere_gaps: pair %zd names no geometry", k);
            goto done;
        }
        const double *wa = world + 3 * (Py_ssize_t)a, *wb = world + 3 * (Py_ssize_t)b;
        double dx = wa[0] - wb[0], dy = wa[1] - wb[1], dz = wa[2] - wb[2];
        gv[k] = sqrt(dx * dx + dy * dy + dz * dz) - sv[k];
    }
    result = Py_None;
    Py_INCREF(result);
done:
    poses_free(&S);
    free(world);
    free(poses);
    release(&joints); release(&centres); release(&pairs); release(&span); release(&gap);
    return result;
}

/* Whether pair k's bound lever_k |q - reference| (moved) plus its influence stays under its
 * gap */
static int lever_holds(Mat L, Py_ssize_t k, const double *moved, const double *gap,
                       const double *influence)
{
    double acc = 0.0;
    for (Py_ssize_t j = 0; j < L.n; j++) acc += AT(L, k, j) * moved[j];
    return acc + influence[k] < gap[k];
}

/* The order of near_pairs' test (prefilter, 1 + 3 npairs: a flag, then thresholds, pairs and
 * the influence they were made for): each pair's r_k = s_k / |lever_k| with its slack s_k =
 * gap_k - influence_k less 1e-12 (1 + |gap_k| + |influence_k|) (inf where the gap is; -inf
 * where s_k is not > 0 or the lever's norm is 0 or not finite), ascending. As lever_k . m <=
 * |lever_k| |m| (Cauchy-Schwarz), a pair with r_k (1 - 1e-9) > |m| meets the test at m, beyond
 * the rounding of either side; the pairs are tested from the smallest r_k on, until one
 * exceeds |m|: after a broad phase most pairs lie far beyond their influence and none of
 * them is summed. */
static int by_threshold(const void *a, const void *b)
{
    double x = ((const double *)a)[0], y = ((const double *)b)[0];
    return (x > y) - (x < y);
}

static int prefilter_build(Mat L, const double *gap, const double *influence, double *P)
{
    Py_ssize_t m = L.m;
    double *pairs = (double *)malloc((size_t)(2 * (m > 0 ? m : 1)) * sizeof(double));
    if (!pairs) return -1;
    for (Py_ssize_t k = 0; k < m; k++) {
        double norm = 0.0;
        for (Py_ssize_t j = 0; j < L.n; j++) norm += AT(L, k, j) * AT(L, k, j);
        norm = sqrt(norm);
        double slack = gap[k] - influence[k]
                       - 1e-12 * (1.0 + fabs(gap[k]) + fabs(influence[k]));
        double r = -INFINITY;
        if (isinf(gap[k]) && gap[k] > 0 && isfinite(influence[k]) && isfinite(norm))
            r = INFINITY;
        else if (slack > 0.0 && norm > 0.0 && isfinite(norm))
            r = slack / norm;
        pairs[2 * k] = r;
        pairs[2 * k + 1] = (double)k;
    }
    qsort(pairs, (size_t)m, 2 * sizeof(double), by_threshold);
    for (Py_ssize_t i = 0; i < m; i++) {
        P[1 + i] = pairs[2 * i];
        P[1 + m + i] = pairs[2 * i + 1];
        P[1 + 2 * m + i] = influence[i];
    }
    P[0] = 1.0;
    free(pairs);
    return 0;
}

/* Whether q lies in the box [lower, upper] the levers hold in and every pair's bound
 * lever |q - reference| plus its influence stays under its gap (else the broad phase must run
 * again); with a prefilter (prefilter_build's, or P[0] < 0: built here first) only the pairs
 * whose threshold does not clear |q - reference| are summed, which answers the same. -1 when
 * out of memory. */
static int lever_within(const double *q, const double *ref, const double *lo, const double *hi,
                        Mat L, const double *gap, const double *influence, double *P)
{
    double moved[L.n > 0 ? L.n : 1], norm = 0.0;
    for (Py_ssize_t j = 0; j < L.n; j++) {
        if (!(q[j] >= lo[j] && q[j] <= hi[j])) return 0;
        moved[j] = fabs(q[j] - ref[j]);
        norm += moved[j] * moved[j];
    }
    if (P) {
        if (P[0] < 0.0 && prefilter_build(L, gap, influence, P)) return -1;
        int same = 1;  /* (made for these influences: near_pairs' callers pass one array) */
        for (Py_ssize_t k = 0; k < L.m && same; k++) same = P[1 + 2 * L.m + k] == influence[k];
        if (same) {
            norm = sqrt(norm);
            for (Py_ssize_t i = 0; i < L.m && !(P[1 + i] * (1.0 - 1e-9) > norm); i++)
                if (!lever_holds(L, (Py_ssize_t)P[1 + L.m + i], moved, gap, influence))
                    return 0;
            return 1;
        }
    }
    Py_ssize_t k = 0;
    if (L.s1 == 1)  /* four pairs at a time: four sums that do not wait on each other (each
                     * summed in the same order as one at a time) */
        for (; k + 4 <= L.m; k += 4) {
            const double *r0 = L.p + k * L.s0, *r1 = r0 + L.s0, *r2 = r1 + L.s0;
            const double *r3 = r2 + L.s0;
            double a0 = 0.0, a1 = 0.0, a2 = 0.0, a3 = 0.0;
            for (Py_ssize_t j = 0; j < L.n; j++) {
                double m = moved[j];
                a0 += r0[j] * m;
                a1 += r1[j] * m;
                a2 += r2[j] * m;
                a3 += r3[j] * m;
            }
            if (!(a0 + influence[k] < gap[k]) || !(a1 + influence[k + 1] < gap[k + 1])
                || !(a2 + influence[k + 2] < gap[k + 2]) || !(a3 + influence[k + 3] < gap[k + 3]))
                return 0;
        }
    for (; k < L.m; k++)
        if (!lever_holds(L, k, moved, gap, influence)) return 0;
    return 1;
}

/* The pairs of the sequence `near` whose floor, aged from floor_q to q (floor_k -= lever_k
 * |q - floor_q|), is not above their influence (a new list); floor_q becomes q */
static PyObject *pairs_to_query(PyObject *near_seq, double *floor_, double *floor_q,
                                const double *q, Mat L, const double *influence)
{
    PyObject *near = PySequence_Fast(near_seq, "near must be a sequence of pair indices");
    if (!near) return NULL;
    PyObject *out = PyList_New(0);
    Py_ssize_t m = PySequence_Fast_GET_SIZE(near);
    PyObject **items = PySequence_Fast_ITEMS(near);
    double moved[L.n > 0 ? L.n : 1];
    for (Py_ssize_t j = 0; j < L.n; j++) moved[j] = fabs(q[j] - floor_q[j]);
    for (Py_ssize_t i = 0; i < m && out; i++) {
        Py_ssize_t k = PyLong_AsSsize_t(items[i]);
        if (k == -1 && PyErr_Occurred()) {
            Py_CLEAR(out);
        } else if (k < 0 || k >= L.m) {
            PyErr_Format(PyExc_ValueError, "near[%zd] = %zd is no pair (npairs %zd)", i, k, L.m);
            Py_CLEAR(out);
        } else {
            double closed = 0.0;
            for (Py_ssize_t j = 0; j < L.n; j++) closed += AT(L, k, j) * moved[j];
            floor_[k] -= closed;
            if (!(floor_[k] > influence[k]) && PyList_Append(out, items[i]) < 0) Py_CLEAR(out);
        }
    }
    Py_DECREF(near);
    if (out)
        for (Py_ssize_t j = 0; j < L.n; j++) floor_q[j] = q[j];
    return out;
}

/* near_pairs(q, skip, influence) -> list | None: the collision limit's skip of its broad phase
 * and of its queries (limits/collision.py, _near and _rows) for q in its own tangent space
 * (revolute and prismatic joints); skip: the limit's (reference, lower, upper, lever, gap,
 * near, floor, floor_q), with lever (npairs, n) bounding how far |dq| moves each pair. None
 * when q leaves the box lower <= q <= upper (n,) the levers hold in, or when some pair's bound
 * lever |q - reference| plus its influence (npairs,) reaches the gap (npairs,) its bounding
 * volumes had at the reference (the broad phase must run again); else the pairs of the list
 * `near` whose floor (npairs,; a lower bound of their distance at floor_q (n,), m), aged to q,
 * is not above their influence (those to query), floor_q then q. A ninth item of skip, a
 * writable prefilter (1 + 3 npairs,; its first number < 0 until the first call builds it for
 * this gap), orders the lever test so that the pairs far beyond reach are not summed (the
 * same answer: lever_within). */
PyObject *py_near_pairs(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!nargs_ok(nargs, 3, "near_pairs")) return NULL;
    Py_ssize_t size = PyTuple_Check(args[1]) ? PyTuple_GET_SIZE(args[1]) : 0;
    if (size != 8 && size != 9) {
        PyErr_SetString(PyExc_TypeError, "near_pairs: skip must be a tuple of 8 or 9");
        return NULL;
    }
    PyObject *const *S = &PyTuple_GET_ITEM(args[1], 0);
    Arg q = {0}, ref = {0}, lo = {0}, hi = {0}, lever = {0}, gap = {0}, floor_ = {0},
        floor_q = {0}, infl = {0}, pre = {0};
    PyObject *result = NULL;
    if (acquire(args[0], &q, 0, 1, "q") || acquire(S[0], &ref, 0, 1, "reference")
        || acquire(S[1], &lo, 0, 1, "lower") || acquire(S[2], &hi, 0, 1, "upper")
        || acquire(S[3], &lever, 0, 2, "lever") || acquire(S[4], &gap, 0, 1, "gap")
        || acquire(S[6], &floor_, 1, 1, "floor") || acquire(S[7], &floor_q, 1, 1, "floor_q")
        || acquire(args[2], &infl, 0, 1, "influence")
        || (size == 9 && acquire(S[8], &pre, 1, 1, "prefilter")))
        goto done;
    double *qv = vec(&q, "q"), *rv = vec(&ref, "reference"), *gv = vec(&gap, "gap");
    double *pv = size == 9 ? out_vec(&pre, "prefilter") : NULL;
    double *lov = vec(&lo, "lower"), *hiv = vec(&hi, "upper");
    double *fv = out_vec(&floor_, "floor"), *fqv = out_vec(&floor_q, "floor_q");
    double *iv = vec(&infl, "influence");
    if (!qv || !rv || !lov || !hiv || !gv || !fv || !fqv || !iv || (size == 9 && !pv))
        goto done;
    Mat L = mat(&lever);
    Py_ssize_t n = length(&q), npairs = L.m;
    if (length(&ref) != n || length(&lo) != n || length(&hi) != n || L.n != n
        || length(&floor_q) != n || length(&gap) != npairs || length(&floor_) != npairs
        || length(&infl) != npairs || (pv && length(&pre) != 1 + 3 * npairs)) {
        PyErr_Format(PyExc_ValueError, "near_pairs: q, reference, lower, upper, floor_q (n,), "
                     "lever (npairs, n), gap, floor and influence (npairs,), prefilter (1 + 3 "
                     "npairs,) do not fit (n %zd, npairs %zd)", n, npairs);
        goto done;
    }
    int within = lever_within(qv, rv, lov, hiv, L, gv, iv, pv);
    if (within < 0) {
        PyErr_NoMemory();
    } else if (!within) {
        result = Py_None;
        Py_INCREF(result);
    } else {
        result = pairs_to_query(S[5], fv, fqv, qv, L, iv);
    }
done:
    release(&q); release(&ref); release(&lo); release(&hi); release(&lever); release(&gap);
    release(&floor_); release(&floor_q); release(&infl); release(&pre);
    return result;
}

/* The indices k of `seq` (pair indices below npairs) with floor_[k] kept: every other
 * floor becomes -inf (no bound known); seq None keeps none. 0, or -1 with the error set. */
static int keep_floors(PyObject *seq, double *floor_, Py_ssize_t npairs)
{
    char *keep = (char *)calloc((size_t)(npairs > 0 ? npairs : 1), 1);
    if (!keep) {
        PyErr_NoMemory();
        return -1;
    }
    if (seq != Py_None) {
        PyObject *kept = PySequence_Fast(seq, "kept must be a sequence of pair indices");
        if (!kept) {
            free(keep);
            return -1;
        }
        Py_ssize_t m = PySequence_Fast_GET_SIZE(kept);
        PyObject **items = PySequence_Fast_ITEMS(kept);
        for (Py_ssize_t i = 0; i < m; i++) {
            Py_ssize_t k = PyLong_AsSsize_t(items[i]);
            if ((k == -1 && PyErr_Occurred()) || k < 0 || k >= npairs) {
                if (!PyErr_Occurred())
                    PyErr_Format(PyExc_ValueError, "kept[%zd] = %zd is no pair (npairs %zd)", i,
                                 k, npairs);
                Py_DECREF(kept);
                free(keep);
                return -1;
            }
            keep[k] = 1;
        }
        Py_DECREF(kept);
    }
    for (Py_ssize_t k = 0; k < npairs; k++)
        if (!keep[k]) floor_[k] = -INFINITY;
    free(keep);
    return 0;
}

/* refresh_pairs' lists: near (the pairs with gap < influence + skin, their gap set to inf)
 * and listed (those of near whose floor, aged from floor_q to q by lever |q - floor_q| where
 * floor_q is given, is not above their influence); floor_q then q. 0, or -1 with the error
 * set. */
static int candidates(const double *q, double *gap, const double *influence, double skin,
                      double *floor_, double *floor_q, Mat L, PyObject *near, PyObject *listed)
{
    Py_ssize_t n = L.n;
    double moved[n > 0 ? n : 1];
    for (Py_ssize_t j = 0; j < n; j++) moved[j] = floor_q ? fabs(q[j] - floor_q[j]) : 0.0;
    for (Py_ssize_t k = 0; k < L.m; k++) {
        if (!(gap[k] < influence[k] + skin)) continue;
        gap[k] = INFINITY;
        PyObject *index = PyLong_FromSsize_t(k);
        if (!index) return -1;
        int failed = PyList_Append(near, index) < 0;
        if (!failed && floor_q) {
            double closed = 0.0;
            for (Py_ssize_t j = 0; j < n; j++) closed += AT(L, k, j) * moved[j];
            floor_[k] -= closed;
        }
        if (!failed && (!floor_q || !(floor_[k] > influence[k])))
            failed = PyList_Append(listed, index) < 0;
        Py_DECREF(index);
        if (failed) return -1;
    }
    if (floor_q)
        for (Py_ssize_t j = 0; j < n; j++) floor_q[j] = q[j];
    return 0;
}

/* refresh_pairs(q, lower, upper, gap, influence, skin, floor, kept, floor_q, lever) ->
 * (near, listed) | None: the collision limit's new candidate list after a broad phase
 * (limits/collision.py, _near and _aged, in one call): None, changing nothing, when q leaves
 * the box lower <= q <= upper (n,) the levers hold in; else near, the pairs whose bounding
 * volumes' gap (npairs,; m, from sphere_gaps) is below their influence (npairs,) plus skin (m),
 * their gaps set to inf (a candidate stays one); every floor (npairs,) but those of the pairs in
 * the sequence kept (None: none) becomes -inf; with floor_q (n,; None: not yet) the floors of
 * near aged from floor_q to q by lever (npairs, n) |q - floor_q|, floor_q then q, and listed the
 * pairs of near whose floor is not above their influence (without floor_q: near). */
PyObject *py_refresh_pairs(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!nargs_ok(nargs, 10, "refresh_pairs")) return NULL;
    Arg q = {0}, lo = {0}, hi = {0}, gap = {0}, infl = {0}, floor_ = {0}, floor_q = {0},
        lever = {0};
    PyObject *result = NULL, *near = NULL, *listed = NULL;
    double skin = PyFloat_AsDouble(args[5]);
    if (skin == -1.0 && PyErr_Occurred()) return NULL;
    int aged = args[8] != Py_None;
    if (acquire(args[0], &q, 0, 1, "q") || acquire(args[1], &lo, 0, 1, "lower")
        || acquire(args[2], &hi, 0, 1, "upper") || acquire(args[3], &gap, 1, 1, "gap")
        || acquire(args[4], &infl, 0, 1, "influence") || acquire(args[6], &floor_, 1, 1, "floor")
        || (aged && acquire(args[8], &floor_q, 1, 1, "floor_q"))
        || acquire(args[9], &lever, 0, 2, "lever"))
        goto done;
    double *qv = vec(&q, "q"), *lov = vec(&lo, "lower"), *hiv = vec(&hi, "upper");
    double *gv = out_vec(&gap, "gap"), *iv = vec(&infl, "influence");
    double *fv = out_vec(&floor_, "floor"), *fqv = aged ? out_vec(&floor_q, "floor_q") : NULL;
    if (!qv || !lov || !hiv || !gv || !iv || !fv || (aged && !fqv)) goto done;
    Mat L = mat(&lever);
    Py_ssize_t n = length(&q), npairs = L.m;
    if (length(&lo) != n || length(&hi) != n || L.n != n || (aged && length(&floor_q) != n)
        || length(&gap) != npairs || length(&floor_) != npairs || length(&infl) != npairs) {
        PyErr_Format(PyExc_ValueError, "refresh_pairs: q, lower, upper, floor_q (n,), lever "
                     "(npairs, n), gap, floor and influence (npairs,) do not fit (n %zd, npairs "
                     "%zd)", n, npairs);
        goto done;
    }
    for (Py_ssize_t j = 0; j < n; j++)
        if (!(qv[j] >= lov[j] && qv[j] <= hiv[j])) {
            result = Py_None;
            Py_INCREF(result);
            goto done;
        }
    if (keep_floors(args[7], fv, npairs)) goto done;
    near = PyList_New(0);
    listed = PyList_New(0);
    if (!near || !listed || candidates(qv, gv, iv, skin, fv, fqv, L, near, listed)) goto done;
    result = PyTuple_Pack(2, near, listed);
done:
    Py_XDECREF(near);
    Py_XDECREF(listed);
    release(&q); release(&lo); release(&hi); release(&gap); release(&infl); release(&floor_);
    release(&floor_q); release(&lever);
    return result;
}

/* braking_reach(lever, dq, accelerations, jerks, dt, share, influence, margin, out): each
 * pair's influence (m) for a step of an arm with acceleration (and jerk) limits: out_k =
 * max(influence, margin + s_k (tau + T_k / (2 share))), the distance within which a damper
 * row may have to start braking the pair. With w_j = |dq_j| + accelerations_j dt (a joint's
 * speed after this step at most), s_k = sum_j lever_kj w_j bounds the pair's closing speed
 * (lever (npairs, N): m per unit of q_dot_j, as near_pairs'), T_k = max_j w_j /
 * accelerations_j over the joints that move it, tau = dt + max_j accelerations_j / jerks_j
 * (jerks None: dt). A row's closing speed s = A_i q_dot and acceleration a = sum_j |A_ij|
 * accelerations_j give s / a <= T_k, so the distance s tau + s^2 / (2 share a) a row needs
 * to stop it (stoppable_rows) is at most s_k (tau + T_k / (2 share)). */
PyObject *py_braking_reach(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (!nargs_ok(nargs, 9, "braking_reach")) return NULL;
    double dt = PyFloat_AsDouble(args[4]), share = PyFloat_AsDouble(args[5]);
    double influence = PyFloat_AsDouble(args[6]), margin = PyFloat_AsDouble(args[7]);
    if (PyErr_Occurred()) return NULL;
    if (!(dt > 0.0 && share > 0.0 && share <= 1.0 && isfinite(influence) && isfinite(margin))) {
        PyErr_SetString(PyExc_ValueError, "braking_reach: dt must be > 0, share in (0, 1], "
                        "influence and margin finite");
        return NULL;
    }
    Arg lever = {0}, dq = {0}, acc = {0}, jerk = {0}, out = {0};
    PyObject *result = NULL;
    int has_jerk = args[3] != Py_None;
    if (acquire(args[0], &lever, 0, 2, "lever") || acquire(args[1], &dq, 0, 1, "dq")
        || acquire(args[2], &acc, 0, 1, "accelerations")
        || (has_jerk && acquire(args[3], &jerk, 0, 1, "jerks"))
        || acquire(args[8], &out, 1, 1, "out"))
        goto done;
    Mat L = mat(&lever);
    const double *dv = vec(&dq, "dq"), *av = vec(&acc, "accelerations");
    const double *jv = has_jerk ? vec(&jerk, "jerks") : NULL;
    double *ov = out_vec(&out, "out");
    if (!dv || !av || (has_jerk && !jv) || !ov) goto done;
    if (length(&dq) != L.n || length(&acc) != L.n || (has_jerk && length(&jerk) != L.n)
        || length(&out) != L.m) {
        PyErr_Format(PyExc_ValueError, "braking_reach: lever (npairs, N), dq, accelerations, "
                     "jerks (N,) and out (npairs,) do not fit: lever (%zd, %zd)", L.m, L.n);
        goto done;
    }
    double tau = dt;
    for (Py_ssize_t j = 0; j < L.n; j++)
        if (jv && jv[j] > 0.0 && isfinite(jv[j]) && isfinite(av[j]))
            tau = fmax(tau, dt + av[j] / jv[j]);
    for (Py_ssize_t k = 0; k < L.m; k++) {
        double s = 0.0, T = 0.0;
        for (Py_ssize_t j = 0; j < L.n; j++) {
            double l = AT(L, k, j);
            if (!(l > 0.0) || !(av[j] > 0.0) || !isfinite(av[j])) continue;
            double w = fabs(dv[j]) + av[j] * dt;
            s += l * w;
            T = fmax(T, w / av[j]);
        }
        ov[k] = fmax(influence, margin + s * (tau + T / (2.0 * share)));
    }
    result = Py_None;
    Py_INCREF(result);
done:
    release(&lever); release(&dq); release(&acc); release(&jerk); release(&out);
    return result;
}
