"""A trial's summary without the simulator, for the studies' logic on small inputs."""
import math
from typing import Any, Dict

import numpy as np


def fake_summary(spec: Any) -> Dict[str, Any]:
    """What a trial of ``spec`` would report, computed without simulating: every axis rises later the
    further the set's overrides lie from zero (so that sets differ in cost) and settles nowhere, as a
    0.2 s trial does."""
    flat = [float(v) for _, value in spec.tank_overrides for v in np.ravel(np.asarray(value, dtype=float))]
    slow = 1.0 + sum(math.log1p(abs(v)) for v in flat)
    axis = {"t_r": 5.0 * slow, "t_s": None, "e_ss": 2.0, "M_p": 20.0}
    return {"label": spec.label, "setpoint_rpy_deg": list(spec.setpoint_rpy_deg),
            "initial_rpy_deg": list(spec.initial_rpy_deg), "plant": spec.plant, "engine": "fake",
            "metrics": {"theta_init_deg": 10.0, "roll": dict(axis), "pitch": dict(axis),
                        "yaw": dict(axis, t_r=2.0 * slow)}}
