"""Which stamped commands the controller takes, and how old they are.

With ``cmd_vel_stamped`` the base controller subscribes ``cmd_vel`` as a
``geometry_msgs/TwistStamped``, whose stamp says when the publisher sampled
the command. A command is taken when its age (the node's clock now minus the
stamp) lies in the window ``[-FUTURE_TOLERANCE, cmd_timeout]``:

* a stamp up to ``FUTURE_TOLERANCE`` ahead of the node's clock is a clock
  offset between two hosts, not a command from the future; it counts as
  sent now (age 0);
* an older command is dated back by its age, so that it goes stale at
  ``stamp + cmd_timeout`` rather than ``cmd_timeout`` after it arrived
  (a command delayed 0.2 s on the way stops the base 0.2 s earlier);
* outside the window it is refused (the old age bound only when
  ``cmd_timeout`` > 0: 0 disables the timeout, and with it this bound).

ROS-free: the node's callback hands the stamp and its clock to
:func:`stamped_command_age` and dates the command it hands on by the age.
"""

from __future__ import annotations

#: [s] how far ahead of the node's clock a command's stamp may be
FUTURE_TOLERANCE = 0.1


def stamped_command_age(now: float, stamp: float, cmd_timeout: float
                        ) -> tuple[float | None, str | None]:
    """``(age [s] to date the command back by, None)`` when the command is
    taken, ``(None, why not)`` when it is refused.

    ``now`` [s]: the node's clock; ``stamp`` [s]: the command's stamp on the
    same clock; ``cmd_timeout`` [s] (0: no timeout). The age is never
    negative: a stamp slightly in the future counts as now.
    """
    age = now - stamp
    if age < -FUTURE_TOLERANCE or (cmd_timeout > 0.0 and age > cmd_timeout):
        return None, (f"cmd_vel stamped {age:+.3f} s from now rejected (allowed: "
                      f"-{FUTURE_TOLERANCE:g} s to cmd_timeout={cmd_timeout:g} s old)")
    return max(age, 0.0), None
