"""quadruped_control.studies.robustness through the CLI (``simulate --study robustness``), on 2 s trials."""
from __future__ import annotations

import json
import os

from quadruped_control import simulate


def test_robustness_study_runs_every_variant_and_writes_its_table(tmp_path) -> None:
    out = str(tmp_path / "robustness")
    assert simulate.main(["--study", "robustness", "--duration", "2", "--out", out, "--quiet", "--jobs", "2"]) == 0
    with open(os.path.join(out, "robustness.json")) as stream:
        study = json.load(stream)
    variants = [r["variant"] for r in study["rows"]]
    assert len(variants) == 3 * len(set(variants))  # each variant: the three paper-sim setpoints
    assert {"baseline (sim gains, ideal servos)", "experiment gains, rate-limited servos",
            "paper's literal pairs (1,2), (3,4)", "nominal foot +1 cm in z"} <= set(variants)
    assert not any(r["settled"] for r in study["rows"])  # 2 s cannot meet a 30 s criterion: reported as such
    table = open(os.path.join(out, "robustness.md")).read()
    assert table.count("\n") == len(study["rows"]) + 2
