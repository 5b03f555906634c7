"""One bus, one user: the driver nodes share it by role, a tool has it alone, and a refusal names the holder."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from quadruped_drivers.i2c.bus_lock import BusBusyError, BusLock
from quadruped_drivers.node_support import bus_name, open_bus


def test_a_tool_has_the_bus_alone(tmp_path):
    tool = BusLock("i2c-7", directory=str(tmp_path)).acquire()
    with pytest.raises(BusBusyError, match=r"^the I2C bus i2c-7 is in use by pid %d: " % os.getpid()):
        BusLock("i2c-7", directory=str(tmp_path)).acquire()
    with pytest.raises(BusBusyError, match="pid %d" % os.getpid()):
        BusLock("i2c-7", "pwm", directory=str(tmp_path)).acquire()
    BusLock("i2c-1", directory=str(tmp_path)).acquire()  # another bus is another lock
    tool.release()
    BusLock("i2c-7", "pwm", directory=str(tmp_path)).acquire()


def test_the_nodes_share_the_bus_one_process_per_role(tmp_path):
    pwm = BusLock("i2c-7", "pwm", directory=str(tmp_path)).acquire()
    feedback = BusLock("i2c-7", "feedback", directory=str(tmp_path)).acquire()
    with pytest.raises(BusBusyError, match="in use by pid"):
        BusLock("i2c-7", "pwm", directory=str(tmp_path)).acquire()
    with pytest.raises(BusBusyError) as refused:
        BusLock("i2c-7", directory=str(tmp_path)).acquire()
    assert str(refused.value).count("pid %d" % os.getpid()) == 2  # both nodes named
    pwm.release()
    feedback.release()
    BusLock("i2c-7", directory=str(tmp_path)).acquire()


def test_a_second_process_is_refused_and_the_lock_dies_with_its_holder(tmp_path):
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time; from quadruped_drivers.i2c.bus_lock import BusLock; "
         "BusLock('i2c-7', directory=sys.argv[1]).acquire(); print('held', flush=True); time.sleep(60)",
         str(tmp_path), "jog-tool"], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(BusBusyError, match=r"in use by pid %d: .*jog-tool: stop it first" % holder.pid):
            BusLock("i2c-7", "pwm", directory=str(tmp_path)).acquire()
    finally:
        holder.send_signal(signal.SIGKILL)  # however it ends, the kernel drops its lock
        holder.wait()
    deadline = time.monotonic() + 5.0
    while True:
        try:
            BusLock("i2c-7", "pwm", directory=str(tmp_path)).acquire()
            break
        except BusBusyError:
            assert time.monotonic() < deadline
            time.sleep(0.05)


def test_open_bus_takes_the_lock_before_opening(tmp_path, monkeypatch):
    monkeypatch.setenv("UQ_LOCK_DIR", str(tmp_path))
    socket_path = str(tmp_path / "absent.sock")
    BusLock(bus_name("sim", 7, socket_path), directory=str(tmp_path)).acquire()  # a tool holds the sim bus
    with pytest.raises(BusBusyError, match="sim-absent.sock"):
        open_bus("sim", 7, socket_path, role="pwm", wait=0.0)
    with pytest.raises(ValueError, match="unknown bus backend"):
        open_bus("usb", 7, socket_path)
    assert bus_name("real", 7, "") == "i2c-7"


def test_a_role_must_be_known(tmp_path):
    with pytest.raises(ValueError, match="role"):
        BusLock("i2c-7", "jog", directory=str(tmp_path))
