"""Which tank parameter sets a plant step can resolve: :func:`unresolved_terms`, the checks behind
:meth:`TankModel.check_step_stability <quadruped_control.sim.plants.tank.TankModel.check_step_stability>`.

Each stiff term is a rate of the linearised plant against the torso's own mass and inertia (with added mass,
without the paws': the smaller, so the stricter):

- in the RK4 step, |lambda| dt <= 2.5: the appendage damping c / I and, at 1 rad/s, 2 k |w| / I per axis; the
  rope's torsion c_t / I_zz and sqrt((k_t + k_r) / I_zz); the rope's damping c / M_z and stiffness sqrt(k / M_z),
  and both again through the hook's arm h about the tilts (c h^2 / I, sqrt(k h^2 / I));
- the hook friction's presliding spring, held over the step (symplectic Euler): K dt^2 / I <= 1 at its stiffest,
  K = tau_c max(1, tau_s / tau_c) max(1, m_x) exp(mu_w phi) / theta_p, phi the tether's turn;
- the floating block, its rope's pull explicit: (k + k_g) dt^2 / m_b < 4;
- the torso's buoyancy positive.

The tether's bend needs none (at its largest, sqrt(4 / I) dt < 0.1 at 10 ms).
"""
from __future__ import annotations

import math
from typing import Any, List

import numpy as np

from quadruped_control.sim.plants.tank_params import yaml_path

__all__ = ["MAX_STEP", "RK4_LIMIT", "unresolved_terms"]

#: The plant step a TankModel is checked for at construction (s): the 100 Hz control period.
MAX_STEP = 0.01

#: |lambda| dt the explicit terms of a step may reach: RK4 is stable to 2.785 on the negative real axis and 2.83
#: on the imaginary one; 2.5 leaves a margin for the angles between.
RK4_LIMIT = 2.5

#: The body rate (rad/s) at which the quadratic appendage damping's stiffness is checked (Table 1's fastest
#: turn is under 0.5 rad/s).
CHECK_RATE = 1.0


def unresolved_terms(model: Any, dt: float, turn: float) -> List[str]:
    """The stiff terms of ``model`` (a TankModel) a step of ``dt`` s cannot resolve at the tether's turn ``turn``
    (rad), each naming its tank.yaml keys; empty if it resolves them all (module docstring)."""
    tank, limit = model.tank, RK4_LIMIT / dt
    inertia = np.diag(model.body_mass_matrix[3:, 3:])
    tilt_inertia, heave_mass = float(min(inertia[0], inertia[1])), float(model.body_mass_matrix[2, 2])
    problems = []
    for axis, name in enumerate("xyz"):
        if tank.appendage_damping_linear[axis] / inertia[axis] > limit:
            problems.append("%s[%d] (%s) = %g N m s/rad > %.3g" % (
                yaml_path("appendage_damping_linear"), axis, name, tank.appendage_damping_linear[axis],
                limit * inertia[axis]))
        if 2.0 * tank.appendage_damping_quadratic[axis] * CHECK_RATE / inertia[axis] > limit:
            problems.append("%s[%d] (%s) = %g N m s^2/rad^2 > %.3g" % (
                yaml_path("appendage_damping_quadratic"), axis, name, tank.appendage_damping_quadratic[axis],
                limit * inertia[axis] / (2.0 * CHECK_RATE)))
    if tank.suspension:
        arm2 = float(np.dot(model.hook, model.hook))
        if tank.rope_torsion_damping / inertia[2] > limit:
            problems.append("%s = %g N m s/rad > %.3g" % (
                yaml_path("rope_torsion_damping"), tank.rope_torsion_damping, limit * inertia[2]))
        twist_stiffness = tank.rope_torsion_stiffness + tank.rope_torsion_relaxing_stiffness
        if twist_stiffness / inertia[2] > limit ** 2:
            problems.append("%s + rope_torsion_relaxing_stiffness = %g N m/rad > %.3g" % (
                yaml_path("rope_torsion_stiffness"), twist_stiffness, limit ** 2 * inertia[2]))
        rope_mass = min(heave_mass, tilt_inertia / arm2 if arm2 > 0.0 else math.inf)  # at the hook
        if tank.rope_damping / rope_mass > limit:
            problems.append("%s = %g N s/m > %.3g" % (yaml_path("rope_damping"), tank.rope_damping,
                                                      limit * rope_mass))
        if tank.rope_stiffness / rope_mass > limit ** 2:
            problems.append("%s = %g N/m > %.3g" % (yaml_path("rope_stiffness"), tank.rope_stiffness,
                                                    limit ** 2 * rope_mass))
        friction_limit = model._friction_limit  # pylint: disable=protected-access (tau_c as built)
        if friction_limit > 0.0:
            stiffest = (friction_limit * max(1.0, tank.hook_friction_static_ratio)
                        * max(1.0, tank.hook_friction_roll_ratio) * math.exp(tank.hook_friction_wrap * turn)
                        / tank.hook_friction_angle)
            if stiffest * dt * dt / tilt_inertia > 1.0:
                problems.append("the hook friction's presliding stiffness %.3g N m/rad > %.3g (suspension."
                                "hook_friction_arm, hook_friction_angle, hook_friction_static_ratio, "
                                "hook_friction_roll_ratio, hook_friction_wrap and the rope's tension)"
                                % (stiffest, tilt_inertia / (dt * dt)))
    pull = tank.rope_stiffness + tank.block_tie_stiffness
    if tank.suspension and tank.block_mass > 0.0 and pull * dt * dt >= 4.0 * tank.block_mass:
        problems.append("%s = %g kg <= (rope_stiffness + block_tie_stiffness) * %g s^2 / 4 = %.3g"
                        % (yaml_path("block_mass"), tank.block_mass, dt * dt, pull * dt * dt / 4.0))
    if tank.hydrostatics and model.torso_buoyancy <= 0.0:
        problems.append("%s = %g N leaves the torso (%.3g N) no buoyancy"
                        % (yaml_path("net_weight"), tank.net_weight, model.torso_weight))
    return problems
