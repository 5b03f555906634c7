"""Run one ROS node's script under this interpreter, after leaving a record of who runs it.

tests/python38_graph.sh makes every node of the graph start as ``PYTHON38 node.py NODE_SCRIPT ARGS...``.
Before the node's own code runs, this writes ``$UQ_PY38_RECORD/<pid>.json`` with the interpreter's
version and the executable the kernel started (``/proc/self/exe``), as seen from inside the process
that then becomes the node; the step checks every process roslaunch started against those records.
"""
import json
import os
import runpy
import sys


def main() -> None:
    script = sys.argv[1]
    record = {
        "pid": os.getpid(),
        "version": sys.version.split()[0],
        "executable": os.path.realpath("/proc/self/exe"),
        "script": script,
        "argv": sys.argv[2:],
    }
    with open(os.path.join(os.environ["UQ_PY38_RECORD"], "%d.json" % os.getpid()), "w") as stream:
        json.dump(record, stream)
    sys.argv = [script] + sys.argv[2:]
    sys.path[0] = os.path.dirname(os.path.abspath(script))  # as when the script is run itself
    runpy.run_path(script, run_name="__main__")


if __name__ == "__main__":
    main()
