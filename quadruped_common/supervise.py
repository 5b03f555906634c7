"""Start a node again when it crashes, with a back-off; never when it cannot start (no rospy).

roslaunch's ``respawn`` starts a dead node again after a fixed delay whatever ended it: a node that
cannot start (its I2C device file missing, a configuration refused) printed its error and was started
again every second, for ever. The long-running nodes' executables (``nodes/``) therefore supervise
themselves when the launch file asks for it (``UQ_RESPAWN=true`` in the node's environment, from the
launch files' ``respawn`` argument; the nodes then have roslaunch's ``respawn`` off):
:func:`supervise_if_asked` makes the process roslaunch started the node's supervisor, which runs the same
command line (roslaunch's ``__name:=`` / ``__log:=`` remappings included) with the same environment as
its child, the node itself, and when the child ends:

* any end after the supervisor was asked to stop (SIGINT / SIGTERM, passed on to the child): the
  supervisor ends the same way (the same exit status, or the same signal);
* :data:`~quadruped_common.startup_errors.EX_CONFIG` (78): the node cannot start and has said why in one
  line (:func:`quadruped_common.ros.node_startup.start_node`); the supervisor exits 78 at once, no restart;
* anything else (a crash, SIGKILL, a lost link the node gave up on): one line naming the exit status,
  then the node is started again after the back-off (:class:`Backoff`: 1 s, doubling up to 30 s, back to
  1 s after a run of 60 s or more). Exit status 0 without a stop request is one of these, as it was
  for roslaunch's respawn: these nodes run until stopped, so ending by themselves means they gave up
  (vn100_node ends itself when its publisher closes, to be started again), and ``rosnode kill`` stays
  the way to restart one.

The child runs in a process group of its own and dies with the supervisor (Linux ``PR_SET_PDEATHSIG``
SIGKILL): roslaunch stops a node with ``killpg`` (SIGINT, SIGTERM after 15 s, SIGKILL after 2 s more),
so the child gets each stop signal once, from the supervisor (in the supervisor's group it would get it
twice, and a second SIGINT can interrupt a node's shutdown), and roslaunch's final SIGKILL of the
supervisor still ends the child: no orphan is left holding the bus. Where ``prctl`` is not available the
child stays in the supervisor's group (roslaunch's signals then reach it directly as well). A node
killed by a signal the supervisor did not get (``kill -9 <node pid>``, the OOM killer) is a crash.

Without ``UQ_RESPAWN=true`` (``rosrun``, ``respawn:=false`` launches, where a death ends the launch) the
process is the node itself, as before. (A debugger in ``launch-prefix`` would run the supervisor, not the
node: debug with ``respawn:=false``.)
"""
from __future__ import annotations

import ctypes
import ctypes.util
import os
import signal
import subprocess
import sys
import time
from typing import Callable, List, Mapping, NamedTuple, Optional, Sequence

from quadruped_common.startup_errors import EX_CONFIG

#: Set to "true" in a node's environment (launch files: ``<env name="UQ_RESPAWN" value="$(arg respawn)"/>``)
#: to have its executable supervise it.
RESPAWN_ENV = "UQ_RESPAWN"
#: Set by the supervisor in its child's environment: this process is the node.
CHILD_ENV = "UQ_SUPERVISED_CHILD"
#: The signals that ask the supervisor (and its node) to stop.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Backoff(NamedTuple):
    """Seconds between a crash and the next start: ``first``, doubled after each crash up to ``longest``;
    ``first`` again after a run of at least ``reset_after`` s."""
    first: float = 1.0
    longest: float = 30.0
    reset_after: float = 60.0

    def next_delay(self, previous: Optional[float], ran: float) -> float:
        """The wait before the next start, after a crash ``ran`` s after its start; ``previous``: the wait
        before that start (None: it was the first start)."""
        if previous is None or ran >= self.reset_after:
            return self.first
        return min(2.0 * previous, self.longest)


def describe_status(status: int) -> str:
    """``subprocess`` return code in words: ``exit status 1``, ``killed by SIGKILL``."""
    if status < 0:
        try:
            return "killed by %s" % signal.Signals(-status).name
        except ValueError:
            return "killed by signal %d" % -status
    return "exit status %d" % status


#: prctl(2) option: the signal this process gets when its parent dies.
_PR_SET_PDEATHSIG = 1


def _prctl() -> Optional[Callable[..., int]]:
    """libc's ``prctl`` (Linux), loaded in the supervisor before any fork; None where there is none."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        return ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None


def start_child(command: Sequence[str], env: Optional[Mapping[str, str]] = None) -> "subprocess.Popen":
    """``subprocess.Popen(command)``: in a process group of its own and killed with its parent where Linux
    allows (module docstring), in the supervisor's group otherwise."""
    prctl, parent = _prctl(), os.getpid()

    def own_group_dying_with_parent() -> None:  # in the child, between fork and exec
        if prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) != 0:
            return  # not set: stay in the parent's group, where roslaunch's SIGKILL reaches it
        os.setpgid(0, 0)
        if os.getppid() != parent:  # the parent died before prctl: nobody would stop this child
            os._exit(1)  # noqa: SLF001 - no clean-up between fork and exec

    return subprocess.Popen(list(command), env=None if env is None else dict(env),
                            preexec_fn=None if prctl is None else own_group_dying_with_parent)


def _stderr(line: str) -> None:
    sys.stderr.write(line + "\n")
    sys.stderr.flush()


class Supervisor:
    """Runs ``command`` as a child (environment ``env``) and starts it again after a crash (module docstring).

    :meth:`run` returns the status to end with (``subprocess`` convention: negative is a signal);
    :meth:`request_stop` is the stop signals' handler. ``popen``, ``clock``, ``sleep`` and ``log`` are
    there for tests.
    """

    def __init__(self, name: str, command: Sequence[str], env: Optional[Mapping[str, str]] = None,
                 backoff: Backoff = Backoff(), popen: Callable[..., "subprocess.Popen"] = start_child,
                 clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
                 log: Callable[[str], None] = _stderr) -> None:
        self.name = name
        self.command: List[str] = list(command)
        self.env = None if env is None else dict(env)
        self.backoff = backoff
        self.popen = popen
        self.clock = clock
        self.sleep = sleep
        self.log = log
        self.stop_signal: Optional[int] = None
        self.starts = 0
        self._child = None
        self._signalled = None  # the child last sent the stop signal

    def request_stop(self, signum: int, _frame=None) -> None:
        """Stop: pass ``signum`` on to the child (if one runs) and start no other."""
        if self.stop_signal is None:
            self.stop_signal = signum
        self._pass_on(signum)

    def _pass_on(self, signum: int) -> None:
        child = self._child
        if child is None or child.returncode is not None:
            return
        try:
            os.kill(child.pid, signum)
        except ProcessLookupError:  # pragma: no cover - ended between the check and the kill
            pass
        self._signalled = child

    def run(self) -> int:
        """Supervise until the child ends for good; the status to end with (module docstring)."""
        delay: Optional[float] = None
        while True:
            started = self.clock()
            self._child = self.popen(self.command, env=self.env)
            self.starts += 1
            if self.stop_signal is not None and self._signalled is not self._child:
                self._pass_on(self.stop_signal)  # asked to stop while the child was being started
            status = self._child.wait()
            ran = self.clock() - started
            if self.stop_signal is not None or status == EX_CONFIG:
                return status
            delay = self.backoff.next_delay(delay, ran)
            self.log("%s: %s after %.1f s; starting it again in %.3g s (restart %d)"
                     % (self.name, describe_status(status), ran, delay, self.starts))
            if not self._wait(delay):
                return 0  # asked to stop during the back-off: nothing runs any more

    def _wait(self, seconds: float) -> bool:
        """Sleep ``seconds`` unless asked to stop meanwhile; False when asked to stop."""
        deadline = self.clock() + seconds
        while self.stop_signal is None:
            left = deadline - self.clock()
            if left <= 0:
                return True
            self.sleep(min(left, 0.05))
        return False


def exit_as(status: int) -> None:
    """End this process the way the child ended: the same exit status, or the same signal."""
    if status < 0:
        signum = -status
        signal.signal(signum, signal.SIG_DFL)
        os.kill(os.getpid(), signum)
        sys.exit(128 + signum)  # pragma: no cover - only if the signal did not end the process
    sys.exit(status)


def respawn_asked(environ: Mapping[str, str]) -> bool:
    """True when ``environ`` asks for a supervisor (``UQ_RESPAWN`` true) and this is not its child."""
    return (environ.get(RESPAWN_ENV, "").strip().lower() in ("1", "true", "yes")
            and not environ.get(CHILD_ENV))


def supervise_if_asked(name: str, argv: Optional[Sequence[str]] = None, backoff: Backoff = Backoff()) -> None:
    """Called first by a node's executable: when asked (:func:`respawn_asked`), become the supervisor of
    ``name`` (roslaunch's ``__name:=`` if given) running this same executable (``sys.executable`` and
    ``argv``, default ``sys.argv``) as the node, and end as :meth:`Supervisor.run` says: it never returns
    then. Returns at once otherwise: the caller is the node."""
    if not respawn_asked(os.environ):
        return
    argv = list(sys.argv if argv is None else argv)
    name = next((arg.split(":=", 1)[1] for arg in argv if arg.startswith("__name:=")), name)  # roslaunch's name
    env = dict(os.environ)
    env[CHILD_ENV] = "1"
    supervisor = Supervisor(name, [sys.executable] + argv, env, backoff)
    for signum in STOP_SIGNALS:
        signal.signal(signum, supervisor.request_stop)
    exit_as(supervisor.run())


__all__ = ["Backoff", "CHILD_ENV", "RESPAWN_ENV", "Supervisor", "describe_status", "exit_as", "respawn_asked",
           "start_child", "supervise_if_asked"]
