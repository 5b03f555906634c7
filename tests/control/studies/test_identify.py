"""Identification: parameters and bounds, objective and targets, tank.yaml output, and a tiny end-to-end run
(screening, CMA-ES fit, cross-validation with the baseline, ensemble files)."""
from __future__ import annotations

import glob
import json
import math
import os

import pytest

from quadruped_common.config import config_path
from quadruped_control import simulate
from quadruped_control.sim.plants import TankParams, load_tank_params
from quadruped_control.studies import StudyError
from quadruped_control.studies import identify as idf
from quadruped_control.studies import identify_objective as ido
from quadruped_control.studies import identify_parameters as idp
from quadruped_control.studies import identify_report as idr
from quadruped_control.studies import identify_search as ids
from quadruped_control.studies import paper_experiments as pe
from quadruped_control.studies.runner import code_fingerprint, code_source, describe_source
from tests.control.studies.fake_trials import fake_summary


def _row(paper_ts=50.0, sim_ts=50.0, yaw=True):
    metrics = {"t_s": paper_ts, "t_r": 20.0, "e_ss": 1.0, "M_p": 10.0}
    row = {"settled_paper": paper_ts is not None, "settled_sim": sim_ts is not None,
           "paper": dict(metrics, yaw={"t_s": 30.0, "t_r": 10.0, "e_ss": 0.0, "M_p": 5.0} if yaw else None),
           "sim": dict(metrics, t_s=sim_ts, yaw={"t_s": 30.0, "t_r": 10.0, "e_ss": 0.0, "M_p": 5.0})}
    if not yaw:
        row["paper"]["yaw"] = None
    return row


def test_case_cost_weighs_every_metric_yaw_included() -> None:
    row = _row()
    assert ido.case_cost(row) == 0.0
    row["sim"].update(t_s=100.0, t_r=10.0, e_ss=6.0, M_p=60.0)
    assert ido.case_cost(row) == pytest.approx(2 * math.log(2.0) + 1.0 + 1.0)
    row["sim"]["yaw"] = {"t_s": 60.0, "t_r": None, "e_ss": 0.0, "M_p": 0.0}  # yaw twice as slow, never rose
    assert ido.case_cost(row) == pytest.approx(2 * math.log(2.0) + 2.0 + 0.5 * math.log(2.0) + 0.5)
    row["settled_sim"], row["sim"]["t_s"] = False, None  # outcome differs: 1 instead of the t_s term
    assert ido.case_cost(row) == pytest.approx(1.0 + math.log(2.0) + 2.0 + 0.5 * math.log(2.0) + 0.5)
    assert ido.objective([row, _row()]) == pytest.approx(ido.case_cost(row))


def test_a_band_counts_only_the_timing_beyond_its_factor_and_one_is_the_plain_log_ratio() -> None:
    row = _row(sim_ts=150.0)  # t_s 3x the paper's
    row["sim"].update(t_r=30.0, e_ss=6.0)  # t_r 1.5x: inside a band of 2; e_ss (5 deg off: 1) is no timing
    row["sim"]["yaw"] = {"t_s": 120.0, "t_r": None, "e_ss": 0.0, "M_p": 5.0}  # yaw 4x slower, never rose
    assert ido.case_cost(row, band=1.0) == ido.case_cost(row)  # bit for bit
    assert ido.case_cost(row) == pytest.approx(math.log(3.0) + math.log(1.5) + 1.0 + 0.5 * math.log(4.0) + 0.5)
    assert ido.case_cost(row, band=2.0) == pytest.approx(math.log(1.5) + 0.0 + 1.0 + 0.5 * math.log(2.0) + 0.5)
    assert ido.case_cost(_row(sim_ts=99.0), band=2.0) == 0.0


def test_targets_count_the_issue_figures() -> None:
    rows = [_row(), _row(sim_ts=120.0), _row(paper_ts=None, sim_ts=None), _row(sim_ts=None)]
    rows[1]["sim"]["yaw"]["t_s"] = None
    counts = ido.targets(rows)
    assert counts == {"cases": 4, "same_outcome": 3, "t_s_within_2x": 1, "t_r_within_2x": 4,
                      "yaw_t_s_within_2x": 3, "yaw_t_s_reported": 4, "failed": 0}
    # experiments whose trial failed: cases, and reported yaw settling times, that every count misses
    failed = [pe.PAPER_TABLE[0], dict(pe.PAPER_TABLE[0], yaw_t_s=None)]
    assert ido.targets(rows, failed) == dict(counts, cases=6, yaw_t_s_reported=4 + (pe.PAPER_TABLE[0]["yaw_t_s"]
                                                                                     is not None), failed=2)


def test_a_reported_zero_is_met_by_a_simulated_zero_alone() -> None:
    # Table 1's yaw t_s 0.00 (pitch 15, roll+pitch 30): the heading started inside the band and stayed
    assert pe.within_factor(0.0, 0.0)
    assert not pe.within_factor(0.3, 0.0) and not pe.within_factor(None, 0.0) and not pe.within_factor(0.0, 5.0)
    assert pe.within_factor(10.0, 5.0) and pe.within_factor(2.5, 5.0) and not pe.within_factor(10.01, 5.0)
    assert not pe.within_factor(5.0, None) and pe.within_factor(14.9, 5.0, factor=3.0)
    rows = [_row(), _row(), _row()]
    rows[0]["paper"]["yaw"]["t_s"], rows[0]["sim"]["yaw"]["t_s"] = 0.0, 0.0
    rows[1]["paper"]["yaw"]["t_s"], rows[1]["sim"]["yaw"]["t_s"] = 0.0, 0.4  # left the band, came back
    counts = ido.targets(rows)
    assert (counts["yaw_t_s_within_2x"], counts["yaw_t_s_reported"]) == (2, 3)
    assert ido.case_cost(rows[0]) == 0.0  # the objective already counted the 0.00 pair as met


def _member(*rows):
    return {"rows": list(rows), "failed": [], "objective": ido.objective(rows), "targets": ido.targets(rows)}


def test_an_ensemble_of_copies_predicts_as_its_one_set_does() -> None:
    rows = [_row(), _row(sim_ts=120.0), _row(paper_ts=None, sim_ts=None), _row(sim_ts=None)]
    rows[1]["sim"]["yaw"]["t_s"] = None
    for size in (1, 2, 5):
        predicted = ido.ensemble_rows([rows] * size)
        assert ido.targets(predicted) == ido.targets(rows)
        assert ido.objective(predicted) == pytest.approx(ido.objective(rows))


def test_the_ensemble_predicts_the_members_median_and_settles_when_most_members_do() -> None:
    members = [[_row(sim_ts=t)] for t in (10.0, 40.0, 60.0, None)]  # 3 of 4 settle: settled, median of the three
    (row,) = ido.ensemble_rows(members)
    assert row["settled_sim"] and row["sim"]["t_s"] == 40.0 and row["paper"] == members[0][0]["paper"]
    (row,) = ido.ensemble_rows([[_row(sim_ts=t)] for t in (10.0, 40.0, None, None)])  # half: not settled
    assert not row["settled_sim"] and row["sim"]["t_s"] is None
    members = [[_row()] for _ in range(3)]
    for member, t_r in zip(members, (5.0, None, 7.0)):
        member[0]["sim"]["t_r"] = t_r
    members[2][0]["sim"]["yaw"]["t_s"] = None
    (row,) = ido.ensemble_rows(members)
    assert row["sim"]["t_r"] == 6.0 and row["sim"]["yaw"]["t_s"] == 30.0  # the median of those that have it
    members[1][0]["sim"]["yaw"]["t_s"] = None
    assert ido.ensemble_rows(members)[0]["sim"]["yaw"]["t_s"] is None  # most never settled in yaw


def test_the_spread_covers_the_robot_where_it_lies_between_the_members() -> None:
    def spread(paper_ts, *sim_ts):
        return ido.coverage([[_row(paper_ts=paper_ts, sim_ts=t)] for t in sim_ts])["t_s"]

    assert spread(50.0, 30.0, 60.0) == 1 and spread(50.0, 50.0) == 1
    assert spread(50.0, 60.0, 70.0) == 0 and spread(50.0, 20.0, 30.0) == 0  # all later, all sooner
    assert spread(50.0, 20.0, None) == 1  # a member that never settles is later than any
    assert spread(50.0, None, None) == 0  # ... but a robot that settled is not covered by none that did
    assert spread(None, 20.0, None) == 1 and spread(None, 20.0, 30.0) == 0  # the robot did not settle
    members = [[_row(), _row()], [_row(), _row()]]
    for member in members:
        member[1]["paper"]["yaw"]["t_s"] = None  # the paper reports no yaw settling time for the second
    members[1][0]["sim"]["yaw"]["t_s"] = 90.0  # the first's robot yaw 30 s: within 30-90 s
    assert ido.coverage(members) == {"cases": 2, "t_s": 2, "t_r": 2, "yaw_t_s": 1, "yaw_t_s_reported": 1}
    members[0][0]["sim"]["yaw"]["t_s"] = 40.0
    assert ido.coverage(members)["yaw_t_s"] == 0


def test_an_ensemble_prediction_leaves_out_a_member_that_could_not_run_every_experiment() -> None:
    good = [_member(_row(), _row(sim_ts=200.0)) for _ in range(2)]
    broken = dict(_member(_row(sim_ts=None)), failed=[{"case": 1, "label": "x", "reason": "diverged"}])
    e = ido.ensemble_prediction(good + [broken])
    assert e["members"] == 2 and e["left_out"] == 1 and len(e["member_targets"]) == 3
    assert e["targets"] == ido.targets(good[0]["rows"]) and e["coverage"]["cases"] == 2
    assert ido.ensemble_prediction([broken]) is None


def test_distinct_best_skips_sets_that_differ_only_in_their_last_bits() -> None:
    results = [{"values": {"a": v, "b": 1.0}} for v in (0.1, 0.1 + 1e-9, 0.2, 0.3)]
    assert [r["values"]["a"] for r in ids.distinct_best(results, ["a"], 2)] == [0.1, 0.2]
    assert len(ids.distinct_best(results, ["b"], 3)) == 1  # b alone: all the same set
    assert len(ids.distinct_best(results, ["a", "b"], 8)) == 3


def test_timing_bias_is_the_geometric_mean_of_paper_over_simulation_per_group() -> None:
    """Per group: exp(mean ln(paper / sim)) over the experiments where both report the metric (0.5 s
    floor), their number, and each side's median overshoot; groups without rows are left out."""
    rows = [dict(_row(paper_ts=60.0, sim_ts=20.0), set="roll"),
            dict(_row(paper_ts=40.0, sim_ts=40.0 / 3.0), set="roll"),
            dict(_row(paper_ts=50.0, sim_ts=None), set="roll"), dict(_row(sim_ts=100.0), set="pitch")]
    rows[1]["sim"]["t_r"], rows[1]["sim"]["M_p"] = 80.0, 40.0  # the model 4x slower to rise here
    rows[3]["sim"]["yaw"]["t_s"], rows[3]["sim"]["yaw"]["t_r"] = None, 0.1  # yaw never settles; rises below the floor
    bias = idr.timing_bias(rows)
    assert list(bias) == ["roll", "pitch"]
    roll, pitch = bias["roll"], bias["pitch"]
    assert roll["t_s"][0] == pytest.approx(3.0) and roll["t_s"][1] == 2
    assert roll["t_r"][0] == pytest.approx(0.25 ** (1.0 / 3.0)) and roll["t_r"][1] == 3
    assert roll["yaw t_s"] == (pytest.approx(1.0), 3)
    assert roll["M_p paper"] == 10.0 and roll["M_p sim"] == 10.0
    assert pitch["t_s"][0] == pytest.approx(0.5) and pitch["yaw t_s"] == (None, 0)
    assert pitch["yaw t_r"][0] == pytest.approx(10.0 / 0.5)
    report = {"fit": {"best": {"rows": rows}}, "cross_validation": [{"prediction": {"rows": rows[:2]}}]}
    text = idr.format_timing_bias(report)
    assert "| full fit, in sample | roll | 0.63 (3) | 3.00 (2) | 1.00 (3) | 1.00 (3) | 10 / 10 | -- |" in text
    assert "| full fit, in sample | pitch | 1.00 (1) | 0.50 (1) | 20.00 (1) | -- | 10 / 10 | -- |" in text
    assert "| held out | roll | 0.63 (2) |" not in text and "| held out | roll | 0.50 (2) | 3.00 (2) |" in text


def test_yaw_first_compares_how_much_sooner_yaw_rises_than_the_tilt_on_both_sides() -> None:
    """exp(mean ln(yaw t_r / t_r)) per side (0.5 s floor), over the experiments with a heading error of
    at least 10 deg where both sides report both rise times; the paper's Table 1 gives 0.38."""
    rows = [_row() for _ in range(4)]
    for row, psi in zip(rows, (-78.0, 61.0, 1.5, 40.0)):
        row["paper"]["psi_init"] = psi
    rows[0]["paper"].update(t_r=40.0)  # paper: yaw 10 s, tilt 40 s
    rows[1]["sim"]["yaw"] = dict(rows[1]["sim"]["yaw"], t_r=40.0)  # sim: yaw 40 s, tilt 20 s
    rows[2]["paper"].update(t_r=80.0)  # heading error 1.5 deg: left out
    rows[3]["sim"]["yaw"] = dict(rows[3]["sim"]["yaw"], t_r=None)  # the simulation's yaw never rose: left out
    paper, sim, count = idr.yaw_first_ratio(rows)
    assert count == 2
    assert paper == pytest.approx(math.sqrt(0.25 * 0.5)) and sim == pytest.approx(math.sqrt(0.5 * 2.0))
    in_sample = "10 / 10 | %.2f / %.2f (2) |" % (paper, sim)
    assert idr.yaw_first_ratio(rows[2:]) == (None, None, 0)
    from quadruped_control.studies.paper_experiments import PAPER_TABLE
    table = [{"t_r": case["t_r"], "psi_init": case["psi_init"], "yaw": {"t_r": case["yaw_t_r"]}} for case in PAPER_TABLE]
    robot, same, count = idr.yaw_first_ratio([{"paper": side, "sim": side} for side in table])
    assert count == 13 and robot == same == pytest.approx(0.38, abs=0.005)  # all but pitch 15 and roll+pitch 30
    for row in rows:
        row["set"] = "roll"
    report = {"fit": {"best": {"rows": rows}}, "cross_validation": [{"prediction": {"rows": rows[:1]}}]}
    text = idr.format_timing_bias(report)
    assert in_sample in text and "| held out | roll |" in text and "10 / 10 | 0.25 / 0.50 (1) |" in text


def test_a_folds_start_is_the_best_screening_set_on_its_training_groups_only() -> None:
    """best_on judges each set on the chosen experiments: the held-out group must not pick the start."""
    good, bad = _row(), _row(sim_ts=200.0)
    costs = [ido.case_cost(row) for row in (good, bad)]
    first = {"values": {"name": "first"}, "cases": [7, 9, 12], "costs": [costs[0], costs[1], costs[1]]}
    second = {"values": {"name": "second"}, "cases": [7, 9, 12], "costs": [costs[1], costs[0], costs[0]]}
    results = [first, second]  # first: best on case 7 alone; second: best on all, and on 9 and 12
    assert ids.best_on(results, [7, 9, 12]) is second
    assert ids.best_on(results, [7]) is first
    assert ids.best_on(results, [9, 12]) is second
    # a slow-recovery check (numbered after Table 1's rows) counts like any experiment
    second["cases"], second["costs"] = [7, 9, 12, 16], second["costs"] + [ido.slow_recovery_cost(True)]
    first["cases"], first["costs"] = [7, 9, 12, 16], first["costs"] + [ido.slow_recovery_cost(False)]
    assert ids.best_on(results, [9, 12]) is second and ids.best_on(results, [7, 16]) is first
    assert ido.slow_recovery_cost(True) == ido.WEIGHTS["slow_recovery"] == 1.0 and ido.slow_recovery_cost(False) == 0.0


def _values():
    return {"center_of_buoyancy_z": -0.0012, "center_of_buoyancy_x": 0.0007, "center_of_buoyancy_y": -0.0003, "hook_z": 0.06, "net_weight": 0.5, "rope_length": 0.8,
            "added_mass_scale": 1.5,
            "servo_speed_scale": 0.7, "servo_lag_scale": 3.0, "paw_drag_scale": 1.1, "appendage_damping_linear_xy": 0.01,
            "appendage_damping_linear_z": 0.02,
            "appendage_damping_quadratic_xy": 0.1, "appendage_damping_quadratic_z": 0.2, "rope_torsion_stiffness": 0.03,
            "rope_torsion_damping": 0.04, "paw_wake_fraction": 0.45, "paw_wake_time_constant": 0.25, "paw_wake_body_share": 0.35,
            "servo_stall_torque_inverse": 0.5, "body_wake_fraction": 0.55, "body_wake_time_constant": 7.5, "block_mass_inverse": 2.5,
            "block_drag": 4.0, "block_tie_stiffness": 6.0, "paw_buoyancy_offset": 0.04,
            "servo_dead_band": 0.008, "hook_friction_arm": 0.0025, "hook_friction_static_ratio": 1.4,
            "hook_friction_stribeck_rate": 0.05, "hook_friction_roll_ratio": 2.5, "hook_friction_wrap": 0.35,
            "imu_field_residual_x": 0.1, "imu_field_residual_y": -0.35, "imu_field_residual_z": 0.45, "tether_stiffness": 0.015,
            "tether_relaxing_stiffness": 0.12, "tether_relaxation_time": 25.0, "rope_torsion_relaxing_stiffness": 0.02,
            "rope_torsion_relaxation_time": 7.0}


def test_every_parameter_reaches_the_tank_plant_and_its_yaml_round_trips(tmp_path) -> None:
    values = _values()
    assert [name for name, _, _ in idp.PARAMETERS] == list(values)
    with open(config_path("tank.yaml")) as stream:
        text = idp.update_tank_yaml(stream.read(), values, "test")
    path = str(tmp_path / "tank.yaml")
    with open(path, "w") as stream:
        stream.write(text)
    tank = load_tank_params(path)
    assert tank == load_tank_params().with_values(**dict(idp.tank_overrides(values)))
    assert tank.appendage_damping_quadratic == (0.1, 0.1, 0.2) and tank.rope_torsion_damping == 0.04
    assert tank.rope_torsion_relaxing_stiffness == 0.02 and tank.rope_torsion_relaxation_time == 7.0
    assert tank.paw_wake_fraction == 0.45 and tank.paw_wake_time_constant == 0.25 and tank.paw_wake_body_share == 0.35
    assert tank.servo_stall_torque == 2.0 and idp.field_value("servo_stall_torque_inverse", 0.0) == 0.0
    assert tank.body_wake_fraction == 0.55 and tank.body_wake_time_constant == 7.5
    assert tank.block_mass == 0.4 and tank.block_drag == 4.0 and tank.block_tie_stiffness == 6.0
    assert tank.paw_buoyancy_offset == 0.04 and tank.servo_dead_band == 0.008 and tank.hook_friction_arm == 0.0025
    assert tank.hook_friction_static_ratio == 1.4 and tank.hook_friction_stribeck_rate == 0.05
    assert tank.hook_friction_roll_ratio == 2.5 and tank.imu_field_residual == (0.1, -0.35, 0.45)
    assert tank.hook_friction_wrap == 0.35
    assert (tank.tether_stiffness, tank.tether_relaxing_stiffness, tank.tether_relaxation_time) == (0.015, 0.12, 25.0)
    assert idp.nominal_values(tank) == pytest.approx(values)
    assert tank.center_of_buoyancy == (0.0007, -0.0003, -0.0012)
    # the centre of buoyancy's and the IMU field's lines carry three parameters each, the two appendage
    # lines four
    assert text.count("[identified] test") == 34
    with pytest.raises(ValueError, match="no line for center_of_buoyancy_z"):
        idp.update_tank_yaml("hydrostatics:\n  net_weight: 1.0\n", {"center_of_buoyancy_z": 0.001, "net_weight": 1.0}, "x")


def test_a_file_written_before_a_key_existed_gets_its_line() -> None:
    """An ensemble member written before the torsion's relaxing twist existed has no line for it: a fit that
    starts from it (--tank-yaml) writes the line at the end of its section, a missing section at the end,
    and the file loads with the fitted values; the members' other lines are untouched."""
    import yaml

    assert idp.update_tank_yaml("hydrostatics:\n  center_of_buoyancy: [0, 0, 0]\n\nservos:\n  servo_lag_scale: 1.0\n",
                                {"net_weight": 1.5}, "x") == \
        "hydrostatics:\n  center_of_buoyancy: [0, 0, 0]\n  net_weight: 1.5  # [identified] x\n\nservos:\n" \
        "  servo_lag_scale: 1.0\n"
    assert idp.update_tank_yaml("hydrostatics:\n  center_of_buoyancy: [0, 0, 0]\n# the servos\nservos:\n",
                                {"net_weight": 1.5}, "x") == \
        "hydrostatics:\n  center_of_buoyancy: [0, 0, 0]\n  net_weight: 1.5  # [identified] x\n# the servos\nservos:\n"
    assert idp.update_tank_yaml("servos:\n  servo_lag_scale: 1.0\n", {"net_weight": 1.5}, "x").endswith(
        "\nhydrostatics:\n  net_weight: 1.5  # [identified] x\n")
    with open(config_path("tank_ensemble/member_00.yaml")) as stream:
        member = stream.read()
    assert "rope_torsion_relaxing_stiffness" not in member
    text = idp.update_tank_yaml(member, {"rope_torsion_relaxing_stiffness": 0.02, "rope_torsion_relaxation_time": 7.0}, "y")
    tank = load_tank_params(tree=yaml.safe_load(text))
    assert tank == load_tank_params(config_path("tank_ensemble/member_00.yaml")).with_values(
        rope_torsion_relaxing_stiffness=0.02, rope_torsion_relaxation_time=7.0)
    assert [line for line in text.splitlines() if "[identified] y" not in line] == member.splitlines()


def test_a_partial_set_keeps_the_templates_other_components_in_the_yaml() -> None:
    """One table places every parameter (identify_parameters.PLACES, read from the tank schema): the overrides,
    the yaml and the nominal values agree for a set that names only some components of a vector. The overrides (given whole sets by the
    studies) put the others at 0; the yaml keeps the template's, as written, so that a fit of some
    components (identify_bags --parameters appendage_damping_linear_z) writes the plant it ran."""
    values = {"center_of_buoyancy_x": 0.001, "appendage_damping_linear_z": 0.15, "servo_stall_torque_inverse": 0.25}
    assert dict(idp.tank_overrides(values)) == {"center_of_buoyancy": (0.001, 0.0, 0.0),
                                                "appendage_damping_linear": (0.0, 0.0, 0.15),
                                                "servo_stall_torque": 4.0}
    text = idp.update_tank_yaml("hydrostatics:\n  center_of_buoyancy: [0, 0, 0.002]  # old\nsuspension:\n"
                                "  hook: [0, 0, 0.07]\nappendage_damping:\n  appendage_damping_linear: [0.18, 0.1832, 0.1]\n"
                                "servos:\n  servo_stall_torque: 0\n", values, "n")
    assert text.splitlines() == ["hydrostatics:", "  center_of_buoyancy: [0.001, 0, 0.002]  # [identified] n",
                                 "suspension:", "  hook: [0, 0, 0.07]", "appendage_damping:",
                                 "  appendage_damping_linear: [0.18, 0.1832, 0.14999999999999999]  # [identified] n",
                                 "servos:", "  servo_stall_torque: 4  # [identified] n"]
    tank = TankParams().with_values(**dict(idp.tank_overrides(values)))
    nominal = idp.nominal_values(tank)
    assert nominal["center_of_buoyancy_x"] == 0.001 and nominal["appendage_damping_linear_z"] == 0.15 and nominal["servo_stall_torque_inverse"] == 0.25


def test_a_vector_line_that_is_not_three_numbers_is_refused_by_name() -> None:
    for line in ("  center_of_buoyancy: 0.002", "  center_of_buoyancy: [0, 0]", "  center_of_buoyancy: [0, a, 0]",
                 "  center_of_buoyancy: [0, nan, 0]"):
        with pytest.raises(ValueError, match="center_of_buoyancy.*not a vector of three numbers"):
            idp.update_tank_yaml("hydrostatics:\n" + line + "\n", {"center_of_buoyancy_z": 0.001}, "n")


def test_the_screening_design_is_the_same_for_the_same_seed_zero_included() -> None:
    """SALib 1.5 ignores seed=0 (``if seed:``); morris_sets seeds it anyway."""
    pytest.importorskip("SALib")
    names = [name for name, _, _ in idp.PARAMETERS]
    problem = {"num_vars": len(names), "names": names, "bounds": [[low, high] for _, low, high in idp.PARAMETERS]}
    import numpy as np
    for seed in (0, 3):
        np.testing.assert_array_equal(ids.morris_sets(problem, 4, seed), ids.morris_sets(problem, 4, seed))
    assert not np.array_equal(ids.morris_sets(problem, 4, 0), ids.morris_sets(problem, 4, 1))


def test_the_fit_is_the_same_for_the_same_seed_zero_included() -> None:
    """pycma reads seed 0 as "from the clock"; fit gives it seed + 1, so the study's default seed repeats."""
    pytest.importorskip("cma")
    names = ["center_of_buoyancy_z", "net_weight"]
    start = idp.nominal_values(TankParams())

    def searched(seed):
        asked = []

        def evaluate(sets, cases, tag):  # a bowl around the nominal set: the fit's own arithmetic only
            asked.extend(tuple(v[n] for n in names) for v in sets)
            return [{"values": v, "objective": sum((v[n] - start[n]) ** 2 for n in names)} for v in sets]

        ids.fit(evaluate, names, start, start, 8, 4, seed, [0], "t")
        return asked

    for seed in (0, 5):
        assert searched(seed) == searched(seed)
    assert searched(0) != searched(1)
    with pytest.raises(StudyError, match="seed must be >= 0"):
        ids.fit(lambda *a: [], names, start, start, 8, 4, -1, [0], "t")


def test_nominal_values_lie_within_the_bounds() -> None:
    nominal = idp.nominal_values(TankParams(net_weight=50.0))
    for name, low, high in idp.PARAMETERS:
        assert low <= nominal[name] <= high
    assert nominal["net_weight"] == 3.0  # clipped to its plausible bound


def _tiny_identify(out: str, evaluations: int, ensemble: int, *choice: str) -> dict:
    """A tiny identification (0.2 s trials, two screening trajectories: the fewest the CLI takes) through the
    CLI; its report."""
    pytest.importorskip("cma")
    pytest.importorskip("SALib")
    assert simulate.main(["--study", "identify", "--screen", "2", "--evaluations", str(evaluations),
                          "--cv-evaluations", "2", "--popsize", "2", "--ensemble", str(ensemble), "--duration", "0.2",
                          "--out", out, "--quiet", "--jobs", "1", *choice]) == 0
    with open(os.path.join(out, "identify.json")) as stream:
        return json.load(stream)


def _fake_trials(monkeypatch) -> None:
    """The study's logic on small inputs: the real CLI, Evaluator (labels, costs, counts, checks) and trial
    runner (its per-trial files and their reuse) with each trial's simulation replaced by :func:`~tests.control.studies.fake_trials.fake_summary`.
    The one CLI smoke test (test_identify_cli_tiny_run) runs the real trials."""
    from quadruped_control.studies import trial

    monkeypatch.setattr(trial, "run_batch", lambda specs: [fake_summary(s) for s in specs])
    monkeypatch.setattr(trial, "run_trial", fake_summary)
    monkeypatch.setattr(ido, "run_batch", lambda specs: [])  # the Evaluator's compile of the batch's loops
    monkeypatch.setattr(pe, "initial_attitude", _initial_attitude)


_ATTITUDES: dict = {}


def _initial_attitude(*args):
    """paper_experiments.initial_attitude (a root search per Table-1 row, for every Evaluator), remembered:
    a pure function of its arguments."""
    if args not in _ATTITUDES:
        _ATTITUDES[args] = _REAL_INITIAL_ATTITUDE(*args)
    return _ATTITUDES[args]


_REAL_INITIAL_ATTITUDE = pe.initial_attitude


def test_identify_cli_tiny_run(tmp_path, monkeypatch) -> None:
    """The study's one smoke test on real trials, end to end through the CLI."""
    import copy

    from quadruped_common import config

    # Every trial's setup reads the same YAML files again (most of this run's time): each text is parsed once
    # and each read gets its own copy of the tree, as a parse would give it.
    trees, real_parse = {}, config.parse_yaml

    def parse_yaml(text):
        if text not in trees:
            trees[text] = real_parse(text)
        return copy.deepcopy(trees[text])

    monkeypatch.setattr(config, "parse_yaml", parse_yaml)
    out = str(tmp_path / "id")
    report = _tiny_identify(out, 4, 2, "--include", "paw_wake_fraction")
    names = [p[0] for p in idp.PARAMETERS]
    assert report["screening"]["names"] == names and report["screening"]["sets"] == 2 * (len(names) + 1)
    assert set(report["identified"]) <= set(names) and "paw_wake_fraction" in report["identified"]
    assert report["fit"]["evaluations"] >= 4
    assert [f["held_out"] for f in report["cross_validation"]] == list(ido.GROUPS)
    for fold, cases in zip(report["cross_validation"], (6, 6, 3)):
        assert fold["prediction"]["targets"]["cases"] == cases == fold["baseline_prediction"]["targets"]["cases"]
        # the fold's own ensemble (up to --ensemble distinct sets of its fit) on the held-out group
        ensemble = fold["ensemble_prediction"]
        assert 1 <= ensemble["members"] <= 2 and ensemble["targets"]["cases"] == cases
        assert ensemble["coverage"]["cases"] == cases and len(ensemble["rows"]) == cases
    assert len(report["ensemble_files"]) == 2
    # what produced the report: the command as given and the code's fingerprint, in the report and each set
    assert report["command"][:4] == ["python", "-m", "quadruped_control.simulate", "--study"]
    assert "--include" in report["command"] and report["code"] == code_fingerprint()
    assert report["code_source"] == code_source()  # the commit, and any file that differs from it
    with open(os.path.join(out, "identify.md")) as stream:
        text = stream.read()
    assert "Code %s (%s)." % (report["code"], describe_source(report["code_source"])) in text
    assert "The folds' ensembles on their held-out groups" in text
    # every set the run tried, joined to its trials by their label prefix
    with open(os.path.join(out, "sets.json")) as stream:
        tried = json.load(stream)
    assert tried["code"] == report["code"] and tried["code_source"] == report["code_source"]
    prefixes = [s["set"] for s in tried["sets"]]
    assert len(prefixes) == len(set(prefixes)) and sum(len(s["cases"]) for s in tried["sets"]) == report["trials"]
    labels = set()
    for path in glob.glob(os.path.join(out, "trials", "*.json")):
        with open(path) as stream:
            labels.add(json.load(stream)["label"].split(" ", 1)[0])
    assert set(prefixes) <= labels
    assert report["fit"]["best"]["values"] in [s["values"] for s in tried["sets"]]
    assert min(s["objective"] for s in tried["sets"] if s["cases"] == list(range(15))) <= \
        report["fit"]["best"]["objective"] + 1e-9
    best = report["fit"]["ensemble"][0]["values"]
    for path in report["ensemble_files"]:
        # a valid tank.yaml, holding the set it was written from (the parameters the fit held, at the values
        # it held them), and only the fitted parameters' lines are marked identified
        assert idp.nominal_values(load_tank_params(path)).keys() == best.keys()
        with open(path) as stream:
            text = stream.read()
        assert "code %s)" % report["code"][:12] in text
        assert text.count("[identified] simulate --study identify") == len(
            {(idp.PLACES[n][0].section, idp.PLACES[n][0].name) for n in report["identified"]})
    written = idp.nominal_values(load_tank_params(report["ensemble_files"][0]))
    assert all(written[n] == pytest.approx(best[n], rel=1e-12, abs=1e-15) for n in best)
    assert report["weights"] == ido.WEIGHTS
    with pytest.raises(SystemExit):  # a parameter the study does not know is refused by name
        simulate.main(["--study", "identify", "--include", "wake_speed", "--out", out])
    with pytest.raises(SystemExit):
        simulate.main(["--study", "identify", "--parameters", "wake_speed", "--out", out])
    with pytest.raises(SystemExit):  # pycma does not fit one dimension: refused before any trial
        simulate.main(["--study", "identify", "--parameters", "center_of_buoyancy_z", "--out", out])
    with pytest.raises(SystemExit):  # adding to the screening's choice and replacing it: one or the other
        simulate.main(["--study", "identify", "--parameters", "center_of_buoyancy_z", "--include", "hook_z", "--out", out])
    assert report["band"] == 1.0
    for band in ("0.5", "nan"):  # a band is a factor >= 1
        with pytest.raises(SystemExit):
            simulate.main(["--study", "identify", "--band", band, "--out", out])


def test_the_slow_recovery_check_adds_the_papers_t_rec_cases_to_their_groups(tmp_path, monkeypatch) -> None:
    """Evaluator's case selection and its checks' trials (real, 0.2 s) directly; then the study's use of them
    (objective, counts, folds, report, band) on fake trials."""
    args = simulate.build_parser().parse_args(["--study", "identify", "--out", str(tmp_path / "cases"), "--quiet",
                                               "--jobs", "1"])
    evaluate = ido.Evaluator(args, 0.2, "rate-limited", True)
    # the three checks on the real batch: 0.2 s trials settle nowhere, so every check is met
    (checked,) = evaluate([idp.nominal_values(load_tank_params())], [15, 16, 17], "chk")
    assert [c["case"] for c in checked["slow_recovery"]] == ["t_rec 1.5 pitch 75", "t_rec 1.5 pitch 90",
                                                             "t_rec 1.5 roll+pitch 60"]
    assert checked["rows"] == [] and checked["failed"] == [] and checked["costs"] == [0.0, 0.0, 0.0]
    assert checked["targets"]["slow_recovery_checks"] == 3 == checked["targets"]["slow_recovery_unsettled"]
    _fake_trials(monkeypatch)
    without = ido.Evaluator(args, 0.2, "rate-limited")
    labels = {k: pe.case_label(pe.PAPER_TABLE[row]) for k, row in evaluate.check_row.items()}
    assert labels == {15: "pitch 75", 16: "pitch 90", 17: "roll+pitch 60"}
    # the checks come after Table 1's rows, which keep their numbers
    assert [evaluate.base[k].label for k in range(15)] == [spec.label for spec in without.base]
    for k, row in evaluate.check_row.items():  # the Table-1 trial run with the experiment gains' own t_rec 1.5 s
        check, table = evaluate.base[k], evaluate.base[row]
        assert check.label == "t_rec 1.5 " + table.label and check.duration == table.duration == 0.2
        assert ("t_rec", 1.0) in table.config_overrides and all(o[0] != "t_rec" for o in check.config_overrides)
    assert evaluate.cases(ido.GROUPS) == list(range(18))
    for group, checks in zip(ido.GROUPS, ([], [15, 16], [17])):  # each check in its Table-1 row's group
        assert evaluate.cases([group]) == [k for k, row in enumerate(pe.PAPER_TABLE) if row["set"] == group] + checks
    assert evaluate.cases(["roll", "roll+pitch"]) == [k for k, row in enumerate(pe.PAPER_TABLE)
                                                       if row["set"] != "pitch"] + [17]
    assert without.cases(ido.GROUPS) == list(range(15)) and without.check_row == {}  # no check by default
    report = _tiny_identify(str(tmp_path / "slow"), 2, 1, "--parameters", "center_of_buoyancy_z", "net_weight",
                            "--slow-recovery-check")
    assert report["slow_recovery_check"] is True
    best = report["fit"]["best"]
    assert [c["case"] for c in best["slow_recovery"]] == ["t_rec 1.5 pitch 75", "t_rec 1.5 pitch 90",
                                                          "t_rec 1.5 roll+pitch 60"]
    assert best["cases"] == list(range(18)) and len(best["rows"]) == 15
    assert best["objective"] == pytest.approx(ido.objective(best["rows"]) + sum(
        ido.slow_recovery_cost(c["settled_sim"]) for c in best["slow_recovery"]))
    # 0.2 s trials settle nowhere: every check is met
    assert best["targets"]["slow_recovery_checks"] == 3 == best["targets"]["slow_recovery_unsettled"]
    for fold, checks in zip(report["cross_validation"], (0, 2, 1)):  # held out: roll, pitch, roll+pitch
        assert fold["prediction"]["targets"]["slow_recovery_checks"] == checks
        assert fold["prediction"]["targets"]["cases"] == (6, 6, 3)[ido.GROUPS.index(fold["held_out"])]
    with open(os.path.join(str(tmp_path / "slow"), "identify.md")) as stream:
        assert "t_rec 1.5 s not settled" in stream.read()
    bands = []  # the band every cost of the run is computed with
    case_cost = ido.case_cost
    monkeypatch.setattr(ido, "case_cost", lambda row, weights=None, band=1.0: bands.append(band) or case_cost(
        row, weights, band))
    plain = _tiny_identify(str(tmp_path / "plain"), 2, 1, "--parameters", "center_of_buoyancy_z", "net_weight", "--band", "2")
    assert bands and set(bands) == {2.0}
    assert plain["slow_recovery_check"] is False and plain["fit"]["best"]["cases"] == list(range(15))
    assert plain["fit"]["best"]["targets"]["slow_recovery_checks"] == 0
    # the band reaches every cost the fit sees, and the report says so
    assert plain["band"] == 2.0
    assert plain["fit"]["best"]["objective"] == pytest.approx(
        sum(ido.case_cost(row, band=2.0) for row in plain["fit"]["best"]["rows"]))
    with open(os.path.join(str(tmp_path / "plain"), "identify.md")) as stream:
        assert "beyond a factor 2 of the paper's (--band)" in stream.read()


def _screening_without_trials(monkeypatch, mu_star) -> None:
    """The study with no trial to run: an evaluator of one experiment that runs nothing, and a screening
    that returns ``mu_star`` (one per parameter) and no set."""
    class NoTrials:
        trials, check_row = 0, {}

        def __init__(self, *args: object) -> None:
            pass

        def cases(self, groups):
            return [0]

    names = [name for name, _, _ in idp.PARAMETERS]
    monkeypatch.setattr(idf, "Evaluator", NoTrials)
    monkeypatch.setattr(idf, "screen", lambda *args: {"names": names, "best": {"values": {}}, "results": [],
                                                      "mu_star": list(mu_star)})


def test_a_screening_that_chooses_one_parameter_is_refused_by_name(tmp_path, monkeypatch) -> None:
    """pycma does not fit one dimension: the study says so instead of failing inside the fit."""
    _screening_without_trials(monkeypatch, [1.0] + [0.0] * (len(idp.PARAMETERS) - 1))
    args = simulate.build_parser().parse_args(["--study", "identify", "--out", str(tmp_path)])
    args.duration_given, args.servo_model_given = False, None
    with pytest.raises(StudyError, match="chose center_of_buoyancy_z; CMA-ES fits two or more"):
        idf.main_study(args)


def test_a_start_that_is_neither_the_screening_nor_the_nominal_values_is_refused(tmp_path, monkeypatch) -> None:
    """Called without the CLI (whose choices refuse it first), main_study names the bad --start before any
    fit."""
    _screening_without_trials(monkeypatch, [1.0] * len(idp.PARAMETERS))
    monkeypatch.setattr(idf, "fit", lambda *args, **kw: pytest.fail("no fit may run"))
    args = simulate.build_parser().parse_args(["--study", "identify", "--out", str(tmp_path)])
    args.duration_given, args.servo_model_given, args.start = False, None, "best"
    with pytest.raises(StudyError, match="--start is 'screening' or 'nominal', got 'best'"):
        idf.main_study(args)


def test_a_polish_added_to_an_earlier_run_reuses_its_searches_trials(tmp_path, monkeypatch) -> None:
    """Trial labels number the sets per search (Evaluator.count_of): the same command with
    --polish-evaluations runs only the polishes' trials; the screening's, the CMA-ES fits', the
    baselines' and the predictions' come from the trial cache (the runner's real one; the trials are fakes)."""
    _fake_trials(monkeypatch)
    out = str(tmp_path / "id")
    first = _tiny_identify(out, 2, 1, "--parameters", "center_of_buoyancy_z", "net_weight")
    trials = os.path.join(out, "trials")
    before = set(os.listdir(trials))
    # one round of the compass search: each of the two parameters up and down
    polished = _tiny_identify(out, 2, 1, "--parameters", "center_of_buoyancy_z", "net_weight", "--polish-evaluations", "4")
    added = set(os.listdir(trials)) - before
    polishes = {name for name in added if name.startswith(("fit-pol", "cv-roll-pol", "cv-pitch-pol",
                                                           "cv-roll+pitch-pol"))}
    # four polishes of four sets each: the full fit's on 15 experiments, each fold's on its training groups
    assert len(polishes) == 4 * (15 + 9 + 9 + 12)
    # and the held-out predictions (best set and ensemble) of the folds whose polish found a better set;
    # nothing else ran again
    assert all(name.startswith(("held-", "ens-")) for name in added - polishes), sorted(added - polishes)[:5]
    assert polished["fit"]["search"]["sets"] == first["fit"]["search"]["sets"] + 4


def test_identify_fits_exactly_the_parameters_given(tmp_path, monkeypatch) -> None:
    _fake_trials(monkeypatch)
    report = _tiny_identify(str(tmp_path / "exact"), 2, 1, "--parameters", "servo_lag_scale", "center_of_buoyancy_z")
    assert report["identified"] == ["center_of_buoyancy_z", "servo_lag_scale"]  # in the order of PARAMETERS
    fixed = idp.nominal_values(load_tank_params())
    for result in report["fit"]["ensemble"] + [fold["fit"] for fold in report["cross_validation"]]:
        for name, value in result["values"].items():
            if name not in ("center_of_buoyancy_z", "servo_lag_scale"):
                assert value == fixed[name]


def test_every_fit_starts_from_the_nominal_values_with_start_nominal(tmp_path, monkeypatch) -> None:
    """--start nominal: the full fit and every fold start at --tank-yaml's values, whatever the screening
    found; the default starts the full fit at the screening's best set and each fold at its best on the
    fold's training groups (so adding a candidate to the screening moves every start)."""
    _fake_trials(monkeypatch)
    starts, screenings = [], []
    real_fit, real_screen = ids.fit, ids.screen
    monkeypatch.setattr(idf, "fit", lambda evaluate, names, fixed, start, *rest, **kw: starts.append(
        (tuple(names), dict(start))) or real_fit(evaluate, names, fixed, start, *rest, **kw))
    monkeypatch.setattr(idf, "screen", lambda *a: screenings.append(real_screen(*a)) or screenings[-1])
    names = ("center_of_buoyancy_z", "net_weight")
    nominal = idp.nominal_values(load_tank_params())
    report = _tiny_identify(str(tmp_path / "nominal"), 2, 1, "--parameters", *names, "--start", "nominal")
    assert report["start"] == "nominal" and len(starts) == 4  # the full fit and three folds
    for fitted, start in starts:
        assert fitted == names and all(start[n] == nominal[n] for n in names)
    with open(os.path.join(str(tmp_path / "nominal"), "identify.md")) as stream:
        assert "from the nominal values" in stream.read()
    del starts[:]
    report = _tiny_identify(str(tmp_path / "screening"), 2, 1, "--parameters", *names)
    assert report["start"] == "screening" and len(starts) == 4
    results = screenings[-1]["results"]
    assert starts[0][1] == min(results, key=lambda r: r["objective"])["values"]
    for (_, start), group in zip(starts[1:], ido.GROUPS):
        train = [k for k, row in enumerate(pe.PAPER_TABLE) if row["set"] != group]
        assert start == ids.best_on(results, train)["values"]
    with pytest.raises(SystemExit):  # only the two starts
        simulate.main(["--study", "identify", "--start", "best", "--out", str(tmp_path)])


def _bowl(names, centre, asked=None):
    """An evaluator whose objective is the squared distance (in the scaled ranges) from ``centre``."""

    def evaluate(sets, cases, tag):
        out = []
        for values in sets:
            u = ids.to_unit(values, names)
            if asked is not None:
                asked.append(u)
            out.append({"values": dict(values), "objective": sum((a - b) ** 2 for a, b in zip(u, centre))})
        return out

    return evaluate


def test_improvements_are_where_the_best_so_far_fell() -> None:
    assert ids.improvements([]) == []
    assert ids.improvements([5.0, 6.0, 4.0, 4.0, 3.5, 9.0]) == [(1, 5.0), (3, 4.0), (5, 3.5)]  # a tie is no gain


def test_the_polish_walks_to_a_minimum_on_a_bound_and_inside_within_its_smallest_step() -> None:
    names = ["center_of_buoyancy_z", "servo_dead_band"]
    fixed = idp.nominal_values(TankParams())
    centre = [0.3, 0.0]  # inside on center_of_buoyancy_z, on the lower bound of the dead band
    asked = []
    evaluate = _bowl(names, centre, asked)
    start = evaluate([ids.to_values([0.8, 0.6], names, fixed)], [0], "t")[0]
    asked.clear()
    results = ids.polish(evaluate, names, fixed, start, 400, [0], "t", step=0.125, smallest=1.0 / 64.0)
    best = min(results, key=lambda r: r["objective"])
    u = ids.to_unit(best["values"], names)
    assert u[1] == 0.0  # the bound itself, reached by clipping
    assert abs(u[0] - centre[0]) <= 1.0 / 64.0
    assert all(0.0 <= v <= 1.0 for point in asked for v in point)  # every move clipped to the bounds
    assert len({tuple(round(v, 9) for v in point) for point in asked} | {(0.8, 0.6)}) == len(asked) + 1  # no repeat
    for values in (r["values"] for r in results):  # the other parameters stay where they were
        assert all(values[n] == fixed[n] for n in fixed if n not in names)
    assert len(results) <= 400


def test_the_polish_keeps_to_its_budget_and_never_returns_a_worse_best() -> None:
    names = ["center_of_buoyancy_z", "net_weight", "servo_lag_scale"]
    fixed = idp.nominal_values(TankParams())
    evaluate = _bowl(names, [0.1, 0.9, 0.5])
    start = evaluate([ids.to_values([0.5, 0.5, 0.5], names, fixed)], [0], "t")[0]
    assert ids.polish(evaluate, names, fixed, start, 5, [0], "t") == []  # one round is six sets: none fits
    results = ids.polish(evaluate, names, fixed, start, 11, [0], "t")
    assert len(results) == 11  # a round of six, then five (the set it came from is not asked again)
    assert min(r["objective"] for r in results) < start["objective"]
    with pytest.raises(StudyError, match="smallest <= step"):
        ids.polish(evaluate, names, fixed, start, 13, [0], "t", step=0.01, smallest=0.1)


def test_identify_polishes_the_full_fit_and_every_fold(tmp_path, monkeypatch) -> None:
    _fake_trials(monkeypatch)
    report = _tiny_identify(str(tmp_path / "pol"), 2, 1, "--parameters", "servo_lag_scale", "center_of_buoyancy_z",
                            "--polish-evaluations", "8")
    polished = [report["fit"]["polish"]] + [fold["polish"] for fold in report["cross_validation"]]
    for record in polished:
        assert 0 < record["evaluations"] <= 8  # whole rounds of at most 2 x 2 moves, within the budget
        assert record["objective_after"] <= record["objective_before"]
    assert report["fit"]["best"]["objective"] == report["fit"]["polish"]["objective_after"]
    # the search record: every set CMA-ES and the polish asked for, in order, and where the best fell
    searches = [(report["fit"]["search"], report["fit"]["best"]["objective"])] + [
        (fold["search"], fold["fit"]["objective"]) for fold in report["cross_validation"]]
    for search, best_objective in searches:
        found = [n for n, _ in search["improvements"]]
        assert found == sorted(set(found)) and found[0] == 1 and found[-1] <= search["sets"]
        objectives = [value for _, value in search["improvements"]]
        assert objectives == sorted(objectives, reverse=True)
        assert objectives[-1] == best_objective
    assert report["fit"]["search"]["sets"] == report["fit"]["evaluations"]
    with open(str(tmp_path / "pol" / "identify.md")) as stream:
        assert "Where each search found its best" in stream.read()
    with pytest.raises(SystemExit):  # a negative budget is refused
        simulate.main(["--study", "identify", "--polish-evaluations", "-1", "--out", str(tmp_path / "neg")])


def test_both_corners_of_the_identifications_bounds_are_plants_a_control_step_resolves() -> None:
    """Every parameter at its lower bound, and every one at its upper bound (the stiffest tie, the most
    damping, the heaviest net weight): TankModel's step check takes both, so no fit meets a refused set."""
    from quadruped_control.model.params import load_robot_params
    from quadruped_control.sim.plants import TankModel
    robot, base = load_robot_params(), load_tank_params()
    for corner in (0, 1):
        values = {name: (low, high)[corner] for name, low, high in idp.PARAMETERS}
        TankModel(robot, base.with_values(**dict(idp.tank_overrides(values))))


def test_a_set_whose_trial_diverges_scores_badly_and_the_study_goes_on(tmp_path, monkeypatch) -> None:
    """One diverging trial must not stop a study's screening. Here the first experiment of the
    screening's third set and of the fit's first set diverge (through the real batch): the screening leaves
    that set's trajectory out, the fit ranks the set behind the others, and the report says what failed."""
    import dataclasses

    from quadruped_control.studies import trial

    real_batch = trial.run_batch
    _fake_trials(monkeypatch)

    def breaking(specs):  # paws with ten thousand times their drag: the tank plant's step diverges at once
        # (those two on the real batch; the others are fakes)
        return [real_batch([dataclasses.replace(s, tank_overrides=s.tank_overrides + (("paw_drag_scale", 1e4),))])[0]
                if s.label.startswith(("scr00003 roll 15", "fit00001 roll 15")) else fake_summary(s) for s in specs]

    monkeypatch.setattr(trial, "run_batch", breaking)
    # the schema refuses a paw drag scale past 10 (tank_params): let this one set through to the plant
    from quadruped_control.sim.plants.tank_params import TankParams
    monkeypatch.setattr(TankParams, "__post_init__", lambda self: None)
    out = str(tmp_path / "failing")
    report = _tiny_identify(out, 4, 1, "--parameters", "center_of_buoyancy_z", "net_weight", "--engine", "batch")
    screening = report["screening"]
    assert screening["trajectories"] == 2 and screening["trajectories_dropped"] == 1
    assert report["failed_sets"] == 2
    failed = report["failed_examples"]
    assert [[f["case"] for f in example["failed"]] for example in failed] == [[0], [0]]
    assert all("plant step failed" in example["failed"][0]["reason"] for example in failed)
    best = report["fit"]["best"]
    assert best["failed"] == [] and best["targets"]["failed"] == 0
    assert all(example["objective"] > best["objective"] + ido.FAILED_CASE_COST / 2 for example in failed)
    with open(os.path.join(out, "identify.md")) as stream:
        text = stream.read()
    assert "1 of the screening's 2 trajectories are left out" in text
    assert "2 parameter set(s) could not run every experiment" in text
    # a failed experiment costs FAILED_CASE_COST and misses every count, and still counts as a case
    evaluate = ido.Evaluator(simulate.build_parser().parse_args(["--study", "identify", "--out", out, "--quiet",
                                                                  "--jobs", "1"]), 0.2, "rate-limited")
    monkeypatch.setattr(ido, "run_many", lambda specs, args, desc: [
        trial.failed_summary(s, "diverged", "batch") if s.label.startswith("x00001 roll 15") else
        trial.run_batch([s])[0] for s in specs])
    result = evaluate([{}], [0, 1], "x")[0]
    assert result["costs"][0] == ido.FAILED_CASE_COST and len(result["rows"]) == 1
    assert result["targets"]["cases"] == 2 and result["targets"]["failed"] == 1
    assert result["targets"]["yaw_t_s_reported"] == sum(pe.PAPER_TABLE[k]["yaw_t_s"] is not None for k in (0, 1))
