"""Calibrate the servos against the reference poses (docs/on_the_robot.md, "Calibration").

    python -m quadruped_control.bringup.calibrate [--poses] [--fake [--faults SPEC]] [--bus N] [--out PATH]

Outputs off, you put the limp legs in the ``open`` then the ``stance`` pose (a prompt each); then each servo
is swept about the stance. Every finding names the joint and the fix, and then nothing is written (exit 1);
otherwise the fitted zeros, gains and feedback maps are written to ``--out`` (default: the calibration file).
``--fake``: the simulated rig (no prompts), built wrong by ``--faults`` (a file or an inline YAML mapping of
:mod:`quadruped_drivers.hardware_faults`).
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time
from typing import Callable, Optional, Sequence

from quadruped_common.config import ParameterError, config_path
from quadruped_control.bringup.reference import ReferencePose, reference_poses
from quadruped_control.bringup.servo_check import DriverBench, ServoCheck, ServoCheckResult, ServoCheckSettings
from quadruped_control.model.params import RobotParams, load_robot_params
from quadruped_drivers.servo_rig import PoseDriver, SimulatedServoRig
from quadruped_drivers.calibration import ServoCalibration, load_servo_calibration, save_servo_calibration
from quadruped_drivers.hardware_config import HardwareConfig, load_hardware_config
from quadruped_drivers.hardware_faults import HardwareFaults, load_hardware_faults
from quadruped_drivers.i2c.real_bus import I2CBackendError
from quadruped_drivers.node_support import open_bus
from quadruped_drivers.pwm_output import ServoPwmOutput
from quadruped_drivers.servo_feedback import ServoFeedbackArray


def run_on_rig(rig: SimulatedServoRig, hardware: HardwareConfig, calibration: ServoCalibration,
               params: RobotParams, settings: ServoCheckSettings = ServoCheckSettings(),
               log: Callable[[str], None] = lambda line: None) -> ServoCheckResult:
    """The calibration on a simulated rig; the rig's hand places the legs."""
    return _run(rig.bus, rig.clock, rig.sleep, lambda pose: rig.place(pose.joint_angles()), hardware, calibration,
                params, settings, log)


def speeds_on_rig(rig: SimulatedServoRig, hardware: HardwareConfig, calibration: ServoCalibration,
                  params: RobotParams, settings: ServoCheckSettings = ServoCheckSettings()) -> ServoCheckResult:
    """The pre-dive check's speed check (:meth:`ServoCheck.check_speeds`) on a simulated rig whose limp legs are at
    the stance, read through ``calibration`` (a passed calibration's)."""
    def speeds(check: ServoCheck) -> ServoCheckResult:
        check.bench.current = check._mean(check.bench.read_angles, powered=False)  # where the legs are, limp
        return check.check_speeds(reference_poses(params)[0])
    return _run(rig.bus, rig.clock, rig.sleep, lambda pose: rig.place(pose.joint_angles()), hardware, calibration,
                params, settings, lambda line: None, speeds)


def _run(bus, clock, sleep, place: Callable[[ReferencePose], None], hardware: HardwareConfig,
         calibration: ServoCalibration, params: RobotParams, settings: ServoCheckSettings,
         log: Callable[[str], None],
         procedure: Callable[[ServoCheck], ServoCheckResult] = lambda check: check.calibrate(
             reference_poses(check.params))) -> ServoCheckResult:
    pwm = ServoPwmOutput(bus, hardware, clock=clock, sleep=sleep)
    feedback = ServoFeedbackArray(bus, hardware, calibration, clock=clock)
    try:
        pwm.start()
        feedback.start()
        bench = DriverBench(PoseDriver(pwm, feedback, calibration, clock=clock, sleep=sleep), pwm)
        return procedure(ServoCheck(bench, params, calibration, place, settings, log))
    finally:
        pwm.shutdown()


def _prompt(pose: ReferencePose) -> None:
    input("Put every leg in the %s pose: %s. Press Enter when done. " % (pose.name, pose.instruction))


def _parse_args(argv: Optional[Sequence[str]]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m quadruped_control.bringup.calibrate",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--poses", action="store_true", help="print the reference poses' joint angles and exit")
    parser.add_argument("--fake", action="store_true", help="the simulated rig instead of the I2C bus")
    parser.add_argument("--faults", default="", help="--fake: the rig built wrong (file or inline YAML mapping)")
    parser.add_argument("--seed", type=int, default=0, help="--fake: noise seed")
    parser.add_argument("--bus", type=int, default=None, help="I2C bus number (default: hardware.yaml i2c.bus)")
    parser.add_argument("--hardware", default=None, help="hardware.yaml (default: config/hardware.yaml)")
    parser.add_argument("--calibration", default=None, help="calibration to start from (default: config/)")
    parser.add_argument("--out", default=None, help="where to write (default: the --calibration file; with "
                        "--fake: out/servo_calibration.fake.yaml)")
    parser.add_argument("--settle", type=float, default=ServoCheckSettings.settle_s, help="wait per sweep point (s)")
    parser.add_argument("--zero-tolerance", type=float, default=ServoCheckSettings.zero_tolerance_deg,
                        help="largest zero error written rather than reported (deg)")
    args = parser.parse_args(argv)
    if not (math.isfinite(args.settle) and args.settle >= 0.0):
        parser.error("--settle must be >= 0")
    if not (math.isfinite(args.zero_tolerance) and args.zero_tolerance > 0.0):
        parser.error("--zero-tolerance must be > 0")
    if args.faults and not args.fake:
        parser.error("--faults needs --fake (the real robot's faults are what this finds)")
    return args


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Exit code: 0 written, 1 findings (nothing written), 2 set-up error."""
    args = _parse_args(argv)
    try:
        hardware = load_hardware_config(args.hardware)
        source = args.calibration or config_path("servo_calibration.yaml")
        calibration = load_servo_calibration(source)
        params = load_robot_params()
        faults = load_hardware_faults(args.faults) if args.fake else HardwareFaults()
        poses = reference_poses(params)
    except (ParameterError, ValueError) as exc:
        print("calibrate: configuration error: %s" % exc, file=sys.stderr)
        return 2
    if args.poses:
        for pose in poses:
            print("%-7s theta1 %7.1f  theta2 %7.1f  theta3 %7.1f deg: %s"
                  % ((pose.name,) + tuple(math.degrees(v) for v in pose.leg_angles) + (pose.instruction,)))
        return 0
    settings = ServoCheckSettings(settle_s=args.settle, zero_tolerance_deg=args.zero_tolerance)
    try:
        if args.fake:
            rig = SimulatedServoRig(hardware, calibration, seed=args.seed, faults=faults)
            result = run_on_rig(rig, hardware, calibration, params, settings, log=print)
            out = args.out or os.path.join("out", "servo_calibration.fake.yaml")
        else:
            try:
                bus = open_bus("real", hardware.i2c_bus if args.bus is None else args.bus, "")  # alone on the bus
            except (OSError, I2CBackendError, ValueError) as exc:
                print("calibrate: %s" % exc, file=sys.stderr)
                return 2
            result = _run(bus, time.monotonic, time.sleep, _prompt, hardware, calibration, params, settings, print)
            out = args.out or source
    except Exception as exc:  # bus or chip failure: outputs went off in _run's finally
        print("calibrate: error: %s: %s (nothing written)" % (type(exc).__name__, exc), file=sys.stderr)
        return 2
    if not result.passed:
        for finding in result.findings:
            print("calibrate: FOUND %s" % finding, file=sys.stderr)
        print("calibrate: %d finding(s); nothing written" % len(result.findings), file=sys.stderr)
        return 1
    assert result.calibration is not None
    save_servo_calibration(result.calibration, out, "zeros, gains and feedback fitted against the reference "
                           "poses %s%s" % (time.strftime("%Y-%m-%d %H:%M"), " (FAKE rig)" if args.fake else ""))
    for joint in result.calibration.joints:
        print("%-12s neutral %7.1f us  %5.2f us/deg  feedback %6.2f deg/V %+8.2f deg"
              % (joint.name, joint.neutral_us, math.radians(joint.us_per_rad) , math.degrees(joint.feedback_slope),
                 math.degrees(joint.feedback_offset)))
    print("calibrate: wrote %s" % out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
