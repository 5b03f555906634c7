"""The servo's position loop: a first-order lag with a speed limit, the model the simulated robot's servos
follow (:mod:`quadruped_control.sim.servo_model`) and the tracking watch predicts the real ones with
(:mod:`quadruped_control.control.servo_watch`)."""
from __future__ import annotations

import math

from quadruped_common.jit import jitable

__all__ = ["rate_limited_lag_step"]


@jitable
def rate_limited_lag_step(q: float, command: float, max_speed: float, time_constant: float, dt: float) -> float:
    """One joint of :class:`RateLimitedServo` after ``dt`` s with ``command`` held: the exact solution of
    dq/dt = clip((q_cmd - q) / T, -w_max, w_max).

    With e = q_cmd - q the joint runs at w_max for t_sat = max(0, (|e| - w_max T) / w_max), then the
    error decays as exp(-t / T) from |e| <= w_max T; T <= 1e-9 dt is a pure rate limiter (no overflow
    in dt / T). On floats: twelve joints per step are faster than a dozen small numpy operations. A NaN
    command or angle gives NaN.
    """
    error = command - q
    if error != error:
        return error
    if time_constant <= 1e-9 * dt:
        step = max_speed * dt
        if error > 0.0:
            return q + (error if error < step else step)
        if error < 0.0:
            return q - (-error if -error < step else step)
        return q
    magnitude = error if error >= 0.0 else -error
    knee = max_speed * time_constant  # |e| below which the lag is linear
    t_saturated = (magnitude - knee) / max_speed if magnitude > knee else 0.0
    if t_saturated >= dt:
        new_magnitude = magnitude - max_speed * dt
    else:
        new_magnitude = (magnitude if magnitude < knee else knee) * math.exp(-(dt - t_saturated) / time_constant)
    if error > 0.0:
        return command - new_magnitude
    if error < 0.0:
        return command + new_magnitude
    return command
