"""The jog tool on the simulated rig (virtual time): only the jogged servo gets pulses and moves, by the step,
from where it was; the others stay limp or held; steps out of the limits or the five-bar's safe set are
refused; scripted keys and the keyboard work; quitting switches the outputs off; a busy bus is refused."""
from __future__ import annotations

import dataclasses
import io
import math
import os
import re
import signal
import subprocess
import sys
import termios

import numpy as np
import pytest

from quadruped_common.robot import JOINT_NAMES
from quadruped_control.bringup import jog as jog_module
from quadruped_control.bringup.jog import Jog, RawKeyboard, keyboard_loop, run_keys
from quadruped_control.model.kinematics import five_bar_problem
from quadruped_control.model.params import load_robot_params
from quadruped_drivers.calibration import load_servo_calibration
from quadruped_drivers.hardware_config import load_hardware_config
from quadruped_drivers.hardware_faults import HardwareFaults, load_hardware_faults
from quadruped_drivers.i2c.bus_lock import BusLock
from quadruped_drivers.node_support import bus_name
from quadruped_drivers.pwm_output import ServoPwmOutput
from quadruped_drivers.servo_feedback import ServoFeedbackArray
from quadruped_drivers.servo_rig import COMMAND_PERIOD, SimulatedServoRig
from tests.repo import REPO_ROOT

HW, CAL, PARAMS = load_hardware_config(), load_servo_calibration(), load_robot_params()
HIP, MOTOR1, MOTOR2 = JOINT_NAMES.index("leg1_hip"), JOINT_NAMES.index("leg1_motor1"), JOINT_NAMES.index("leg1_motor2")
#: half a degree: feedback noise and ADC steps are far below, a missed or doubled step far above
TOLERANCE = math.radians(0.5)


def make(hardware=HW, noise_v: float = 0.0, faults: HardwareFaults = HardwareFaults(), angles=None):
    """A rig whose servos are the calibration file's (its feedback tells where they are) and a started jog."""
    rig = SimulatedServoRig(hardware, CAL, slope_scale=1.0, offset_shift_deg=0.0, noise_v=noise_v, faults=faults)
    if angles is not None:
        rig.place(angles)
    pwm = ServoPwmOutput(rig.bus, hardware, clock=rig.clock, sleep=rig.sleep)
    feedback = ServoFeedbackArray(rig.bus, hardware, CAL, clock=rig.clock)
    messages = []
    jog = Jog(pwm, feedback, CAL, hardware, PARAMS, clock=rig.clock, sleep=rig.sleep, log=messages.append)
    jog.start()
    return jog, rig, messages


def neutral() -> np.ndarray:
    return np.array([j.neutral_angle_rad for j in CAL.joints])


def test_a_step_moves_only_the_selected_servo_by_the_step_and_the_others_stay_limp():
    jog, rig, _ = make(noise_v=0.002)
    before = rig.angles.copy()
    assert np.all(rig.hardware.pulse_widths_us() == 0.0), "a servo got pulses before it was jogged"
    jog.select("leg1_hip")
    assert jog.step(5.0)
    jog.wait(0.5)
    moved = rig.angles - before
    assert moved[HIP] == pytest.approx(math.radians(5.0), abs=TOLERANCE)
    others = np.arange(12) != HIP
    assert np.all(moved[others] == 0.0)
    widths = rig.hardware.pulse_widths_us()
    assert widths[HIP] > 0.0 and np.all(widths[others] == 0.0)
    assert jog.step(-1.0) and jog.step(-1.0)
    jog.wait(0.5)
    assert rig.angles[HIP] - before[HIP] == pytest.approx(math.radians(3.0), abs=TOLERANCE)
    assert "leg1_hip" in jog.status() and "held 1" in jog.status()


def test_the_first_command_holds_the_servo_where_it_is():
    # the limp legs put somewhere else than the calibration's neutral angles, by hand
    placed = neutral() + np.tile(np.radians([-10.0, 8.0, -30.0]), 4)
    jog, rig, messages = make(noise_v=0.002, angles=placed)
    sent = []
    command = jog.pwm.command
    jog.pwm.command = lambda widths: sent.append(np.array(widths)) or command(widths)
    jog.select("leg1_hip")
    assert jog.hold()
    jog.wait(0.5)
    assert abs(rig.angles[HIP] - placed[HIP]) < TOLERANCE, "the servo jumped when its pulses started"
    first = next(widths[HIP] for widths in sent if np.isfinite(widths[HIP]))
    assert abs(first - jog.pulse_of(HIP, placed[HIP])) < CAL.joints[HIP].us_per_rad * TOLERANCE
    assert all(np.isnan(widths[np.arange(12) != HIP]).all() for widths in sent)  # the others: no pulse asked
    assert "held where it is" in messages[-1]
    assert jog.step(1.0)  # and the steps go from there
    jog.wait(0.3)
    assert rig.angles[HIP] - placed[HIP] == pytest.approx(math.radians(1.0), abs=TOLERANCE)


def test_a_servo_jogged_before_stays_held_and_the_watchdog_is_fed():
    jog, rig, _ = make(noise_v=0.002)
    times = []
    command = jog.pwm.command
    jog.pwm.command = lambda widths: times.append(rig.clock()) or command(widths)
    jog.select("leg1_hip")
    assert jog.step(5.0)
    jog.select("leg3_hip")
    assert jog.step(-5.0)
    jog.next()
    jog.wait(2.0)
    start = neutral()
    assert rig.angles[HIP] - start[HIP] == pytest.approx(math.radians(5.0), abs=TOLERANCE)
    leg3_hip = JOINT_NAMES.index("leg3_hip")
    assert rig.angles[leg3_hip] - start[leg3_hip] == pytest.approx(math.radians(-5.0), abs=TOLERANCE)
    widths = rig.hardware.pulse_widths_us()
    assert np.count_nonzero(widths) == 2 and widths[HIP] > 0 and widths[leg3_hip] > 0
    assert jog.pwm.watchdog_trips == 0
    assert max(np.diff(times)) <= COMMAND_PERIOD + 1e-9
    assert np.isnan(jog.commanded[JOINT_NAMES.index("leg4_motor1")])


def test_a_step_beyond_the_joint_limits_is_refused_and_the_servo_stays():
    placed = neutral()
    placed[HIP] = math.radians(176.5)
    jog, rig, messages = make(angles=placed)
    jog.select(HIP)
    assert not jog.step(5.0)
    assert "limits [0, 180]" in messages[-1] and "refused" in messages[-1]
    jog.wait(0.3)
    assert abs(rig.angles[HIP] - placed[HIP]) < TOLERANCE  # held where it was, not moved
    assert jog.step(1.0) and jog.step(1.0) and jog.step(1.0)
    assert not jog.step(1.0)
    jog.wait(0.3)
    assert math.degrees(rig.angles[HIP]) == pytest.approx(179.5, abs=0.5)
    low, high = jog.safe_range()
    assert math.degrees(high) == pytest.approx(180.0) and math.degrees(low) == pytest.approx(0.0, abs=0.5)


def test_a_step_beyond_the_channel_pulse_limits_is_refused():
    joints = list(HW.joints)
    joints[HIP] = dataclasses.replace(joints[HIP], min_us=1400.0, neutral_us=1500.0)
    narrow = dataclasses.replace(HW, joints=tuple(joints))
    jog, rig, messages = make(hardware=narrow)
    jog.select(HIP)
    floor = math.degrees(CAL.pulses_to_angles(np.full(12, 1400.0))[HIP])  # the hip's angle at 1400 us
    steps = int((90.0 - floor) // 5.0)
    for _ in range(steps):
        assert jog.step(-5.0)
    assert not jog.step(-5.0)
    assert "pulse limits [1400, 2500] us" in messages[-1]
    jog.wait(0.3)
    assert rig.hardware.pulse_widths_us()[HIP] >= 1400.0 - 5.0


def test_a_step_into_an_unsafe_five_bar_is_refused():
    # leg 1's motor2 a degree and a half inside the five-bar's safe set (motor1 where it is)
    theta1 = neutral()[MOTOR1]
    edge = neutral()[MOTOR2]
    while five_bar_problem(theta1, edge - math.radians(0.1), PARAMS.five_bar) is None:
        edge -= math.radians(0.1)
    placed = neutral()
    placed[MOTOR2] = edge + math.radians(1.5)
    jog, rig, messages = make(angles=placed)
    jog.select("leg1_motor2")
    assert not jog.step(-5.0)
    assert "unsafe five-bar" in messages[-1] and "leg1_motor1" in messages[-1]
    jog.wait(0.3)
    assert abs(rig.angles[MOTOR2] - placed[MOTOR2]) < TOLERANCE
    assert jog.step(1.0)  # away from the edge: allowed
    low, _ = jog.safe_range()
    assert five_bar_problem(theta1, low, PARAMS.five_bar) is None
    assert five_bar_problem(theta1, low - math.radians(1.0), PARAMS.five_bar) is not None
    # the other motor, now held at its command, limits motor1 the same way
    jog.select("leg1_motor1")
    assert jog.safe_range() is not None


def test_a_servo_without_feedback_is_not_driven():
    jog, rig, messages = make(faults=load_hardware_faults("{stuck_feedback_v: {leg1_hip: 5.0}}"))
    jog.select(HIP)
    assert not jog.step(1.0)
    assert "no feedback of leg1_hip" in messages[-1]
    assert np.all(rig.hardware.pulse_widths_us() == 0.0)
    assert "limp" in jog.status() and "safe none" in jog.status()


def test_scripted_keys_select_step_and_quit_with_the_outputs_off():
    jog, rig, _ = make(noise_v=0.002)
    before = rig.angles.copy()
    out = io.StringIO()
    run_keys(jog, "nn+]-.p[q+++", 0.2, out)  # stops at q: the last steps never happen
    lines = out.getvalue().splitlines()
    assert len(lines) == 8 and lines[-1].startswith("'['")
    moved = rig.angles - before
    assert moved[HIP] == pytest.approx(math.radians(5.0), abs=TOLERANCE)
    assert moved[MOTOR2] == pytest.approx(math.radians(-5.0), abs=TOLERANCE)
    assert np.count_nonzero(moved) == 2
    assert jog.handle_key("q") is False
    assert jog.close()
    assert np.all(rig.hardware.pulse_widths_us() == 0.0)
    angles = rig.angles.copy()
    rig.sleep(0.5)
    assert np.array_equal(rig.angles, angles)  # limp: nothing moves any more


def test_the_cli_on_the_fake_rig(capsys):
    assert jog_module.main(["--fake", "--joint", "leg2_hip", "--keys", "]]+?zq", "--settle", "0.1"]) == 0
    out = capsys.readouterr().out
    last = out.splitlines()[-2]
    assert last.startswith("'z'  leg2_hip")
    assert float(re.search(r"cmd ([-+.\d]+) deg", last).group(1)) == pytest.approx(101.0, abs=0.5)
    assert "does nothing" in out and "n next joint" in out
    assert out.splitlines()[-1] == "outputs off"


def test_the_keyboard_loop_on_a_terminal_restores_it():
    master, slave = os.openpty()
    try:
        before = termios.tcgetattr(slave)
        jog, rig, _ = make()
        os.write(master, b"nn\x1b[A]q")  # next, next, up arrow (+1), +5, quit
        out = io.StringIO()
        with RawKeyboard(slave) as keyboard:
            assert not termios.tcgetattr(slave)[3] & termios.ICANON
            keyboard_loop(jog, keyboard, out, rig.sleep)
        assert termios.tcgetattr(slave) == before
        assert math.degrees(jog.commanded[HIP] - neutral()[HIP]) == pytest.approx(6.0, abs=0.5)
        assert "\rleg1_hip" in out.getvalue()
        # Ctrl-C inside the loop: the terminal comes back all the same
        jog.handle_key = lambda key: (_ for _ in ()).throw(KeyboardInterrupt())
        os.write(master, b"+")
        with pytest.raises(KeyboardInterrupt):
            with RawKeyboard(slave) as keyboard:
                keyboard_loop(jog, keyboard, io.StringIO(), rig.sleep)
        assert termios.tcgetattr(slave) == before
    finally:
        os.close(master)
        os.close(slave)


@pytest.mark.parametrize("argv, bus", [(["--bus", "7"], "i2c-7"),
                                       (["--backend", "sim", "--bus-socket", "/tmp/uq_jog_test.sock"],
                                        "sim-uq_jog_test.sock")])
def test_a_bus_held_by_the_driver_nodes_is_refused_in_one_line(tmp_path, monkeypatch, capsys, argv, bus):
    monkeypatch.setenv("UQ_LOCK_DIR", str(tmp_path))
    assert bus == bus_name(*(("real", 7, "") if bus.startswith("i2c") else ("sim", 0, "/tmp/uq_jog_test.sock")))
    node = BusLock(bus, "pwm").acquire()  # what pwm_node holds
    try:
        assert jog_module.main(argv + ["--keys", "+q"]) == 2
    finally:
        node.release()
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith("jog: the I2C bus %s is in use by pid %d" % (bus, os.getpid()))


def test_keys_need_a_terminal_or_a_script(capsys, monkeypatch):
    monkeypatch.setattr("sys.stdin", io.StringIO(""))
    assert jog_module.main(["--fake"]) == 2
    assert "needs a terminal" in capsys.readouterr().err


def test_a_terminated_jog_switches_the_outputs_off():
    jog_process = subprocess.Popen([sys.executable, "-m", "quadruped_control.bringup.jog", "--fake", "--keys",
                                    "h" + "." * 100000, "--settle", "0.02"], cwd=REPO_ROOT,
                                   stdout=subprocess.PIPE, stderr=subprocess.PIPE, universal_newlines=True)
    try:
        assert "held where it is" in jog_process.stdout.readline()  # jogging: its servo has pulses
        jog_process.send_signal(signal.SIGTERM)
        out, err = jog_process.communicate(timeout=30)
    finally:
        if jog_process.poll() is None:
            jog_process.kill()
    assert jog_process.returncode == 0, err
    assert out.splitlines()[-1] == "outputs off"
