"""Tests of the safety supervisor the controller node wraps around the controller (no ROS)."""
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from quadruped_common.robot import JOINT_NAMES
from quadruped_common.so3 import rot_to_quat, rpy_to_rot
from quadruped_control.control.controller import AttitudeController
from quadruped_control.control.controller_config import load_controller_config
from quadruped_control.control.safety_config import SafetyConfig
from quadruped_control.control.supervisor import TETHER_STALL, ControlSupervisor
from quadruped_control.model.kinematics import joint_angles
from quadruped_control.model.params import load_robot_params

LOW, HIGH = 500.0, 2500.0
LEVEL = (0.0, 0.0, 0.0, 1.0)


def pulse_map(angles):
    """A stand-in calibration: 1500 us at 0 rad, 600 us/rad, clamped like the node's map."""
    return np.clip(1500.0 + 600.0 * np.asarray(angles), LOW, HIGH)


@pytest.fixture
def supervisor():
    robot = load_robot_params()
    controller = AttitudeController(robot, load_controller_config(gain_set="simulation"))
    controller.set_setpoint(rpy_to_rot(math.radians(30.0), 0.0, 0.0))
    return ControlSupervisor(controller, pulse_map, max_imu_age=0.05)


def run(supervisor, seconds, quaternion=LEVEL, rate=(0.0, 0.0, 0.0), start=0.0, feed=True):
    """Tick at 100 Hz for ``seconds``; returns the outputs."""
    outputs = []
    for k in range(int(round(seconds * 100))):
        t = start + 0.01 * k
        if feed:
            supervisor.set_imu(quaternion, rate, t)
        outputs.append(supervisor.tick(t, t))
    return outputs


def stroke_amplitude(outputs):
    targets = np.array([o.joint_targets for o in outputs if o.joint_targets is not None])
    return float(np.max(np.ptp(targets, axis=0))) if len(targets) else 0.0


def test_unarmed_sends_nothing_and_does_not_stroke(supervisor):
    outputs = run(supervisor, 2.0)
    assert all(o.pulse_widths_us is None and o.joint_targets is None for o in outputs)
    assert all(o.problem == "disarmed" and not o.armed for o in outputs)
    assert all(o.output.state.holding for o in outputs)


def test_armed_with_good_imu_strokes_within_limits(supervisor):
    assert "armed" in supervisor.arm(True)
    outputs = run(supervisor, 3.0)
    assert all(o.problem == "" for o in outputs)
    assert stroke_amplitude(outputs) > math.radians(5.0)
    widths = np.array([o.pulse_widths_us for o in outputs])
    assert np.all((widths >= LOW) & (widths <= HIGH))


@pytest.mark.parametrize("quaternion, reason", [
    ((math.nan, 0.0, 0.0, 1.0), "non-finite"),
    ((0.0, 0.0, 0.0, 0.5), "quaternion norm"),
    ((0.0, 0.0, 0.0, 0.0), "quaternion norm"),
])
def test_invalid_imu_holds_the_safe_pose(supervisor, quaternion, reason):
    supervisor.arm(True)
    run(supervisor, 1.0)
    outputs = run(supervisor, 2.5, quaternion=quaternion, start=1.0)
    # Each bad sample is dropped; the last good one is still fresh for the first two ticks, the third
    # implausible sample in a row holds the controller.
    assert [o.problem for o in outputs[:2]] == ["", ""]
    assert all(reason in o.problem and "3 implausible IMU samples in a row" in outputs[2].problem
               for o in outputs[2:])
    assert all(o.output.state.holding for o in outputs[2:])
    assert supervisor.imu_dropped == len(outputs) and supervisor.implausible_run == len(outputs)
    assert all(o.pulse_widths_us is not None for o in outputs)  # the safe pose is still commanded
    # The feet retrace to the nominal pose over t_rec (1.5 s), then stay: no stroking.
    assert stroke_amplitude(outputs[160:]) < 1e-9
    integral = [o.output.state.integral for o in outputs]
    np.testing.assert_allclose(integral[2], integral[-1])  # frozen while holding


def test_stale_imu_holds_and_resumes(supervisor):
    supervisor.arm(True)
    run(supervisor, 1.0)
    # The IMU stops: the last sample ages past max_imu_age.
    stale = [supervisor.tick(1.0 + 0.01 * k, 1.0 + 0.01 * k) for k in range(100)]
    assert stale[0].problem == ""  # 0 ms old
    assert all("stale" in o.problem for o in stale[10:])
    resumed = run(supervisor, 3.0, start=2.0)
    assert all(o.problem == "" for o in resumed)
    assert stroke_amplitude(resumed) > math.radians(5.0)


def test_no_imu_at_all_holds(supervisor):
    supervisor.arm(True)
    output = supervisor.tick(0.0, 0.0)
    assert output.problem == "no IMU sample received yet"
    assert output.pulse_widths_us is not None


def test_arming_resets_integral(supervisor):
    supervisor.arm(True)
    before = run(supervisor, 5.0)[-1].output.state.integral
    assert np.linalg.norm(before) > 0.1
    supervisor.arm(False)
    supervisor.arm(True)
    first = run(supervisor, 0.01, start=6.0)[0]
    assert np.linalg.norm(first.output.state.integral) < 0.02  # one step of integration at most


def test_estimated_torque_is_nan_without_feedback_and_finite_with_it(supervisor):
    supervisor.arm(True)
    out = run(supervisor, 0.1)[-1]
    assert np.all(np.isnan(out.torque_estimated))
    q = out.joint_targets
    supervisor.set_joint_feedback(q, np.zeros(12))
    out = run(supervisor, 0.01, start=0.1)[0]
    np.testing.assert_allclose(out.torque_estimated, 0.0, atol=1e-12)  # legs still: no leg torque
    supervisor.set_joint_feedback(q, np.full(12, 2.0))
    out = run(supervisor, 0.01, start=0.11)[0]
    assert np.all(np.isfinite(out.torque_estimated)) and np.linalg.norm(out.torque_estimated) > 0
    with pytest.raises(ValueError):
        supervisor.set_joint_feedback(q[:6], np.zeros(6))


def test_bad_max_age_rejected(supervisor):
    with pytest.raises(ValueError):
        ControlSupervisor(supervisor.controller, pulse_map, max_imu_age=0.0)


@settings(max_examples=30, deadline=None)
@given(st.lists(st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.just(0.0)), min_size=7, max_size=7))
def test_any_imu_message_never_raises_or_leaves_limits(values):
    robot = load_robot_params()
    controller = AttitudeController(robot, load_controller_config(gain_set="simulation"))
    supervisor = ControlSupervisor(controller, pulse_map, armed=True)
    supervisor.set_imu(values[:4], values[4:], 0.0)
    output = supervisor.tick(0.0, 0.0)
    assert np.all((output.pulse_widths_us >= LOW) & (output.pulse_widths_us <= HIGH))
    assert np.all(np.isfinite(output.joint_targets))


def test_tilted_good_sample_is_used():
    robot = load_robot_params()
    controller = AttitudeController(robot, load_controller_config(gain_set="simulation"))
    supervisor = ControlSupervisor(controller, pulse_map, armed=True)
    q = rot_to_quat(rpy_to_rot(0.3, -0.2, 1.0))
    supervisor.set_imu(q, (0.1, 0.0, 0.0), 0.0)
    output = supervisor.tick(0.0, 0.01)
    assert output.problem == ""
    assert output.output.state.geodesic_error == pytest.approx(
        np.arccos((np.trace(rpy_to_rot(0.3, -0.2, 1.0)) - 1) / 2), abs=1e-9)


def test_an_imu_rate_spike_inside_the_range_is_dropped_and_counted(supervisor):
    """The controller checks the physical rate too (a corrupted /imu/data from anywhere)."""
    assert supervisor.set_imu(LEVEL, (0.0, 0.0, 0.0), 1.0) is None
    problem = supervisor.set_imu(LEVEL, (0.0, 0.0, 15.0), 1.005)
    assert problem is not None and "angular acceleration" in problem
    assert supervisor.imu_drop_reasons == {"angular acceleration": 1}
    assert supervisor.set_imu(LEVEL, (0.0, 0.0, 0.05), 1.01) is None


def test_arming_waits_for_a_passed_preflight_when_required(supervisor):
    gated = ControlSupervisor(supervisor.controller, supervisor.pulse_map, require_preflight=True)
    message = gated.arm(True)
    assert not gated.armed and message.startswith("arming refused: pre-dive check: no pre-dive check has passed")
    assert "none has run" in message
    gated.set_preflight(False, "FAILED: channels")
    assert not gated.armed and "FAILED: channels" in gated.arm(True)
    gated.set_preflight(True, "passed")
    assert gated.arming_refusal() is None and gated.arm(True) == "armed: legs will stroke" and gated.armed
    assert gated.arm(False).startswith("disarmed")  # disarming is never refused


def test_arm_on_start_is_refused_while_the_gate_is_closed(supervisor):
    assert not ControlSupervisor(supervisor.controller, supervisor.pulse_map, armed=True,
                                 require_preflight=True).armed
    assert ControlSupervisor(supervisor.controller, supervisor.pulse_map, armed=True).armed  # not required


def test_the_estop_disarms_and_refuses_arming_until_reset(supervisor):
    supervisor.arm(True)
    supervisor.set_estop(True)
    assert not supervisor.armed
    assert "the e-stop is latched" in supervisor.arm(True) and not supervisor.armed
    gated = ControlSupervisor(supervisor.controller, supervisor.pulse_map, require_preflight=True)
    gated.set_estop(True)
    reasons = gated.arming_refusal()
    assert "e-stop" in reasons and "pre-dive check" in reasons  # every reason named
    supervisor.set_estop(False)
    assert not supervisor.armed and supervisor.arm(True) == "armed: legs will stroke"


def test_the_tether_heartbeat_gates_arming_and_its_loss_disarms(supervisor):
    watched = ControlSupervisor(supervisor.controller, supervisor.pulse_map, heartbeat_timeout=2.0)
    run(watched, 0.1)
    assert "no tether heartbeat" in watched.arm(True) and not watched.armed
    watched.set_heartbeat(0.05)
    assert watched.arm(True) == "armed: legs will stroke"
    assert watched.check_tether(2.0) is None  # 1.95 s without a heartbeat: within the timeout
    assert watched.check_tether(2.06) == "disarm" and not watched.armed and watched.tether_losses == 1
    assert watched.check_tether(2.5) is None  # acts once
    watched.set_heartbeat(3.0)  # it returns: nothing moves until an arm
    outputs = run(watched, 0.5, start=3.0)
    assert not watched.armed and all(o.pulse_widths_us is None for o in outputs)
    assert watched.arm(True) == "armed: legs will stroke"


def test_a_supervisor_that_stalled_lets_the_queued_heartbeats_arrive_first(supervisor):
    watched = ControlSupervisor(supervisor.controller, supervisor.pulse_map, heartbeat_timeout=2.0)
    watched.set_heartbeat(0.0)
    watched.arm(True)
    for k in range(1, 100):  # 100 Hz checks, a heartbeat every 0.2 s, until 1 s
        now = 0.01 * k
        if k % 20 == 0:
            watched.set_heartbeat(now)
        assert watched.check_tether(now) is None
    # the process starved for 10 s (no check, no callback); at once the heartbeat queued meanwhile is not yet in
    assert watched.check_tether(11.0) is None and watched.armed
    watched.set_heartbeat(11.01)  # ... it arrives
    assert watched.check_tether(11.3) is None and watched.armed
    # a real loss across a stall still acts, TETHER_STALL late
    assert watched.check_tether(30.0) is None
    assert watched.check_tether(30.1) is None
    assert watched.check_tether(30.0 + TETHER_STALL + 0.01) == "disarm" and not watched.armed


def test_the_tether_failsafe_can_go_limp_and_refuses_bad_settings(supervisor):
    limp = ControlSupervisor(supervisor.controller, supervisor.pulse_map, heartbeat_timeout=1.0, tether_action="limp")
    limp.set_heartbeat(0.0)
    limp.arm(True)
    assert limp.check_tether(1.5) == "limp"
    with pytest.raises(ValueError, match="tether_action"):
        ControlSupervisor(supervisor.controller, supervisor.pulse_map, heartbeat_timeout=1.0, tether_action="swim")
    with pytest.raises(ValueError, match="heartbeat_timeout"):
        ControlSupervisor(supervisor.controller, supervisor.pulse_map, heartbeat_timeout=-1.0)
    unwatched = ControlSupervisor(supervisor.controller, supervisor.pulse_map)
    unwatched.arm(True)
    assert unwatched.check_tether(1e6) is None and unwatched.armed


# ---- checked arming and the soft start (a SafetyConfig given, as the node does) --------------------------------

SAFETY = SafetyConfig(max_joint_speed=1.0, soft_start_tolerance=0.05)


def nominal(robot):
    return np.array([joint_angles(robot.nominal_foot_body(leg), leg, robot) for leg in (1, 2, 3, 4)]).reshape(12)


@pytest.fixture
def checked(supervisor):
    return ControlSupervisor(supervisor.controller, pulse_map, safety=SAFETY, heartbeat_timeout=2.0,
                             require_preflight=True)


def feed(supervisor, t, joints=None, outputs="", skip=()):
    """Every input fresh at ``t`` (the legs at ``joints``, default the nominal pose) but those in ``skip``."""
    if "imu" not in skip:
        supervisor.set_imu(LEVEL, (0.0, 0.0, 0.0), t)
    if "joints" not in skip:
        q = nominal(supervisor.controller.robot) if joints is None else joints
        supervisor.set_joint_feedback(q, np.zeros(12), t)
    if "outputs" not in skip:
        supervisor.set_outputs_state(outputs, t)
    if "tether" not in skip:
        supervisor.set_heartbeat(t)
    if "pre-dive check" not in skip:
        supervisor.set_preflight(True, "passed")


def run_fed(supervisor, seconds, start, joints=None):
    """Tick at 100 Hz with every input fresh; the joint feedback follows the targets (ideal servos) unless given."""
    outputs = []
    for k in range(int(round(seconds * 100))):
        t = start + 0.01 * k
        previous = outputs[-1].joint_targets if outputs and outputs[-1].joint_targets is not None else None
        feed(supervisor, t, joints if joints is not None else previous)
        outputs.append(supervisor.tick(t, t))
    return outputs


def test_with_every_input_fresh_the_checked_supervisor_arms(checked):
    feed(checked, 1.0)
    checked.tick(1.0, 1.0)
    assert checked.arming_refusal() is None and checked.arm(True).startswith("armed") and checked.armed


@pytest.mark.parametrize("missing, reason", [
    ("imu", "imu: no IMU sample received yet"),
    ("joints", "joints: no joint feedback received yet"),
    ("outputs", "outputs: no outputs_state from pwm_node yet"),
    ("tether", "tether: no tether heartbeat for 2.0 s"),
    ("pre-dive check", "pre-dive check: no pre-dive check has passed"),
])
def test_each_input_missing_refuses_arming_on_its_own_with_its_reason(checked, missing, reason):
    feed(checked, 1.0, skip=(missing,))
    checked.tick(1.0, 1.0)
    refusal = checked.arming_refusal()
    assert refusal.startswith(reason) and ";" not in refusal, refusal
    assert checked.arm(True) == "arming refused: " + refusal and not checked.armed
    assert [name for name, problem in checked.arming_checks() if problem] == [missing]


def test_stale_or_bad_inputs_refuse_arming_each_named(checked):
    feed(checked, 1.0)
    checked.set_imu(LEVEL, (0.0, 0.0, 0.0), 0.5)  # 0.5 s old
    checked.tick(1.0, 1.0)
    assert checked.arming_refusal().startswith("imu: ") and "old" in checked.arming_refusal()
    feed(checked, 2.0)
    checked.set_joint_feedback(nominal(checked.controller.robot), np.zeros(12), 1.5)
    checked.tick(2.0, 2.0)
    assert checked.arming_refusal().startswith("joints: joint feedback")
    q = nominal(checked.controller.robot)
    q[4] = 10.0  # leg 2's knee reads far outside its servo range
    feed(checked, 3.0, joints=q)
    checked.tick(3.0, 3.0)
    assert checked.arming_refusal() == ("joints: no usable reading (missing or outside the servo range) from "
                                        + JOINT_NAMES[4])
    feed(checked, 4.0, outputs="outputs disabled")
    checked.tick(4.0, 4.0)
    assert checked.arming_refusal() == "outputs: outputs disabled"
    feed(checked, 5.0)
    checked.tick(6.5, 6.5)  # pwm_node silent for 1.5 s (and everything else old too)
    assert "pwm_node's outputs_state is 1.5 s old" in checked.arming_refusal()
    checked.set_estop(True)
    assert checked.arming_refusal().startswith("e-stop: the e-stop is latched")


def test_the_soft_start_travels_at_the_bound_then_strokes_with_a_fresh_integral(checked):
    robot = checked.controller.robot
    start = nominal(robot)
    start[[0, 5, 10]] += np.array([0.5, -0.3, 0.2])  # three joints off the nominal pose
    feed(checked, 1.0, joints=start)
    checked.tick(1.0, 1.0)
    assert checked.arm(True).startswith("armed: legs to the nominal pose")
    travel = run_fed(checked, 0.7, 1.01, joints=start)  # the legs still read where they started
    targets = np.array([o.joint_targets for o in travel])
    np.testing.assert_allclose(targets[0], start)  # the first command: where the legs are
    end = next(k for k, o in enumerate(travel) if not o.problem.startswith("soft start"))
    assert 50 <= end <= 52  # 0.5 rad at 1 rad/s: 50 ticks (and float rounding)
    assert np.max(np.abs(np.diff(targets[:end], axis=0))) <= 1.0 * 0.01 + 1e-12  # 1 rad/s at 100 Hz
    np.testing.assert_allclose(targets[end - 1], nominal(robot), atol=1e-12)
    assert np.linalg.norm(travel[end].output.state.integral) < 0.02  # the integral starts after the travel
    strokes = run_fed(checked, 3.0, 1.71)
    assert all(o.problem == "" for o in strokes) and stroke_amplitude(strokes) > math.radians(5.0)


def test_legs_within_the_tolerance_start_stroking_at_once(checked):
    start = nominal(checked.controller.robot) + 0.04
    feed(checked, 1.0, joints=start)
    checked.tick(1.0, 1.0)
    checked.arm(True)
    first = run_fed(checked, 1.0, 1.01)
    assert first[0].problem == "" and not checked.soft_starting


def test_arming_again_after_a_disarm_mid_stroke_starts_softly_from_where_the_legs_are(checked):
    feed(checked, 1.0)
    checked.tick(1.0, 1.0)
    checked.arm(True)
    strokes = run_fed(checked, 2.3, 1.01)
    held = strokes[-1].joint_targets  # mid-stroke
    assert np.max(np.abs(held - nominal(checked.controller.robot))) > 0.1
    assert checked.arm(False).startswith("disarmed")
    feed(checked, 3.5, joints=held)
    checked.tick(3.5, 3.5)
    checked.arm(True)
    again = run_fed(checked, 1.0, 3.51, joints=held)
    travel = [o.joint_targets for o in again if o.problem.startswith("soft start")]
    assert len(travel) > 10 and again[0].problem.startswith("soft start")
    assert np.max(np.abs(np.diff(np.array([held] + travel), axis=0))) <= 0.01 + 1e-12


def test_a_holds_retrace_keeps_the_bound(checked):
    feed(checked, 1.0)
    checked.tick(1.0, 1.0)
    checked.arm(True)
    strokes = run_fed(checked, 2.3, 1.01)
    last = strokes[-1].joint_targets
    stale = []
    for k in range(300):  # the IMU stops; joints and outputs stay fresh
        t = 3.31 + 0.01 * k
        checked.set_joint_feedback(stale[-1].joint_targets if stale else last, np.zeros(12), t)
        checked.set_outputs_state("", t)
        checked.set_heartbeat(t)
        stale.append(checked.tick(t, t))
    assert all("stale" in o.problem for o in stale[10:])
    targets = np.array([last] + [o.joint_targets for o in stale])
    assert np.max(np.abs(np.diff(targets, axis=0))) <= 0.01 + 1e-12
    np.testing.assert_allclose(targets[-1], nominal(checked.controller.robot), atol=1e-9)


def test_an_arm_asked_at_start_waits_for_the_checks_and_a_disarm_cancels_it(supervisor):
    pending = ControlSupervisor(supervisor.controller, pulse_map, armed=True, safety=SAFETY)
    assert not pending.armed and pending.arm_pending
    pending.tick(0.5, 0.5)
    assert not pending.armed
    feed(pending, 1.0)
    pending.tick(1.0, 1.0)
    assert pending.armed and not pending.arm_pending
    cancelled = ControlSupervisor(supervisor.controller, pulse_map, armed=True, safety=SAFETY)
    cancelled.arm(False)
    feed(cancelled, 1.0)
    cancelled.tick(1.0, 1.0)
    assert not cancelled.armed


def test_a_limp_disarm_says_so(supervisor):
    limp = ControlSupervisor(supervisor.controller, pulse_map, safety=SafetyConfig(disarm_action="limp"))
    feed(limp, 1.0)
    limp.tick(1.0, 1.0)
    limp.arm(True)
    assert limp.arm(False) == "disarmed: no servo commands, every output off (limp)"


def test_health_sources_gate_arming_and_their_errors_take_their_actions(supervisor):
    safety = SafetyConfig(health_actions=(("depth", "warn"), ("battery", "disarm"), ("leak", "limp")))
    watched = ControlSupervisor(supervisor.controller, pulse_map, safety=safety,
                                health_sources=("depth", "battery", "leak"))
    feed(watched, 1.0)
    watched.tick(1.0, 1.0)
    assert [name for name, problem in watched.arming_checks() if problem] == ["depth", "battery", "leak"]
    assert "depth: no health/depth status yet" in watched.arm(True)
    for source in ("depth", "battery", "leak"):
        watched.set_health(source, False, "ok", 1.0)
    watched.set_health("battery", True, "motors pack 6.1 V: below its critical 6.4 V", 1.0)
    assert watched.arming_refusal() == "battery: motors pack 6.1 V: below its critical 6.4 V"
    watched.set_health("battery", False, "ok", 1.0)
    assert watched.arm(True).startswith("armed")
    # depth lost: reported once, the robot keeps stroking (warn)
    watched.set_health("depth", True, "no reading for 1.2 s", 1.5)
    assert watched.check_health(1.5) == [("depth", "warn", "no reading for 1.2 s")]
    assert watched.check_health(1.6) == [] and watched.armed
    # a leak status that stops coming counts as lost after health.max_age: reported, the robot goes on
    for source in ("depth", "battery"):
        watched.set_health(source, False, "ok", 6.0)
    assert watched.check_health(6.0) == []  # 5.0 s (health.max_age): not yet
    assert watched.check_health(6.1) == [("leak", "warn", "health/leak is 5.1 s old (is its node running?)")]
    assert watched.armed and watched.check_health(6.2) == []  # once
    # a measurement fault in error is not a hazard either; water inside is: its action (limp) disarms
    watched.set_health("leak", True, "probe reads nothing", 6.3, reason="no_reading")
    assert watched.check_health(6.3) == [] and watched.armed  # still the same lost-sensor episode
    watched.set_health("leak", True, "water in the enclosure", 6.4, reason="wet")
    assert watched.check_health(6.4) == [("leak", "limp", "water in the enclosure")]
    assert not watched.armed and watched.health_actions_taken == 1
    assert watched.check_health(6.5) == []  # once
    with pytest.raises(ValueError, match="health_sources need a SafetyConfig"):
        ControlSupervisor(supervisor.controller, pulse_map, health_sources=("depth",))


def test_a_battery_error_while_armed_disarms(supervisor):
    watched = ControlSupervisor(supervisor.controller, pulse_map, safety=SAFETY, health_sources=("battery",))
    feed(watched, 1.0)
    watched.set_health("battery", False, "ok", 1.0)
    watched.tick(1.0, 1.0)
    assert watched.arm(True).startswith("armed")
    watched.set_health("battery", True, "electronics: 15.9 V, stale", 1.2, reason="electronics:stale")
    assert watched.check_health(1.2) == [("battery", "warn", "electronics: 15.9 V, stale")] and watched.armed
    watched.set_health("battery", True, "electronics pack 3.3 V/cell: critical", 1.3,
                       reason="motors:stale,electronics:critical")
    assert watched.check_health(1.3) == [("battery", "disarm", "electronics pack 3.3 V/cell: critical")]
    assert not watched.armed


def test_the_tether_failsafe_can_hold_the_attitude_the_robot_has(supervisor):
    held = ControlSupervisor(supervisor.controller, pulse_map, heartbeat_timeout=1.0, tether_action="hold")
    held.set_heartbeat(0.0)
    assert held.arm(True).startswith("armed")
    tilted = rot_to_quat(rpy_to_rot(math.radians(12.0), math.radians(-5.0), 0.0))
    run(held, 1.5, quaternion=tilted)  # heartbeat last at 0.0: lost after 1.0 s
    assert held.check_tether(1.5) == "hold" and held.armed and held.tether_losses == 1
    np.testing.assert_allclose(held.controller.setpoint, rpy_to_rot(math.radians(12.0), math.radians(-5.0), 0.0),
                               atol=1e-9)
    assert held.check_tether(1.6) is None  # once per loss
    strokes = run(held, 1.0, quaternion=tilted, start=1.6)
    assert all(o.problem == "" for o in strokes)  # armed and tracking the held attitude
    held.set_heartbeat(2.7)
    assert held.check_tether(2.7) is None
    stale = ControlSupervisor(supervisor.controller, pulse_map, heartbeat_timeout=1.0, tether_action="hold")
    stale.set_heartbeat(0.0)
    stale.arm(True)
    assert stale.check_tether(1.5) == "disarm" and not stale.armed  # no IMU sample to hold: disarm
