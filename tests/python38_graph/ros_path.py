"""Build the folder through which a Python 3.8 node sees ROS's pure-Python packages (tests/python38_graph.sh).

Debian 12's ROS 1 installs its Python packages for Python 3.11 in /usr/lib/python3/dist-packages, beside
compiled modules (PyYAML's C loader, pycryptodome, ...) that Python 3.8 must not import. So that folder is
never put on a 3.8 path; this script makes a folder of symlinks to the top-level modules of the Debian
packages the nodes need (ROOTS and everything they depend on, python3-* only) that are

- pure Python (no .so anywhere below them): ROS's own packages (rospy, rosgraph, roslib, genpy, the
  message packages, diagnostic_updater, dynamic_reconfigure ...) and the pure helpers they import
  (catkin_pkg, rospkg, distro, ...), and
- not already importable from the 3.8 venv (numpy, PyYAML, dateutil, pyparsing, six come from there,
  built for 3.8 and pinned by requirements-jetson-test.txt).

Compiled ones are left out and listed in the folder's MANIFEST.txt with the 3.11 file that shows why.

    python3 ros_path.py OUT_DIR VENV38_PYTHON
"""
import os
import subprocess
import sys

DIST = "/usr/lib/python3/dist-packages"
#: the Debian packages holding what our nodes import (quadruped_common/ros, quadruped_control/ros,
#: quadruped_drivers/*_node.py); their python3-* dependencies come along. python3-tf2-ros is among them
#: so that MANIFEST.txt names what stops visualization_node on 3.8: tf2_ros is pure, but it imports
#: tf2_py, whose _tf2 is compiled for 3.11.
ROOTS = (
    "python3-rospy", "python3-roslib", "python3-rosgraph", "python3-rospkg", "python3-genpy",
    "python3-std-msgs", "python3-sensor-msgs", "python3-geometry-msgs", "python3-std-srvs",
    "python3-diagnostic-msgs", "python3-diagnostic-updater", "python3-dynamic-reconfigure",
    "python3-visualization-msgs", "python3-rosgraph-msgs", "python3-tf2-ros",
)


def dpkg_field(package, field):
    done = subprocess.run(["dpkg-query", "-W", "-f", "${%s}" % field, package], capture_output=True, text=True)
    return done.stdout if done.returncode == 0 else None


def closure(roots):
    """The installed python3-* packages among ``roots`` and their dependencies, recursively."""
    seen, todo = set(), list(roots)
    while todo:
        package = todo.pop()
        if package in seen:
            continue
        if "install ok installed" not in (dpkg_field(package, "Status") or ""):
            raise SystemExit("ros_path.py: Debian package %s is not installed (scripts/setup.sh installs it)" % package)
        seen.add(package)
        for alternative in (dpkg_field(package, "Depends") or "").split(","):
            name = alternative.split("|")[0].strip().split(" ")[0].split(":")[0]
            if name.startswith("python3-") and name not in seen:
                todo.append(name)
    return sorted(seen)


def top_level_modules(package):
    """Top-level modules (package folders, module files) ``package`` installs in DIST."""
    listing = subprocess.run(["dpkg", "-L", package], capture_output=True, text=True, check=True).stdout.split()
    tops = set()
    for path in listing:
        if path.startswith(DIST + "/"):
            top = path[len(DIST) + 1:].split("/")[0]
            if not top.endswith((".egg-info", ".dist-info", ".pth")) and top != "__pycache__":
                tops.add(top)
    return sorted(tops)


def compiled_file(path):
    """The first compiled module at or below ``path``, or None."""
    if path.endswith(".so"):
        return path
    for folder, _dirs, files in os.walk(path):
        for name in sorted(files):
            if name.endswith(".so"):
                return os.path.join(folder, name)
    return None


def main(out, venv_python):
    modules = {}  # module name -> (Debian package, path in DIST)
    for package in closure(ROOTS):
        for top in top_level_modules(package):
            name = top[:-3] if top.endswith(".py") else top.split(".")[0]
            modules[name] = (package, os.path.join(DIST, top))
    # what the 3.8 venv imports by itself (-E -s: its own site-packages only)
    probe = "import importlib.util, sys\nfor n in sys.argv[1:]:\n    print(n, importlib.util.find_spec(n) is not None)"
    found = subprocess.run([venv_python, "-E", "-s", "-c", probe] + sorted(modules),
                           capture_output=True, text=True, check=True).stdout.split("\n")
    in_venv = {line.split()[0] for line in found if line.endswith(" True")}
    os.makedirs(out, exist_ok=True)
    for entry in os.listdir(out):
        if os.path.islink(os.path.join(out, entry)):
            os.unlink(os.path.join(out, entry))
    exposed, from_venv, left_out = [], [], []
    for name, (package, path) in sorted(modules.items()):
        so = compiled_file(path)
        if name in in_venv:
            from_venv.append("%s (%s)" % (name, package))
        elif so:
            left_out.append("%s (%s): compiled for Python 3.11, %s" % (name, package, so))
        else:
            os.symlink(path, os.path.join(out, os.path.basename(path)))
            exposed.append("%s (%s)" % (name, package))
    with open(os.path.join(out, "MANIFEST.txt"), "w") as stream:
        stream.write("Debian's pure-Python packages seen by the Python 3.8 nodes (symlinks here):\n  ")
        stream.write("\n  ".join(exposed))
        stream.write("\nfrom the 3.8 venv instead (built for 3.8):\n  " + "\n  ".join(from_venv))
        stream.write("\nleft out, compiled for 3.11 (a node importing them cannot run on 3.8):\n  ")
        stream.write("\n  ".join(left_out) + "\n")
    print("ros_path: %d Debian pure-Python modules exposed, %d from the 3.8 venv, %d compiled left out: %s"
          % (len(exposed), len(from_venv), len(left_out), ", ".join(x.split(" ")[0] for x in left_out)))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
