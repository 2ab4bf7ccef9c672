"""Step-response figures of a sampled signal: rise time, overshoot, settling, error.

ROS-free. The usual control-textbook definitions, measured on samples with
linear interpolation between them (so a 1 kHz record resolves a rise time of
a few milliseconds):

* final value ``y_f``: mean of the last ``tail`` fraction of the record;
* rise time: from the first crossing of 10 % of ``y_f`` to the first crossing
  of 90 % of ``y_f`` [s];
* overshoot: ``(max y - y_f) / |y_f|`` [-], 0 when the record never exceeds ``y_f``;
* settling time: from the step to when ``y`` enters the +-2 % band around
  ``y_f`` for the last time [s];
* steady-state error: ``target - y_f`` (in the signal's unit).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np


@dataclass(frozen=True)
class StepResponse:
    """Figures of one step (seconds, the signal's unit, fractions)."""

    target: float
    final_value: float
    rise_time_s: float
    overshoot: float
    settling_time_s: float
    steady_state_error: float

    def as_dict(self) -> dict:
        return asdict(self)


def _crossing(t: np.ndarray, y: np.ndarray, level: float) -> float:
    """First time [s] the record reaches ``level`` (rising), interpolated."""
    above = np.nonzero(y >= level)[0]
    if len(above) == 0:
        return float("nan")
    k = int(above[0])
    if k == 0:
        return float(t[0])
    t0, t1, y0, y1 = t[k - 1], t[k], y[k - 1], y[k]
    return float(t0 + (level - y0) / (y1 - y0) * (t1 - t0))


def step_response(t, y, target: float, t_step: float, band: float = 0.02,
                  tail: float = 0.2) -> StepResponse:
    """Figures of the response ``y`` (samples at times ``t`` [s], the first at
    or before ``t_step``, the time the step was commanded) to a step from 0 to
    ``target``. Raises ValueError when the record is too short or the
    response never leaves zero."""
    t = np.asarray(t, float)
    y = np.asarray(y, float)
    if len(t) != len(y) or len(t) < 10:
        raise ValueError("a step record needs at least 10 samples of (t, y)")
    n_tail = max(1, int(round(tail * len(y))))
    final = float(np.mean(y[-n_tail:]))
    if final == 0.0 or np.sign(final) != np.sign(target):
        raise ValueError(f"the response ended at {final:g}, not towards the target {target:g}")
    sign = np.sign(final)
    ys, fs = y * sign, final * sign                  # a rising response
    rise = _crossing(t, ys, 0.9 * fs) - _crossing(t, ys, 0.1 * fs)
    overshoot = max(0.0, (float(ys.max()) - fs) / fs)
    outside = np.nonzero(np.abs(ys - fs) > band * fs)[0]
    if len(outside) == 0:
        settling = 0.0
    elif outside[-1] == len(ys) - 1:
        settling = float("nan")                      # never settled within the record
    else:
        k = int(outside[-1])
        # enter the band between sample k (outside) and k + 1 (inside)
        edge = fs + band * fs * np.sign(ys[k] - fs)
        frac = (edge - ys[k]) / (ys[k + 1] - ys[k])
        settling = float(t[k] + frac * (t[k + 1] - t[k])) - t_step
    return StepResponse(target=float(target), final_value=final, rise_time_s=float(rise),
                        overshoot=overshoot, settling_time_s=settling,
                        steady_state_error=float(target - final))
