"""The recorder wrapper of launch/record.launch (quadruped_control.ros.bag_record)."""
import os
import stat

import pytest

from quadruped_control.ros.bag_record import BagDirError, main, prepare_bag_dir, record_command, resolve_topics


def test_missing_bag_dir_is_created(tmp_path):
    target = tmp_path / "a" / "b"
    assert prepare_bag_dir(str(target)) == str(target)
    assert target.is_dir()
    assert prepare_bag_dir(str(target)) == str(target)  # existing folder: fine


def test_bad_bag_dirs_give_clear_errors(tmp_path):
    a_file = tmp_path / "file"
    a_file.write_text("x")
    with pytest.raises(BagDirError, match="exists and is not a folder"):
        prepare_bag_dir(str(a_file))
    with pytest.raises(BagDirError, match="cannot create bag_dir"):
        prepare_bag_dir(str(a_file / "sub"))
    with pytest.raises(BagDirError, match="empty"):
        prepare_bag_dir("")


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes everywhere")
def test_read_only_bag_dir_is_refused(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(stat.S_IRUSR | stat.S_IXUSR)
    with pytest.raises(BagDirError, match="not writable"):
        prepare_bag_dir(str(ro))


def test_command_keeps_roslaunch_arguments(tmp_path):
    command = record_command(str(tmp_path), "uq", ["imu/data", "__name:=recorder"])
    assert command == ["rosbag", "record", "-o", os.path.join(str(tmp_path), "uq"), "/imu/data", "__name:=recorder"]


def test_relative_topics_are_resolved_in_the_namespace():
    args = ["--split", "--size=1024", "-l", "5", "imu/data", "/diagnostics", "__log:=x", "sim/pose"]
    assert resolve_topics(args, "/uq1/") == ["--split", "--size=1024", "-l", "5", "/uq1/imu/data", "/diagnostics",
                                             "__log:=x", "/uq1/sim/pose"]
    assert resolve_topics(args, "fleet/uq2")[4] == "/fleet/uq2/imu/data"
    assert resolve_topics(["imu/data"], "/") == ["/imu/data"]
    assert resolve_topics(["imu/data"], "") == ["/imu/data"]


def test_main_refuses_a_bad_bag_dir_without_starting_rosbag(tmp_path, capsys):
    a_file = tmp_path / "file"
    a_file.write_text("x")
    assert main(["bag_record", str(a_file), "uq", "imu/data"]) == 1
    assert "is not a folder; nothing is recorded" in capsys.readouterr().err
    assert main(["bag_record"]) == 2


def test_record_launch_uses_relative_names_and_the_wrapper():
    """Under ROS_NAMESPACE=uq1 the recorder must record /uq1/imu/data etc.: relative names, except the
    topics that are global by convention."""
    import shlex
    import xml.etree.ElementTree as ET

    from quadruped_common.config import config_dir
    launch = os.path.join(os.path.dirname(config_dir()), "launch", "record.launch")
    node = ET.parse(launch).getroot().find("node")
    assert (node.get("pkg"), node.get("type"), node.get("required")) == ("underwater_quadruped", "bag_record", "true")
    args = shlex.split(node.get("args"))
    assert args[:2] == ["$(arg bag_dir)", "uq"]
    topics = [a for a in args[2:] if not a.startswith("-") and not a.isdigit() and "=" not in a]
    global_topics = {t for t in topics if t.startswith("/")}
    assert global_topics == {"/diagnostics", "/tf", "/tf_static", "/rosout"}
    assert {"imu/data", "joint_states", "servo_command", "controller_state", "attitude_setpoint",
            "attitude_setpoint_rpy_deg", "attitude_controller/parameter_updates"} <= set(topics)
    # the gains in force: the controller's dynamic_reconfigure updates, under the name controller.launch gives it
    controller = ET.parse(launch.replace("record.launch", "controller.launch")).getroot().find("node")
    assert controller.get("name") + "/parameter_updates" in topics


def test_a_recorder_that_dies_is_started_again_until_the_launch_stops(tmp_path):
    """supervise: each death of the recorder (here a child that exits at once) restarts it after the
    delay; once stopping, the last exit ends the wrapper with success."""
    from quadruped_control.ros.bag_record import supervise
    started, logged = [], []

    class Child:
        def __init__(self, command):
            started.append(command)

        def wait(self):
            return 0 if len(started) >= 3 else -9  # killed twice, then stopped by the launch

    status = supervise(["rosbag", "record"], str(tmp_path), lambda: len(started) >= 3, restart_delay=0.01,
                       popen=Child, log=lambda *a, **k: logged.append(a[0]))
    assert status == 0 and len(started) == 3
    assert len(logged) == 2 and "restart 1" in logged[0]


def test_the_wrapper_ends_when_the_bag_dir_can_no_longer_be_written(tmp_path):
    from quadruped_control.ros.bag_record import supervise
    folder = tmp_path / "bags"
    folder.mkdir()

    class Child:
        def __init__(self, command):
            folder.rmdir()
            folder.write_text("now a file")  # the folder is gone: the next start would record nothing

        def wait(self):
            return 1

    assert supervise(["x"], str(folder), lambda: False, restart_delay=0.0, popen=Child, log=lambda *a, **k: None) == 1


def test_the_wrapper_records_for_real_and_stops_on_sigint(tmp_path):
    """main with a stand-in recorder: a child process that lives until SIGINT reaches its group."""
    import signal
    import subprocess
    import sys
    import time
    script = ("import sys, time, os\n"
              "sys.argv = sys.argv[:1]\n"
              "from quadruped_control.ros import bag_record\n"
              "bag_record.record_command = lambda d, p, a, n='/': [sys.executable, '-c', 'import time; time.sleep(60)']\n"
              "sys.exit(bag_record.main(['bag_record', %r, 'uq', 'imu/data']))\n" % str(tmp_path))
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
    process = subprocess.Popen([sys.executable, "-c", script], cwd=root, start_new_session=True,
                               env=dict(os.environ, PYTHONPATH=root))
    time.sleep(1.0)
    os.killpg(process.pid, signal.SIGINT)  # as roslaunch stops a node: SIGINT to its process group
    assert process.wait(timeout=10) == 0
