"""Calibration of the odometry covariance against ground truth.

The one fit that both tools run: the simulator's
``holonomic-odometry-experiment --calibrate`` and, on a real floor,
``holonomic-odometry-calibrate`` (a robot's recording with a reference of
the true pose); ROS-free and simulator-free. It takes recordings
(:class:`Recording`: joint readings and the true pose and twist at the same
instants), replays
each recording through :class:`holonomic_core.odometry.Odometry`, and fits
the coefficients of :class:`OdometryNoise` so that the published covariance
matches the errors it claims:

* the covariance is linear in the coefficients (every increment adds ``Q``
  linear in them and the propagation ``F P F^T`` does not depend on them), so
  one replay per coefficient, with that coefficient 1 and the others 0, gives
  its basis ``B_k(t)``, and ``P(t) = sum_k c_k B_k(t)`` for any coefficients;
* the heading coefficients are fitted first (the heading variance depends on
  them alone), then the position ones, each by maximum likelihood of a
  Gaussian error (coefficients >= 0, a multiplicative fixed-point
  iteration), then scaled so that 95 % of the sampled errors fall inside
  the 95 % region -- the errors are partly systematic (a bias that grows
  with distance), not the random walk the model assumes, so the likelihood
  alone does not give the coverage; over several floors (slip conditions)
  the mix of the terms is searched so that every floor comes as close to
  95 % as one set allows (the slip residual can tell floors apart, a
  single scale cannot);
* the twist coefficients by likelihood too, per axis, from the published
  twist's error, scaled so that the worst floor is covered 95 % (its error
  is mostly the filter's lag, alike on every floor);
* one profile per floor (``--profiles``), with its coverage held out (leave
  one run out), because the coefficients belong to the floor as much as to
  the robot.

Samples: every 0.1 s of each run after its first second. The coverage is
reported per slip condition and pooled: the fraction of samples whose true
position lies in the published 95 % ellipse (Mahalanobis distance^2 <=
5.991, chi^2 with 2 degrees of freedom), whose true heading lies within
1.96 sigma, and whose true twist component lies within 1.96 sigma.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, replace

import numpy as np

from holonomic_core.odometry import Odometry, OdometryNoise
from holonomic_core.se2 import wrap_angle


@dataclass
class Recording:
    """One run: every joint reading and the true state at the same instants.

    What the fit reads, from the simulator (``holonomic-odometry-experiment``)
    or from a robot's recording with a reference of the true pose
    (``holonomic-odometry-calibrate``). ``robot``, ``condition`` and
    ``seed`` name the run. ``stamps`` (N,) [s]; ``positions`` (N, joints) [rad]; ``truth`` (N, 3)
    true pose (x, y, yaw) in odom [m, m, rad]; ``truth_twist`` (N, 3) true
    body twist in base_link [m/s, m/s, rad/s]; ``config`` the robot config
    the controller ran (with a calibration overlay, if any); ``internal_force``
    (N,) [N] the magnitude of the wheels' internal force (the simulator's;
    empty from a recording); ``fault`` the controller's fault if it stopped
    the run; ``hidden_truth`` the simulator's hidden geometry (empty from a
    recording); ``motion`` how the base was driven (the experiment's kind of
    motion: random, teleop, sweep, nav2, straight, spin, creep).
    """

    robot: str
    condition: str
    seed: int
    config: object
    stamps: np.ndarray
    positions: np.ndarray
    truth: np.ndarray
    truth_twist: np.ndarray
    seconds: float = 0.0
    internal_force: np.ndarray = field(default_factory=lambda: np.zeros(0))
    fault: str | None = None
    hidden_truth: dict = field(default_factory=dict)
    motion: str = "random"

#: pose coefficients (OdometryNoise fields), heading-only ones first
HEADING_KEYS = ("angular_variance_per_radian", "angular_variance_per_meter",
                "slip_heading_gain", "slip4_heading_gain", "latency_variance")
POSITION_KEYS = ("linear_variance_per_meter", "slip_position_gain", "slip4_position_gain")
CHI2_2_95 = 5.991            # 95 % quantile of chi^2 with 2 degrees of freedom
Z_95 = 1.96
#: coverage the scale step gives the worst floor (the target band is 90-99.5 %)
TARGET_COVERAGE = 0.95
SAMPLE_PERIOD = 0.1          # [s]
#: smallest calibrated twist variance [(m/s)^2, (rad/s)^2]
TWIST_VARIANCE_FLOOR = 1e-9
WARM_UP = 1.0                # [s] before the first sample


def _zero_noise(**values) -> OdometryNoise:
    base = OdometryNoise(0.0, 0.0, 0.0, 0.0, 0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                         (0.0, 0.0, 0.0), 0.0, 0.0, 0.0)
    return replace(base, **values)


def replay(rec, noise: OdometryNoise) -> dict:
    """Odometry over a recording with ``noise``; the samples (dict of arrays)."""
    cfg = rec.config.controller
    odo = Odometry(rec.config.model, cfg.estimator, noise, cfg.twist_window)
    t0 = rec.stamps[0]
    next_sample = t0 + WARM_UP
    out = {"index": [], "pose": [], "cov": [], "twist": [], "twist_var": []}
    for k, (stamp, positions) in enumerate(zip(rec.stamps.tolist(), rec.positions)):
        odo.update(positions, stamp)
        if stamp >= next_sample - 1e-9:
            next_sample += SAMPLE_PERIOD
            out["index"].append(k)
            out["pose"].append(odo.pose.copy())
            out["cov"].append(odo.pose_covariance)
            out["twist"].append(odo.twist.copy())
            out["twist_var"].append(np.diag(odo.twist_covariance).copy())
    return {key: np.array(v) for key, v in out.items()}


class Samples:
    """Errors and covariance bases of one or more recordings, pooled.
    ``bar`` (holonomic_core.progress): advanced once per recording replayed
    (the replays are most of the time a calibration of many recordings takes)."""

    def __init__(self, recordings=(), bar=None):
        parts = [self._one(rec) for rec in (recordings if bar is None else bar.over(recordings))]
        self._pool(parts)

    @staticmethod
    def _one(rec) -> dict:
        bases = {}
        for key in HEADING_KEYS + POSITION_KEYS:
            bases[key] = replay(rec, _zero_noise(**{key: 1.0}))
        slip = replay(rec, _zero_noise(twist_slip_gain=(1.0, 1.0, 1.0)))
        lag = replay(rec, _zero_noise(twist_lag_gain=(1.0, 1.0, 1.0)))
        first = bases[HEADING_KEYS[0]]
        idx = first["index"]
        err = first["pose"] - rec.truth[idx]
        err[:, 2] = [wrap_angle(v) for v in err[:, 2]]
        motion = getattr(rec, "motion", "random")
        return {"condition": np.array([rec.condition] * len(idx)),
                "motion": np.array([motion] * len(idx)),
                "group": np.array([group_label(rec.condition, motion)] * len(idx)),
                "run": np.array([f"{group_label(rec.condition, motion)} seed {rec.seed}"]
                                * len(idx)), "error": err,
                "twist_error": first["twist"] - rec.truth_twist[idx],
                "bases": {k: b["cov"] for k, b in bases.items()},
                "slip_basis": slip["twist_var"], "lag_basis": lag["twist_var"]}

    def _pool(self, parts: list) -> None:
        self._parts = parts
        self.condition = np.concatenate([p["condition"] for p in parts])
        self.motion = np.concatenate([p["motion"] for p in parts])
        #: condition, and the kind of motion when it is not random: what
        #: the fit balances and the tables list
        self.group = np.concatenate([p["group"] for p in parts])
        self.run = np.concatenate([p["run"] for p in parts])
        self.error = np.concatenate([p["error"] for p in parts])
        self.twist_error = np.concatenate([p["twist_error"] for p in parts])
        self.bases = {k: np.concatenate([p["bases"][k] for p in parts])
                      for k in HEADING_KEYS + POSITION_KEYS}
        self.slip_basis = np.concatenate([p["slip_basis"] for p in parts])
        self.lag_basis = np.concatenate([p["lag_basis"] for p in parts])

    def subset(self, conditions=None, runs=None, motions=None) -> "Samples":
        """The samples of the runs in ``conditions`` (and in ``runs``, labels
        of :attr:`run`, and of the kinds of motion in ``motions``) only;
        ``None``: no selection by that key."""
        out = Samples.__new__(Samples)
        out._pool([p for p in self._parts
                   if (conditions is None or p["condition"][0] in conditions)
                   and (runs is None or p["run"][0] in runs)
                   and (motions is None or p["motion"][0] in motions)])
        return out

    @property
    def runs(self) -> list:
        """Labels of the pooled runs ("condition seed N"), in order."""
        return [p["run"][0] for p in self._parts]

    def pose_covariance(self, noise: OdometryNoise) -> np.ndarray:
        """(K, 3, 3) published pose covariance at the samples under ``noise``."""
        return sum(getattr(noise, k) * self.bases[k] for k in HEADING_KEYS + POSITION_KEYS)

    def twist_variance(self, noise: OdometryNoise) -> np.ndarray:
        """(K, 3) published twist variances at the samples under ``noise``."""
        return (np.asarray(noise.twist_variance) + np.asarray(noise.twist_slip_gain)
                * self.slip_basis + noise.twist_lag_gain * self.lag_basis)

    def coverage(self, noise: OdometryNoise, mask=None) -> dict:
        """Fractions of samples inside the 95 % regions (position, heading, twist axes)."""
        mask = np.ones(len(self.error), bool) if mask is None else mask
        P = self.pose_covariance(noise)[mask]
        e = self.error[mask]
        d2 = mahalanobis2(e[:, :2], P[:, :2, :2])
        hdg = np.abs(e[:, 2]) <= Z_95 * np.sqrt(P[:, 2, 2])
        tv = self.twist_variance(noise)[mask]
        tw = np.abs(self.twist_error[mask]) <= Z_95 * np.sqrt(tv)
        return {"position": float(np.mean(d2 <= CHI2_2_95)), "heading": float(np.mean(hdg)),
                "vx": float(np.mean(tw[:, 0])), "vy": float(np.mean(tw[:, 1])),
                "wz": float(np.mean(tw[:, 2])), "samples": int(mask.sum())}


def group_label(condition: str, motion: str) -> str:
    """A run's group: its condition (floor), and its kind of motion unless
    that is the experiment's random motion."""
    return condition if motion == "random" else f"{condition} / {motion}"


def mahalanobis2(e: np.ndarray, P: np.ndarray) -> np.ndarray:
    """e^T P^-1 e for (K, 2) errors and (K, 2, 2) covariances (2x2 inverse by hand)."""
    a, b, d = P[:, 0, 0], P[:, 0, 1], P[:, 1, 1]
    det = np.maximum(a * d - b * b, 1e-30)
    x, y = e[:, 0], e[:, 1]
    return (d * x * x - 2.0 * b * x * y + a * y * y) / det


def _fit_variances(bases: np.ndarray, err2: np.ndarray, iterations: int = 300,
                   fixed=0.0) -> np.ndarray:
    """Maximum-likelihood c >= 0 of var_t = fixed_t + bases[t] @ c for
    zero-mean errors with squared values ``err2`` (T,), bases (T, m) >= 0,
    ``fixed`` (T,) >= 0 or a scalar.

    Multiplicative fixed point of the likelihood's stationarity condition
    ``sum B_k / v = sum e^2 B_k / v^2`` (both sides positive, so c stays
    >= 0; a coefficient whose basis never helps decays towards 0). Starts
    with every basis explaining an equal share of the mean squared error.
    """
    m = bases.shape[1]
    scale = np.maximum(bases.mean(axis=0), 1e-300)
    c = np.full(m, err2.mean() / m) / scale
    for _ in range(iterations):
        v = np.maximum(fixed + bases @ c, 1e-300)
        c = c * ((bases * (err2 / v ** 2)[:, None]).sum(axis=0)
                 / np.maximum((bases / v[:, None]).sum(axis=0), 1e-300))
    return c


def _fit_covariances(fixed: np.ndarray, bases: list, e: np.ndarray,
                     iterations: int = 300) -> np.ndarray:
    """The same for 2 x 2 covariances ``fixed + sum_k c_k bases[k]`` and
    errors e (T, 2): ``c_k *= sum e^T P^-1 B_k P^-1 e / sum tr(P^-1 B_k)``."""
    m = len(bases)
    scale = np.array([max(float(np.mean(b[:, 0, 0] + b[:, 1, 1])), 1e-300) for b in bases])
    c = np.full(m, float(np.mean(np.sum(e * e, axis=1))) / m) / scale
    for _ in range(iterations):
        P = fixed + sum(ci * b for ci, b in zip(c, bases))
        a, b_, d = P[:, 0, 0], P[:, 0, 1], P[:, 1, 1]
        det = np.maximum(a * d - b_ * b_, 1e-300)
        inv = np.stack([np.stack([d, -b_], -1), np.stack([-b_, a], -1)], -2) / det[:, None, None]
        w = np.einsum("tij,tj->ti", inv, e)          # P^-1 e
        num = np.array([np.sum(np.einsum("ti,tij,tj->t", w, B, w)) for B in bases])
        den = np.array([np.sum(np.einsum("tij,tji->t", inv, B)) for B in bases])
        c = c * num / np.maximum(den, 1e-300)
    return c


def _scale_to_coverage(inside, groups) -> float:
    """Smallest scale s (bisection in log space) at which every group's
    fraction of samples inside the 95 % region reaches TARGET_COVERAGE.

    ``inside(s)`` -> boolean array over the samples; ``groups``: the label of
    each sample (a slip condition = a floor). The worst floor decides: an
    odometry that claims 95 % must not be over-confident on any floor it was
    calibrated on, at the price of being a little pessimistic on the others.
    """
    labels = list(dict.fromkeys(groups.tolist()))
    masks = [groups == g for g in labels]

    def worst(scale):
        hit = inside(scale)
        return min(float(np.mean(hit[m])) for m in masks)

    lo, hi = 1e-6, 1e6
    for _ in range(80):
        mid = math.sqrt(lo * hi)
        if worst(mid) < TARGET_COVERAGE:
            lo = mid
        else:
            hi = mid
    return hi


def _band_loss(fractions: np.ndarray) -> float:
    """How far per-floor coverages are from 95 %: squared, 4x heavier below
    95 % (over-confidence misleads a fusion filter; over-coverage only costs
    it weight), and 100x heavier outside the band (below 90 %, above
    99.5 %: a floor covered 100 % is as much out of the band as one at
    85 %, it only errs on the safe side)."""
    d = fractions - TARGET_COVERAGE
    return float(np.sum(np.where(d < 0.0, 4.0, 1.0) * d * d)
                 + 100.0 * np.sum(np.maximum(BAND[0] - fractions, 0.0) ** 2)
                 + 100.0 * np.sum(np.maximum(fractions - BAND[1], 0.0) ** 2))


def _coverage_search(inside, c0: np.ndarray, natural: np.ndarray, groups) -> np.ndarray:
    """Coefficients c >= 0 that bring every group's (floor's) coverage
    closest to 95 % (:func:`_band_loss`), searched on a grid.

    Why not the likelihood plus one scale: with floors whose errors differ
    tenfold, one scale of the likelihood's shape must over-cover the good
    floors to cover the bad one; only the *mix* of terms (distance against
    slip residual) can tell floors apart, so the mix is searched for
    coverage directly. ``inside(c)`` -> boolean array over the samples;
    ``c0``: the likelihood fit, scaled; ``natural``: per coefficient, the
    value at which its basis alone explains the mean squared error (the
    grid's centre for a coefficient the likelihood drove to 0). Grid: 0 and
    4 decades around the centre, as many points per axis as keep the grid
    near :data:`SEARCH_POINTS` (4 coefficients: 2 per decade, 5: 1 per
    decade); then each coefficient, and one common scale, refined by
    factors between 1/4 and 4 until no step improves (at most
    :data:`SEARCH_PASSES` passes).
    """
    labels = list(dict.fromkeys(groups.tolist()))
    masks = [groups == g for g in labels]

    def loss(c):
        hit = inside(c)
        return _band_loss(np.array([np.mean(hit[m]) for m in masks]))

    centre = np.where(c0 > 0.0, c0, natural)
    per_axis = max(int(round(SEARCH_POINTS ** (1.0 / len(c0)))) - 1, 2)
    axes = [np.concatenate(([0.0], ck * np.logspace(-3.0, 1.0, per_axis))) for ck in centre]
    best, best_loss = np.asarray(c0, float), loss(c0)
    for point in np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, len(c0)):
        if not point.any():
            continue
        value = loss(point)
        if value < best_loss:
            best, best_loss = point, value
    factors = np.geomspace(0.25, 4.0, 17)
    for _ in range(SEARCH_PASSES):
        start_loss = best_loss
        for k in range(len(best)):
            for f in factors:
                point = best.copy()
                point[k] *= f
                value = loss(point)
                if value < best_loss - 1e-15:
                    best, best_loss = point, value
        for f in factors:
            value = loss(best * f)
            if value < best_loss - 1e-15:
                best, best_loss = best * f, value
        if best_loss >= start_loss - 1e-15:
            break
    return np.asarray(best, float)


#: about how many points the coverage search's grid has (per axis: its
#: len(c)-th root), and how many refinement passes follow it at most
SEARCH_POINTS = 10_000
SEARCH_PASSES = 6


#: a basis whose mean is below this is rounding, not a term of the robot: a
#: DDROT's slip residual is ~1e-12 m/s (square Jacobian), and a coefficient
#: fitted to it would be ~1e+20 times anything physical
BASIS_FLOOR = 1e-10


def _present(bases: np.ndarray) -> np.ndarray:
    """1.0 for the basis columns the samples can see, 0.0 for absent ones."""
    return (bases.mean(axis=0) > BASIS_FLOOR).astype(float)


def _natural(bases: np.ndarray, err2: np.ndarray) -> np.ndarray:
    """Per basis column, the coefficient that alone explains mean(err2)
    (0 for an absent basis, :data:`BASIS_FLOOR`)."""
    return _present(bases) * err2.mean() / np.maximum(bases.mean(axis=0), 1e-300)


def _held_out_fits(samples: Samples, fit_one) -> np.ndarray | None:
    """Per sample, ``fit_one(mask)`` (a fit on the samples of ``mask``)
    evaluated on the run the sample belongs to, fitted on the *other* runs:
    ``fit_one(train)`` returns a function of the held-out mask. None with
    fewer than :data:`PREDICTIVE_RUNS` runs."""
    runs = samples.runs
    if len(runs) < PREDICTIVE_RUNS:
        return None
    out = None
    for run in runs:
        held = samples.run == run
        values = fit_one(~held)(held)
        if out is None:
            out = np.empty((len(samples.run),) + values.shape[1:])
        out[held] = values
    return out


#: the random-walk terms: per metre travelled and per radian turned
FLOOR_KEYS = ("linear_variance_per_meter", "angular_variance_per_radian",
              "angular_variance_per_meter")
#: the share of the fitted samples' mean squared error each random-walk term
#: explains at least, alone (its floor, the fit's lower bound): see :func:`_floors`
FLOOR_SHARE = 0.1


def _floors(keys, bases: np.ndarray, err2: np.ndarray) -> np.ndarray:
    """Lower bounds of the coefficients ``keys`` (columns of ``bases``):
    for the random-walk terms (:data:`FLOOR_KEYS`), :data:`FLOOR_SHARE` of
    the value at which the term alone explains the samples' mean squared
    error; 0 for the others.

    Why a floor: no odometry is free of random walk -- every metre and every
    radian carry tyre contact, floor texture and encoder counts the model
    does not resolve -- while the slip terms follow the contact residual,
    which smooth driving (a long straight run, a slow creep, a spin with the
    wheels in agreement) keeps near zero. A fit left free puts the whole
    error on the slip terms when the fitting runs' residual tracks it, and
    then publishes almost no uncertainty on motion that shows no residual.
    The floor keeps the covariance growing with the distance and the angle
    on every kind of motion; the slip terms come on top of it.
    """
    natural = _natural(bases, err2)
    return np.array([FLOOR_SHARE * n if k in FLOOR_KEYS else 0.0
                     for k, n in zip(keys, natural)])


#: fewest runs of one floor for the scale to be set on held-out runs
PREDICTIVE_RUNS = 3


def fit(samples: Samples, start: OdometryNoise, predictive: bool = True) -> OdometryNoise:
    """Coefficients of OdometryNoise calibrated on ``samples``.

    One floor (slip condition) in the samples: the likelihood fit, scaled
    so that 95 % of the samples lie in the 95 % region -- with
    ``predictive`` (and at least :data:`PREDICTIVE_RUNS` runs) 95 % of the
    samples of *unseen* runs: the scale is the one at which each run,
    against the likelihood fit of the other runs, is covered 95 % of the
    time (pooled). Scaled on the runs it was fitted to, a profile is
    optimistic on the next run: runs of one floor differ (each seed draws
    its wheels' friction, radii and drives), and a run whose errors are
    larger than the others' falls far below 95 % while a smaller one cannot
    rise above 100 %. Several floors: the pose terms' mix searched so that
    every floor comes closest to 95 % (:func:`_coverage_search`); the twist
    keeps the scaled likelihood fit (its errors are the filter's lag, alike
    on every floor, and nearly independent from sample to sample).
    """
    e = samples.error
    g = samples.group
    several = len(set(g.tolist())) > 1
    predictive = predictive and not several
    # heading: P22 = sum_k c_k B_k22, the random-walk floors (lo) and the
    # fitted terms on top of them
    h_bases = np.stack([samples.bases[k][:, 2, 2] for k in HEADING_KEYS], axis=1)
    e2 = e[:, 2] ** 2
    lo = _floors(HEADING_KEYS, h_bases, e2)
    hfix = h_bases @ lo
    present = _present(h_bases)
    h = _fit_variances(h_bases, e2, fixed=hfix) * present
    hvar = _held_out_fits(samples, lambda train: (
        lambda held, c=_fit_variances(h_bases[train], e2[train], fixed=hfix[train]) * present:
        h_bases[held] @ c)) if predictive else None
    if hvar is None:
        hvar = h_bases @ h
    s = _scale_to_coverage(lambda f: np.abs(e[:, 2]) <= Z_95 * np.sqrt(hfix + f * hvar), g)
    h = h * s
    if several:
        h = _coverage_search(lambda c: np.abs(e[:, 2]) <= Z_95 * np.sqrt(hfix + h_bases @ c),
                             h, _natural(h_bases, e2), g)
    noise = replace(start, **dict(zip(HEADING_KEYS, (lo + h).tolist())))
    # position, with the heading's contribution and the position floor fixed
    p_bases = [samples.bases[k][:, :2, :2] for k in POSITION_KEYS]
    traces = np.stack([b[:, 0, 0] + b[:, 1, 1] for b in p_bases], axis=1)
    lo = _floors(POSITION_KEYS, traces, np.sum(e[:, :2] ** 2, axis=1))
    fixed = (sum(getattr(noise, k) * samples.bases[k] for k in HEADING_KEYS)[:, :2, :2]
             + sum(li * b for li, b in zip(lo, p_bases)))
    present = _present(traces)
    p = _fit_covariances(fixed, p_bases, e[:, :2]) * present

    def position_fit(train):
        c = _fit_covariances(fixed[train], [b[train] for b in p_bases], e[train, :2]) * present
        return lambda held: sum(ci * b[held] for ci, b in zip(c, p_bases))

    pcov = _held_out_fits(samples, position_fit) if predictive else None
    if pcov is None:
        pcov = sum(ci * b for ci, b in zip(p, p_bases))
    s = _scale_to_coverage(lambda f: mahalanobis2(e[:, :2], fixed + f * pcov) <= CHI2_2_95, g)
    p = p * s
    if several:
        p = _coverage_search(lambda c: mahalanobis2(
            e[:, :2], fixed + sum(ci * b for ci, b in zip(c, p_bases))) <= CHI2_2_95, p,
            _natural(traces, np.sum(e[:, :2] ** 2, axis=1)), g)
    p = lo + p
    noise = replace(noise, **dict(zip(POSITION_KEYS, p.tolist())))
    # twist, per axis j: var_j = tv_j + gs_j rho^2 + gl_j L_j^2
    te = samples.twist_error
    coeffs = []
    for j in range(3):
        basis = np.stack([np.ones(len(te)), samples.slip_basis[:, j], samples.lag_basis[:, j]],
                         axis=1)

        c = _fit_variances(basis, te[:, j] ** 2) * _present(basis)
        var = basis @ c
        c = c * _scale_to_coverage(lambda f: np.abs(te[:, j]) <= Z_95 * np.sqrt(f * var), g)
        coeffs.append(c)
    coeffs = np.array(coeffs)
    # a variance of exactly 0 (at rest the encoders are exact) makes a fusion
    # filter's innovation covariance singular: keep a floor
    coeffs[:, 0] = np.maximum(coeffs[:, 0], TWIST_VARIANCE_FLOOR)
    return replace(noise, twist_variance=tuple(coeffs[:, 0].tolist()),
                   twist_slip_gain=tuple(coeffs[:, 1].tolist()),
                   twist_lag_gain=tuple(coeffs[:, 2].tolist()))


#: the coverage band every floor must reach (the 95 % region must hold
#: the truth this often): below it the odometry is over-confident, above it
#: a fusion filter gives the wheels less weight than they deserve
BAND = (0.90, 0.995)
COMPONENTS = ("position", "heading", "vx", "vy", "wz")


def held_out(samples: Samples, start: OdometryNoise) -> dict:
    """Leave-one-run-out coverage of a floor's own calibration.

    Each run is checked against the profile :func:`fit` makes from the other
    runs (of the same floor: pass one floor's samples), which is what a user
    who calibrated on a few recordings of their floor gets on the next drive.
    Returns per component the pooled fraction, its binomial standard error
    over the samples and its standard error over the runs (the samples of a
    run are correlated: the pose error is a random walk, so the spread
    between runs is the honest uncertainty), plus ``samples`` and ``runs``.
    """
    runs = samples.runs
    if len(runs) < 2:
        raise ValueError("held-out coverage needs at least 2 runs of the floor")
    per_run = []
    for run in runs:
        noise = fit(samples.subset(runs=[r for r in runs if r != run]), start)
        per_run.append(samples.subset(runs=[run]).coverage(noise))
    return _pooled(per_run)


def held_out_by_seed(samples: Samples, start: OdometryNoise, fit_floors=None,
                     fit_motions=None) -> dict:
    """Leave-one-seed-out coverage of the all-floor profile, per floor.

    For each seed, :func:`fit` over the runs of the other seeds on every
    floor in ``fit_floors`` (None: every floor) and of the kinds of motion
    in ``fit_motions`` (None: every kind), checked on that seed's run of
    each floor and kind (also of those it was not fitted on). Returns group
    (floor, and kind of motion: :func:`group_label`) -> the dict of
    :func:`held_out`.
    """
    seeds = sorted({r.rsplit(" seed ", 1)[1] for r in samples.runs})
    if len(seeds) < 2:
        raise ValueError("held-out coverage needs at least 2 seeds")
    per_floor: dict = {}
    for seed in seeds:
        noise = fit(samples.subset(fit_floors, runs=[r for r in samples.runs
                                                     if not r.endswith(f" seed {seed}")],
                                   motions=fit_motions), start)
        for run in samples.runs:
            if run.endswith(f" seed {seed}"):
                one = samples.subset(runs=[run])
                per_floor.setdefault(one.group[0], []).append(one.coverage(noise))
    return {floor: _pooled(cs) for floor, cs in per_floor.items()}


def per_group(samples: Samples, noise: OdometryNoise) -> dict:
    """Coverage of one ``noise`` per group (floor and kind of motion), run
    by run and pooled with standard errors over the runs (the dict of
    :func:`held_out`); a group's runs are held out when ``noise`` was not
    fitted on them."""
    out: dict = {}
    for run in samples.runs:
        one = samples.subset(runs=[run])
        out.setdefault(one.group[0], []).append(one.coverage(noise))
    return {group: _pooled(cs) for group, cs in out.items()}


def _pooled(per_run: list) -> dict:
    """Pooled fractions of per-run coverages with their standard errors."""
    n = np.array([c["samples"] for c in per_run], float)
    out = {"samples": int(n.sum()), "runs": len(per_run)}
    for key in COMPONENTS:
        f = np.array([c[key] for c in per_run])
        p = float(np.sum(f * n) / n.sum())
        out[key] = p
        out[key + "_se_samples"] = math.sqrt(max(p * (1.0 - p), 1e-12) / n.sum())
        out[key + "_se_runs"] = (float(np.std(f, ddof=1) / math.sqrt(len(f)))
                                 if len(f) > 1 else float("nan"))
    return out


def random_walk_spread(samples_per_run: int = 400, warm_up: int = 10, runs: int = 4000,
                       seed: int = 0) -> dict:
    """Coverage of a *perfectly calibrated* random walk, run by run.

    A pose error that is a random walk with exactly the published variance
    (sigma^2 ~ t) is inside its 95 % region 95 % of the time on average,
    but one run's fraction is one path's: a path that wanders out stays out
    for a while. Simulated here (``runs`` paths of ``samples_per_run``
    steps, the first ``warm_up`` not counted, like the calibration's
    samples): the standard deviation between runs of the fraction, 1-D
    (heading, a twist axis) and 2-D (position, chi^2 with 2 degrees of
    freedom). It does not shrink with longer runs (a random walk looks the
    same at every time scale); only more runs shrink the standard error of
    the mean, as 1/sqrt(runs). Returns {"heading": sd, "position": sd,
    "heading_mean": mean, "position_mean": mean}.
    """
    rng = np.random.default_rng(seed)
    t = np.arange(1, samples_per_run + 1)[warm_up:]
    one = np.cumsum(rng.standard_normal((runs, samples_per_run)), axis=1)[:, warm_up:]
    two = np.cumsum(rng.standard_normal((runs, samples_per_run, 2)), axis=1)[:, warm_up:]
    heading = np.mean(np.abs(one) <= Z_95 * np.sqrt(t), axis=1)
    position = np.mean(np.sum(two * two, axis=2) / t <= CHI2_2_95, axis=1)
    return {"heading": float(np.std(heading)), "position": float(np.std(position)),
            "heading_mean": float(np.mean(heading)), "position_mean": float(np.mean(position))}


def band_table(rows: list) -> str:
    """Coverage with its uncertainty, one row per (label, held_out() dict):
    percent, +- the standard error over the runs; '!' marks a fraction
    outside the 90-99.5 % band."""
    head = (f"{'floor':43s} {'runs':>4s} {'samples':>7s} {'binom':>5s}  "
            + "  ".join(f"{k:>11s}" for k in COMPONENTS))
    lines = [head, "-" * len(head)]
    for label, c in rows:
        cells = []
        for key in COMPONENTS:
            p = c[key]
            flag = " " if BAND[0] <= p <= BAND[1] else "!"
            cells.append(f"{100 * p:5.1f}\u00b1{100 * c[key + '_se_runs']:4.1f}{flag}")
        lines.append((f"{label:43s} {c['runs']:4d} {c['samples']:7d} "
                      f"{100 * c['position_se_samples']:4.1f}%  " + "  ".join(cells)).rstrip())
    return "\n".join(lines)


def coverage_table(samples: Samples, noise: OdometryNoise) -> str:
    """Coverage per condition and pooled (percent)."""
    head = (f"{'condition':43s} {'samples':>7s} {'position':>8s} {'heading':>8s} "
            f"{'vx':>6s} {'vy':>6s} {'wz':>6s}")
    lines = [head, "-" * len(head)]
    groups = list(dict.fromkeys(samples.group.tolist())) + ["all"]
    for group in groups:
        mask = None if group == "all" else samples.group == group
        c = samples.coverage(noise, mask)
        lines.append(f"{group:43s} {c['samples']:7d} {100 * c['position']:7.1f}% "
                     f"{100 * c['heading']:7.1f}% {100 * c['vx']:5.1f}% {100 * c['vy']:5.1f}% "
                     f"{100 * c['wz']:5.1f}%")
    return "\n".join(lines)


def noise_yaml(noise: OdometryNoise, twist_window: float) -> str:
    """The ``odometry:`` block of a config file for ``noise``."""
    def g(v):
        # coefficients the fit drove to nothing print as 0
        if abs(v) < 1e-15:
            return "0.0"
        text = f"{v:.3g}"
        # YAML 1.1 (PyYAML, rcl) reads 1e-09 as a string: a float needs a dot
        if "." not in text:
            mantissa, _, exponent = text.partition("e")
            text = f"{mantissa}.0" + (f"e{exponent}" if exponent else "")
        return text
    return "\n".join([
        "    odometry:",
        f"      twist_window: {g(twist_window)}",
        f"      linear_variance_per_meter: {g(noise.linear_variance_per_meter)}",
        f"      angular_variance_per_radian: {g(noise.angular_variance_per_radian)}",
        f"      angular_variance_per_meter: {g(noise.angular_variance_per_meter)}",
        f"      slip_position_gain: {g(noise.slip_position_gain)}",
        f"      slip_heading_gain: {g(noise.slip_heading_gain)}",
        f"      slip4_position_gain: {g(noise.slip4_position_gain)}",
        f"      slip4_heading_gain: {g(noise.slip4_heading_gain)}",
        f"      twist_variance: [{', '.join(g(v) for v in noise.twist_variance)}]",
        f"      twist_slip_gain: [{', '.join(g(v) for v in noise.twist_slip_gain)}]",
        f"      twist_lag_gain: [{', '.join(g(v) for v in noise.twist_lag_gain)}]",
        f"      latency_variance: {g(noise.latency_variance)}",
    ])


def _published(samples: Samples, noise) -> tuple[np.ndarray, np.ndarray]:
    """Pose covariances (K, 3, 3) and twist variances (K, 3) at the samples,
    under one OdometryNoise or a dict condition -> OdometryNoise."""
    if isinstance(noise, OdometryNoise):
        return samples.pose_covariance(noise), samples.twist_variance(noise)
    P = np.zeros((len(samples.error), 3, 3))
    tv = np.zeros((len(samples.error), 3))
    for cond, n in noise.items():
        m = samples.condition == cond
        P[m] = samples.pose_covariance(n)[m]
        tv[m] = samples.twist_variance(n)[m]
    return P, tv


def _coverage(samples: Samples, noise) -> dict:
    """Pooled coverage under one noise or per-condition noises (sample-weighted)."""
    if isinstance(noise, OdometryNoise):
        return samples.coverage(noise)
    parts = [samples.subset([c]).coverage(n) for c, n in noise.items()]
    total = sum(p["samples"] for p in parts)
    return {k: sum(p[k] * p["samples"] for p in parts) / total for k in COMPONENTS}


def plot(samples: Samples, noise, path: str, title: str) -> None:
    """Error against published sigma (position, heading, vx), one colour per
    condition; ``noise``: one OdometryNoise, or a dict condition ->
    OdometryNoise (each floor against its own profile)."""
    import matplotlib
    import matplotlib.ticker
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    P, tv = _published(samples, noise)
    e = samples.error
    panels = [
        # the ellipse's sigma in the direction of the error, |e| / sqrt(e' P^-1 e):
        # below the line <=> inside the 95 % ellipse
        ("position", np.linalg.norm(e[:, :2], axis=1) * 1e3,
         np.linalg.norm(e[:, :2], axis=1) / np.sqrt(np.maximum(
             mahalanobis2(e[:, :2], P[:, :2, :2]), 1e-30)) * 1e3, math.sqrt(CHI2_2_95),
         "sigma of the ellipse along the error [mm]", "|position error| [mm]"),
        ("heading", np.degrees(np.abs(e[:, 2])), np.degrees(np.sqrt(P[:, 2, 2])), Z_95,
         "sigma [deg]", "|heading error| [deg]"),
        ("twist vx", np.abs(samples.twist_error[:, 0]) * 1e3, np.sqrt(tv[:, 0]) * 1e3, Z_95,
         "sigma [mm/s]", "|vx error| [mm/s]"),
    ]
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.8))
    cover = _coverage(samples, noise)
    for ax, (name, err, sig, k, xlabel, ylabel) in zip(axes, panels):
        for cond in dict.fromkeys(samples.group.tolist()):
            m = samples.group == cond
            ax.scatter(sig[m], np.maximum(err[m], 1e-6), s=2, alpha=0.35, label=cond)
        lo = max(np.percentile(sig, 0.5), 1e-6)
        hi = np.percentile(sig, 99.5) * 1.2
        xs = np.geomspace(lo, hi, 50)
        ax.plot(xs, k * xs, "k-", lw=1.5, label=f"{k:.2f} sigma (95 % bound)")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_ylim(max(np.percentile(err, 1), 1e-4), np.max(err) * 1.5)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
        key = {"position": "position", "heading": "heading", "twist vx": "vx"}[name]
        ax.set_title(f"{name}: {100 * cover[key]:.1f} % inside")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=7, markerscale=4, loc="upper left")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def profile_yaml(noise: OdometryNoise, twist_window: float, header: list) -> str:
    """A ROS 2 params file holding only the ``odometry:`` block (an overlay
    for ``holonomic-bringup ROBOT --params-file FILE``); ``header``: comment
    lines (how it was made, its coverage)."""
    return "\n".join([f"# {line}" if line else "#" for line in header]
                     + ["base_controller:", "  ros__parameters:", noise_yaml(noise, twist_window),
                        ""])


def _write_profile(path: str, noise: OdometryNoise, twist_window: float, robot: str,
                   floor: str, command: str, held: dict | None) -> None:
    """One floor's profile as a params overlay, with how it was made in a comment."""
    name = os.path.basename(robot)
    header = [f"Odometry covariance of the {robot} calibrated on one floor: {floor},",
              "in the simulator (ground truth), by",
              f"  {command}" if command else "  holonomic-odometry-experiment",
              "Coverage holds on the floor it was calibrated on only; re-calibrate on yours",
              f"(docs/odometry_experiment.md). Use: holonomic-bringup {name} --params-file {path}"]
    if held:
        header.append(f"Held-out coverage on this floor ({held['runs']} runs, {held['samples']} "
                      "samples): " + ", ".join(f"{k} {100 * held[k]:.1f} %" for k in COMPONENTS))
    os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
    with open(path, "w") as handle:
        handle.write(profile_yaml(noise, twist_window, header))


def calibrate_main(recordings, fit_noise: bool = True, plot_path: str | None = None,
                   per_floor: bool = False, profile_dir: str | None = None,
                   floor_names: dict | None = None, command: str = "",
                   default_floors=None, fit_motions=None, bar=None) -> OdometryNoise:
    """Print the coverage of the config's noise and, with ``fit_noise``:

    * one profile for all the recorded floors (:func:`fit`; only those in
      ``default_floors`` when given: the floors the config's default is
      meant for; only the runs of the kinds of motion in ``fit_motions``
      when given, default: random), its coverage and YAML block, and with
      ``per_floor`` its coverage held out by seed, on every recorded floor;
    * the coverage of the config's noise and of that profile on each kind
      of motion it was not fitted on (held out), per floor;
    * with ``per_floor`` and recordings of several floors (conditions), also
      one profile per floor (fitted on the ``fit_motions`` runs), with
      its held-out coverage (leave one run out) when a floor has >= 2 runs,
      written to ``profile_dir`` as ``ROBOT_FLOOR.yaml`` params overlays
      (``floor_names``: condition -> short name for the file).

    ``plot_path``: error against sigma; with per-floor profiles each floor's
    samples against its own profile's sigma. Returns the all-floors noise.
    ``bar`` (holonomic_core.progress): advanced once per recording replayed.
    """
    everything = Samples(recordings, bar)
    motions = list(dict.fromkeys(everything.motion.tolist()))
    fit_motions = [m for m in (fit_motions or ["random"]) if m in motions] or motions
    held_kinds = [m for m in motions if m not in fit_motions]
    samples = everything.subset(motions=fit_motions)
    cfg = recordings[0].config.controller
    noise = cfg.noise
    robot = recordings[0].robot
    print(f"\ncoverage of the config's covariance ({robot}, estimator {cfg.estimator}):")
    print(coverage_table(everything, noise))
    if held_kinds:
        print(f"\nthe config's covariance on each kind of motion, per run ({robot}; +- standard "
              "error over the runs, ! outside 90-99.5 %):")
        print(band_table(list(per_group(everything, noise).items())))
    floors = list(dict.fromkeys(samples.condition.tolist()))
    profiles = {}
    fit_floors = [f for f in floors if default_floors is None or f in default_floors]
    if not fit_floors:      # the default floors' runs were all skipped
        print("none of the default floors was recorded: the profile is fitted on every floor")
        fit_floors = floors
    if fit_noise:
        start = noise
        noise = fit(samples.subset(fit_floors), start)
        print(f"\ncalibrated coverage, one profile fitted on {len(fit_floors)} of the "
              f"{len(floors)} recorded floor(s) ({', '.join(fit_floors)}; motion: "
              f"{', '.join(fit_motions)}; one: scaled to 95 %; several: each as close to 95 % "
              "as one set allows):")
        print(coverage_table(everything, noise))
        print("\ncalibrated parameters (config file, base_controller: ros__parameters:):")
        print(noise_yaml(noise, cfg.twist_window))
        if held_kinds:
            print(f"\nthe calibrated profile on the kinds of motion it was not fitted on "
                  f"({', '.join(held_kinds)}; fitted on {', '.join(fit_motions)}), per run:")
            print(band_table(list(per_group(everything.subset(motions=held_kinds),
                                            noise).items())))
        if per_floor and (len(floors) > 1 or held_kinds):
            if len({r.rsplit(" seed ", 1)[-1] for r in samples.runs}) >= 2:
                print("\nthe profile for several floors, held out (each seed's runs against "
                      "the profile fitted on the other seeds' runs of its floors and kinds of "
                      "motion, on every floor and kind):")
                print(band_table(list(held_out_by_seed(everything, start, fit_floors,
                                                       fit_motions).items())))
        if per_floor and len(floors) > 1:
            rows = []
            for floor in floors:
                sub = samples.subset([floor])
                profiles[floor] = fit(sub, start)
                if len(sub.runs) >= 2:
                    rows.append((floor, held_out(sub, start)))
            if rows:
                print("\none profile per floor, held out (each run against the profile fitted "
                      "on the other runs of its floor; +- standard error over the runs, binom: "
                      "binomial standard error of the position fraction over the samples, "
                      "! outside 90-99.5 %):")
                print(band_table(rows))
            spread = random_walk_spread(int(np.mean([len(samples.subset(runs=[r]).error)
                                                     for r in samples.runs])))
            print(f"\nfor scale: a perfectly calibrated random walk covers 95 % on average, "
                  f"but one run's fraction has a standard deviation of "
                  f"{100 * spread['position']:.0f} % (position) and "
                  f"{100 * spread['heading']:.0f} % (heading) between runs: "
                  "even an exact covariance shows a +- (standard error over runs) of about "
                  "that / sqrt(runs)")
            held = dict(rows)
            for floor, prof in profiles.items():
                name = (floor_names or {}).get(floor, floor)
                print(f"\nprofile for {floor}:")
                print(noise_yaml(prof, cfg.twist_window))
                if profile_dir:
                    path = os.path.join(profile_dir, f"{os.path.basename(robot)}_{name}.yaml")
                    _write_profile(path, prof, cfg.twist_window, robot, floor, command,
                                   held.get(floor))
                    print(f"written to {path}")
    if plot_path and held_kinds:
        plot(everything, noise, plot_path,
             f"{robot}: odometry error against the published sigma, "
             + (f"fitted on {', '.join(fit_motions)}" if fit_noise
                else "the configured covariance")
             + f" ({len(recordings)} runs)")
        print(f"plot written to {plot_path}")
    elif plot_path:
        plot(samples, profiles or noise, plot_path,
             f"{robot}: odometry error against the published sigma ({len(recordings)} runs"
             + (", each floor's own profile)" if profiles else ")"))
        print(f"plot written to {plot_path}")
    return noise
