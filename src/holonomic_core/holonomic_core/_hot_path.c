/*
 * The control cycle's closed forms, compiled: the same arithmetic as the
 * pure-Python reference implementations, in the same order, one C call each.
 *
 * Why: the cycle works on 3-16 numbers, where Python spends ~1 us per
 * operation and numpy a few us per call; here the whole arithmetic of a
 * step (limits, inverse kinematics, the slip_min fit, the SE(2) arc and the
 * covariance) costs a fraction of a microsecond. holonomic_core.hot_path
 * loads this module and says which Python functions dispatch here.
 *
 * Same numbers: every expression below mirrors its Python counterpart
 * operation for operation (named in each function's comment) and is built
 * with -ffp-contract=off (no fused multiply-add, which gcc would otherwise
 * emit on aarch64), and sin/cos/sqrt come from the same libm that Python's
 * math module calls. So the results are bitwise those of the Python path,
 * except where Python uses its own algorithm: math.hypot (CPython's
 * vector_norm, which differs from libm's hypot by 1 ulp in ~0.1 % of
 * inputs) feeds the per-caster residual, the slip and the travelled distance
 * (and through it the covariance): those agree to a few ulp.
 *
 * Units and frames: as the Python functions (SI; twists (vx, vy, wz) in
 * base_link [m/s, m/s, rad/s], joint arrays in the kinematics' joint order).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#define NPY_NO_DEPRECATED_API NPY_1_7_API_VERSION
#include <numpy/arrayobject.h>
#include <math.h>
#include <string.h>

#define TWO_PI (2.0 * 3.141592653589793)

/* A C-contiguous float64 vector view of `obj` (a new reference; for a
   contiguous float64 ndarray the same object), or NULL with TypeError. */
static PyArrayObject *
as_vector(PyObject *obj, const char *what)
{
    PyArrayObject *arr = (PyArrayObject *)PyArray_FROMANY(
        obj, NPY_DOUBLE, 1, 1, NPY_ARRAY_IN_ARRAY);
    if (arr == NULL && !PyErr_Occurred())
        PyErr_Format(PyExc_TypeError, "%s: a 1-D array of floats", what);
    return arr;
}

static int
need_length(PyArrayObject *arr, npy_intp n, const char *what)
{
    if (PyArray_DIM(arr, 0) < n) {
        PyErr_Format(PyExc_ValueError, "%s: %zd values, need %zd", what,
                     (Py_ssize_t)PyArray_DIM(arr, 0), (Py_ssize_t)n);
        return -1;
    }
    return 0;
}

static PyObject *
new_vector(npy_intp n, double **data)
{
    PyObject *out = PyArray_SimpleNew(1, &n, NPY_DOUBLE);
    if (out != NULL)
        *data = (double *)PyArray_DATA((PyArrayObject *)out);
    return out;
}

/* A new float64 array holding a copy of src[0..n). */
static PyObject *
vector_from(const double *src, npy_intp n)
{
    double *o;
    PyObject *out = new_vector(n, &o);
    if (out != NULL && n > 0)
        memcpy(o, src, n * sizeof(double));
    return out;
}

/* A float argument into *out; -1 with the exception set. */
static int
arg_double(PyObject *obj, double *out)
{
    *out = PyFloat_AsDouble(obj);
    return (*out == -1.0 && PyErr_Occurred()) ? -1 : 0;
}

/* An int argument (a KIND_* constant) into *out; -1 with the exception set. */
static int
arg_kind(PyObject *obj, long *out)
{
    *out = PyLong_AsLong(obj);
    return (*out == -1 && PyErr_Occurred()) ? -1 : 0;
}

static int
check_nargs(Py_ssize_t nargs, Py_ssize_t want, const char *name)
{
    if (nargs != want) {
        PyErr_Format(PyExc_TypeError, "%s takes %zd arguments (%zd given)", name, want, nargs);
        return -1;
    }
    return 0;
}

/* jerk_arrival_bound(gap, jerk): mirrors holonomic_core.limits.jerk_arrival_bound */
static double
jerk_arrival_bound(double gap, double jerk)
{
    if (gap <= 0.0)
        return 0.0;
    if (!(gap / jerk <= 1e12))
        return sqrt(2.0 * gap * jerk);
    double n = floor((sqrt(1.0 + 8.0 * gap / jerk) - 1.0) / 2.0);
    while (n > 0 && jerk * n * (n + 1) / 2.0 > gap)
        n -= 1;
    while (jerk * (n + 1) * (n + 2) / 2.0 <= gap)
        n += 1;
    return (gap + jerk * n * (n + 1) / 2.0) / (n + 1);
}

/* limit_twist(target, previous, dt, limits, acceleration) -> new twist array (3,)
   limits: (vmax[3], amax[3], dmax[3], max_speed, jmax[3]). Mirrors
   TwistLimiter.limit: limit_velocity, then limit_acceleration (no axis with a
   jerk limit) or limit_jerk. */
static PyObject *
limit_twist(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (check_nargs(nargs, 5, "limit_twist") < 0)
        return NULL;
    double dt;
    if (arg_double(args[2], &dt) < 0)
        return NULL;
    PyArrayObject *tgt_a = as_vector(args[0], "target"), *prev_a = NULL, *lim_a = NULL,
                  *acc_a = NULL;
    PyObject *out = NULL;
    if (tgt_a == NULL || need_length(tgt_a, 3, "target") < 0)
        goto done;
    prev_a = as_vector(args[1], "previous");
    if (prev_a == NULL || need_length(prev_a, 3, "previous") < 0)
        goto done;
    lim_a = as_vector(args[3], "limits");
    if (lim_a == NULL || need_length(lim_a, 13, "limits") < 0)
        goto done;
    acc_a = as_vector(args[4], "acceleration");
    if (acc_a == NULL || need_length(acc_a, 3, "acceleration") < 0)
        goto done;
    const double *target = PyArray_DATA(tgt_a), *prev = PyArray_DATA(prev_a);
    const double *acc_in = PyArray_DATA(acc_a);
    const double *vmax = PyArray_DATA(lim_a), *amax = vmax + 3, *dmax = vmax + 6;
    const double max_speed = vmax[9], *jmax = vmax + 10;
    double tgt[3];
    /* limit_velocity: one scale for the three axes */
    double scale = 1.0;
    for (int i = 0; i < 3; i++) {
        double mag = fabs(target[i]);
        if (mag > vmax[i]) {
            double s = vmax[i] / mag;
            if (s < scale)          /* min(scale, s) keeps scale unless s < scale */
                scale = s;
        }
    }
    {
        double vx = target[0] * scale, vy = target[1] * scale;
        double speed = sqrt(vx * vx + vy * vy);
        if (speed > max_speed)
            scale = scale * (max_speed / speed);
    }
    for (int i = 0; i < 3; i++)
        tgt[i] = scale < 1.0 ? target[i] * scale : target[i];
    int jerk_limited = isfinite(jmax[0]) || isfinite(jmax[1]) || isfinite(jmax[2]);
    double *o;
    out = new_vector(3, &o);
    if (out == NULL)
        goto done;
    if (!jerk_limited) {
        /* limit_acceleration */
        scale = 1.0;
        for (int i = 0; i < 3; i++) {
            double change = fabs(tgt[i] - prev[i]);
            if (change == 0.0)
                continue;
            int growing = fabs(tgt[i]) > fabs(prev[i]) && tgt[i] * prev[i] >= 0.0;
            double step = (growing ? amax[i] : dmax[i]) * dt;
            if (change > step) {
                double s = step / change;
                if (s < scale)
                    scale = s;
            }
        }
        for (int i = 0; i < 3; i++)
            o[i] = scale == 1.0 ? tgt[i] : prev[i] + (tgt[i] - prev[i]) * scale;
        goto done;
    }
    /* limit_jerk */
    if (!(dt > 0.0)) {
        for (int i = 0; i < 3; i++)
            o[i] = prev[i];
        goto done;
    }
    double sigma = 1.0, kappa = 1.0, wanted[3], acc[3];
    for (int i = 0; i < 3; i++) {
        double bound = amax[i] > dmax[i] ? amax[i] : dmax[i];   /* np.maximum */
        double a = -bound > acc_in[i] ? -bound : acc_in[i];     /* max(a, -lim) */
        acc[i] = bound < a ? bound : a;                         /* min(., lim) */
    }
    for (int i = 0; i < 3; i++) {
        double change = fabs(tgt[i] - prev[i]);
        if (change == 0.0)
            continue;
        double need = change / dt;
        int growing = fabs(tgt[i]) > fabs(prev[i]) && tgt[i] * prev[i] >= 0.0;
        double allowed = growing ? amax[i] : dmax[i];
        double jerk = jmax[i] * dt;
        if (jerk < INFINITY) {
            double bound = jerk_arrival_bound(need, jerk);
            if (bound < allowed)    /* min(allowed, bound) */
                allowed = bound;
        }
        if (need > allowed) {
            double s = allowed / need;
            if (s < sigma)
                sigma = s;
        }
    }
    for (int i = 0; i < 3; i++)
        wanted[i] = (tgt[i] - prev[i]) / dt * sigma;
    for (int i = 0; i < 3; i++) {
        double change = fabs(wanted[i] - acc[i]);
        double jerk = jmax[i] * dt;
        if (change > jerk) {
            double s = jerk / change;
            if (s < kappa)
                kappa = s;
        }
    }
    for (int i = 0; i < 3; i++)
        o[i] = (sigma == 1.0 && kappa == 1.0) ? tgt[i]
               : prev[i] + (acc[i] + (wanted[i] - acc[i]) * kappa) * dt;
done:
    Py_XDECREF(tgt_a);
    Py_XDECREF(prev_a);
    Py_XDECREF(lim_a);
    Py_XDECREF(acc_a);
    return out;
}

/* saturate_joint_rates(rates, max_rates) -> (rates, scale); mirrors
   holonomic_core.limits.saturate_joint_rates_pure (unsaturated: the same
   object back; non-finite: zeros and 0.0). */
static PyObject *
saturate_joint_rates(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (check_nargs(nargs, 2, "saturate_joint_rates") < 0)
        return NULL;
    PyArrayObject *r_a = as_vector(args[0], "rates"), *m_a = NULL;
    PyObject *out = NULL, *arr = NULL;
    if (r_a == NULL)
        return NULL;
    npy_intp n = PyArray_DIM(r_a, 0);
    m_a = as_vector(args[1], "max_rates");
    if (m_a == NULL || need_length(m_a, n, "max_rates") < 0)
        goto done;
    const double *rates = PyArray_DATA(r_a), *limit = PyArray_DATA(m_a);
    double worst = 0.0, *o;
    for (npy_intp i = 0; i < n; i++) {
        double ratio = fabs(rates[i]) / limit[i];
        if (!isfinite(ratio)) {
            arr = new_vector(n, &o);
            if (arr == NULL)
                goto done;
            for (npy_intp j = 0; j < n; j++)
                o[j] = 0.0;
            out = Py_BuildValue("(Nd)", arr, 0.0);
            goto done;
        }
        if (ratio > worst)
            worst = ratio;
    }
    if (worst <= 1.0) {
        out = Py_BuildValue("(Od)", args[0], 1.0);
        goto done;
    }
    double scale = 1.0 / worst;
    arr = new_vector(n, &o);
    if (arr == NULL)
        goto done;
    for (npy_intp i = 0; i < n; i++)
        o[i] = rates[i] * scale;
    out = Py_BuildValue("(Nd)", arr, scale);
done:
    Py_DECREF(r_a);
    Py_XDECREF(m_a);
    return out;
}

/* ---- kinematics: the geometry arrays are built by the kinematics classes'
   hot_path_geometry() ---- */

/* PCV geometry: (sx, sy, b, r) per caster. Mirrors
   PoweredCasterKinematics.inverse. */
static void
pcv_inverse_into(const double *q, const double *tw, const double *geo, npy_intp n, double *o)
{
    double vx = tw[0], vy = tw[1], wz = tw[2];
    for (npy_intp i = 0; i < n; i++) {
        double sx = geo[4 * i], sy = geo[4 * i + 1], b = geo[4 * i + 2], r = geo[4 * i + 3];
        double phi = q[2 * i], c = cos(phi), s = sin(phi);
        double vsx = vx - wz * sy;
        double vsy = vy + wz * sx;
        o[2 * i] = (c * vsy - s * vsx) / b - wz;
        o[2 * i + 1] = (c * vsx + s * vsy) / r;
    }
}

/* DDROT geometry: (a, b, r_left, r_right). Mirrors OffsetTurretKinematics.inverse. */
static void
ddrot_inverse_into(const double *q, const double *tw, const double *geo, double *o)
{
    double a = geo[0], b = geo[1], rl = geo[2], rr = geo[3];
    double phi = q[2], s = sin(phi), c = cos(phi);
    double vx = tw[0], vy = tw[1], wz = tw[2];
    double v = vx * c - vy * s;
    double wd = (vx * s + vy * c) / b;
    o[0] = (v - a * wd) / rl;
    o[1] = (v + a * wd) / rr;
    o[2] = wz - wd;
}

/* Mirrors OffsetTurretKinematics.forward. */
static void
ddrot_forward_into(const double *q, const double *v, const double *geo, double *o)
{
    double a = geo[0], b = geo[1], rl = geo[2], rr = geo[3];
    double phi = q[2], s = sin(phi), c = cos(phi);
    double vl = rl * v[0], vr = rr * v[1];
    double fwd = 0.5 * (vl + vr);
    double wd = 0.5 * (vr - vl) / a;
    o[0] = fwd * c + b * wd * s;
    o[1] = -fwd * s + b * wd * c;
    o[2] = wd + v[2];
}

/* The slip_min fit; mirrors PoweredCasterKinematics._fit and _slip_min:
   twist into tw[3], per-caster residual norm into res[n]. `scratch` holds
   4 n doubles. */
static void
pcv_slip_min_into(const double *q, const double *v, const double *geo, npy_intp n,
                  double *scratch, double *tw, double *res)
{
    double sum_x = 0.0, sum_y = 0.0, sum_u = 0.0, sum_w = 0.0;
    for (npy_intp i = 0; i < n; i++) {
        double sx = geo[4 * i], sy = geo[4 * i + 1], b = geo[4 * i + 2], r = geo[4 * i + 3];
        double phi = q[2 * i], c = cos(phi), s = sin(phi);
        double dphi = v[2 * i], drho = v[2 * i + 1];
        double x = sx - b * c, y = sy - b * s;
        double u = (-b) * s * dphi + r * c * drho;
        double w = b * c * dphi + r * s * drho;
        double *p = scratch + 4 * i;
        p[0] = x; p[1] = y; p[2] = u; p[3] = w;
        sum_x += x;
        sum_y += y;
        sum_u += u;
        sum_w += w;
    }
    double dn = (double)n;
    double cx = sum_x / dn, cy = sum_y / dn, mu = sum_u / dn, mw = sum_w / dn;
    double num = 0.0, den = 0.0;
    for (npy_intp i = 0; i < n; i++) {
        const double *p = scratch + 4 * i;
        double qx = p[0] - cx, qy = p[1] - cy;
        num += qx * p[3] - qy * p[2];
        den += qx * qx + qy * qy;
    }
    double wz = den > 1e-12 * dn ? num / den : 0.0;
    double tx = mu + wz * cy, ty = mw - wz * cx;
    tw[0] = tx; tw[1] = ty; tw[2] = wz;
    for (npy_intp i = 0; i < n; i++) {
        const double *p = scratch + 4 * i;
        res[i] = hypot(p[2] - (tx - wz * p[1]), p[3] - (ty + wz * p[0]));
    }
}

enum { KIND_DDROT = 1, KIND_PCV = 2 };

/* inverse(kind, positions, twist, geometry) -> joint rates */
static PyObject *
inverse(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (check_nargs(nargs, 4, "inverse") < 0)
        return NULL;
    long kind;
    if (arg_kind(args[0], &kind) < 0)
        return NULL;
    PyArrayObject *q_a = as_vector(args[1], "positions"), *t_a = NULL, *g_a = NULL;
    PyObject *out = NULL;
    double *o;
    if (q_a == NULL)
        return NULL;
    t_a = as_vector(args[2], "twist");
    if (t_a == NULL || need_length(t_a, 3, "twist") < 0)
        goto done;
    g_a = as_vector(args[3], "geometry");
    if (g_a == NULL || need_length(g_a, 4, "geometry") < 0)
        goto done;
    if (kind == KIND_DDROT) {
        if (need_length(q_a, 3, "positions") < 0)
            goto done;
        out = new_vector(3, &o);
        if (out != NULL)
            ddrot_inverse_into(PyArray_DATA(q_a), PyArray_DATA(t_a), PyArray_DATA(g_a), o);
    } else if (kind == KIND_PCV) {
        npy_intp n = PyArray_DIM(g_a, 0) / 4;
        if (need_length(q_a, 2 * n, "positions") < 0)
            goto done;
        out = new_vector(2 * n, &o);
        if (out != NULL)
            pcv_inverse_into(PyArray_DATA(q_a), PyArray_DATA(t_a), PyArray_DATA(g_a), n, o);
    } else {
        PyErr_Format(PyExc_ValueError, "unknown kinematics kind %ld", kind);
    }
done:
    Py_DECREF(q_a);
    Py_XDECREF(t_a);
    Py_XDECREF(g_a);
    return out;
}

/* The estimate of `kind` into tw[3] / res (n_res entries). Returns the
   number of residual entries (0 for the DDROT), -1 on error. */
static npy_intp
estimate_into(long kind, const double *q, npy_intp nq, const double *v, const double *geo,
              npy_intp ngeo, double *tw, double *res, double *scratch)
{
    if (kind == KIND_DDROT) {
        if (nq < 3 || ngeo < 4) {
            PyErr_SetString(PyExc_ValueError, "DDROT: 3 joints and 4 geometry values");
            return -1;
        }
        ddrot_forward_into(q, v, geo, tw);
        return 0;
    }
    if (kind == KIND_PCV) {
        npy_intp n = ngeo / 4;
        if (n < 1 || nq < 2 * n) {
            PyErr_SetString(PyExc_ValueError, "PCV: 2 joints and 4 geometry values per caster");
            return -1;
        }
        pcv_slip_min_into(q, v, geo, n, scratch, tw, res);
        return n;
    }
    PyErr_Format(PyExc_ValueError, "unknown kinematics kind %ld", kind);
    return -1;
}

#define MAX_CASTERS 64     /* hot_path.MAX_CASTERS: beyond it the Python side stays pure */

/* estimate(kind, positions, velocities, geometry) -> (twist, residual) */
static PyObject *
estimate(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (check_nargs(nargs, 4, "estimate") < 0)
        return NULL;
    long kind;
    if (arg_kind(args[0], &kind) < 0)
        return NULL;
    PyArrayObject *q_a = as_vector(args[1], "positions"), *v_a = NULL, *g_a = NULL;
    PyObject *out = NULL, *tw_o = NULL, *res_o = NULL;
    double tw[3], res[MAX_CASTERS], scratch[4 * MAX_CASTERS];
    if (q_a == NULL)
        return NULL;
    v_a = as_vector(args[2], "velocities");
    if (v_a == NULL || need_length(v_a, PyArray_DIM(q_a, 0), "velocities") < 0)
        goto done;
    g_a = as_vector(args[3], "geometry");
    if (g_a == NULL)
        goto done;
    if (PyArray_DIM(g_a, 0) > 4 * MAX_CASTERS) {
        PyErr_SetString(PyExc_ValueError, "at most 64 casters");
        goto done;
    }
    npy_intp nres = estimate_into(kind, PyArray_DATA(q_a), PyArray_DIM(q_a, 0),
                                  PyArray_DATA(v_a), PyArray_DATA(g_a), PyArray_DIM(g_a, 0),
                                  tw, res, scratch);
    if (nres < 0)
        goto done;
    tw_o = vector_from(tw, 3);
    if (tw_o == NULL)
        goto done;
    res_o = vector_from(res, nres);
    if (res_o == NULL)
        goto done;
    out = PyTuple_Pack(2, tw_o, res_o);
done:
    Py_DECREF(q_a);
    Py_XDECREF(v_a);
    Py_XDECREF(g_a);
    Py_XDECREF(tw_o);
    Py_XDECREF(res_o);
    return out;
}

/* The pose composition and covariance growth; mirrors compose_arc and
   Odometry._integrate. pose[3] is updated in place; P[6] is the upper
   triangle; noise = (linear/m, angular/rad, angular/m, slip position gain,
   slip heading gain, slip4 position gain, slip4 heading gain); slip2 = rho^2.
   Returns the distance [m]. */
static double
integrate_into(double *pose, double *P, const double *disp, double slip2, double dt,
               const double *noise)
{
    double slip2_dt = slip2 * dt, slip4_dt = slip2_dt * slip2;
    double dx = disp[0], dy = disp[1], dth = disp[2];
    double x = pose[0], y = pose[1], heading = pose[2];
    double a, b;
    if (fabs(dth) < 1e-6) {
        a = 1.0 - dth * dth / 6.0;
        b = 0.5 * dth;
    } else {
        a = sin(dth) / dth;
        b = (1.0 - cos(dth)) / dth;
    }
    double bx = a * dx - b * dy;
    double by = b * dx + a * dy;
    double c = cos(heading), s = sin(heading);
    double wx = c * bx - s * by, wy = s * bx + c * by;
    pose[0] = x + wx;
    pose[1] = y + wy;
    pose[2] = remainder(heading + dth, TWO_PI);    /* exact, as math.remainder */
    double dist = hypot(dx, dy);
    double var_lin = noise[0] * dist + noise[3] * slip2_dt + noise[5] * slip4_dt;
    double var_ang = noise[1] * fabs(dth) + noise[2] * dist + noise[4] * slip2_dt
        + noise[6] * slip4_dt;
    /* no shortcut when the step adds no noise: F P F^T still swings the
       heading variance already accumulated into the position */
    double fa = -wy, fb = wx;
    double p00 = P[0], p01 = P[1], p02 = P[2], p11 = P[3], p12 = P[4], p22 = P[5];
    P[0] = p00 + 2.0 * fa * p02 + fa * fa * p22 + var_lin;
    P[1] = p01 + fa * p12 + fb * p02 + fa * fb * p22;
    P[2] = p02 + fa * p22;
    P[3] = p11 + 2.0 * fb * p12 + fb * fb * p22 + var_lin;
    P[4] = p12 + fb * p22;
    P[5] = p22 + var_ang;
    return dist;
}

static int
read_covariance(PyObject *obj, double *P)
{
    PyObject *seq = PySequence_Fast(obj, "covariance: a sequence of 6 floats");
    if (seq == NULL)
        return -1;
    if (PySequence_Fast_GET_SIZE(seq) != 6) {
        Py_DECREF(seq);
        PyErr_SetString(PyExc_ValueError, "covariance: 6 values (upper triangle)");
        return -1;
    }
    for (int i = 0; i < 6; i++) {
        P[i] = PyFloat_AsDouble(PySequence_Fast_GET_ITEM(seq, i));
        if (P[i] == -1.0 && PyErr_Occurred()) {
            Py_DECREF(seq);
            return -1;
        }
    }
    Py_DECREF(seq);
    return 0;
}

static int
writable_pose(PyObject *obj, PyArrayObject **pose)
{
    if (!PyArray_Check(obj) || PyArray_TYPE((PyArrayObject *)obj) != NPY_DOUBLE
            || PyArray_NDIM((PyArrayObject *)obj) != 1 || PyArray_DIM((PyArrayObject *)obj, 0) != 3
            || !PyArray_ISCARRAY((PyArrayObject *)obj)) {
        PyErr_SetString(PyExc_TypeError, "pose: a writable contiguous float64 array of 3");
        return -1;
    }
    *pose = (PyArrayObject *)obj;
    return 0;
}

/* odometry_step(kind, geometry, last_positions, positions, dt, pose,
   covariance, noise) -> (rate_twist, residual, disp, slip, covariance,
   distance, positions as a new float64 array), or None when a position is
   not finite (nothing changes: Odometry.update skips such a reading)

   One encoder increment with dt > 0, all of Odometry.update's arithmetic
   before the twist window: the finiteness check, dq, the mid-point configuration,
   the mean rates dq / dt, the estimate (rate twist, residual), disp = rate
   twist x dt, slip = RMS residual, the arc and the covariance (pose updated
   in place). */
static PyObject *
odometry_step(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (check_nargs(nargs, 8, "odometry_step") < 0)
        return NULL;
    long kind;
    if (arg_kind(args[0], &kind) < 0)
        return NULL;
    double dt;
    if (arg_double(args[4], &dt) < 0)
        return NULL;
    PyArrayObject *pose, *g_a = NULL, *l_a = NULL, *q_a = NULL, *n_a = NULL;
    PyObject *out = NULL, *tw_o = NULL, *res_o = NULL, *disp_o = NULL, *copy_o = NULL;
    double P[6], mid[2 * MAX_CASTERS], rates[2 * MAX_CASTERS], tw[3], res[MAX_CASTERS];
    double scratch[4 * MAX_CASTERS], *disp;
    if (writable_pose(args[5], &pose) < 0 || read_covariance(args[6], P) < 0)
        return NULL;
    g_a = as_vector(args[1], "geometry");
    if (g_a == NULL)
        goto done;
    l_a = as_vector(args[2], "last_positions");
    if (l_a == NULL)
        goto done;
    q_a = as_vector(args[3], "positions");
    if (q_a == NULL)
        goto done;
    n_a = as_vector(args[7], "noise");
    if (n_a == NULL || need_length(n_a, 7, "noise") < 0)
        goto done;
    npy_intp nq = PyArray_DIM(q_a, 0);
    if (nq > 2 * MAX_CASTERS || PyArray_DIM(g_a, 0) > 4 * MAX_CASTERS) {
        PyErr_SetString(PyExc_ValueError, "at most 128 joints");
        goto done;
    }
    if (need_length(l_a, nq, "last_positions") < 0)
        goto done;
    const double *last = PyArray_DATA(l_a), *q = PyArray_DATA(q_a);
    /* the pure path tests isfinite(sum(positions)): any NaN or +-inf (a sum
       of finite positions overflowing, |q| ~ 1e308 rad, is not mirrored) */
    for (npy_intp i = 0; i < nq; i++) {
        if (!isfinite(q[i])) {
            out = Py_None;
            Py_INCREF(out);
            goto done;
        }
    }
    copy_o = vector_from(q, nq);
    if (copy_o == NULL)
        goto done;
    for (npy_intp i = 0; i < nq; i++) {
        /* dq = positions - last; mid = last + 0.5 * dq; rates = dq / dt */
        double dq = q[i] - last[i];
        mid[i] = last[i] + 0.5 * dq;
        rates[i] = dq / dt;
    }
    npy_intp nres = estimate_into(kind, mid, nq, rates, PyArray_DATA(g_a), PyArray_DIM(g_a, 0),
                                  tw, res, scratch);
    if (nres < 0)
        goto done;
    double slip = 0.0;
    if (nres > 0) {
        /* sqrt(dot(residual, residual) / n): summed in joint order (numpy's
           dot may sum in another order: the slip agrees to a few ulp) */
        double ss = 0.0;
        for (npy_intp i = 0; i < nres; i++)
            ss += res[i] * res[i];
        slip = sqrt(ss / (double)nres);
    }
    tw_o = vector_from(tw, 3);
    if (tw_o == NULL)
        goto done;
    res_o = vector_from(res, nres);
    if (res_o == NULL)
        goto done;
    disp_o = new_vector(3, &disp);
    if (disp_o == NULL)
        goto done;
    for (int i = 0; i < 3; i++)
        disp[i] = tw[i] * dt;
    double dist = integrate_into(PyArray_DATA(pose), P, disp, slip * slip, dt,
                                 PyArray_DATA(n_a));
    out = Py_BuildValue("(OOOd(dddddd)dO)", tw_o, res_o, disp_o, slip,
                        P[0], P[1], P[2], P[3], P[4], P[5], dist, copy_o);
done:
    Py_XDECREF(g_a);
    Py_XDECREF(l_a);
    Py_XDECREF(q_a);
    Py_XDECREF(n_a);
    Py_XDECREF(tw_o);
    Py_XDECREF(res_o);
    Py_XDECREF(disp_o);
    Py_XDECREF(copy_o);
    return out;
}

/* Reads entry `i` of the twist window's history: (stamp, positions, twist). */
static int
history_entry(PyObject *entry, npy_intp nq, double *stamp, const double **q, const double **tw)
{
    if (!PyTuple_Check(entry) || PyTuple_GET_SIZE(entry) != 3) {
        PyErr_SetString(PyExc_TypeError, "history: (stamp, positions, twist) tuples");
        return -1;
    }
    *stamp = PyFloat_AsDouble(PyTuple_GET_ITEM(entry, 0));
    if (*stamp == -1.0 && PyErr_Occurred())
        return -1;
    PyObject *qo = PyTuple_GET_ITEM(entry, 1), *to = PyTuple_GET_ITEM(entry, 2);
    if (!PyArray_Check(qo) || !PyArray_Check(to)
            || PyArray_TYPE((PyArrayObject *)qo) != NPY_DOUBLE
            || PyArray_TYPE((PyArrayObject *)to) != NPY_DOUBLE
            || !PyArray_ISCARRAY_RO((PyArrayObject *)qo) || !PyArray_ISCARRAY_RO((PyArrayObject *)to)
            || PyArray_SIZE((PyArrayObject *)qo) != nq || PyArray_SIZE((PyArrayObject *)to) != 3) {
        PyErr_SetString(PyExc_TypeError, "history: float64 positions and twist arrays");
        return -1;
    }
    *q = PyArray_DATA((PyArrayObject *)qo);
    *tw = PyArray_DATA((PyArrayObject *)to);
    return 0;
}

/* twist_update(kind, geometry, history, stamp, positions, disp, dt, terms,
   rho2, lag) -> (twist, twist_variance)

   Mirrors Odometry._update_twist after the window's old readings were
   dropped: `history` holds the readings in the window before this one
   (stamp [s], positions [rad], twist); with one, the twist is disp / dt,
   else the least-squares line through the readings' positions over their
   stamps gives the mean rates, mapped through the estimate at the mean
   configuration. terms = (twist_variance[3], twist_slip_gain[3],
   twist_lag_gain[3]); rho2 [(m/s)^2] the squared slip; lag [s]. numpy
   sums the means and the line fit in its own order (pairwise, BLAS): the
   windowed twist agrees with the pure path to a few ulp, the two-reading
   twist bitwise. */
static PyObject *
twist_update(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (check_nargs(nargs, 10, "twist_update") < 0)
        return NULL;
    long kind;
    if (arg_kind(args[0], &kind) < 0)
        return NULL;
    double stamp;
    if (arg_double(args[3], &stamp) < 0)
        return NULL;
    double dt;
    if (arg_double(args[6], &dt) < 0)
        return NULL;
    double rho2;
    if (arg_double(args[8], &rho2) < 0)
        return NULL;
    double lag;
    if (arg_double(args[9], &lag) < 0)
        return NULL;
    PyArrayObject *g_a = NULL, *q_a = NULL, *d_a = NULL, *t_a = NULL;
    PyObject *seq = NULL, *out = NULL, *tw_o = NULL;
    double qm[2 * MAX_CASTERS], rates[2 * MAX_CASTERS], res[MAX_CASTERS];
    double scratch[4 * MAX_CASTERS], *twist;
    g_a = as_vector(args[1], "geometry");
    if (g_a == NULL)
        goto done;
    q_a = as_vector(args[4], "positions");
    if (q_a == NULL)
        goto done;
    d_a = as_vector(args[5], "disp");
    if (d_a == NULL || need_length(d_a, 3, "disp") < 0)
        goto done;
    t_a = as_vector(args[7], "terms");
    if (t_a == NULL || need_length(t_a, 9, "terms") < 0)
        goto done;
    seq = PySequence_Fast(args[2], "history: a sequence");
    if (seq == NULL)
        goto done;
    npy_intp m = PySequence_Fast_GET_SIZE(seq), nq = PyArray_DIM(q_a, 0);
    if (m < 1 || nq > 2 * MAX_CASTERS) {
        PyErr_SetString(PyExc_ValueError, "history: at least one reading; at most 128 joints");
        goto done;
    }
    double t0;
    const double *q0, *twist0;
    if (history_entry(PySequence_Fast_GET_ITEM(seq, 0), nq, &t0, &q0, &twist0) < 0)
        goto done;
    tw_o = new_vector(3, &twist);
    if (tw_o == NULL)
        goto done;
    const double *disp = PyArray_DATA(d_a), *positions = PyArray_DATA(q_a);
    if (m == 1) {
        for (int i = 0; i < 3; i++)
            twist[i] = disp[i] / dt;         /* the line through two readings */
    } else {
        /* t = stamps + [stamp]; tc = t - mean(t); qm = mean of the rows;
           rates = tc @ (q - qm) / (tc @ tc) */
        npy_intp rows = m + 1;
        double tsum = 0.0, tmean, tt = 0.0, ts;
        const double *qi, *twi;
        for (npy_intp k = 0; k < m; k++) {
            if (history_entry(PySequence_Fast_GET_ITEM(seq, k), nq, &ts, &qi, &twi) < 0)
                goto done;
            tsum += ts;
        }
        tsum += stamp;
        tmean = tsum / (double)rows;
        for (npy_intp j = 0; j < nq; j++) {
            qm[j] = 0.0;
            rates[j] = 0.0;
        }
        for (npy_intp k = 0; k < rows; k++) {
            if (k < m)
                history_entry(PySequence_Fast_GET_ITEM(seq, k), nq, &ts, &qi, &twi);
            else
                qi = positions;
            for (npy_intp j = 0; j < nq; j++)
                qm[j] += qi[j];
        }
        for (npy_intp j = 0; j < nq; j++)
            qm[j] /= (double)rows;
        for (npy_intp k = 0; k < rows; k++) {
            if (k < m) {
                history_entry(PySequence_Fast_GET_ITEM(seq, k), nq, &ts, &qi, &twi);
            } else {
                ts = stamp;
                qi = positions;
            }
            double tc = ts - tmean;
            tt += tc * tc;
            for (npy_intp j = 0; j < nq; j++)
                rates[j] += tc * (qi[j] - qm[j]);
        }
        for (npy_intp j = 0; j < nq; j++)
            rates[j] /= tt;
        if (estimate_into(kind, qm, nq, rates, PyArray_DATA(g_a), PyArray_DIM(g_a, 0),
                          twist, res, scratch) < 0)
            goto done;
    }
    /* acceleration over the window, for the lag term of the covariance */
    const double *terms = PyArray_DATA(t_a);
    double var[3];
    for (int i = 0; i < 3; i++) {
        double a = (twist[i] - twist0[i]) / (stamp - t0);
        var[i] = terms[i] + terms[3 + i] * rho2 + terms[6 + i] * pow(a * lag, 2.0);
    }
    out = Py_BuildValue("(O(ddd))", tw_o, var[0], var[1], var[2]);
done:
    Py_XDECREF(g_a);
    Py_XDECREF(q_a);
    Py_XDECREF(d_a);
    Py_XDECREF(t_a);
    Py_XDECREF(seq);
    Py_XDECREF(tw_o);
    return out;
}

/* reading_plausible(positions, velocities, bound, last, span) -> bool

   True when ReadingMonitor.check's per-joint tests all pass: every position
   and velocity finite, |velocity| <= bound [rad/s], and, with a reference
   reading `last` (a sequence of floats, or None), every |position - last|
   <= bound x span + 1e-6 [rad]. False sends the caller to the pure-Python
   loops, which find the same first failure and word its message. */
static PyObject *
reading_plausible(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (check_nargs(nargs, 5, "reading_plausible") < 0)
        return NULL;
    double span;
    if (arg_double(args[4], &span) < 0)
        return NULL;
    PyArrayObject *q_a = as_vector(args[0], "positions"), *v_a = NULL, *b_a = NULL;
    PyObject *last = NULL, *out = NULL;
    if (q_a == NULL)
        return NULL;
    npy_intp n = PyArray_DIM(q_a, 0);
    v_a = as_vector(args[1], "velocities");
    if (v_a == NULL || need_length(v_a, n, "velocities") < 0)
        goto done;
    b_a = as_vector(args[2], "bound");
    if (b_a == NULL || need_length(b_a, n, "bound") < 0)
        goto done;
    const double *q = PyArray_DATA(q_a), *v = PyArray_DATA(v_a), *bound = PyArray_DATA(b_a);
    int ok = 1;
    for (npy_intp i = 0; i < n && ok; i++)
        ok = isfinite(q[i]) && isfinite(v[i]) && !(fabs(v[i]) > bound[i]);
    if (ok && args[3] != Py_None) {
        last = PySequence_Fast(args[3], "last: a sequence of floats");
        if (last == NULL)
            goto done;
        if (PySequence_Fast_GET_SIZE(last) != n) {
            PyErr_SetString(PyExc_ValueError, "last: one position per joint");
            goto done;
        }
        for (npy_intp i = 0; i < n && ok; i++) {
            double ref = PyFloat_AsDouble(PySequence_Fast_GET_ITEM(last, i));
            if (ref == -1.0 && PyErr_Occurred())
                goto done;
            ok = !(fabs(q[i] - ref) > bound[i] * span + 1e-6);
        }
    }
    out = PyBool_FromLong(ok);
done:
    Py_DECREF(q_a);
    Py_XDECREF(v_a);
    Py_XDECREF(b_a);
    Py_XDECREF(last);
    return out;
}

/* ---- PCV operational-space dynamics (pcv_base.dynamics) ---- */

/* One body's rows J (nrows x 3) and dJ/dphi of caster geometry g = (sx, sy,
   b, r, h, cos beta, sin beta) at c = cos phi, s = sin phi, for a point
   `arm` behind the steering axis; `wheel` adds the rolling row. Mirrors
   PcvDynamics._caster_rows (steer, roll, d_steer, d_roll and point(arm)). */
static void
pcv_body_rows(const double *g, double c, double s, double arm, int wheel,
              double J[4][3], double dJ[4][3])
{
    double sx = g[0], sy = g[1], b = g[2], r = g[3], h = g[4], cb = g[5], sb = g[6];
    double s0 = -s / b, s1 = c / b, s2 = h * (cb * c + sb * s) / b - 1.0;
    double d0 = -c / b, d1 = -s / b, d2 = h * (sb * c - cb * s) / b;
    double px = sx - arm * c, py = sy - arm * s;
    double ac = arm * c, as_ = arm * s;
    J[0][0] = 1.0 + as_ * s0;  J[0][1] = as_ * s1;        J[0][2] = -py + as_ * s2;
    J[1][0] = -ac * s0;        J[1][1] = 1.0 - ac * s1;   J[1][2] = px - ac * s2;
    dJ[0][0] = ac * s0 + as_ * d0;  dJ[0][1] = ac * s1 + as_ * d1;
    dJ[0][2] = ac + ac * s2 + as_ * d2;
    dJ[1][0] = as_ * s0 - ac * d0;  dJ[1][1] = as_ * s1 - ac * d1;
    dJ[1][2] = as_ + as_ * s2 - ac * d2;
    J[2][0] = s0;  J[2][1] = s1;  J[2][2] = 1.0 + s2;          /* yaw: wz + phi_dot */
    dJ[2][0] = d0; dJ[2][1] = d1; dJ[2][2] = d2;
    if (wheel) {
        J[3][0] = c / r;  J[3][1] = s / r;  J[3][2] = h * (cb * s - sb * c) / r;
        dJ[3][0] = -s / r; dJ[3][1] = c / r; dJ[3][2] = h * (cb * c + sb * s) / r;
    }
}

/* pcv_terms(positions, twist, geometry, masses) -> (Lambda (3, 3), mu (3,)).
   positions: the joints (steering angles at the even indices); twist: None
   (mu = 0) or (vx, vy, wz); geometry: (sx, sy, b, r, h, cos beta, sin beta)
   per caster; masses: (chassis m, chassis I, fork m, m, I, wheel m, m,
   I_yaw, I_spin). Mirrors PcvDynamics.terms, sums in the same order. */
static PyObject *
pcv_terms(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (check_nargs(nargs, 4, "pcv_terms") < 0)
        return NULL;
    PyArrayObject *q_a = as_vector(args[0], "positions"), *t_a = NULL, *g_a = NULL,
                  *m_a = NULL;
    PyObject *out = NULL, *lam = NULL, *mu = NULL;
    if (q_a == NULL)
        return NULL;
    int moving = args[1] != Py_None;
    if (moving) {
        t_a = as_vector(args[1], "twist");
        if (t_a == NULL)
            goto done;
        if (PyArray_DIM(t_a, 0) != 3) {           /* as unpacking (vx, vy, wz) */
            PyErr_SetString(PyExc_ValueError, "twist: exactly 3 values (vx, vy, wz)");
            goto done;
        }
    }
    g_a = as_vector(args[2], "geometry");
    if (g_a == NULL)
        goto done;
    m_a = as_vector(args[3], "masses");
    if (m_a == NULL || need_length(m_a, 9, "masses") < 0)
        goto done;
    npy_intp n = (PyArray_DIM(q_a, 0) + 1) / 2;        /* positions[0::2] */
    if (n > PyArray_DIM(g_a, 0) / 7) {
        /* as the Python path: a caster beyond the geometry's */
        PyErr_SetString(PyExc_IndexError, "tuple index out of range");
        goto done;
    }
    const double *q = PyArray_DATA(q_a), *geo = PyArray_DATA(g_a), *m = PyArray_DATA(m_a);
    double m_c = m[0], i_c = m[1];
    double l00 = m_c, l01 = 0.0, l02 = 0.0, l11 = m_c, l12 = 0.0, l22 = i_c;
    double mu0 = 0.0, mu1 = 0.0, mu2 = 0.0, vx = 0.0, vy = 0.0, wz = 0.0;
    if (moving) {
        const double *tw = PyArray_DATA(t_a);
        vx = tw[0]; vy = tw[1]; wz = tw[2];
        mu0 = m_c * (-wz * vy);
        mu1 = m_c * (wz * vx);
    }
    for (npy_intp i = 0; i < n; i++) {
        double phi = q[2 * i], c = cos(phi), s = sin(phi), b = geo[7 * i + 2];
        for (int wheel = 0; wheel < 2; wheel++) {
            double J[4][3], dJ[4][3], accel[4] = {0.0, 0.0, 0.0, 0.0};
            int rows = wheel ? 4 : 3;
            const double *masses = wheel ? m + 5 : m + 2;
            pcv_body_rows(geo + 7 * i, c, s, wheel ? b : 0.5 * b, wheel, J, dJ);
            if (moving) {
                double v[4];
                for (int k = 0; k < rows; k++)
                    v[k] = J[k][0] * vx + J[k][1] * vy + J[k][2] * wz;
                double phi_dot = v[2] - wz;
                for (int k = 0; k < rows; k++)
                    accel[k] = phi_dot * (dJ[k][0] * vx + dJ[k][1] * vy + dJ[k][2] * wz);
                accel[0] -= wz * v[1];
                accel[1] += wz * v[0];
            }
            for (int k = 0; k < rows; k++) {
                double w0 = masses[k] * J[k][0], w1 = masses[k] * J[k][1],
                       w2 = masses[k] * J[k][2];
                l00 += w0 * J[k][0];
                l01 += w0 * J[k][1];
                l02 += w0 * J[k][2];
                l11 += w1 * J[k][1];
                l12 += w1 * J[k][2];
                l22 += w2 * J[k][2];
                mu0 += w0 * accel[k];
                mu1 += w1 * accel[k];
                mu2 += w2 * accel[k];
            }
        }
    }
    npy_intp dims[2] = {3, 3};
    lam = PyArray_SimpleNew(2, dims, NPY_DOUBLE);
    double *o;
    mu = new_vector(3, &o);
    if (lam == NULL || mu == NULL)
        goto done;
    o[0] = mu0; o[1] = mu1; o[2] = mu2;
    double *L = PyArray_DATA((PyArrayObject *)lam);
    L[0] = l00; L[1] = l01; L[2] = l02;
    L[3] = l01; L[4] = l11; L[5] = l12;
    L[6] = l02; L[7] = l12; L[8] = l22;
    out = PyTuple_Pack(2, lam, mu);
done:
    Py_XDECREF(lam);
    Py_XDECREF(mu);
    Py_DECREF(q_a);
    Py_XDECREF(t_a);
    Py_XDECREF(g_a);
    Py_XDECREF(m_a);
    return out;
}

static PyMethodDef methods[] = {
    {"limit_twist", (PyCFunction)(void (*)(void))limit_twist, METH_FASTCALL,
     "limit_twist(target, previous, dt, limits, acceleration) -> twist: TwistLimiter.limit."},
    {"saturate_joint_rates", (PyCFunction)(void (*)(void))saturate_joint_rates, METH_FASTCALL,
     "saturate_joint_rates(rates, max_rates) -> (rates, scale)."},
    {"inverse", (PyCFunction)(void (*)(void))inverse, METH_FASTCALL,
     "inverse(kind, positions, twist, geometry) -> joint rates [rad/s]."},
    {"estimate", (PyCFunction)(void (*)(void))estimate, METH_FASTCALL,
     "estimate(kind, positions, velocities, geometry) -> (twist, residual)."},
    {"odometry_step", (PyCFunction)(void (*)(void))odometry_step, METH_FASTCALL,
     "odometry_step(kind, geometry, last, positions, dt, pose, covariance, noise) -> "
     "(rate_twist, residual, disp, slip, covariance, distance, positions) or None."},
    {"twist_update", (PyCFunction)(void (*)(void))twist_update, METH_FASTCALL,
     "twist_update(kind, geometry, history, stamp, positions, disp, dt, terms, rho2, lag) -> "
     "(twist, twist_variance)."},
    {"reading_plausible", (PyCFunction)(void (*)(void))reading_plausible, METH_FASTCALL,
     "reading_plausible(positions, velocities, bound, last, span) -> bool."},
    {"pcv_terms", (PyCFunction)(void (*)(void))pcv_terms, METH_FASTCALL,
     "pcv_terms(positions, twist, geometry, masses) -> (Lambda, mu): PcvDynamics.terms."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_hot_path",
    "The control cycle's closed forms, compiled (see holonomic_core.hot_path).", -1, methods,
};

PyMODINIT_FUNC
PyInit__hot_path(void)
{
    import_array();
    PyObject *m = PyModule_Create(&module);
    if (m == NULL)
        return NULL;
    if (PyModule_AddIntConstant(m, "KIND_DDROT", KIND_DDROT) < 0
            || PyModule_AddIntConstant(m, "KIND_PCV", KIND_PCV) < 0) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
