"""The tank model's restoring torque, and the trim that matches a static pull on the real robot.

    python -m quadruped_control.studies.trim [--tank-yaml YAML] [--robot-yaml YAML]
        [--pull {roll,pitch} TILT_DEG TORQUE_NM]

Why: the identification (docs/identification.md) finds that the strokes deliver only 0.01-0.04 N m, so
the restoring torque of the hanging robot decides what the simulator predicts, and no fit can pin it
down: a tenth of a millimetre of the centre of buoyancy changes the outcomes. It is measured instead. Hold
the robot still in the tank at a known tilt with its legs at their nominal stance (a spring balance on a
lever, or a line to a load cell) and read the torque that holds it; this tool prints the torque the model
gives at that tilt and the height of the centre of buoyancy (``hydrostatics.center_of_buoyancy`` z of
tank.yaml) that makes the model give the measured one.

The model's torque is :meth:`~quadruped_control.sim.plants.tank.TankModel.restoring_torque`: the plant's
own moment at rest (torso buoyancy at the centre of buoyancy, paw buoyancy at the feet, the rope's static
tension at the hook, the rope straight above it). It is linear in the centre of buoyancy's height (the
torso buoyancy's arm), so two evaluations give the height exactly. Signs: a tilt is positive about the
body's +x (roll) or +y (pitch) axis; the *held* torque is the one the pull applies, about the same axis,
positive when it holds the robot against a restoring torque (the model's restoring torque is its
negative).
"""
from __future__ import annotations

import argparse
import math
import sys
from typing import Dict, List, Optional, Sequence

import numpy as np

from quadruped_common.config import ParameterError
from quadruped_common.so3 import rpy_to_rot
from quadruped_control.model.params import RobotParams, load_robot_params
from quadruped_control.sim.plants.tank import VALIDITY_NOTE, TankModel
from quadruped_control.sim.plants.tank_params import TankParams, load_tank_params
from quadruped_control.sim.simulation import nominal_joint_angles

__all__ = ["AXES", "TILTS_DEG", "cob_z_for_pull", "main", "restoring_curve"]

#: Tilt axes: name -> body axis index (roll about x, pitch about y).
AXES = {"roll": 0, "pitch": 1}
#: Tilts of the printed curve, degrees: those of Table 1.
TILTS_DEG = (15.0, 30.0, 45.0, 60.0, 75.0, 90.0)
#: Height of the centre of buoyancy that identify.PARAMETERS calls plausible (m): a trimmed robot.
PLAUSIBLE_COB_Z = (-0.004, 0.004)


def _tilt(axis: str, tilt_deg: float) -> np.ndarray:
    if axis not in AXES:
        raise ValueError("axis must be one of %s, got %r" % (", ".join(AXES), axis))
    if not (math.isfinite(tilt_deg) and 0.0 < abs(tilt_deg) < 180.0):
        raise ValueError("tilt must be finite, non-zero and within +-180 deg, got %r" % (tilt_deg,))
    angles = [0.0, 0.0, 0.0]
    angles[AXES[axis]] = math.radians(tilt_deg)
    return rpy_to_rot(*angles)


def restoring_curve(robot: RobotParams, tank: TankParams, axis: str, tilts_deg: Sequence[float]) -> List[float]:
    """The model's restoring torque about ``axis`` (N m) at each tilt (degrees), legs at the nominal stance
    (:func:`~quadruped_control.sim.simulation.nominal_joint_angles`)."""
    model, q = TankModel(robot, tank), nominal_joint_angles(robot)
    return [float(model.restoring_torque(_tilt(axis, a), q)[AXES[axis]]) for a in tilts_deg]


def cob_z_for_pull(robot: RobotParams, tank: TankParams, axis: str, tilt_deg: float, held_torque: float) -> float:
    """The height of the centre of buoyancy (m, relative to the centre of mass; its x and y as in ``tank``)
    at which the model needs ``held_torque`` (N m, module docstring) to hold the robot at ``tilt_deg``."""
    if not math.isfinite(held_torque):
        raise ValueError("held torque must be finite, got %r" % (held_torque,))
    x, y, z0 = tank.center_of_buoyancy
    probe = z0 + 0.001

    def restoring(z: float) -> float:
        return restoring_curve(robot, tank.with_values(center_of_buoyancy=(x, y, z)), axis, [tilt_deg])[0]

    at_z0 = restoring(z0)
    slope = (restoring(probe) - at_z0) / (probe - z0)
    if slope == 0.0:
        raise ValueError("the model's torque does not depend on the centre of buoyancy (hydrostatics off or no "
                         "torso buoyancy in this tank.yaml)")
    return z0 + (-held_torque - at_z0) / slope


def _report(robot: RobotParams, tank: TankParams, pull: Optional[Sequence[str]]) -> str:
    lines = ["Restoring torque of the model, legs at the nominal stance (N m; negative: back towards level):",
             "", "| tilt [deg] | %s |" % " | ".join("%g" % a for a in TILTS_DEG),
             "|---|%s" % ("---|" * len(TILTS_DEG))]
    curves: Dict[str, List[float]] = {axis: restoring_curve(robot, tank, axis, TILTS_DEG) for axis in AXES}
    for axis, torques in curves.items():
        lines.append("| %s | %s |" % (axis, " | ".join("%.4f" % v for v in torques)))
    if pull is not None:
        axis, tilt, held = pull[0], float(pull[1]), float(pull[2])
        model = -restoring_curve(robot, tank, axis, [tilt])[0]
        z = cob_z_for_pull(robot, tank, axis, tilt, held)
        low, high = PLAUSIBLE_COB_Z
        lines += ["", "Pull in %s at %g deg: it held %.4f N m; the model needs %.4f N m there." % (
                      axis, tilt, held, model),
                  "The model needs %.4f N m with the centre of buoyancy at z = %.5f m (now %.5f m); in tank.yaml:" % (
                      held, z, tank.center_of_buoyancy[2]),
                  "  hydrostatics:", "    center_of_buoyancy: [%r, %r, %.6g]" % (
                      tank.center_of_buoyancy[0], tank.center_of_buoyancy[1], z)]
        if not low <= z <= high:
            lines.append("This lies outside the %g..%g mm the identification calls plausible for a trimmed robot: "
                         "check the pull, or the net weight and hook of this tank.yaml." % (1e3 * low, 1e3 * high))
    return "\n".join(lines)


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--tank-yaml", default=None, help="tank parameters (default: config/tank.yaml)")
    parser.add_argument("--robot-yaml", default=None, help="robot parameters (default: config/robot.yaml)")
    parser.add_argument("--pull", nargs=3, metavar=("AXIS", "TILT_DEG", "TORQUE_NM"),
                        help="a static pull: the torque (N m) that held the robot at TILT_DEG of roll or pitch")
    args = parser.parse_args(argv)
    if args.pull is not None:
        try:
            _tilt(args.pull[0], float(args.pull[1]))
            if not math.isfinite(float(args.pull[2])):
                raise ValueError("the torque must be a finite number of N m, got %r" % args.pull[2])
        except ValueError as exc:
            parser.error("--pull: %s" % exc)
    try:
        robot, tank = load_robot_params(args.robot_yaml), load_tank_params(args.tank_yaml)
        print(_report(robot, tank, args.pull))
        print("\nNote: %s." % VALIDITY_NOTE)  # the curve is the model's: what a pull is checked against
    except (ParameterError, ValueError, OSError) as exc:
        print("trim: %s" % exc, file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
