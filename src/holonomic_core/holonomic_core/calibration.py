"""Self-calibration of a base's kinematic parameters from ordinary driving.

A powered-caster vehicle measures its motion redundantly (2n joint rates for
3 degrees of freedom). With the right wheel radii r_i, caster offsets b_i and
steering zeros, the slip-minimising fit (C# = Cp+ Cq^-1) of every sample
leaves only random slip; a wrong parameter leaves a *systematic* residual,
correlated with the motion. Calibration is the nonlinear least-squares
problem

    theta* = argmin_theta  sum_k |e_k(theta)|^2  (+ reference terms)

where e_k is the contact-displacement residual of the slip-minimising fit of
sample k (the per-sample twist eliminated in closed form: variable
projection). One overall scale is unobservable without a reference (scaling
every radius and caster offset together scales every sensed contact velocity
alike); it comes from the simulator's ground truth (a body-displacement
residual per sample) or a measured distance, or -- without either -- the mean
radius stays as configured. The DDROT has no redundancy: it is calibrated against the
reference alone -- the ground truth, or (:func:`calibrate_measured`) one
straight run whose end point and one rotation whose turns a user measured.

The solver is Levenberg-Marquardt on parameters normalised by their
configured values (radii and offsets relative, zeros in radians), with a
central-difference Jacobian of residuals vectorised over samples and
parameter sets. Standard errors come
from sigma^2 (J^T J)^-1 with sigma^2 the residual variance; consecutive
samples' slip is correlated, so they are lower bounds.

Family-specific residuals live with each family (its ``holonomic.calibration``
entry point, :mod:`holonomic_core.plugins`); this module holds what they share.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping, Protocol, Sequence

import numpy as np

from holonomic_core import plugins
from holonomic_core.se2 import relative_poses, wrap_angles

#: weight of the gauge row that holds the mean radius when there is no reference
_GAUGE_WEIGHT = 1e3
#: below this speed [m/s] and turn rate [rad/s] a sample is "not moving"
_STILL_SPEED, _STILL_TURN = 0.02, 0.05


class CalibrationError(ValueError):
    """The recording cannot determine the parameters; the message says why
    and what motion is missing (one line, for the user)."""


@dataclass(frozen=True)
class Samples:
    """Joint motion over consecutive intervals, in the kinematics' terms.

    ``positions`` (N x joints) [rad]: mid-interval joint positions with the
    config's encoder zeros already subtracted; ``displacements`` (N x joints)
    [rad]: joint displacement over each interval; ``durations`` (N,) [s];
    ``reference`` (N x 3) or None: the true body motion over each interval as
    the chord (dx, dy) [m] in base_link at the interval's start and the turn
    dtheta [rad] (from ground truth).
    """

    positions: np.ndarray
    displacements: np.ndarray
    durations: np.ndarray
    reference: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.displacements)


def _spaced(stamps: np.ndarray, period: float) -> np.ndarray:
    """Indices of the readings kept when each is at least ``period`` [s]
    after the previous kept one (the first is kept)."""
    keep = [0]
    for k in range(1, len(stamps)):
        if stamps[k] - stamps[keep[-1]] >= period - 1e-9:
            keep.append(k)
    return np.array(keep)


def samples_from_readings(stamps: Sequence[float], positions: np.ndarray,
                          truth: np.ndarray | None = None, period: float = 0.02) -> Samples:
    """Intervals between joint readings at least ``period`` [s] apart.

    ``stamps`` [s], ``positions`` (N x joints) [rad] as the controller saw
    them (its encoder zeros subtracted: ``joint_states`` and
    ``BaseController.reading``), ``truth`` (N x 3) optional true poses (x, y,
    yaw) [m, m, rad] in odom at the same stamps. Intervals in which no joint
    moved are dropped (they carry no information).
    """
    stamps = np.asarray(stamps, float)
    q = np.asarray(positions, float)
    idx = _spaced(stamps, period)
    if len(idx) < 2:
        return Samples(np.zeros((0, q.shape[1])), np.zeros((0, q.shape[1])), np.zeros(0))
    q0 = q[idx[:-1]]
    # wrapped: a steering reading may jump by 2 pi; no joint turns half a
    # revolution in one interval of a fraction of a second
    disp = wrap_angles(q[idx[1:]] - q0)
    moving = np.abs(disp).max(axis=1) > 1e-6
    ref = None
    if truth is not None:
        pose = np.asarray(truth, float)[idx]
        ref = relative_poses(pose[:-1], pose[1:])[moving]
    return Samples((q0 + 0.5 * disp)[moving], disp[moving],
                   np.diff(stamps[idx])[moving], ref)


def chord(body: np.ndarray) -> np.ndarray:
    """(... x 3) constant-twist arcs (dx, dy, dtheta) -> their chords (cx, cy,
    dtheta): the displacement of the origin in the start frame, as
    :func:`holonomic_core.odometry.compose_arc` integrates one arc."""
    dx, dy, dth = body[..., 0], body[..., 1], body[..., 2]
    small = np.abs(dth) < 1e-6
    safe = np.where(small, 1.0, dth)
    a = np.where(small, 1.0 - dth * dth / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 * dth, (1.0 - np.cos(safe)) / safe)
    return np.stack((a * dx - b * dy, b * dx + a * dy, dth), axis=-1)


class FamilyCalibration(Protocol):
    """What a family provides to the solver (its holonomic.calibration entry point)."""

    #: flat config keys of the parameters, in theta order
    keys: tuple[str, ...]
    #: human labels ("caster front_left: wheel radius")
    labels: tuple[str, ...]
    #: per parameter: "radius", "offset", "length" (relative) or "zero" (absolute, rad)
    kinds: tuple[str, ...]
    #: configured values of theta (the config's radii, offsets, zero corrections)
    nominal: np.ndarray
    #: whether the joints alone (no reference) determine the parameters up to scale
    self_consistent: bool
    #: length [m] that turns a heading residual into metres
    length_scale: float

    def slip(self, theta: np.ndarray, samples: Samples) -> np.ndarray:
        """Fit residuals [m] (... x anything; no entries without redundancy);
        ``theta`` (... x p) may carry leading batch axes."""

    def body(self, theta: np.ndarray, samples: Samples) -> np.ndarray:
        """(... x N x 3) body motion (dx [m], dy [m], dtheta [rad]) per interval."""

    def overlay(self, theta: np.ndarray) -> dict[str, float]:
        """Flat config keys -> values for a params-file overlay."""


def family_for(model) -> FamilyCalibration:
    """The calibration model of ``model``'s kinematic family (its
    ``holonomic.calibration`` entry point)."""
    if not plugins.provides("calibration", model.kind):
        raise CalibrationError(f"no calibration for kinematics '{model.kind}'")
    return plugins.load("calibration", model.kind, "robot.kinematics")(model)


@dataclass
class CalibrationResult:
    """Estimates theta [m, rad] with standard errors, per parameter."""

    family: FamilyCalibration
    theta: np.ndarray
    stderr: np.ndarray
    rms_residual: float             # [m] per residual entry
    samples: int
    reference: str                  # "none", "ground_truth" or "distance"
    notes: list[str] = field(default_factory=list)

    def overlay(self) -> dict[str, float]:
        return self.family.overlay(self.theta)

    def table(self, truth: Mapping[str, float] | None = None) -> str:
        """One line per parameter: configured, estimate +- standard error,
        change (and the truth, when known: flat keys -> values)."""
        fam = self.family
        lines = []
        for i, label in enumerate(fam.labels):
            zero = fam.kinds[i] == "zero"
            unit, k = ("deg", 180.0 / math.pi) if zero else ("mm", 1e3)
            nom, est, se = fam.nominal[i], self.theta[i], self.stderr[i]
            change = (f"{math.degrees(est - nom):+6.2f} deg" if zero
                      else f"{100 * (est / nom - 1):+6.2f} %")
            spread = "not observed" if math.isnan(se) else f"+- {k * se:.3f} {unit}"
            line = f"{label:34s} {k * nom:8.3f} -> {k * est:8.3f} {spread} ({change})"
            if truth is not None:
                true = truth.get(fam.keys[i], nom)
                line += f"  truth {k * true:8.3f} {unit}"
            lines.append(line)
        return "\n".join(lines)


def _normaliser(family: FamilyCalibration) -> np.ndarray:
    """theta = nominal + scale * z: relative units for lengths, radians for zeros."""
    return np.array([1.0 if k == "zero" else family.nominal[i]
                     for i, k in enumerate(family.kinds)])


def end_point(family, theta: np.ndarray, samples: Samples) -> np.ndarray:
    """(... x 2) position [m] of the last sample relative to the first, in the
    first sample's base_link frame, by odometry with parameters ``theta``."""
    moves = chord(family.body(theta, samples))
    heading = np.cumsum(moves[..., 2], axis=-1) - moves[..., 2]    # before each move
    c, s = np.cos(heading), np.sin(heading)
    return np.stack(((c * moves[..., 0] - s * moves[..., 1]).sum(axis=-1),
                     (s * moves[..., 0] + c * moves[..., 1]).sum(axis=-1)), axis=-1)


def residual_function(family, samples: Samples, use_reference: bool = False,
                      gauge_mean: float | None = None):
    """``(fun, scale)``: ``fun(z)`` is the residual vector [m] at ``theta =
    family.nominal + scale * z`` -- the fit residuals, then (with
    ``use_reference``) the chords' misfit to the reference, then (with
    ``gauge_mean`` [m]) one stiff row that holds the mean radius there."""
    scale = _normaliser(family)
    radius = np.array([k == "radius" for k in family.kinds])
    nominal_mean = float(family.nominal[radius].mean()) if radius.any() else 1.0

    def fun(z):
        # z (p,) -> (m,) residuals; z (k, p) -> (k, m), one row per parameter set
        theta = family.nominal + scale * np.asarray(z, float)
        lead = theta.shape[:-1]
        slip = np.reshape(family.slip(theta, samples), lead + (-1,))
        if use_reference and radius.any():
            # The slip residuals scale with the geometry: every radius and
            # offset times k gives residuals times k. Unnormalised, least
            # squares trades the reference's fit for smaller slip and
            # pulls the common scale low by about (slip energy) / (motion
            # energy): small once skidding samples are left out (calibrate),
            # larger on a slippery floor. In units of the common scale the
            # slip term is blind to it, as the joints are: the scale comes
            # from the reference alone.
            slip = slip * (nominal_mean / theta[..., radius].mean(axis=-1, keepdims=True))
        parts = [slip]
        if use_reference:
            err = chord(family.body(theta, samples)) - samples.reference
            err[..., 2] *= family.length_scale
            parts.append(np.reshape(err, lead + (-1,)))
        if gauge_mean is not None:
            mean = theta[..., radius].mean(axis=-1, keepdims=True)
            parts.append(_GAUGE_WEIGHT * (mean / gauge_mean - 1.0))
        return np.concatenate(parts, axis=-1)

    return fun, scale


def jacobian(fun, z: np.ndarray, step: float = 1e-6) -> np.ndarray:
    """Central-difference Jacobian of ``fun`` at ``z`` (normalised
    parameters), all columns in one batched call."""
    p = len(z)
    plus_minus = z + step * np.vstack((np.eye(p), -np.eye(p)))
    values = fun(plus_minus)
    return ((values[:p] - values[p:]) / (2 * step)).T


def calibrate(model, samples: Samples, reference: str = "none",
              distance: float | None = None, iterations: int = 30,
              distance_samples: Samples | None = None) -> CalibrationResult:
    """Estimate the family's parameters from ``samples``.

    ``reference``: "ground_truth" (``samples.reference`` must be set) fixes
    the scale from the true motion; "distance" scales radii and caster
    offsets so that the odometry's straight-line displacement from the first
    to the last sample is ``distance`` [m] (measured by the user) -- of
    ``distance_samples`` when given (a straight run, :func:`last_straight_run`;
    the fit of ratios, offsets and zeros still uses every sample), else of
    ``samples``; "none" keeps the configured mean radius. Raises
    :class:`CalibrationError` (one line naming the missing motion) when the
    samples cannot determine the parameters, or when the straight run
    turned STRAIGHT_MAX_TURN or more by the fitted geometry.
    """
    if reference not in ("none", "ground_truth", "distance"):
        raise ValueError(f"reference must be none, ground_truth or distance, got {reference!r}")
    family = family_for(model)
    check_motion(family, samples)
    use_ref = reference == "ground_truth"
    if use_ref and samples.reference is None:
        raise CalibrationError("--reference ground_truth needs ground_truth/odom in the "
                               "recording (simulator runs publish it)")
    if not family.self_consistent and not use_ref:
        raise CalibrationError(
            f"a {model.kind} has no redundant joint, so driving alone cannot show a wrong "
            "parameter: calibrate against --reference ground_truth, or a measured straight "
            "run and rotation (--distance, --turns; docs/calibration.md)")
    radius = np.array([k == "radius" for k in family.kinds])
    gauge = None if use_ref else float(family.nominal[radius].mean())
    if reference == "distance":
        if distance is None or not distance > 0:
            raise CalibrationError("--distance must be a measured distance > 0 [m]")
    fun, scale = residual_function(family, samples, use_ref, gauge)
    z = _least_squares(fun, np.zeros(len(family.nominal)), iterations)
    recorded = samples
    skidded = _skidding(family, family.nominal + scale * z, samples)
    if skidded.any():
        # a wheel skidding is not kinematics: fit again without those
        # samples (they would pull the geometry, and against ground truth
        # the scale, toward explaining the skid)
        samples = _subset(samples, ~skidded)
        fun, scale = residual_function(family, samples, use_ref, gauge)
        z = _least_squares(fun, z, iterations)
    r = fun(z)
    J = jacobian(fun, z)
    m = len(r) - (1 if gauge is not None else 0)
    dof = max(m - len(z) + (1 if gauge is not None else 0), 1)
    body_r = r[:m]
    sigma2 = float(body_r @ body_r) / dof
    info = J.T @ J
    weak = weakest_direction(family, info, sigma2)
    if weak is not None:
        raise CalibrationError(weak + " (" + missing_motion(family, samples) + ")")
    cov = np.linalg.inv(info) * sigma2
    theta = family.nominal + scale * z
    stderr = scale * np.sqrt(np.maximum(np.diag(cov), 0.0))
    result = CalibrationResult(family, theta, stderr, math.sqrt(sigma2), len(samples),
                               reference)
    if skidded.any():
        result.notes.append(f"{int(skidded.sum())} of {len(skidded)} samples left out: a wheel "
                            f"skidded (fit residual above {SKID_SPEED:g} m/s)")
    if distance_samples is not None:
        turn = float(family.body(result.theta, distance_samples)[:, 2].sum())
        if abs(turn) >= STRAIGHT_MAX_TURN:
            raise CalibrationError(
                f"the straight run turned {math.degrees(turn):+.1f} deg (by the calibrated "
                f"odometry): drive it at constant heading, turning less than "
                f"{math.degrees(STRAIGHT_MAX_TURN):g} deg")
    if reference == "distance":
        # the odometry's end point: of the whole recording, skids included,
        # or of the measured straight run
        _scale_to_distance(result, recorded if distance_samples is None else distance_samples,
                           distance)
    elif reference == "none" and family.self_consistent:
        result.notes.append("overall scale not observed: the mean wheel radius is kept as "
                            "configured (give --distance or --reference ground_truth)")
    return result


#: [m/s] a sample whose fit residual (at the first estimate) exceeds this
#: rate skids: a wheel slides or spins, which no geometry explains (the
#: controller's diagnostics.slip_threshold default)
SKID_SPEED = 0.05


def _least_squares(fun, z: np.ndarray, iterations: int) -> np.ndarray:
    """Levenberg-Marquardt on ``fun`` (residual vector of normalised
    parameters) from ``z``; the minimiser found."""
    r = fun(z)
    cost = float(r @ r)
    lam = 1e-3
    for _ in range(iterations):
        J = jacobian(fun, z)
        A, g = J.T @ J, J.T @ r
        improved = False
        for _ in range(10):
            step = np.linalg.solve(A + lam * np.diag(np.diag(A) + 1e-12), -g)
            r_new = fun(z + step)
            cost_new = float(r_new @ r_new)
            if cost_new < cost:
                z, r, cost, improved = z + step, r_new, cost_new, True
                lam = max(lam / 10, 1e-9)
                break
            lam *= 10
        if not improved or np.max(np.abs(step)) < 1e-9:
            break
    return z


def _skidding(family, theta: np.ndarray, samples: Samples) -> np.ndarray:
    """(N,) bool: the samples whose fit residual at ``theta``, per second,
    exceeds SKID_SPEED (none for a family without redundancy)."""
    slip = np.asarray(family.slip(theta, samples))
    if slip.size == 0:
        return np.zeros(len(samples), bool)
    rate = np.linalg.norm(slip.reshape(len(samples), -1), axis=1) / samples.durations
    return rate > SKID_SPEED


def _subset(samples: Samples, keep: np.ndarray) -> Samples:
    """The samples where ``keep`` (N,) is true."""
    return Samples(samples.positions[keep], samples.displacements[keep], samples.durations[keep],
                   None if samples.reference is None else samples.reference[keep])


def _scale_to_distance(result: CalibrationResult, samples: Samples, distance: float) -> None:
    """Scale radii and caster offsets together -- the direction the joints
    cannot see -- so that the odometry spans the measured ``distance`` [m]
    from the first to the last sample; the root nearest the configured
    scale, found on a 0.1 % grid over +-10 % and refined linearly."""
    fam = result.family
    lengths = np.array([k in ("radius", "offset") for k in fam.kinds])
    factors = np.linspace(0.9, 1.1, 201)
    thetas = np.where(lengths, result.theta * factors[:, None], result.theta)
    spans = np.linalg.norm(end_point(fam, thetas, samples), axis=-1)
    if spans.max() < 0.5:
        raise CalibrationError(f"--distance needs a run whose end is at least 0.5 m from its "
                               f"start (this one: {spans.max():.2f} m by odometry)")
    miss = spans - distance
    roots = [factors[i] - miss[i] * (factors[i + 1] - factors[i]) / (miss[i + 1] - miss[i])
             for i in range(len(factors) - 1) if miss[i] * miss[i + 1] <= 0 and
             miss[i] != miss[i + 1]]
    if not roots:
        raise CalibrationError(f"the measured distance {distance:g} m is more than 10 % away "
                               f"from the odometry's {spans[100]:.3f} m: check the "
                               "measurement and the recording's start and end")
    k = float(min(roots, key=lambda f: abs(f - 1.0)))
    result.theta[lengths] *= k
    result.stderr[lengths] *= k
    result.notes.append(f"scale from --distance {distance:g} m: radii and caster offsets "
                        f"x {k:.5f}")


#: largest acceptable standard error before the recording counts as not
#: exciting a parameter: relative for lengths, radians for zeros
MAX_STDERR = {"radius": 0.005, "offset": 0.1, "length": 0.005, "zero": math.radians(1.0)}
#: eigenvalue ratio (in units of MAX_STDERR) below which a direction is unobservable
_MIN_CONDITION = 1e-12


def weakest_direction(family, info: np.ndarray, sigma2: float) -> str | None:
    """None when the information matrix ``info`` (normalised parameters)
    determines every parameter to within MAX_STDERR; else a phrase naming the
    parameters the data leaves (nearly) free."""
    tol = np.array([MAX_STDERR[k] for k in family.kinds])
    vals, vecs = np.linalg.eigh(tol[:, None] * info * tol[None, :])
    if not vals[-1] > 0:
        return "no usable motion in the recording"
    singular = vals[0] / vals[-1] < _MIN_CONDITION
    se = np.sqrt(np.maximum(np.diag(np.linalg.pinv(info)), 0.0) * sigma2)
    loose = se > tol
    if not singular and not loose.any():
        return None
    if singular:
        weight = np.abs(vecs[:, 0])
        idx = [i for i in np.argsort(-weight)[:3] if weight[i] > 0.3 * weight.max()]
    else:
        idx = list(np.flatnonzero(loose))[:3]
    return "not enough excitation: " + ", ".join(family.labels[i] for i in idx) + \
        " undetermined"


def motion_summary(family, samples: Samples) -> dict[str, float]:
    """Moving time [s], path [m], turn [rad] and the spread of travel
    directions in base_link [rad], from the configured model."""
    body = family.body(family.nominal, samples)
    dt = np.maximum(samples.durations, 1e-6)
    speed = np.hypot(body[:, 0], body[:, 1]) / dt
    turn = np.abs(body[:, 2]) / dt
    moving = (speed > _STILL_SPEED) | (turn > _STILL_TURN)
    heading = np.arctan2(body[:, 1], body[:, 0])[speed > 0.1]
    # the spread of directions modulo 180 deg (driving back and forth is one
    # direction): 1 - |mean of exp(2 i psi)| is 0 for one direction, 1 for all
    spread = float(1.0 - abs(np.mean(np.exp(2j * heading)))) if len(heading) else 0.0
    return {"moving_s": float(dt[moving].sum()),
            "path_m": float(np.hypot(body[:, 0], body[:, 1]).sum()),
            "turn_rad": float(np.abs(body[:, 2]).sum()),
            "turning_share": float(np.mean(turn[moving] > 0.2)) if moving.any() else 0.0,
            "direction_spread": spread}


#: a usable recording has at least this much motion
MIN_MOVING_S, MIN_PATH_M, MIN_TURN_RAD = 20.0, 5.0, 2 * math.pi


def check_motion(family, samples: Samples) -> None:
    """Reject a recording that is too short before fitting anything."""
    if len(samples) < 10:
        raise CalibrationError(f"too short: {len(samples)} moving samples (drive for about two "
                               "minutes: forward, sideways, diagonally, turning)")
    m = motion_summary(family, samples)
    if m["moving_s"] < MIN_MOVING_S or m["path_m"] < MIN_PATH_M:
        raise CalibrationError(
            f"too short: {m['moving_s']:.0f} s and {m['path_m']:.1f} m of motion (drive at "
            f"least {MIN_MOVING_S:.0f} s and {MIN_PATH_M:.0f} m; about two minutes is best)")


def missing_motion(family, samples: Samples) -> str:
    """What motion the recording lacks, for the excitation error."""
    m = motion_summary(family, samples)
    if m["turn_rad"] < MIN_TURN_RAD or m["turning_share"] < 0.1:
        if m["direction_spread"] < 0.2:
            return "only straight lines: drive with rotation and sideways"
        return "hardly any rotation: turn while driving and spin in place"
    if m["direction_spread"] < 0.2:
        return "one direction of travel only: drive sideways and diagonally too"
    return "drive longer, with more changes of direction and rotation"


# -- a measured straight run (a PCV's scale) --

#: a PCV's straight run for --distance turns less than this [rad] by the
#: calibrated odometry (constant heading: the odometry's heading error does
#: not bend the path the distance is compared with). Judged after the fit:
#: with the configured geometry, steering zeros a degree or two off make a
#: run held at constant heading seem to turn several degrees
STRAIGHT_MAX_TURN = math.radians(10.0)


def last_straight_run(family, stamps: Sequence[float], positions: np.ndarray) -> tuple[int, int]:
    """(first, last) reading indices of the recording's last motion segment
    (:func:`motion_segments`: after a pause of SEGMENT_PAUSE), the straight
    run of ``calibrate(..., distance_samples=...)``: base_link at least
    0.5 m from where it started by the configured odometry (whether it kept
    its heading is judged with the fitted geometry, in :func:`calibrate`).
    Raises CalibrationError naming what is wrong."""
    stamps = np.asarray(stamps, float)
    segments = motion_segments(stamps, positions)
    if len(segments) < 2:
        raise CalibrationError("--straight-run needs the varied driving, a pause of at least "
                               f"{SEGMENT_PAUSE:g} s, then the straight run, then a pause "
                               f"(found {len(segments)} stretch(es) of motion)")
    first, last = segments[-1]
    seg = samples_from_readings(stamps[first:last + 1], positions[first:last + 1])
    if len(seg) < 2:
        raise CalibrationError("the recording's last stretch of motion is too short for a "
                               "straight run")
    span = float(np.linalg.norm(end_point(family, family.nominal, seg)))
    if span < _LINE_MIN_M:
        raise CalibrationError(
            f"the recording's last stretch of motion is not a straight run (it ended "
            f"{span:.2f} m from its start; needs at least {_LINE_MIN_M:g} m at constant heading)")
    return first, last


# -- a measured straight line and a measured rotation (a base without redundancy) --

#: joint rate [rad/s] below which a joint counts as still, judged over
#: STILL_WINDOW [s] (longer than an encoder count's flicker)
_STILL_RATE, _STILL_WINDOW = 0.05, 0.1
#: a pause of at least this long [s] separates two segments of motion
SEGMENT_PAUSE = 0.5
#: a straight run: at least this far [m] and turning less than this [rad]
#: (by the configured model: a 3 % radius mismatch bends 5 m by ~30 deg)
_LINE_MIN_M, _LINE_MAX_TURN = 0.5, math.radians(60.0)
#: a rotation: at least this much turn [rad], the turret axis moving less than this [m]
_SPIN_MIN_TURN, _SPIN_MAX_CHORD = math.radians(90.0), 0.5
#: assumed measurement errors (1 sigma) of the standard errors: a tape read
#: to 5 mm, a rotation realigned to 0.5 deg, a heading measured to 0.5 deg
TAPE_ERROR, TURN_ERROR, HEADING_ERROR = 0.005, math.radians(0.5), math.radians(0.5)


def motion_segments(stamps: Sequence[float], positions: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) reading indices of each stretch of joint motion,
    separated by pauses of at least SEGMENT_PAUSE [s] in which every joint
    turned slower than _STILL_RATE [rad/s]; ``stamps`` [s], ``positions``
    (N x joints) [rad]."""
    t = np.asarray(stamps, float)
    q = np.asarray(positions, float)
    idx = _spaced(t, _STILL_WINDOW)
    if len(idx) < 2:
        return []
    rate = np.abs(wrap_angles(np.diff(q[idx], axis=0))).max(axis=1) / np.diff(t[idx])
    segments: list[list[int]] = []
    for k in np.flatnonzero(rate > _STILL_RATE):
        start, end = int(idx[k]), int(idx[k + 1])
        if segments and t[start] - t[segments[-1][1]] < SEGMENT_PAUSE:
            segments[-1][1] = end
        else:
            segments.append([start, end])
    return [(a, b) for a, b in segments if t[b] - t[a] >= SEGMENT_PAUSE]


@dataclass(frozen=True)
class MeasuredSegments:
    """The straight run and the rotation of a reference drive, as samples."""

    line: Samples
    spin: Samples
    spin_sign: float        # +1 counter-clockwise, -1 clockwise (configured odometry)


def find_reference_segments(family, stamps, positions) -> MeasuredSegments:
    """Split a recording into motion segments (pauses of SEGMENT_PAUSE) and
    pick the one straight run and the one rotation, judged by the configured
    odometry: a straight run moves the base at least 0.5 m and turns it less
    than 60 deg; a rotation turns it at least 90 deg while the base_link
    origin ends within 0.5 m of where it started, with the wheels (not only
    a turret) turning it. Raises CalibrationError naming what is missing."""
    lines, spins = [], []
    for first, last in motion_segments(stamps, positions):
        seg = samples_from_readings(stamps[first:last + 1], positions[first:last + 1])
        if len(seg) < 2:
            continue
        chord_m = float(np.linalg.norm(end_point(family, family.nominal, seg)))
        turn = float(family.body(family.nominal, seg)[:, 2].sum())
        if chord_m >= _LINE_MIN_M and abs(turn) < _LINE_MAX_TURN:
            lines.append(seg)
        elif abs(turn) >= _SPIN_MIN_TURN and chord_m < _SPIN_MAX_CHORD:
            wheels = float(family.wheel_turn(family.nominal, seg).sum())
            if abs(wheels) < 0.5 * abs(turn):
                raise CalibrationError(
                    "the rotation turned the turret, not the wheels: spin the drive about its "
                    "axle (docs/calibration.md, 'measured line and rotation')")
            spins.append((seg, math.copysign(1.0, turn)))
    if not lines:
        raise CalibrationError("no straight run found (at least 0.5 m turning less than 60 deg, "
                               "with a pause of 0.5 s before and after)")
    if not spins:
        raise CalibrationError("no rotation found (at least a quarter turn in place, with a "
                               "pause of 0.5 s before and after)")
    if len(lines) > 1 or len(spins) > 1:
        raise CalibrationError(f"found {len(lines)} straight runs and {len(spins)} rotations: "
                               "record exactly one of each, so the measurements belong to them")
    return MeasuredSegments(lines[0], spins[0][0], spins[0][1])


def calibrate_measured(model, segments: MeasuredSegments, distance: float, lateral: float,
                       turns: float, heading: float | None = None,
                       iterations: int = 20) -> CalibrationResult:
    """Fit the radii and the wheel separation (the family's "radius" and
    "length" parameters) to a measured straight run and rotation: the
    odometry's end point of the run in its start frame must be (``distance``
    forward, ``lateral`` to the left) [m], and the rotation must turn
    ``turns`` revolutions [-] (its direction from the recording). Three
    measurements for three parameters. A "zero" parameter (the turret zero)
    turns the run's direction of travel, which one end point cannot tell from
    a radius ratio (both move the end sideways): it is fitted only when the
    run's change of ``heading`` [rad, counter-clockwise] was measured too,
    else kept as configured (stderr NaN). Standard errors propagate
    TAPE_ERROR, TURN_ERROR and HEADING_ERROR."""
    family = family_for(model)
    if not distance > 0:
        raise CalibrationError(f"--distance must be a measured distance > 0 m, got {distance:g}")
    if not turns > 0:
        raise CalibrationError(f"--turns must be a counted number of turns > 0, got {turns:g}")
    free = np.array([k != "zero" or heading is not None for k in family.kinds])
    scale = _normaliser(family)
    target = [distance, lateral, segments.spin_sign * 2 * math.pi * turns]
    sigma = [TAPE_ERROR, TAPE_ERROR, TURN_ERROR]
    if heading is not None:
        target.append(heading)
        sigma.append(HEADING_ERROR)
    target, sigma = np.array(target), np.array(sigma)

    def fun(z):
        z = np.asarray(z, float)
        full = np.zeros(z.shape[:-1] + (len(free),))
        full[..., free] = z
        theta = family.nominal + scale * full
        end = end_point(family, theta, segments.line)
        turns = [family.body(theta, segments.spin)[..., 2].sum(axis=-1)]
        if heading is not None:
            turns.append(family.body(theta, segments.line)[..., 2].sum(axis=-1))
        return (np.concatenate([end] + [t[..., None] for t in turns], axis=-1)
                - target) / sigma

    z = np.zeros(int(free.sum()))
    for _ in range(iterations):
        r = fun(z)
        J = jacobian(fun, z)
        if not np.all(np.isfinite(J)) or np.linalg.cond(J) > 1e12:
            raise CalibrationError("the straight run and the rotation do not determine the radii "
                                   "and the separation (is the rotation about the axle?)")
        step = np.linalg.solve(J, -r)
        z = z + step
        if np.max(np.abs(step)) < 1e-10:
            break
    miss = fun(z)
    change = np.abs(z[[family.kinds[i] != "zero" for i in np.flatnonzero(free)]])
    if not np.all(np.isfinite(miss)) or np.max(np.abs(miss)) > 1e-3 or np.max(change) > 0.1:
        # as _scale_to_distance: a wheel is not 10 % off its drawing; a
        # mistyped or mis-measured number is likelier
        raise CalibrationError("the measurements need radii or a separation more than 10 % from "
                               "the configured ones: check --distance, --lateral and --turns "
                               "against the recording")
    J = jacobian(fun, z)
    cov = np.linalg.inv(J.T @ J)
    theta = family.nominal.copy()
    theta[free] += scale[free] * z
    stderr = np.full(len(theta), np.nan)
    stderr[free] = scale[free] * np.sqrt(np.diag(cov))
    result = CalibrationResult(family, theta, stderr, 0.0,
                               len(segments.line) + len(segments.spin), "measured")
    fixed = [family.labels[i] for i in np.flatnonzero(~free)]
    if fixed:
        result.notes.append(f"{', '.join(fixed)}: not observable from one line and one rotation, "
                            "kept as configured (measure the run's --heading-deg too)")
    result.notes.append(f"standard errors for a tape read to {TAPE_ERROR * 1e3:g} mm, a "
                        f"rotation to {math.degrees(TURN_ERROR):g} deg"
                        + ("" if heading is None else
                           f", a heading to {math.degrees(HEADING_ERROR):g} deg"))
    return result
