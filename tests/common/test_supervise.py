"""quadruped_common.supervise: a crash (or an end nobody asked for) is restarted after a back-off; a node
that cannot start (exit 78) and a requested stop are not.

The policy runs on a virtual clock with scripted children; then real Python children (a script that is
its own supervisor, as the node executables are) exit 0, 78, 1, crash, or are signalled."""
import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from quadruped_common.startup_errors import EX_CONFIG
from quadruped_common.supervise import (CHILD_ENV, RESPAWN_ENV, Backoff, Supervisor, describe_status,
                                        respawn_asked)
from tests.repo import REPO_ROOT


# ----------------------------------------------------------------------------- the policy, virtual clock
class Clock:
    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now

    def sleep(self, seconds):
        self.now += seconds


class ScriptedChild:
    """A child that runs ``ran`` virtual seconds and ends with ``status``."""
    pid = 999999  # never signalled in these tests

    def __init__(self, clock, ran, status, on_wait=None):
        self.clock, self.ran, self.status, self.on_wait = clock, ran, status, on_wait
        self.returncode = None

    def wait(self):
        if self.on_wait:
            self.on_wait()
        self.clock.now += self.ran
        self.returncode = self.status
        return self.status


def scripted(runs, backoff=Backoff()):
    """A Supervisor whose successive children are ``runs`` [(seconds, status)], on a virtual clock;
    returns (supervisor, clock, log, start times)."""
    clock, log, starts = Clock(), [], []
    runs = list(runs)

    def popen(command, env=None):
        starts.append(clock())
        ran, status = runs.pop(0)
        return ScriptedChild(clock, ran, status)

    supervisor = Supervisor("demo_node", ["demo"], None, backoff, popen=popen, clock=clock, sleep=clock.sleep,
                            log=log.append)
    return supervisor, clock, log, starts


def test_backoff_doubles_to_its_cap_and_resets_after_a_long_run():
    backoff = Backoff(first=1.0, longest=30.0, reset_after=60.0)
    delays, previous = [], None
    for _ in range(7):
        previous = backoff.next_delay(previous, ran=5.0)
        delays.append(previous)
    assert delays == [1.0, 2.0, 4.0, 8.0, 16.0, 30.0, 30.0]
    assert backoff.next_delay(30.0, ran=60.0) == 1.0
    assert backoff.next_delay(30.0, ran=59.9) == 30.0


def test_a_node_that_cannot_start_is_not_restarted():
    supervisor, _clock, log, starts = scripted([(0.3, EX_CONFIG)])
    assert supervisor.run() == EX_CONFIG
    assert len(starts) == 1 and log == []


def test_crashes_are_restarted_after_a_growing_delay_one_line_each():
    runs = [(0.5, 1), (0.5, -signal.SIGSEGV), (2.0, -signal.SIGKILL), (70.0, 1), (1.0, 0), (1.0, EX_CONFIG)]
    supervisor, _clock, log, starts = scripted(runs)
    assert supervisor.run() == EX_CONFIG
    gaps = [round(b - a - ran, 6) for (a, b, (ran, _)) in zip(starts, starts[1:], runs)]
    assert gaps == [1.0, 2.0, 4.0, 1.0, 2.0]  # the 70 s run reset the back-off
    assert len(log) == 5
    assert log[0] == "demo_node: exit status 1 after 0.5 s; starting it again in 1 s (restart 1)"
    assert "killed by SIGSEGV" in log[1] and "killed by SIGKILL" in log[2] and "in 4 s (restart 3)" in log[2]
    # nobody asked it to stop: an end by itself (vn100_node's publisher closed, rosnode kill) is restarted
    assert log[4] == "demo_node: exit status 0 after 1.0 s; starting it again in 2 s (restart 5)"


def test_a_node_that_cannot_start_after_a_crash_stays_down():
    supervisor, _clock, log, starts = scripted([(10.0, -signal.SIGKILL), (0.2, EX_CONFIG)])
    assert supervisor.run() == EX_CONFIG
    assert len(starts) == 2 and len(log) == 1


def test_a_stop_during_the_backoff_starts_nothing_more():
    supervisor, clock, log, starts = scripted([(0.5, 1), (1.0, 0)], Backoff(first=5.0))
    real_sleep = clock.sleep

    def sleep(seconds):
        real_sleep(seconds)
        if clock() - starts[0] > 2.0:
            supervisor.request_stop(signal.SIGINT)
    supervisor.sleep = sleep
    assert supervisor.run() == 0
    assert len(starts) == 1 and len(log) == 1


def test_after_a_stop_request_the_child_ends_the_supervisor_whatever_its_status():
    clock = Clock()
    holder = {}

    def popen(command, env=None):
        child = ScriptedChild(clock, 1.0, -signal.SIGTERM, on_wait=lambda: holder["s"].request_stop(signal.SIGTERM))
        child.pid = None  # the kill is not sent in this test
        return child
    supervisor = Supervisor("demo_node", ["demo"], popen=popen, clock=clock, sleep=clock.sleep, log=print)
    holder["s"] = supervisor
    supervisor._pass_on = lambda signum: None  # noqa: SLF001 - no real process here
    assert supervisor.run() == -signal.SIGTERM
    assert supervisor.starts == 1


def test_describe_status():
    assert describe_status(1) == "exit status 1"
    assert describe_status(-signal.SIGKILL) == "killed by SIGKILL"
    assert describe_status(-200) == "killed by signal 200"


def test_respawn_is_asked_by_the_environment_and_never_by_the_child():
    assert respawn_asked({RESPAWN_ENV: "true"})
    assert respawn_asked({RESPAWN_ENV: "True"})
    assert not respawn_asked({RESPAWN_ENV: "false"})
    assert not respawn_asked({})
    assert not respawn_asked({RESPAWN_ENV: "true", CHILD_ENV: "1"})


# ----------------------------------------------------------------------------- real children
#: A node executable in miniature: its own supervisor (short back-off), then the node, whose behaviour
#: the first argument chooses; it appends its pid to the file of the second argument at each start.
NODE = textwrap.dedent("""\
    import os, signal, sys, time
    from quadruped_common.supervise import Backoff, supervise_if_asked

    if __name__ == "__main__":
        supervise_if_asked("demo_node", backoff=Backoff(first=0.05, longest=0.2, reset_after=60.0))

    mode, starts_file = sys.argv[1], sys.argv[2]
    if mode == "serve":  # like rospy: SIGINT and SIGTERM end it cleanly (set before the start is recorded: the
        signal.signal(signal.SIGINT, lambda *_: sys.exit(0))  # test signals as soon as it sees the start)
        signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    with open(starts_file, "a") as stream:
        stream.write("%d\\n" % os.getpid())
    starts = len(open(starts_file).read().split())
    if mode == "exit":
        sys.exit(int(sys.argv[3]))
    if mode == "fail-then-cannot-start":  # exit 1, exit 0 (an end nobody asked for), then exit 78
        sys.exit({1: 1, 2: 0}.get(starts, 78))
    if mode == "crash-then-cannot-start":  # a crash, then a start-up error a restart cannot fix
        if starts == 1:
            os.abort()
        sys.exit(78)
    while True:  # "serve", or "wait": default signal handling
        time.sleep(0.02)
""")


@pytest.fixture
def node(tmp_path):
    script = tmp_path / "demo_node"
    script.write_text(NODE)
    starts = tmp_path / "starts"
    env = dict(os.environ, PYTHONPATH=REPO_ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    env.pop(CHILD_ENV, None)

    def start(*args, respawn="true"):
        return subprocess.Popen([sys.executable, str(script), args[0], str(starts)] + list(args[1:]),
                                env=dict(env, **{RESPAWN_ENV: respawn}), stderr=subprocess.PIPE,
                                universal_newlines=True, start_new_session=True)

    def pids():
        return [int(p) for p in starts.read_text().split()] if starts.exists() else []
    return start, pids


def wait_for(condition, timeout=10.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.01)
    return False


def alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:
        with open("/proc/%d/stat" % pid) as stream:  # a zombie is not alive
            return stream.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def test_real_child_exit_78_ends_the_supervisor_at_once(node):
    start, pids = node
    supervisor = start("exit", str(EX_CONFIG))
    _out, err = supervisor.communicate(timeout=20)
    assert supervisor.returncode == EX_CONFIG
    assert len(pids()) == 1 and pids()[0] != supervisor.pid  # the node ran as a child
    assert err == ""


def test_real_child_exit_1_and_0_are_restarted_with_one_line_each(node):
    start, pids = node
    supervisor = start("fail-then-cannot-start")
    _out, err = supervisor.communicate(timeout=20)
    assert supervisor.returncode == EX_CONFIG
    assert len(pids()) == 3
    lines = err.splitlines()
    assert len(lines) == 2
    assert lines[0].startswith("demo_node: exit status 1 after ") and lines[0].endswith("in 0.05 s (restart 1)")
    assert lines[1].startswith("demo_node: exit status 0 after ") and lines[1].endswith("in 0.1 s (restart 2)")


def test_real_crash_is_restarted_and_a_start_up_error_then_stays_down(node):
    start, pids = node
    supervisor = start("crash-then-cannot-start")
    _out, err = supervisor.communicate(timeout=20)
    assert supervisor.returncode == EX_CONFIG
    assert len(pids()) == 2
    lines = [line for line in err.splitlines() if line.startswith("demo_node:")]
    assert len(lines) == 1 and lines[0].startswith("demo_node: killed by SIGABRT after ")


def test_a_killed_node_comes_back_and_a_group_sigint_stops_both(node):
    start, pids = node
    supervisor = start("serve")
    assert wait_for(lambda: len(pids()) == 1)
    first = pids()[0]
    os.kill(first, signal.SIGKILL)  # not asked to stop: a crash
    assert wait_for(lambda: len(pids()) == 2)
    second = pids()[1]
    assert alive(second)
    os.killpg(supervisor.pid, signal.SIGINT)  # roslaunch's stop: the whole process group
    _out, err = supervisor.communicate(timeout=20)
    assert supervisor.returncode == 0
    assert not alive(second)
    assert len(pids()) == 2
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("demo_node: killed by SIGKILL after ")
    assert lines[0].endswith("; starting it again in 0.05 s (restart 1)")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
def test_a_sigkill_of_the_supervisor_leaves_no_orphan(node):
    # roslaunch's last resort: SIGKILL to the supervisor's process group, which the node is not in
    start, pids = node
    supervisor = start("serve")
    assert wait_for(lambda: len(pids()) == 1)
    child = pids()[0]
    assert os.getpgid(child) != os.getpgid(supervisor.pid)  # each stop signal reaches it once, passed on
    os.killpg(supervisor.pid, signal.SIGKILL)
    supervisor.communicate(timeout=20)
    assert wait_for(lambda: not alive(child))


def test_sigterm_to_the_supervisor_alone_is_passed_on_and_it_ends_by_the_same_signal(node):
    start, pids = node
    supervisor = start("wait")
    assert wait_for(lambda: len(pids()) == 1)
    child = pids()[0]
    supervisor.send_signal(signal.SIGTERM)
    _out, err = supervisor.communicate(timeout=20)
    assert supervisor.returncode == -signal.SIGTERM
    assert wait_for(lambda: not alive(child))
    assert len(pids()) == 1 and err == ""


def test_without_respawn_the_process_is_the_node(node):
    start, pids = node
    process = start("exit", "3", respawn="false")
    _out, err = process.communicate(timeout=20)
    assert process.returncode == 3
    assert pids() == [process.pid] and err == ""
