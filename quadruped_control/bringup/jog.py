"""Jog one servo at a time from the keyboard, in small steps (docs/on_the_robot.md, "Jog").

    python -m quadruped_control.bringup.jog [--backend real|sim] [--bus N] [--bus-socket PATH] [--joint NAME]
                                            [--keys STRING [--settle S]] [--fake]

The status line shows the selected joint live: its commanded angle, the pulse width the chip outputs, its
feedback angle, its joint limits and the range it may be jogged over from where it is. A servo gets pulses
only once it is jogged: its first command is its feedback angle (it holds where it is) and steps move it from
there; a servo jogged before stays held at its last command; a servo never jogged stays limp (its output off).
A step that would leave the joint's limits (robot.yaml joint_limits_deg, the channel's pulse limits) or, for a
five-bar motor, make the five-bar unsafe with the other motor where it is (:func:`five_bar_problem`), is
refused and the servo stays. The pulses are re-sent every :data:`COMMAND_PERIOD` (the PCA9685 watchdog trips
after 0.1 s without a command); on quit every output goes off.

The tool takes the I2C bus alone (:mod:`quadruped_drivers.i2c.bus_lock`): it refuses to start while the
stack's driver nodes hold it, naming them. ``--backend sim`` jogs the simulated robot (sim_node alone, e.g.
``rosrun underwater_quadruped sim_node``: sim.launch's driver nodes would hold its bus); ``--fake`` the in-process
simulated rig on virtual time. ``--keys`` plays a key sequence instead of the keyboard, each key followed by
``--settle`` seconds (``.``: only wait), then quits.
"""
from __future__ import annotations

import argparse
import math
import os
import select
import signal
import sys
import termios
import threading
import time
from typing import Callable, Dict, Optional, Sequence, TextIO, Tuple, Union

import numpy as np

from quadruped_common.config import ParameterError
from quadruped_common.robot import JOINT_NAMES
from quadruped_control.model.kinematics import five_bar_problem
from quadruped_control.model.params import RobotParams, load_robot_params
from quadruped_drivers.calibration import ServoCalibration, load_servo_calibration
from quadruped_drivers.hardware_config import HardwareConfig, load_hardware_config
from quadruped_drivers.i2c.real_bus import I2CBackendError
from quadruped_drivers.node_support import BACKENDS, open_bus
from quadruped_drivers.pwm_output import ServoPwmOutput
from quadruped_drivers.servo_feedback import ServoFeedbackArray
from quadruped_drivers.servo_rig import COMMAND_PERIOD, SimulatedServoRig

__all__ = ["BIG_STEP_DEG", "Jog", "KEY_HELP", "RawKeyboard", "STEP_DEG", "keyboard_loop", "main", "run_keys"]

#: One step and a big step (deg).
STEP_DEG = 1.0
BIG_STEP_DEG = 5.0
#: The keys: what each does (also the arrow keys: right/left next/previous, up/down +/- one step).
KEY_HELP = (("n", "next joint"), ("p", "previous joint"), ("+", "+%g deg" % STEP_DEG), ("-", "-%g deg" % STEP_DEG),
            ("]", "+%g deg" % BIG_STEP_DEG), ("[", "-%g deg" % BIG_STEP_DEG),
            ("h", "hold the joint where it is (pulses on, no step)"), ("?", "these keys"), ("q", "quit, outputs off"))
_STEPS = {"+": STEP_DEG, "=": STEP_DEG, "-": -STEP_DEG, "]": BIG_STEP_DEG, "[": -BIG_STEP_DEG, "h": 0.0}
_ARROWS = {"\x1b[A": "+", "\x1b[B": "-", "\x1b[C": "n", "\x1b[D": "p"}
_QUIT = ("q", "Q", "\x03", "\x04")  # q, Ctrl-C, Ctrl-D
#: Resolution of the check along a step's path and of the safe-range scan (rad).
SCAN_STEP = math.radians(0.5)
#: Feedback readings averaged for the angle a servo is first held at (one per command period).
FEEDBACK_SAMPLES = 5
#: Tolerances of the limit checks: an angle at a limit is inside it.
_ANGLE_EPS = 1e-6
_PULSE_EPS = 1e-3
#: The simulated robot's bus socket: sim_node's default (as the driver nodes').
DEFAULT_SOCKET = "/tmp/uq_sim_i2c.sock"


def _deg(value: float) -> str:
    return "%+.1f" % math.degrees(value) if math.isfinite(value) else "  n/a"


class Jog:
    """Jogs the servos through the real driver objects ``pwm`` and ``feedback`` (module docstring); no
    terminal, no ROS. Call :meth:`start`, then :meth:`handle_key` or :meth:`step` / :meth:`select`, with
    :meth:`tick` at least every :data:`COMMAND_PERIOD` in between (or :meth:`wait`), and :meth:`close`.

    ``commanded``: each joint's commanded angle (rad), NaN while it is limp. Messages (refusals, holds) go to
    ``log`` and :attr:`message`."""

    def __init__(self, pwm: ServoPwmOutput, feedback: ServoFeedbackArray, calibration: ServoCalibration,
                 hardware: HardwareConfig, params: RobotParams, clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep, log: Callable[[str], None] = lambda line: None) -> None:
        self.pwm = pwm
        self.feedback = feedback
        self.calibration = calibration
        self.hardware = hardware
        self.params = params
        self.clock = clock
        self.sleep = sleep
        self.log = log
        count = len(JOINT_NAMES)
        self.selected = 0
        self.commanded = np.full(count, np.nan)
        self.message = ""
        limits = params.joint_limits.as_array()
        self.limits = np.array([limits[i % 3] for i in range(count)])  # rad, per joint: (low, high)
        self.pulse_limits = np.stack([hardware.min_us, hardware.max_us], axis=1)
        self._samples = np.full((FEEDBACK_SAMPLES, count), np.nan)
        self._next_sample = 0
        self._safe_cache: Dict[Tuple[int, int, int], Optional[Tuple[float, float]]] = {}
        self._started = False

    # ---- the loop --------------------------------------------------------------------------------

    def start(self) -> None:
        """Outputs off (every servo limp), the ADCs configured, a few feedback readings taken."""
        self._started = True  # from here on, close() switches the outputs off
        self.pwm.start()
        failed = self.feedback.start()
        if failed:
            self._say("no answer from the feedback ADCs of %s (retried while jogging)"
                      % ", ".join(JOINT_NAMES[i] for i in failed))
        self.wait(FEEDBACK_SAMPLES * COMMAND_PERIOD)

    def pulses(self) -> np.ndarray:
        """The pulse widths sent: each held joint's commanded angle through the calibration, NaN for a limp
        one (its output stays off: :meth:`ServoPwmOutput.command`)."""
        held = np.isfinite(self.commanded)
        widths = self.calibration.angles_to_pulses(np.where(held, self.commanded, 0.0))
        return np.where(held, widths, np.nan)

    def tick(self) -> None:
        """Send the pulses (feeds the PWM watchdog), run the PWM checks, read the feedback once."""
        self.pwm.command(self.pulses())
        self.pwm.update()
        reading = self.feedback.read()
        self._samples[self._next_sample % FEEDBACK_SAMPLES] = reading.angles
        self._next_sample += 1

    def wait(self, seconds: float) -> None:
        """Let ``seconds`` pass, ticking every :data:`COMMAND_PERIOD` (as PoseDriver.hold)."""
        end = self.clock() + seconds
        while True:
            self.tick()
            remaining = end - self.clock()
            if remaining <= 0:
                return
            self.sleep(min(COMMAND_PERIOD, remaining))

    def close(self) -> bool:
        """Every output off and the chip asleep; True if that was written."""
        if not self._started:
            return True
        self._started = False
        ok = self.pwm.shutdown()
        self._say("outputs off" if ok else "could not switch the outputs off: switch the servo power off")
        return ok

    # ---- what the joints may do ------------------------------------------------------------------

    def feedback_angle(self, index: int) -> float:
        """Joint ``index``'s angle from its last :data:`FEEDBACK_SAMPLES` feedback readings (rad; NaN: none)."""
        column = self._samples[:, index]
        good = column[np.isfinite(column)]
        return float(np.mean(good)) if good.size else math.nan

    def current_angle(self, index: int) -> float:
        """Where joint ``index`` is: its command while held, else its feedback angle (rad)."""
        commanded = float(self.commanded[index])
        return commanded if math.isfinite(commanded) else self.feedback_angle(index)

    def pulse_of(self, index: int, angle: float) -> float:
        """The pulse width (us) that commands joint ``index`` to ``angle`` (rad)."""
        joint = self.calibration.joints[index]
        return joint.neutral_us + joint.direction * joint.us_per_rad * (angle - joint.neutral_angle_rad)

    def _partner(self, index: int) -> Optional[int]:
        """The other five-bar motor of joint ``index``'s leg (None for a hip)."""
        joint = index % 3
        return None if joint == 2 else index - joint + (1 - joint)

    def problem(self, index: int, angle: float) -> Optional[str]:
        """Why joint ``index`` may not be commanded to ``angle`` (rad), or None: its joint limits, its
        channel's pulse limits, and for a five-bar motor the five-bar with the other motor where it is."""
        name = JOINT_NAMES[index]
        low, high = self.limits[index]
        if not low - _ANGLE_EPS <= angle <= high + _ANGLE_EPS:
            return "%s at %s deg leaves its joint limits [%.0f, %.0f] deg" % (
                name, _deg(angle), math.degrees(low), math.degrees(high))
        pulse = self.pulse_of(index, angle)
        low_us, high_us = self.pulse_limits[index]
        if not low_us - _PULSE_EPS <= pulse <= high_us + _PULSE_EPS:
            return "%s at %s deg needs %.0f us, beyond its channel's pulse limits [%.0f, %.0f] us" % (
                name, _deg(angle), pulse, low_us, high_us)
        partner = self._partner(index)
        if partner is None:
            return None
        other = self.current_angle(partner)
        if not math.isfinite(other):
            return "%s: no feedback of %s, the five-bar cannot be checked" % (name, JOINT_NAMES[partner])
        theta1, theta2 = (angle, other) if index % 3 == 0 else (other, angle)
        why = five_bar_problem(theta1, theta2, self.params.five_bar)
        if why:
            return "%s at %s deg with %s at %s deg: unsafe five-bar: %s" % (
                name, _deg(angle), JOINT_NAMES[partner], _deg(other), why)
        return None

    def safe_range(self, index: Optional[int] = None) -> Optional[Tuple[float, float]]:
        """The angles (rad) joint ``index`` (default: the selected one) may be jogged over from where it is,
        the others where they are (scanned in :data:`SCAN_STEP`); None if where it is is not allowed."""
        index = self.selected if index is None else index
        here = self.current_angle(index)
        partner = self._partner(index)
        other = self.current_angle(partner) if partner is not None else 0.0
        if not (math.isfinite(here) and math.isfinite(other)):
            return None
        key = (index, int(round(here / SCAN_STEP)), int(round(other / SCAN_STEP)))
        if key not in self._safe_cache:
            if len(self._safe_cache) > 256:
                self._safe_cache.clear()
            self._safe_cache[key] = self._scan(index, here)
        return self._safe_cache[key]

    def _scan(self, index: int, here: float) -> Optional[Tuple[float, float]]:
        if self.problem(index, here):
            return None
        ends = []
        for sign in (-1.0, 1.0):
            angle = here
            while not self.problem(index, angle + sign * SCAN_STEP):
                angle += sign * SCAN_STEP
            bound = self.limits[index][0 if sign < 0 else 1]  # at most a scan step short of a limit
            if abs(bound - angle) < SCAN_STEP and not self.problem(index, bound):
                angle = bound
            ends.append(angle)
        return ends[0], ends[1]

    # ---- operations ------------------------------------------------------------------------------

    def select(self, joint: Union[int, str]) -> None:
        """Select joint ``joint`` (an index or a name of JOINT_NAMES); ValueError for another."""
        if isinstance(joint, str):
            if joint not in JOINT_NAMES:
                raise ValueError("no joint %r (joints: %s)" % (joint, ", ".join(JOINT_NAMES)))
            joint = JOINT_NAMES.index(joint)
        if not 0 <= joint < len(JOINT_NAMES):
            raise ValueError("no joint %r" % (joint,))
        self.selected = int(joint)

    def next(self) -> None:
        """Select the next joint (after the last: the first)."""
        self.selected = (self.selected + 1) % len(JOINT_NAMES)

    def previous(self) -> None:
        """Select the previous joint (before the first: the last)."""
        self.selected = (self.selected - 1) % len(JOINT_NAMES)

    def hold(self) -> bool:
        """Start the selected servo's pulses at its feedback angle (it holds where it is); True when held
        (already, or now). Refused without feedback, or when its pulse would be clamped (a jump)."""
        index = self.selected
        name = JOINT_NAMES[index]
        if math.isfinite(self.commanded[index]):
            return True
        angle = self.feedback_angle(index)
        if not math.isfinite(angle):
            self._say("refused: no feedback of %s: it cannot be held where it is" % name)
            return False
        pulse = self.pulse_of(index, angle)
        low_us, high_us = self.pulse_limits[index]
        if not low_us - _PULSE_EPS <= pulse <= high_us + _PULSE_EPS:
            self._say("refused: %s reads %s deg, which needs %.0f us, beyond its pulse limits [%.0f, %.0f] us: it "
                      "would jump" % (name, _deg(angle), pulse, low_us, high_us))
            return False
        self.commanded[index] = angle
        self.tick()
        why = self.problem(index, angle)
        self._say("%s held where it is, at %s deg%s" % (name, _deg(angle), " (%s)" % why if why else ""))
        return True

    def step(self, degrees: float) -> bool:
        """Move the selected servo by ``degrees`` (held first where it is if it was limp); a step whose path
        leaves the joint's limits or the five-bar's safe set is refused (the servo stays). True if moved."""
        if not self.hold():
            return False
        if degrees == 0.0:
            return True
        index = self.selected
        start = float(self.commanded[index])
        delta = math.radians(degrees)
        points = max(1, int(math.ceil(abs(delta) / SCAN_STEP)))
        for k in range(1, points + 1):
            why = self.problem(index, start + delta * k / points)
            if why:
                self._say("refused %+g deg: %s" % (degrees, why))
                return False
        self.commanded[index] = start + delta
        self.tick()
        self.message = ""
        return True

    def handle_key(self, key: str) -> bool:
        """Do what ``key`` says (:data:`KEY_HELP`; ``.`` does nothing); False: quit."""
        key = _ARROWS.get(key, key)
        if key in _QUIT:
            return False
        if key == "n":
            self.next()
        elif key == "p":
            self.previous()
        elif key in _STEPS:
            self.step(_STEPS[key])
        elif key == "?":
            self._say(key_help())
        elif key not in (".", " ", "\r", "\n"):
            self._say("key %r does nothing (%s)" % (key, key_help()))
        return True

    def status(self) -> str:
        """The selected joint's status line: commanded angle, pulse, feedback angle, limits, safe range."""
        index = self.selected
        commanded = float(self.commanded[index])
        low, high = np.degrees(self.limits[index])
        safe = self.safe_range(index)
        held = int(np.count_nonzero(np.isfinite(self.commanded)))
        line = ("%-12s (%2d/%d)  cmd %s  %6.1f us  fb %s deg  limits [%.0f, %.0f]  safe %s deg  held %d"
                % (JOINT_NAMES[index], index + 1, len(JOINT_NAMES),
                   "%s deg" % _deg(commanded) if math.isfinite(commanded) else "    limp",
                   self.pwm.applied_us[index], _deg(self.feedback_angle(index)), low, high,
                   "[%.1f, %.1f]" % (math.degrees(safe[0]), math.degrees(safe[1])) if safe else "none", held))
        if self.pwm.write_errors:
            line += "  PWM write errors %d" % self.pwm.write_errors
        return line

    def _say(self, text: str) -> None:
        self.message = text
        self.log(text)


def key_help() -> str:
    """The keys, one line."""
    return ", ".join("%s %s" % item for item in KEY_HELP)


# ---- the terminal ---------------------------------------------------------------------------------

class RawKeyboard:
    """Single keys from terminal ``fd`` without Enter or echo (Ctrl-C still interrupts); the terminal's
    settings come back on exit, however the block is left."""

    def __init__(self, fd: int) -> None:
        self.fd = fd
        self._saved: Optional[list] = None

    def __enter__(self) -> "RawKeyboard":
        self._saved = termios.tcgetattr(self.fd)
        raw = termios.tcgetattr(self.fd)
        raw[3] &= ~(termios.ICANON | termios.ECHO)
        raw[6][termios.VMIN] = 0
        raw[6][termios.VTIME] = 0
        termios.tcsetattr(self.fd, termios.TCSADRAIN, raw)
        return self

    def __exit__(self, *exc_info: object) -> None:
        if self._saved is not None:
            termios.tcsetattr(self.fd, termios.TCSADRAIN, self._saved)
            self._saved = None

    def read(self, timeout: float) -> Optional[str]:
        """One key (an arrow key's escape sequence whole), or None after ``timeout`` s without one."""
        ready, _, _ = select.select([self.fd], [], [], max(0.0, timeout))
        if not ready:
            return None
        data = os.read(self.fd, 1)
        if not data:
            return None
        if data == b"\x1b":
            more, _, _ = select.select([self.fd], [], [], 0.005)
            if more:
                data += os.read(self.fd, 2)
        return data.decode("utf-8", "replace")


def keyboard_loop(jog: Jog, keyboard: RawKeyboard, out: TextIO, idle: Callable[[float], None],
                  clock: Callable[[], float] = time.monotonic) -> None:
    """Tick the jog every :data:`COMMAND_PERIOD` (``clock``: the wall clock the keys are waited on), do each
    key, redraw the status line; ``idle`` passes the time of a wait to a simulated rig. Returns on quit."""
    out.write(key_help() + "\n")
    last_draw = -math.inf
    while True:
        ticked = clock()
        jog.tick()
        key = keyboard.read(ticked + COMMAND_PERIOD - clock())  # the next tick within the period
        idle(COMMAND_PERIOD)
        if key is not None:
            if not jog.handle_key(key):
                return
        now = clock()
        if key is not None or now - last_draw >= 0.1:
            out.write("\r%s\x1b[K" % jog.status())
            out.flush()
            last_draw = now


def run_keys(jog: Jog, keys: str, settle: float, out: TextIO) -> None:
    """Play ``keys``, each followed by ``settle`` s of ticks and a status line; stops at a quit key."""
    for key in keys:
        if not jog.handle_key(key):
            return
        jog.wait(settle)
        out.write("%r  %s\n" % (key, jog.status()))
        out.flush()


# ---- the command line -----------------------------------------------------------------------------

def _parse_args(argv: Optional[Sequence[str]]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m quadruped_control.bringup.jog",
                                     description=__doc__.split("\n\n")[0],
                                     epilog="keys: %s; arrows: right/left next/previous, up/down +/-%g deg"
                                     % (key_help(), STEP_DEG))
    parser.add_argument("--backend", choices=BACKENDS, default="real",
                        help="real: the I2C bus; sim: the simulated robot's bus socket (default real)")
    parser.add_argument("--bus", type=int, default=None, help="I2C bus number (default: hardware.yaml i2c.bus)")
    parser.add_argument("--bus-socket", default=DEFAULT_SOCKET,
                        help="--backend sim: sim_node's bus socket (default %s)" % DEFAULT_SOCKET)
    parser.add_argument("--fake", action="store_true", help="the in-process simulated rig (virtual time)")
    parser.add_argument("--joint", default=JOINT_NAMES[0], choices=JOINT_NAMES, metavar="NAME",
                        help="the joint selected first (default %s)" % JOINT_NAMES[0])
    parser.add_argument("--keys", default=None, help="play these keys instead of the keyboard, then quit")
    parser.add_argument("--settle", type=float, default=0.5, help="--keys: wait after each key (s)")
    parser.add_argument("--hardware", default=None, help="hardware.yaml (default: config/hardware.yaml)")
    parser.add_argument("--calibration", default=None, help="servo_calibration.yaml (default: config/)")
    parser.add_argument("--robot", default=None, help="robot.yaml (default: config/robot.yaml)")
    args = parser.parse_args(argv)
    if not (math.isfinite(args.settle) and args.settle >= 0.0):
        parser.error("--settle must be >= 0")
    if args.fake and args.backend != "real":
        parser.error("--fake is the in-process rig: it takes no --backend")
    return args


def _interrupt(number: int, frame: object) -> None:
    """SIGTERM, SIGHUP (the terminal closed): quit as on Ctrl-C, so the outputs go off (the chip would
    otherwise keep the last pulses: its watchdog is this process)."""
    raise KeyboardInterrupt


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Exit code: 0 quit, 2 set-up error (configuration, bus busy or not there) or a bus failure."""
    args = _parse_args(argv)
    try:
        hardware = load_hardware_config(args.hardware)
        calibration = load_servo_calibration(args.calibration)
        params = load_robot_params(args.robot)
    except (ParameterError, ValueError) as exc:
        print("jog: configuration error: %s" % exc, file=sys.stderr)
        return 2
    if args.keys is None and not sys.stdin.isatty():
        print("jog: the keyboard needs a terminal (or give --keys)", file=sys.stderr)
        return 2
    if args.fake:  # servos as the calibration file says: the feedback tells where they really are
        rig = SimulatedServoRig(hardware, calibration, slope_scale=1.0, offset_shift_deg=0.0)
        bus, clock, sleep, idle = rig.bus, rig.clock, rig.sleep, rig.sleep
    else:
        try:  # alone on the bus: refused while the driver nodes (or another tool) hold it
            bus = open_bus(args.backend, hardware.i2c_bus if args.bus is None else args.bus, args.bus_socket)
        except (OSError, I2CBackendError, ValueError) as exc:
            print("jog: %s" % exc, file=sys.stderr)
            return 2
        clock, sleep, idle = time.monotonic, time.sleep, (lambda seconds: None)
    out = sys.stdout
    pwm = ServoPwmOutput(bus, hardware, clock=clock, sleep=sleep)
    feedback = ServoFeedbackArray(bus, hardware, calibration, clock=clock)
    jog = Jog(pwm, feedback, calibration, hardware, params, clock=clock, sleep=sleep,
              log=lambda line: out.write("\r%s\x1b[K\n" % line if args.keys is None else line + "\n"))
    jog.select(args.joint)
    code = 0
    handlers = {}
    if threading.current_thread() is threading.main_thread():  # only there may signals be handled
        handlers = {number: signal.signal(number, _interrupt) for number in (signal.SIGTERM, signal.SIGHUP)}
    try:
        jog.start()
        if args.keys is not None:
            run_keys(jog, args.keys, args.settle, out)
        else:
            with RawKeyboard(sys.stdin.fileno()) as keyboard:
                keyboard_loop(jog, keyboard, out, idle)
    except KeyboardInterrupt:
        pass
    except Exception as exc:  # bus or chip failure: the outputs go off below
        print("\njog: error: %s: %s" % (type(exc).__name__, exc), file=sys.stderr)
        code = 2
    finally:
        try:
            if not jog.close():
                code = 2
        except Exception as exc:
            print("jog: could not switch the outputs off (%s): switch the servo power off" % exc, file=sys.stderr)
            code = 2
        for number, handler in handlers.items():
            signal.signal(number, handler)
    if args.keys is None:
        out.write("\n")
    return code


if __name__ == "__main__":
    sys.exit(main())
