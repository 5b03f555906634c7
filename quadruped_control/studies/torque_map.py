"""The torque the strokes deliver against the torque the controller asks for, on a clamped robot.

    python -m quadruped_control.studies.torque_map [--tank-yaml YAML] [--robot-yaml YAML]
        [--controller-yaml YAML] [--gains bench] [--axes roll pitch yaw] [--errors DEG ...]
        [--duration 40] [--settle 10] [--measured AXIS ERROR_DEG TORQUE_NM] ...

Why (docs/identification.md, "What the model misses, and why"): on the identified tank model the strokes' net torque
reaches half its largest value at 1-2 degrees of attitude error, where the experiment gains ask for a
tenth to a sixth of the 2 N m they saturate at. Beyond a few degrees the controller acts as a relay: the model
approaches at a steady rate and stops. The real robot overshoots and settles slowly, as a loop that stays
proportional over a wider range would. Which one the robot has is measured on a bench, and this tool
prints what the model predicts for that measurement.

The bench: hold the robot's body still (a clamp on a load cell, or the hanging robot held by a spring
balance on a lever about the axis), start the controller with the ``bench`` gain set of
config/controller.yaml (the experiment gains' K_p, no integral or derivative term) and a setpoint e degrees
away from the clamped attitude about one axis (clamped level: ``robot.launch gain_set:=bench roll:=e``;
for yaw, the heading the IMU reads plus e), and average the held torque from 10 s on
over 30 s (fifteen 2-s stroke cycles). Subtract the torque held with the controller off, then repeat for
each e. ``--measured AXIS ERROR_DEG TORQUE_NM`` puts such a reading beside the model's.

In the model, :class:`~quadruped_control.sim.plants.clamped.ClampedTank` holds the tank plant at rest,
level. The robot's own controller and the tank's servos run for ``duration`` s. The clamp's torque about
the axis is averaged from ``settle`` s on. Less the torque with the legs still at the nominal stance
(:meth:`~quadruped_control.sim.plants.tank.TankModel.restoring_torque`, zero for a symmetric trim), it
is the delivered torque. The commanded torque is the controller's tau_sat about the axis, averaged the
same way: K_p sin(e) with the bench gains, plus the buoyancy feedforward (the paws' moment at the
commanded feet). Signs: positive about the body's +x (roll), +y (pitch) or +z (yaw) axis, the direction
of the setpoint; a stroke scheme that pushes the wrong way gives a negative delivered torque.
"""
from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from quadruped_common.config import ParameterError
from quadruped_common.so3 import rpy_to_rot
from quadruped_control.control.controller_config import ControllerConfig, load_controller_config
from quadruped_control.model.params import RobotParams, load_robot_params
from quadruped_control.sim.plants.clamped import ClampedTank
from quadruped_control.sim.plants.tank import VALIDITY_NOTE, TankModel
from quadruped_control.sim.plants.tank_params import TankParams, load_tank_params
from quadruped_control.sim.servo_model import RateLimitedServo, ServoParams, load_servo_params, tank_servo_params
from quadruped_control.sim.simulation import ClosedLoopSimulation, nominal_joint_angles

__all__ = ["AXES", "BENCH_GAINS", "ERRORS_DEG", "MapPoint", "clamped_torque", "half_ceiling_error", "main",
           "torque_map"]

#: Axes: name -> body axis index.
AXES = {"roll": 0, "pitch": 1, "yaw": 2}
#: Gain set of config/controller.yaml for the bench: K_p alone.
BENCH_GAINS = "bench"
#: Attitude errors of the printed map, degrees: from well inside the experiment gains' 11.5 deg of
#: saturation (2 N m / K_p 10) to beyond it.
ERRORS_DEG = (0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0)


@dataclass(frozen=True)
class MapPoint:
    """One point of the map: the held error (deg) about ``axis``, and the mean commanded (tau_sat) and
    delivered torque about that axis (N m)."""

    axis: str
    error_deg: float
    commanded: float
    delivered: float


def _check(axis: str, error_deg: float, duration: float, settle: float, dt: float) -> None:
    if axis not in AXES:
        raise ValueError("axis must be one of %s, got %r" % (", ".join(AXES), axis))
    if not (math.isfinite(error_deg) and 0.0 < abs(error_deg) < 90.0):
        raise ValueError("the attitude error must be finite, non-zero and within +-90 deg, got %r" % (error_deg,))
    if not (math.isfinite(settle) and settle >= 0.0 and math.isfinite(duration) and duration - settle >= 10 * dt):
        raise ValueError("need 0 <= settle < duration (finite, at least 10 control periods to average), got "
                         "settle %r, duration %r" % (settle, duration))


def clamped_torque(robot: RobotParams, tank: TankParams, config: ControllerConfig, servo: ServoParams, axis: str,
                   error_deg: float, duration: float = 40.0, settle: float = 10.0) -> MapPoint:
    """The map's point at ``error_deg`` about ``axis`` (module docstring): the robot clamped level, its
    setpoint ``error_deg`` away, rate-limited servos with ``servo``'s parameters, ``duration`` s, averages
    from ``settle`` s on. ValueError for an unknown axis, a zero, non-finite or >= 90 deg error, or too
    short an averaging window."""
    _check(axis, error_deg, duration, settle, config.dt)
    index = AXES[axis]
    angles = [0.0, 0.0, 0.0]
    angles[index] = math.radians(error_deg)
    clamp = ClampedTank(TankModel(robot, tank))
    sim = ClosedLoopSimulation(robot, config, RateLimitedServo(servo), initial_R=np.eye(3),
                               setpoint_R=rpy_to_rot(*angles), model=clamp)
    steps = int(round(duration / sim.dt))
    first = int(round(settle / sim.dt))
    commanded = []
    for _ in range(steps):
        _, output = sim.step()
        commanded.append(float(output.state.tau_sat[index]))
    held = np.array(clamp.torques[first:], dtype=float)[:, index]
    still = float(clamp.model.restoring_torque(np.eye(3), nominal_joint_angles(robot))[index])
    return MapPoint(axis, float(error_deg), float(np.mean(commanded[first:])), float(np.mean(held)) - still)


def torque_map(robot: RobotParams, tank: TankParams, config: ControllerConfig, servo: ServoParams,
               axes: Sequence[str] = tuple(AXES), errors_deg: Sequence[float] = ERRORS_DEG,
               duration: float = 40.0, settle: float = 10.0) -> List[MapPoint]:
    """:func:`clamped_torque` for every axis and error (axis by axis, errors in the order given)."""
    return [clamped_torque(robot, tank, config, servo, axis, error, duration, settle)
            for axis in axes for error in errors_deg]


def half_ceiling_error(points: Sequence[MapPoint]) -> Optional[float]:
    """The smallest error (deg) at which the delivered torque reaches half the largest delivered among
    ``points`` (one axis, one sign of error): where the map turns from proportional to saturated. None
    if no point delivers a positive torque."""
    if not points:
        return None
    top = max(p.delivered for p in points)
    if not top > 0.0:
        return None
    return min(abs(p.error_deg) for p in points if p.delivered >= 0.5 * top)


def _report(points: Sequence[MapPoint], measured: Sequence[Sequence[str]],
            model: Dict[Tuple[str, float], MapPoint]) -> str:
    lines = ["Torque the strokes deliver on the clamped robot against the held command (N m, about the axis):",
             "", "| axis | error [deg] | commanded tau_sat | delivered | delivered / commanded |",
             "|---|---|---|---|---|"]
    for p in points:
        ratio = p.delivered / p.commanded if p.commanded != 0.0 else math.nan
        lines.append("| %s | %g | %.4f | %.5f | %.4f |" % (p.axis, p.error_deg, p.commanded, p.delivered, ratio))
    lines.append("")
    for axis in dict.fromkeys(p.axis for p in points):
        own = [p for p in points if p.axis == axis and p.error_deg > 0.0]
        knee = half_ceiling_error(own)
        lines.append("%s: half of the largest delivered torque (%s) is reached at %s." % (
            axis, "%.5f N m" % max(p.delivered for p in own) if own else "none",
            "%g deg" % knee if knee is not None else "no positive error"))
    for axis, error, torque in measured:
        point = model[(axis, float(error))]
        lines.append("Measured %s %s deg: %s N m held; the model delivers %.5f N m (measured / model %.2f)." % (
            axis, error, torque, point.delivered, float(torque) / point.delivered if point.delivered else math.nan))
    return "\n".join(lines)


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--tank-yaml", default=None, help="tank parameters (default: config/tank.yaml)")
    parser.add_argument("--robot-yaml", default=None, help="robot parameters (default: config/robot.yaml)")
    parser.add_argument("--controller-yaml", default=None,
                        help="controller parameters (default: config/controller.yaml)")
    parser.add_argument("--gains", default=BENCH_GAINS, help="gain set (default %(default)s: K_p alone)")
    parser.add_argument("--axes", nargs="+", default=list(AXES), choices=list(AXES))
    parser.add_argument("--errors", nargs="+", type=float, default=list(ERRORS_DEG), metavar="DEG",
                        help="held attitude errors, degrees (default %(default)s)")
    parser.add_argument("--duration", type=float, default=40.0, help="seconds per point (default %(default)s)")
    parser.add_argument("--settle", type=float, default=10.0,
                        help="seconds left out of the averages (default %(default)s)")
    parser.add_argument("--measured", nargs=3, action="append", default=[], metavar=("AXIS", "ERROR_DEG", "TORQUE_NM"),
                        help="a bench reading to compare (the model runs that point too); repeatable")
    args = parser.parse_args(argv)
    try:
        for axis, error, torque in args.measured:
            _check(axis, float(error), args.duration, args.settle, 0.01)
            if not math.isfinite(float(torque)):
                raise ValueError("the torque must be a finite number of N m, got %r" % torque)
        for error in args.errors:
            _check(args.axes[0], error, args.duration, args.settle, 0.01)
    except ValueError as exc:
        parser.error(str(exc))
    try:
        robot = load_robot_params(args.robot_yaml)
        tank = load_tank_params(args.tank_yaml)
        config = load_controller_config(args.controller_yaml, args.gains)
        servo = tank_servo_params(load_servo_params(robot_yaml=args.robot_yaml), tank)
        points = torque_map(robot, tank, config, servo, args.axes, args.errors, args.duration, args.settle)
        model = {(p.axis, p.error_deg): p for p in points}
        for axis, error, _ in args.measured:
            if (axis, float(error)) not in model:
                model[(axis, float(error))] = clamped_torque(robot, tank, config, servo, axis, float(error),
                                                             args.duration, args.settle)
        print(_report(points, args.measured, model))
        print("\nNote: %s." % VALIDITY_NOTE)  # the map is the model's: what a bench reading is checked against
    except (ParameterError, ValueError, OSError) as exc:
        print("torque_map: %s" % exc, file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
