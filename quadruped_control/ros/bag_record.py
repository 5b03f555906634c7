"""Start ``rosbag record`` into a bag folder that exists: ``launch/record.launch``'s recorder.

``rosbag record -o DIR/uq`` dies at start when DIR does not exist, and the rest of the stack would go on
unrecorded. This wrapper makes the folder (like ``mkdir -p``) or stops with a clear message naming it,
then replaces itself with ``rosbag record -o DIR/PREFIX ARGS...`` (ARGS include roslaunch's
``__name:=`` / ``__log:=``, so the recorder keeps its node name). No rospy.

    bag_record BAG_DIR PREFIX [rosbag record arguments...]
"""
from __future__ import annotations

import os
import sys
from typing import List, Sequence


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
    os.execvp(command[0], command)
    return 0  # not reached: execvp replaces the process
