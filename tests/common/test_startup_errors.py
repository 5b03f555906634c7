"""quadruped_common.startup_errors: which start-up errors a restart cannot fix, and the one line for them."""
import errno

import pytest

from quadruped_common.config import ParameterError
from quadruped_common.startup_errors import (EX_CONFIG, FIX_BUSY, FIX_CONFIGURATION, FIX_LIBRARY, FIX_MISSING,
                                             FIX_PERMISSION, PermanentCause, cannot_start_line, permanent_cause)
from quadruped_drivers.i2c.bus_lock import BusLock
from quadruped_drivers.i2c.real_bus import I2CBackendError, open_i2c_bus


def test_ex_config_is_sysexits_value():
    assert EX_CONFIG == 78


def test_a_missing_i2c_device_names_itself_and_the_fix():
    with pytest.raises(I2CBackendError) as raised:
        open_i2c_bus(250)  # no machine has 251 I2C buses
    cause = permanent_cause(raised.value)
    assert cause == PermanentCause("/dev/i2c-250 does not exist", raised.value.fix)
    assert "i2c.bus" in cause.fix and "hardware_yaml" in cause.fix
    line = cannot_start_line("pwm_node", cause)
    assert line.startswith("pwm_node cannot start: /dev/i2c-250 does not exist. Fix: enable the I2C controller")
    assert "\n" not in line
    assert str(raised.value) == "%s: %s" % (raised.value.cause, raised.value.fix)  # the message is both


def test_an_i2c_error_without_a_fix_is_left_to_the_restart():
    assert permanent_cause(I2CBackendError("opening /dev/i2c-7 failed: [Errno 5] Input/output error")) is None


def test_no_permission_on_the_i2c_device(monkeypatch):
    monkeypatch.setattr("os.path.exists", lambda path: True)
    monkeypatch.setattr("os.access", lambda path, mode: False)
    with pytest.raises(I2CBackendError) as raised:
        open_i2c_bus(7)
    cause = permanent_cause(raised.value)
    assert cause.cause == "no permission to open /dev/i2c-7"
    assert "i2c' group" in cause.fix


def test_a_configuration_refused_is_permanent():
    cause = permanent_cause(ParameterError("hardware.yaml: i2c.bus: must be an integer, got 'seven'"))
    assert cause == PermanentCause("hardware.yaml: i2c.bus: must be an integer, got 'seven'", FIX_CONFIGURATION)
    assert permanent_cause(ValueError("failsafe must be one of hold, neutral, off, got 'x'")).fix == FIX_CONFIGURATION


def test_extra_types_are_taken_as_a_configuration_refused():
    class Refused(Exception):
        pass
    assert permanent_cause(Refused("no")) is None
    assert permanent_cause(Refused("no"), (Refused,)) == PermanentCause("no", FIX_CONFIGURATION)


def test_a_missing_library_is_permanent():
    cause = permanent_cause(ModuleNotFoundError("No module named 'serial'", name="serial"))
    assert cause == PermanentCause("ModuleNotFoundError: No module named 'serial'", FIX_LIBRARY)


def test_the_bus_held_by_another_process_is_permanent(tmp_path):
    holder = BusLock("i2c-7", None, directory=str(tmp_path)).acquire()
    try:
        with pytest.raises(OSError) as raised:
            BusLock("i2c-7", "pwm", directory=str(tmp_path)).acquire()
    finally:
        holder.release()
    cause = permanent_cause(raised.value)
    assert cause.fix == FIX_BUSY
    assert cause.cause.startswith("the I2C bus i2c-7 is in use by pid ")


@pytest.mark.parametrize("exc, fix", [
    (PermissionError(errno.EACCES, "Permission denied", "/dev/ttyUSB0"), FIX_PERMISSION),
    (OSError(errno.EPERM, "Operation not permitted"), FIX_PERMISSION),
    (FileNotFoundError(errno.ENOENT, "No such file or directory", "/dev/vn100"), FIX_MISSING),
    (OSError(errno.ENXIO, "No such device or address", "/dev/ttyUSB0"), FIX_MISSING),
])
def test_permission_and_missing_files_are_permanent(exc, fix):
    cause = permanent_cause(exc)
    assert cause is not None and cause.fix == fix
    assert cause.cause == str(exc)


@pytest.mark.parametrize("exc", [
    RuntimeError("boom"),
    KeyError("x"),
    ConnectionRefusedError(errno.ECONNREFUSED, "Connection refused"),
    FileNotFoundError(errno.ENOENT, "No such file or directory"),  # a socket not there yet: no file name
    OSError("simulated I2C bus socket /tmp/x.sock did not appear within 15 s (is sim_node running?)"),
    TimeoutError(errno.ETIMEDOUT, "timed out"),
    OSError(errno.EIO, "Input/output error", "/dev/i2c-7"),
])
def test_what_a_restart_may_fix_is_not_permanent(exc):
    assert permanent_cause(exc) is None


def test_the_line_is_one_line_without_doubled_stops():
    cause = PermanentCause("first line\n  second line.", "do this.\n")
    assert cannot_start_line("vn100_node", cause) == "vn100_node cannot start: first line second line. Fix: do this"
    blank = permanent_cause(ValueError())
    assert cannot_start_line("x", blank) == "x cannot start: ValueError. Fix: %s" % FIX_CONFIGURATION
