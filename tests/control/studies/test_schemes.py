"""quadruped_control.studies.schemes through the CLI (``simulate --study schemes``)."""
from __future__ import annotations

import json
import math
import os

from quadruped_control import simulate
from quadruped_control.studies.runner import code_fingerprint, code_source


def test_schemes_study_runs_both_schemes_and_writes_the_comparison(tmp_path) -> None:
    """`--study schemes` on the paper-sim group only (3 cases x 2 schemes, simulation gains, ideal servos):
    both schemes per case, the comparison table, figure and JSON; exit 0 or 2 (targets met or not)."""
    out = str(tmp_path / "schemes")
    code = simulate.main(["--study", "schemes", "--scheme-groups", "paper-sim", "--scheme-gains", "simulation",
                          "--scheme-servos", "ideal", "--perturbed", "0", "--out", out, "--quiet", "--jobs", "2"])
    assert code in (0, 2)
    with open(os.path.join(out, "schemes.json")) as stream:
        result = json.load(stream)
    rows = result["rows"]
    assert result["trials"] == len(rows) == 6
    assert sorted({r["scheme"] for r in rows}) == ["coordinated", "paper"]
    assert sorted({r["case"] for r in rows}) == ["sim 15", "sim 45", "sim 75"]
    for row in rows:
        assert 0.0 <= row["power_fraction"] <= 1.0 and math.isfinite(row["worst_last_30s"])
    assert set(result["groups"]["all"]) >= {"paper", "coordinated"}
    assert result["all_met"] == all(result["targets"].values()) and code == (0 if result["all_met"] else 2)
    assert result["command"][3:5] == ["--study", "schemes"] and result["code"] == code_fingerprint()
    assert result["code_source"] == code_source()
    assert result["plant"] == "paper" and result["tank_yaml"] is None
    assert os.path.getsize(os.path.join(out, "schemes.png")) > 0
    assert "| group |" in open(os.path.join(out, "schemes.md")).read()
