"""Start ``rosbag record`` into a bag folder that exists: ``launch/record.launch``'s recorder.

``rosbag record -o DIR/uq`` dies at start when DIR does not exist, and the rest of the stack would go on
unrecorded. This wrapper makes the folder (like ``mkdir -p``) or stops with a clear message naming it,
then runs ``rosbag record -o DIR/PREFIX ARGS...`` (ARGS include roslaunch's ``__name:=`` / ``__log:=``,
so the recorder keeps its node name) and supervises it (:func:`supervise`): a recorder that dies (a
crash, SIGKILL, the OOM killer) is started again after ``RESTART_DELAY`` s into a new bag file, the one it
left ``.active`` is reindexed by the bag report, which names the missing span. The wrapper is the
launch's *required* process: it ends the launch only when the folder can no longer be written, so a
run asked to record never goes on unrecorded, and a recorder crash no longer stops the robot (it used to:
the recorder itself was the required node). roslaunch's SIGINT reaches the recorder directly (same
process group); the wrapper then waits for it to close its bag. No rospy.

    bag_record BAG_DIR PREFIX [rosbag record arguments...]
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from typing import Callable, List, Sequence

#: Seconds between a recorder's death and its restart (roslaunch's respawn_delay of the other nodes).
RESTART_DELAY = 1.0


class BagDirError(RuntimeError):
    """The bag folder cannot be made or written."""


def prepare_bag_dir(path: str) -> str:
    """Absolute path of ``path``, created if missing; BagDirError when it is not a writable folder."""
    if not path:
        raise BagDirError("bag_dir is empty: pass bag_dir:=/path/to/bags")
    path = os.path.abspath(os.path.expanduser(path))
    if os.path.exists(path) and not os.path.isdir(path):
        raise BagDirError("bag_dir %s exists and is not a folder" % path)
    try:
        os.makedirs(path, exist_ok=True)
    except OSError as exc:
        raise BagDirError("cannot create bag_dir %s: %s" % (path, exc.strerror or exc)) from None
    if not os.access(path, os.W_OK | os.X_OK):
        raise BagDirError("bag_dir %s is not writable by this user" % path)
    return path


#: rosbag record options whose value is the next argument (the rest are flags or --opt=value)
_VALUE_OPTIONS = {"-o", "-O", "-b", "-l", "-e", "-x", "-p", "--output-prefix", "--output-name", "--buffsize",
                  "--chunksize", "--limit", "--exclude", "--node", "--duration", "--size", "--max-splits",
                  "--lz4", "--publish"}


def resolve_topics(args: Sequence[str], namespace: str) -> List[str]:
    """``args`` with every relative topic name made absolute in ``namespace`` (ROS_NAMESPACE).

    rosbag subscribes to a relative name in its namespace but writes the name as given into the bag;
    absolute names keep the bags' topics what ``rostopic list`` shows (and what bag_report reads).
    Options, their values and roslaunch's ``__name:=`` remappings are left alone.
    """
    prefix = "/" + "/".join(part for part in namespace.split("/") if part)
    out = []
    takes_value = False
    for arg in args:
        if takes_value or arg.startswith("-") or ":=" in arg or arg.startswith("/"):
            out.append(arg)
        else:
            out.append(prefix.rstrip("/") + "/" + arg)
        takes_value = arg in _VALUE_OPTIONS
    return out


def record_command(bag_dir: str, prefix: str, args: Sequence[str], namespace: str = "/") -> List[str]:
    """The rosbag command line: bags named PREFIX_<date>.bag in bag_dir, topics absolute."""
    return ["rosbag", "record", "-o", os.path.join(bag_dir, prefix)] + resolve_topics(args, namespace)


def main(argv: Sequence[str]) -> int:
    if len(argv) < 3:
        print("usage: bag_record BAG_DIR PREFIX [rosbag record arguments...]", file=sys.stderr)
        return 2
    try:
        bag_dir = prepare_bag_dir(argv[1])
    except BagDirError as exc:
        print("bag_record: %s; nothing is recorded" % exc, file=sys.stderr)
        return 1
    command = record_command(bag_dir, argv[2], argv[3:], os.environ.get("ROS_NAMESPACE", "/"))
    print("bag_record: recording into %s" % bag_dir, flush=True)
    stopping = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda number, _frame: stopping.append(number))
    return supervise(command, bag_dir, lambda: bool(stopping))


def supervise(command: Sequence[str], bag_dir: str, stopping: Callable[[], bool],
              restart_delay: float = RESTART_DELAY, popen=subprocess.Popen, log=print) -> int:
    """Run ``command`` until ``stopping()``; start it again ``restart_delay`` s after it dies otherwise.
    Returns its exit status once stopping, 1 when ``bag_dir`` can no longer be written (module docstring)."""
    starts = 0
    while True:
        child = popen(list(command))
        starts += 1
        while True:
            try:
                status = child.wait()
                break
            except InterruptedError:  # pragma: no cover - Python retries wait() itself (PEP 475)
                continue
        if stopping():
            return 0 if status in (0, -signal.SIGINT, -signal.SIGTERM) else status
        log("bag_record: the recorder died (exit status %s); recording again in %.1f s into a new bag "
            "(restart %d)" % (status, restart_delay, starts), flush=True)
        deadline = time.monotonic() + restart_delay
        while time.monotonic() < deadline and not stopping():
            time.sleep(0.05)
        if stopping():
            return 0
        try:
            prepare_bag_dir(bag_dir)
        except BagDirError as exc:
            log("bag_record: %s; nothing more is recorded" % exc, flush=True)
            return 1
