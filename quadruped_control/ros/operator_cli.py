"""``uq``, the operator's commands over the tether: its arguments, its answers and exit codes (pure, no ROS).

The ROS side is :mod:`quadruped_control.ros.operator_tool` (``rosrun underwater_quadruped uq --help``):

- ``arm`` / ``disarm``: the controller's ``attitude_controller/arm`` service (SetBool);
- ``stop``: the e-stop, pwm_node's ``estop`` service (SetBool true; the ``estop`` topic when the service does not
  answer); ``reset``: ``estop`` false, then ``pwm_node/enable`` true (arm again after it);
- ``setpoint ROLL PITCH YAW`` (degrees, REP-103) on ``attitude_setpoint_rpy_deg``, in the yaw reference
  ``--relative`` / ``--absolute`` / ``--tilt`` names (header.frame_id; none: the controller's ``~yaw_reference``),
  confirmed once ``controller_state`` carries it;
- ``status``: one line: armed, holding, the e-stop, attitude and setpoint in degrees, why arming is refused;
- ``sequence NAME``: a named setpoint sequence of :data:`~quadruped_control.control.setpoint_sequence.PROTOCOLS`
  run by the maneuver node's code in this process, in the foreground (Ctrl-C ends it).

Each prints the answer (a service's message) and exits :data:`OK`, :data:`REFUSED` (the stack said no, or did not
do it), :data:`NO_ANSWER` (nothing answered within ``--timeout``) or 2 (bad arguments, argparse's).
"""
from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np

from quadruped_common.so3 import geodesic_angle, rpy_to_rot
from quadruped_control.control.attitude_degrees import RPY, wrap_degrees
from quadruped_control.control.setpoint_sequence import MAX_ANGLE_DEG, PROTOCOLS
from quadruped_control.control.yaw_reference import YAW_REFERENCES, WorldSetpoint, world_setpoint

__all__ = ["NO_ANSWER", "OK", "REFUSED", "SETPOINT_TOLERANCE", "Status", "build_parser", "expected_setpoint",
           "format_rpy", "format_status", "parse_args", "setpoint_answer", "setpoint_taken"]

OK, REFUSED, NO_ANSWER = 0, 1, 3
#: a setpoint counts as taken when controller_state's R_d is this close to the expected one (rad)
SETPOINT_TOLERANCE = math.radians(0.05)


def build_parser() -> argparse.ArgumentParser:
    """The parser of ``uq`` (module docstring)."""
    parser = argparse.ArgumentParser(prog="uq", description="The operator's commands to the underwater quadruped "
                                     "over the tether (the ROS master of ROS_MASTER_URI, names in ROS_NAMESPACE).")
    parser.add_argument("--timeout", type=float, default=5.0, metavar="S",
                        help="seconds to wait for a service, a subscriber or an answer (default 5)")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND")
    commands.required = True
    commands.add_parser("arm", help="arm the controller (refused, with every reason, while a check fails)")
    commands.add_parser("disarm", help="disarm the controller")
    commands.add_parser("stop", help="the e-stop: every servo limp, latched until reset")
    commands.add_parser("reset", help="reset the e-stop and enable the outputs again (then arm)")
    commands.add_parser("status", help="one line: armed, holding, e-stop, attitude and setpoint in degrees")
    setpoint = commands.add_parser("setpoint", help="an attitude setpoint in degrees")
    for axis in ("roll", "pitch", "yaw"):
        setpoint.add_argument(axis, type=float, help="%s, degrees (REP-103)" % axis)
    frames = setpoint.add_mutually_exclusive_group()
    for mode, what in zip(YAW_REFERENCES, ("yaw from the heading at arming", "yaw in world ENU (magnetic heading)",
                                           "roll and pitch only, yaw free")):
        frames.add_argument("--" + mode, dest="frame", action="store_const", const=mode, help=what)
    sequence = commands.add_parser("sequence", help="run a named setpoint sequence to its end (Ctrl-C stops it)")
    sequence.add_argument("name", choices=sorted(PROTOCOLS), help="the sequence")
    return parser


def parse_args(argv: Optional[Sequence[str]] = None) -> argparse.Namespace:
    """``uq``'s arguments (sys.argv[1:] for None); a setpoint angle not finite or beyond +-MAX_ANGLE_DEG and a
    timeout not positive end the program with exit status 2 and the reason."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not (math.isfinite(args.timeout) and args.timeout > 0.0):
        parser.error("--timeout must be a positive number of seconds, got %r" % args.timeout)
    if args.command == "setpoint":
        args.frame = args.frame or ""
        angles = (args.roll, args.pitch, args.yaw)
        if not all(math.isfinite(a) and abs(a) <= MAX_ANGLE_DEG for a in angles):
            parser.error("setpoint angles must be finite degrees within +-%g, got %s" % (MAX_ANGLE_DEG, angles))
    return args


def format_rpy(rpy: Optional[Sequence[float]]) -> str:
    """'roll R pitch P yaw Y deg' (one decimal), or 'unknown' (None, or a NaN)."""
    if rpy is None or not all(math.isfinite(v) for v in rpy):
        return "unknown"
    return "roll %.1f pitch %.1f yaw %.1f deg" % tuple(round(v, 1) + 0.0 for v in rpy)  # + 0.0: no "-0.0"


def _relative_yaw(yaw: float, heading: Optional[float]) -> str:
    if heading is None or not math.isfinite(heading):
        return ""
    return " (yaw %.1f from the heading at arming %.1f)" % (wrap_degrees(yaw - heading), heading)


@dataclass
class Status:
    """What ``uq status`` heard: controller_state's ``armed``, ``holding``, ``hold_reason``; telemetry's attitude
    ``rpy`` and world ``setpoint`` (deg, None: not heard) and ``heading`` at arming (deg, NaN or None: none yet);
    ``estop`` (None: not heard); ``arming``: the controller's arming diagnostic's message ("" not heard)."""

    armed: bool
    holding: bool
    hold_reason: str
    rpy: Optional[RPY] = None
    setpoint: Optional[RPY] = None
    heading: Optional[float] = None
    estop: Optional[bool] = None
    arming: str = ""


def format_status(status: Status) -> str:
    """The one line of ``uq status``: state, e-stop, attitude, setpoint (with its yaw from the heading at arming)
    and, disarmed, the arming diagnostic's verdict."""
    if not status.armed:
        state = "disarmed"
    elif status.holding:
        state = "armed, holding (%s)" % (status.hold_reason or "no reason given")
    else:
        state = "armed, stroking"
    estop = {None: "e-stop unknown (no estop_state)", True: "E-STOP LATCHED", False: "e-stop clear"}[status.estop]
    setpoint = format_rpy(status.setpoint)
    if status.setpoint is not None and setpoint != "unknown":
        setpoint += _relative_yaw(status.setpoint[2], status.heading)
    parts = [state, estop, "attitude " + format_rpy(status.rpy), "setpoint " + setpoint]
    if not status.armed and status.arming:
        parts.append(status.arming)
    return " | ".join(parts)


def expected_setpoint(rpy_deg: Sequence[float], mode: str, heading_deg: Optional[float]) -> WorldSetpoint:
    """The world setpoint the controller makes of ``rpy_deg`` in yaw reference ``mode`` given the heading at arming
    (deg; None or NaN: not armed yet), as :func:`~quadruped_control.control.yaw_reference.world_setpoint`."""
    psi_0 = None if heading_deg is None or not math.isfinite(heading_deg) else math.radians(heading_deg)
    return world_setpoint(rpy_to_rot(*np.radians(rpy_deg)), mode, psi_0)


def setpoint_taken(R_d: np.ndarray, target: WorldSetpoint, tolerance: float = SETPOINT_TOLERANCE) -> bool:
    """Whether controller_state's R_d is ``target`` (for a yaw-free one: has its tilt, the world vertical in the
    body frame, as the controller turns its yaw each step)."""
    if target.yaw_free:
        cosine = float(np.clip(np.dot(R_d[2], target.R_d[2]), -1.0, 1.0))
        return math.acos(cosine) <= tolerance
    return geodesic_angle(target.R_d, R_d) <= tolerance


def setpoint_answer(rpy_deg: Sequence[float], mode: str, world: Sequence[float], heading: Optional[float]) -> str:
    """The line ``uq setpoint`` prints once the controller has the setpoint: as given, and in world degrees."""
    line = "setpoint taken: %s, %s" % (format_rpy(rpy_deg), mode)
    if mode == "tilt":
        return line + " (yaw free)"
    return line + "; world %s%s" % (format_rpy(world), _relative_yaw(world[2], heading) if mode == "relative" else "")
