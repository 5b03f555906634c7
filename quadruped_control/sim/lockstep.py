"""Lock-step simulation on simulated time: when has the stack answered, and are two runs the same.

In lock-step mode (``sim.launch lockstep:=true``) ``sim_node`` owns the ROS clock (``/clock``,
``use_sim_time``) and runs the cycle

1. publish ``/clock`` = t_k (t_k = t_0 + k dt, computed, never summed) and let the fake VN-100 emit
   the packets due in (t_{k-1}, t_k] through its pty;
2. wait until the stack has answered those packets (:class:`AnswerTracker`): the attitude controller
   has published its ``controller_state`` of the step at t_k, and, when armed, the fake PCA9685 holds
   the pulse widths of that step's ``servo_command`` (the real pwm_node wrote them over the bus);
3. step the plant from t_k to t_{k+1} with those pulse widths and write the new sensor values.

Nothing in the drivers' byte-level paths changes; only the clock they read is the simulation's. The
robot therefore advances only when the stack has answered, whatever the load on the machine, and two
runs give the same trajectory (:func:`compare_trajectories`). A cycle without IMU output (sensor
stalled on purpose) expects no answer. No rospy here: the node feeds the tracker from its callbacks.
"""
from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from typing import Callable, Iterable, List, Optional, Sequence, Tuple

import numpy as np


@dataclass(frozen=True)
class SimClock:
    """Simulated time of cycle k: ``t0 + k * dt`` (exact multiples, so 800 Hz IMU ticks line up)."""

    t0: float
    dt: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.t0) and self.t0 > 0):
            raise ValueError("t0 must be a positive time (0 means 'no time yet' to ROS), got %r" % (self.t0,))
        if not (math.isfinite(self.dt) and self.dt > 0):
            raise ValueError("dt must be positive, got %r" % (self.dt,))

    def time(self, k: int) -> float:
        return self.t0 + k * self.dt


def widths_match(chip_us: Sequence[float], command_us: Sequence[float], tolerance_us: float) -> bool:
    """True when every channel with a finite command outputs it to within ``tolerance_us`` (half a
    PCA9685 tick: the chip quantises). Channels commanded NaN keep their old width in the driver."""
    chip = np.asarray(chip_us, dtype=float)
    command = np.asarray(command_us, dtype=float)
    if chip.shape != command.shape:
        raise ValueError("chip has %d channels, command %d" % (chip.size, command.size))
    finite = np.isfinite(command)
    return bool(np.all(np.abs(chip[finite] - command[finite]) <= tolerance_us))


class AnswerTracker:
    """What the stack has answered so far (thread-safe: ROS callbacks feed it, the sim loop waits).

    :meth:`on_state` for each ``controller_state`` (stamp, armed), :meth:`on_command` for each
    ``servo_command`` (12 pulse widths). An armed controller step publishes its command and then its
    state; the two topics may arrive in either order, so a step counts as answered once the state of
    step t is in and, when armed, as many commands as armed states have arrived and the chip shows the
    last one.
    """

    def __init__(self, tolerance_us: float) -> None:
        self.tolerance_us = float(tolerance_us)
        self._condition = threading.Condition()
        self._state_stamp = -math.inf
        self._state_armed = False
        self._armed_states = 0
        self._commands = 0
        self._command: Optional[np.ndarray] = None

    def on_state(self, stamp: float, armed: bool) -> None:
        with self._condition:
            self._state_stamp = max(self._state_stamp, float(stamp))
            self._state_armed = bool(armed)
            self._armed_states += int(bool(armed))
            self._condition.notify_all()

    def on_command(self, widths_us: Sequence[float]) -> None:
        with self._condition:
            self._commands += 1
            self._command = np.asarray(widths_us, dtype=float).copy()
            self._condition.notify_all()

    def notify(self) -> None:
        """Wake a waiter to look at the chip again (call after a bus write reached the fake chip)."""
        with self._condition:
            self._condition.notify_all()

    def answered(self, t: float, chip_us: Sequence[float], epsilon: float = 1e-6) -> bool:
        """Has the stack answered the IMU samples of simulated time ``t``?"""
        with self._condition:
            return self._answered(t, chip_us, epsilon)

    def _answered(self, t: float, chip_us: Sequence[float], epsilon: float) -> bool:
        if self._state_stamp < t - epsilon:
            return False
        if not self._state_armed:
            return True
        if self._commands < self._armed_states or self._command is None:
            return False
        return widths_match(chip_us, self._command, self.tolerance_us)

    def wait(self, t: float, chip, timeout: float, epsilon: float = 1e-6) -> bool:
        """Block until :meth:`answered` for ``t`` (``chip()`` reads the fake chip's widths) or
        ``timeout`` seconds of wall time; returns whether it was answered. Polls the chip every
        millisecond besides waking on callbacks, as the bus write itself notifies no one."""
        import time

        deadline = time.monotonic() + timeout
        with self._condition:
            while not self._answered(t, chip(), epsilon):
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return False
                self._condition.wait(min(remaining, 0.001))
        return True


#: One link of the lock-step graph: (publisher node, topic, subscriber node), all resolved names.
Link = Tuple[str, str, str]


def missing_links(links: Iterable[Link], bus_info: Callable[[str], Optional[Sequence[Sequence]]]) -> List[str]:
    """The links that cannot carry a message yet, in words (empty: every link is up at both ends).

    ``bus_info(node)`` is the node's ``getBusInfo`` list (ROS slave API: ``(id, endpoint, direction,
    transport, topic, connected, info)`` per connection) or None when the node is not up. A link is up
    when the subscriber lists a connected inbound connection on the topic *and* the publisher lists an
    outbound one to that subscriber. The publisher's side matters: rospy answers a subscriber's
    handshake before it adds the connection to the list it publishes to, so in between the subscriber
    already shows "connected" while a message published then is silently lost. Asking only the
    subscriber let the first IMU samples of a run vanish now and then under load, and the run was no
    longer deterministic.
    """
    cache = {}

    def info(node: str) -> Optional[Sequence[Sequence]]:
        if node not in cache:
            cache[node] = bus_info(node)
        return cache[node]

    missing: List[str] = []
    for publisher, topic, subscriber in links:
        inbound, outbound = info(subscriber), info(publisher)
        if inbound is None:
            missing.append("%s not up" % subscriber)
        elif not any(entry[2] == "i" and entry[4] == topic and entry[5] for entry in inbound):
            missing.append("%s not connected to %s" % (subscriber, topic))
        if outbound is None:
            missing.append("%s not up" % publisher)
        elif not any(entry[2] == "o" and entry[4] == topic and entry[1] == subscriber for entry in outbound):
            missing.append("%s does not publish %s to %s yet" % (publisher, topic, subscriber))
    return list(dict.fromkeys(missing))


@dataclass
class TrajectoryDifference:
    """Result of :func:`compare_trajectories`: samples on common stamps, samples only in one run, and
    the largest absolute difference of any state component on the common stamps."""

    common: int
    only_first: int
    only_second: int
    max_difference: float

    def same(self, tolerance: float, min_common: int) -> bool:
        return self.common >= min_common and self.max_difference <= tolerance


def compare_trajectories(first_ns: Sequence[int], first_x: Sequence[Sequence[float]],
                         second_ns: Sequence[int], second_x: Sequence[Sequence[float]]) -> TrajectoryDifference:
    """Compare two recorded trajectories sample by sample on their common stamps (integer ns; lock-step
    stamps are exact multiples of the step). ``*_x``: one row of state per stamp."""
    def table(stamps, rows):
        if len(stamps) == 0:
            return {}
        rows = np.asarray(rows, dtype=float).reshape(len(stamps), -1)
        return {int(k): r for k, r in zip(stamps, rows)}

    a, b = table(first_ns, first_x), table(second_ns, second_x)
    common = sorted(set(a) & set(b))
    difference = max((float(np.max(np.abs(a[k] - b[k]))) for k in common), default=math.inf)
    return TrajectoryDifference(common=len(common), only_first=len(set(a) - set(b)),
                                only_second=len(set(b) - set(a)), max_difference=difference)


def main(argv: Optional[Sequence[str]] = None) -> int:
    """``python -m quadruped_control.sim.lockstep A.npz B.npz``: same trajectory (closed_loop_test files)?"""
    import argparse

    parser = argparse.ArgumentParser(description="Compare two lock-step trajectories (stamp_ns, quaternion).")
    parser.add_argument("first")
    parser.add_argument("second")
    parser.add_argument("--tolerance", type=float, default=1e-6)
    parser.add_argument("--min-samples", type=int, default=1000, help="common samples needed (10 s at 100 Hz)")
    args = parser.parse_args(argv)
    a, b = np.load(args.first), np.load(args.second)
    result = compare_trajectories(a["stamp_ns"], a["quaternion"], b["stamp_ns"], b["quaternion"])
    print("%d common samples (%.2f s of simulated time), %d only in the first run, %d only in the second; "
          "largest quaternion difference %.3g (tolerance %.1g)"
          % (result.common, result.common * 0.01, result.only_first, result.only_second,
             result.max_difference, args.tolerance))
    same = result.same(args.tolerance, args.min_samples)
    print("SAME trajectory" if same else "DIFFERENT trajectories")
    return 0 if same else 1


if __name__ == "__main__":
    import sys

    sys.exit(main())
