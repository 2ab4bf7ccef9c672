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
  the wheel takes ``v . e(phi) / r``: no steering about at a zero command.
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
    speed = math.hypot(vx, vy)
    c, s = math.cos(phi), math.sin(phi)
    if speed < hold_speed:
        return 0.0, (vx * c + vy * s) / radius
    heading, sign = choose_heading(math.atan2(vy, vx), phi, steering_range)
    error = heading - phi
    wheel = sign * speed * max(math.cos(error), 0.0) / radius
    feed_forward = (vx * ay - vy * ax) / (speed * speed)
    return gain * error + feed_forward, wheel


def desaturate(wheel_rates: Sequence[float], max_rates: Sequence[float]) -> tuple[list[float], float]:
    """Every wheel rate scaled by one factor so that none exceeds its limit
    [rad/s]: the modules' speeds keep their ratios, so the base keeps the
    twist's direction and only goes slower. Returns (rates, factor <= 1)."""
    factor = 1.0
    for rate, limit in zip(wheel_rates, max_rates):
        if abs(rate) > limit:
            factor = min(factor, limit / abs(rate))
    return [rate * factor for rate in wheel_rates], factor
