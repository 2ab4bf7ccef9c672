"""The command law of one swerve module: from the velocity its steering axis
must have to the steering and wheel rates to command (README, "Inverse").

A module at ``(x, y)`` in base_link with wheel radius ``r``, measured heading
phi [rad] (``NAME_steer_joint``) and wheel ``NAME_wheel_joint``. With the
module's velocity ``v = (vx - wz y, vy + wz x)`` [m/s] and speed ``s = |v|``:

* target heading ``theta = atan2(v_y, v_x)``; the module may point along
  ``theta + k pi`` (k odd: wheel reversed). :func:`choose_heading` takes the
  one of least steering travel from phi, inside ``(min, max)`` where the
  steering joint has a range;
* wheel rate ``omega = sigma s cos(eps) / r`` (sigma = -1 reversed, ``eps``
  the remaining steering error, cos clipped at 0): the wheel pushes only
  with the component of v along its heading and never drives sideways.
  Without a range ``|eps| <= pi/2`` and ``sigma s cos(eps) = v . e(phi)``,
  continuous through a flip;
* steering rate ``phi_dot = k_s eps + theta_dot`` with the feed-forward
  ``theta_dot = (v_x a_y - v_y a_x) / s^2`` from the module's acceleration
  ``a = (ax - alpha y, ay + alpha x)`` (the twist's rate (ax, ay, alpha)):
  a base that keeps a line in odom while it spins has a body twist that
  turns, and without it the heading lags by ``theta_dot / k_s``;
* below ``hold_speed`` [m/s] the module holds its heading (phi_dot = 0) and
  the wheel takes ``v . e(phi) / r``: no steering about at a zero command,
  or while the command falls to zero; a module whose speed is growing
  (``v . a > 0``: the base starting in a new direction) turns towards it;
* the wheels wait for their modules (:func:`drive_fraction`): while a module
  is more than a small angle from its heading, no rigid motion of the base
  has every wheel rolling without sliding sideways (a wheel at ``eps`` from
  its heading scrubs ``s sin(eps)``), and the slip is what the encoders do
  not see. So every wheel drives the fraction ``kappa`` of its rate,
  ``kappa = 1`` while the worst error is within a fifth of ``window``
  (``swerve.drive_alignment``), falling linearly to 0 at ``window``; the
  controller continues from ``kappa`` times the twist, so the base waits
  for the modules and then accelerates within its limits.
"""

from __future__ import annotations

import math
from typing import Sequence



def choose_heading(theta: float, phi: float,
                   steering_range: tuple[float, float] | None = None) -> tuple[float, int]:
    """The heading ``theta + k pi`` [rad] of least travel from ``phi`` [rad],
    and the wheel's sign ``(-1)^k``.

    ``steering_range`` ``(min, max)`` [rad]: only headings inside it (a joint
    with a cable or a hard stop); it must be at least pi wide, so that one of
    every pair of opposite headings lies in it (ValueError otherwise).
    """
    if steering_range is None:
        k = round((phi - theta) / math.pi)
        return theta + k * math.pi, (-1 if k % 2 else 1)
    low, high = steering_range
    if not high - low >= math.pi:
        raise ValueError(f"steering range ({low:g}, {high:g}) rad: must be at least pi wide "
                         "(a module must reach one of every two opposite headings)")
    best = None
    for k in range(math.ceil((low - theta) / math.pi), math.floor((high - theta) / math.pi) + 1):
        heading = theta + k * math.pi
        travel = abs(heading - phi)
        if best is None or travel < best[0]:
            best = (travel, heading, -1 if k % 2 else 1)
    return best[1], best[2]


def module_command(vx: float, vy: float, ax: float, ay: float, phi: float, radius: float,
                   gain: float, hold_speed: float,
                   steering_range: tuple[float, float] | None = None) -> tuple[float, float]:
    """(steering rate [rad/s], wheel rate [rad/s]) of one module.

    ``(vx, vy)`` [m/s] and ``(ax, ay)`` [m/s^2]: the velocity and
    acceleration its steering axis must have (base_link); ``phi`` [rad]
    the measured heading; ``radius`` [m]; ``gain`` k_s [1/s];
    ``hold_speed`` [m/s]; ``steering_range`` as :func:`choose_heading`.
    """
    steer, wheel, _ = module_law(vx, vy, ax, ay, phi, radius, gain, hold_speed, steering_range)
    return steer, wheel


def module_law(vx: float, vy: float, ax: float, ay: float, phi: float, radius: float,
               gain: float, hold_speed: float,
               steering_range: tuple[float, float] | None = None) -> tuple[float, float, float]:
    """:func:`module_command` and the module's remaining steering error
    ``|eps|`` [rad] (0 while it holds its heading)."""
    speed = math.hypot(vx, vy)
    c, s = math.cos(phi), math.sin(phi)
    if speed == 0.0 or (speed < hold_speed and vx * ax + vy * ay <= 0.0):
        return 0.0, (vx * c + vy * s) / radius, 0.0
    heading, sign = choose_heading(math.atan2(vy, vx), phi, steering_range)
    error = heading - phi
    wheel = sign * speed * max(math.cos(error), 0.0) / radius
    feed_forward = (vx * ay - vy * ax) / (speed * speed)
    return gain * error + feed_forward, wheel, abs(error)


def drive_fraction(worst_error: float, window: float) -> float:
    """The fraction ``kappa`` in [0, 1] of their rates the wheels drive when
    the worst module is ``worst_error`` [rad] from its heading: 1 up to
    ``window / 5``, 0 from ``window`` [rad] on, linear between; ``window``
    0: always 1 (the cosine scaling alone)."""
    if window <= 0.0:
        return 1.0
    full = 0.2 * window
    if worst_error <= full:
        return 1.0
    return max(0.0, (window - worst_error) / (window - full))


def desaturate(wheel_rates: Sequence[float], max_rates: Sequence[float]) -> tuple[list[float], float]:
    """Every wheel rate scaled by one factor so that none exceeds its limit
    [rad/s]: the modules' speeds keep their ratios, so the base keeps the
    twist's direction and only goes slower. Returns (rates, factor <= 1)."""
    factor = 1.0
    for rate, limit in zip(wheel_rates, max_rates):
        if abs(rate) > limit:
            factor = min(factor, limit / abs(rate))
    return [rate * factor for rate in wheel_rates], factor
