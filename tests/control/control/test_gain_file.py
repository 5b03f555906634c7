"""Tests of quadruped_control.control.gain_file: the gains in force written back as a loadable gain set."""
import os
import shutil

import pytest

from quadruped_common.config import ParameterError, config_path, load_yaml
from quadruped_control.control.controller_config import apply_tunables, load_controller_config
from quadruped_control.control.gain_file import gain_set_values, save_gain_set

SHIPPED = config_path("controller.yaml")


def tuned():
    """The experiment set as tuned live: every tunable off its file value, one that YAML must write as 1.0e-05;
    the stroke scheme switched, and settings that are no tunables off the shipped file's too."""
    config = load_controller_config(gain_set="experiment").replace(normalize_force_direction=True, integral_limit=5.0)
    return apply_tunables(config, {"k_p": 12.5, "k_i": 1e-5, "k_d": 0.75, "k_aw": 0.3, "tau_max": 1.5,
                                   "t_rec": 1.2, "t_pow_max": 0.45}).replace(stroke_scheme="coordinated")


def test_a_new_file_holds_the_configuration_in_force_and_loads_back_as_it(tmp_path):
    path = str(tmp_path / "gains" / "day3.yaml")  # the folder is made
    message = save_gain_set(tuned(), path, "tank_day3", note="saved by a test")
    assert load_controller_config(path, "tank_day3") == tuned()  # stroke scheme and every setting too
    assert "controller_yaml:=%s gain_set:=tank_day3" % path in message and "k_p 12.5" in message
    assert "# saved by a test" in open(path).read()
    assert os.listdir(str(tmp_path / "gains")) == ["day3.yaml"]  # no temporary file left


def test_a_set_is_added_to_a_given_file_and_nothing_else_of_it_changes(tmp_path):
    path = str(tmp_path / "controller.yaml")
    shutil.copyfile(SHIPPED, path)
    message = save_gain_set(tuned(), path, "tuned", note="saved live")
    before, after = open(SHIPPED).read().splitlines(), open(path).read().splitlines()
    assert [line for line in after if line not in before] == ["  # saved live", "  tuned:"] + [
        "    %s: %s" % (k, "1.0e-05" if k == "k_i" else v) for k, v in gain_set_values(tuned()).items()]
    assert [line for line in before if line not in after] == []  # every comment and value kept
    assert gain_set_values(load_controller_config(path, "tuned")) == gain_set_values(tuned())
    for name in load_yaml(SHIPPED)["gain_sets"]:
        assert load_controller_config(path, name) == load_controller_config(SHIPPED, name)
    # the file's stroke scheme stays its own: the message says how to get the one in force
    assert "stroke_scheme:=coordinated" in message


def test_an_existing_set_or_the_shipped_file_is_replaced_only_when_asked(tmp_path):
    path = str(tmp_path / "controller.yaml")
    shutil.copyfile(SHIPPED, path)
    with pytest.raises(ParameterError, match="already has a gain set 'experiment'.*set overwrite"):
        save_gain_set(tuned(), path, "experiment")
    with pytest.raises(ParameterError, match="is the shipped configuration: save to a file of your own"):
        save_gain_set(tuned(), path, "new_name", shipped=path)
    with pytest.raises(ParameterError, match="is the shipped configuration"):
        save_gain_set(tuned(), SHIPPED, "new_name")
    assert open(path).read() == open(SHIPPED).read()
    save_gain_set(tuned(), path, "experiment", overwrite=True)
    assert gain_set_values(load_controller_config(path, "experiment")) == gain_set_values(tuned())
    for name in ("simulation", "experiment_fast_recovery", "bench"):  # the sets around it are untouched
        assert load_controller_config(path, name) == load_controller_config(SHIPPED, name)
    assert len(open(path).read().splitlines()) == len(open(SHIPPED).read().splitlines()) + 2  # t_pow_max, tau_max


@pytest.mark.parametrize("name, path, text, error", [
    ("bad name", "/abs/g.yaml", None, "letters, digits and _"),
    ("ok", "relative/g.yaml", None, "absolute path"),
    ("ok", "FILE", "pairs: [[1, 3], [2, 4]]\n", "no mapping gain_sets"),
    ("ok", "FILE", "gain_sets: {a: {k_p: 1.0, k_i: 0.0, k_d: 0.0, k_aw: 0.0}}\n", "cannot add gain set 'ok'"),
    ("ok", "FILE", "gain_sets:\n  a: {k_p: 1.0, k_i: 0.0, k_d: 0.0, k_aw: 0.0}\nt_rec: 0.1\n", "cannot add gain set"),
])
def test_what_would_not_load_is_refused_and_nothing_written(tmp_path, name, path, text, error):
    if text is not None:
        path = str(tmp_path / "g.yaml")
        with open(path, "w") as stream:
            stream.write(text)
    with pytest.raises(ParameterError, match=error):
        save_gain_set(tuned(), path, name)
    if text is not None:
        assert open(path).read() == text and os.listdir(str(tmp_path)) == ["g.yaml"]
