"""quadruped_control.studies.paper_sim through the CLI (``simulate --study paper-sim``)."""
from __future__ import annotations

import json
import os

from quadruped_control import simulate


def test_paper_sim_study_short_runs_in_parallel_and_writes_study(tmp_path) -> None:
    out = str(tmp_path / "study")
    code = simulate.main(["--study", "paper-sim", "--duration", "2", "--out", out, "--quiet", "--jobs", "2"])
    assert code == 2  # 2 s trials cannot satisfy the 30 s settling criterion: reported, not hidden
    with open(os.path.join(out, "study.json")) as stream:
        study = json.load(stream)
    assert [t["setpoint_rpy_deg"] for t in study["trials"]] == [[15.0] * 3, [45.0] * 3, [75.0] * 3]
    assert all(t["gains"] == "simulation" and t["info"]["servo_model"] == "ideal" for t in study["trials"])
    assert study["all_settled"] is False
    assert os.path.getsize(os.path.join(out, "paper_sim.png")) > 0
    assert os.path.exists(os.path.join(out, "trial_45", "timeseries.csv"))
