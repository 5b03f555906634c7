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
            "attitude_setpoint_rpy_deg"} <= set(topics)
