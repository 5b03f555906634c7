"""The test-tank plant: the paper's model plus the effects of the tank the experiments ran in.

Equations of motion (body axes, about the centre of mass, nu = (v^B, omega) with v^B = R^T v^W):

    M nu_dot = tau_paper + tau_rope + tau_hydrostatic - C(nu) nu - f_paw(nu)                  (tank)
    dv^W/dt = R (v_dot^B + omega x v^B),  dp/dt = v^W,  dR/dt = R hat(omega)

- ``tau_paper``: the paper's paw drag, body drag and paw buoyancy of eq. (trans), (rot)
  (:meth:`FloatingBaseModel._body_wrench <quadruped_control.sim.plants.paper.FloatingBaseModel._body_wrench>`,
  the plants' shared assembly of the :mod:`quadruped_control.model.hydrodynamics` force laws; paw
  buoyancy's force 4 B_net z_hat is added here).
- M = M_RB + M_A + sum_i M_paw(r_i): rigid body diag(m I, I), the torso's ellipsoid added mass and the
  paws' point added masses rho V / 2 at the foot positions (:mod:`.added_mass`).
- C(nu) nu = Kirchhoff terms of M_RB + M_A (rigid-body gyroscopic and added-mass Coriolis/centripetal,
  Fossen eq. 6.43); f_paw = sum_i m_a (omega x v + omega x (omega x r_i) + 2 omega x c_i) with its
  moments r_i x f_i (paw added mass, :mod:`.added_mass`).
- ``tau_rope`` (:func:`rope_force`): tension-only, stiff and damped rope from the hook h^B to an
  anchor a^W (fixed, unless the floating block below moves it): with d = a - (p + R h), L = |d|,
  T = max(0, k (L - L_0) + c dL/dt) when L > L_0 (slack otherwise); force T d / L at the hook, moment
  h x R^T (T d / L).
- ``tau_hydrostatic`` (:func:`hydrostatic_wrench`): torso weight W (paws excluded: their net weight is
  the paper's paw buoyancy) down at the centre of mass and torso buoyancy B = W - net_weight up at the
  centre of buoyancy r_cb: force (B - W) z_hat, moment r_cb x (B R^T z_hat).

Candidate effects of the identification against Table 1, each zero (today's model) unless
``config/tank.yaml`` sets it:

- ``tau_appendage`` (:func:`appendage_damping_torque`): rotational damping of what the inertia box
  leaves out (leg links, motor housings, the enclosure's corners sweeping through the water as the body
  turns), per body axis -(c_lin + c_quad |omega|) omega: the linear (skin friction, laminar) plus
  quadratic (form drag, strip theory of appendages at radius r: 1/2 rho C_D A r^3 |omega| omega) damping
  of Fossen, "Handbook of Marine Craft Hydrodynamics and Motion Control" (2011), section 6.4.
- ``tau_torsion`` (:func:`rope_torsion_torque`): the rope and its floating block resist twisting:
  -(k_t theta + c_t theta_dot) g, theta the rope's whole twist since :meth:`TankModel.attach`: the integral
  of the body's rate about the world vertical, every turn counted (plant state, :attr:`TankModel.twist`,
  carried step by step as the twist of each step's rotation, :func:`~.tank_dynamics.whole_twist`), and g
  the gradient of that step's twist, the world vertical to first order: the spring of potential
  k_t theta^2 / 2 and a damper on the twist's rate, about the world vertical at any tilt. A rope is
  twisted by turns about itself, not by the body's tilts. (Two earlier versions took the twist as a
  function of the attitude, the twist of the swing-twist decomposition of R R_0^T from the attitude at
  attach: about the vertical, that torque did work round closed paths of tilts and turns; along that
  twist's gradient, it pushed the tilt of a twisted rope, without bound near a swing of 180 deg, where a
  fit's trial diverged.) Acts only with the suspension on.
- ``relaxing twist`` (``rope_torsion_relaxing_stiffness`` k_r, ``rope_torsion_relaxation_time`` tau_r,
  :func:`~.tank_dynamics.twist_relaxation_update`): what the body's turns twist may let go over seconds. The
  rope is tied to a floating block that can turn in the water: the rope's torsion spring in series with the
  block's rotational drag is a Maxwell element, whose twist the block unwinds with tau_r = c_block / k_r. The
  robot's tether leaves the enclosure's gland beside the hook (the paper, section "Robot Design") and hangs
  to the surface: a turn of the body twists it at the gland at once, and the hanging cable untwists along its
  length through the water, and its jacket creeps, over seconds. Both resist a turn at once and then fade.
  A third branch of the torsion beside k_t and c_t, -k_r (theta - s) g, the relaxed twist s following the
  whole twist theta, ds/dt = (theta - s) / tau_r, 0 at :meth:`TankModel.attach` (the rope and the tether hang
  untwisted at a trial's start): a standard linear solid about the vertical, as the tether's bend is on the
  tilt. A long turn builds a torque against it; the controller's integral winds up to carry the body through
  it; at the setpoint the branch still pulls back and then fades, and the wound-up integral carries the body
  past the setpoint and returns it as slowly as it unwinds: overshoot and slow settling that grow with the
  turn made, in yaw and, through the SO(3) error, in the tilt the robot holds while it turns. A 6-8 mm
  jacketed cable's torsional rigidity GJ of about 0.001-0.02 N m^2 over a twisted length of 0.2-1 m gives
  k_r of about 0.001-0.1 N m/rad. The spring inside the step's RK4, s held over the step and carried exactly
  after it (tau_r >= 0.1 s). k_r = 0 (the default) is today's model exactly.

- ``paw wake`` (:func:`paw_wake_update`): a paw that strokes sets the water around it moving, and the
  recovery stroke reverses into that water. Each paw carries a wake velocity w_i (body axes) that relaxes
  towards a fraction kappa of the paw's own velocity u_i with a time constant tau_w,
  dw_i/dt = -omega x w_i + (kappa u_i - w_i) / tau_w (the first term turns the water's velocity back as
  the body turns), and the drag law sees u_i - w_i: late in the power stroke the paw
  pushes water that already moves with it (less thrust), and the retracing recovery stroke meets that
  water head-on (more drag against the stroke), so the net torque of a stroke cycle, the small difference
  of the two impulses, drops; the body's own rotation builds the same wake, so its passive damping drops
  too. The share s_b (``paw_wake_body_share``, default 1) says how much of the body's motion enters the
  velocity that builds the wake, dw_i/dt = (kappa (c_i + s_b (b + omega x r_i)) - w_i) / tau_w: s_b = 0
  keeps the wake to the strokes, which reverse within a few paw diameters (the history effect), and
  leaves the slow, steady motion of the body to the steady C_D, whose measurement already contains the
  steady wake; the passive damping then stays as it is. A first-order "entrained water" model of the
  history effects of unsteady drag (the Basset history force of Maxey and Riley, Phys. Fluids 26 (1983);
  oscillating spheres at low Keulegan-Carpenter numbers, Sarpkaya and Isaacson, "Mechanics of Wave
  Forces on Offshore Structures" (1981), ch. 3).
  kappa = 0 is today's quasi-steady drag. The wake is integrated once per step with the legs and the body
  velocity of the step's start held (exact for the linear relaxation), and held through the step's RK4
  stages: tau_w >= 0.02 s (two 10 ms steps; the identification keeps it >= 0.05 s).
- ``body wake`` (:func:`body_wake_update`): the legs, housings and corners that the appendage damping stands
  for set the water around the body turning with it, and that water keeps turning after the body slows. The
  water's rate W (world axes) relaxes towards a fraction kappa_b of the body's, dW/dt = (kappa_b R omega -
  W) / tau_b, and the appendage damping acts on the body's rate relative to it, -(c_lin + c_quad |omega -
  R^T W|) (omega - R^T W) per body axis. While the body turns steadily its damping drops to (1 - kappa_b) of
  tau_appendage's linear part and (1 - kappa_b)^2 of its quadratic part; when it slows, the water pushes it
  on, the mechanism of an overshoot that only a fluid memory on the time scale of the manoeuvre (seconds,
  not the paws' tenths) gives. The same first-order "entrained water" model as the paws' wake, applied to
  the body's rotation: the history (memory) effects of unsteady flow around a body that starts and stops
  (Sarpkaya and Isaacson, "Mechanics of Wave Forces on Offshore Structures" (1981), ch. 3; the convolution
  (retardation) terms of Cummins' equation, Fossen (2011), section 5.4, whose simplest state-space form is
  this one pole). kappa_b = 0 is today's damping. Held over a step like the paws' wake: tau_b >= 0.05 s
  against the 10 ms step.
- ``floating block`` (:func:`~.tank_dynamics.floating_block_update`, ``block_mass``, ``block_drag``,
  ``block_tie_stiffness``): the rope hangs from a foam block that floats on the surface, tied to a gantry
  (the paper, section "Experimental Setup"), not from a fixed point. The block moves horizontally under
  the rope's pull, its drag and its tie: m_b a'' = -T u_h - c_b |a'| a' - k_g (a - a_0), with m_b its mass
  with added mass, c_b = 1/2 rho C_D A of its draft (a bluff block: C_D about 1, Hoerner, "Fluid-Dynamic
  Drag" (1965), ch. 3), k_g the tie's horizontal stiffness around the block's rest a_0. The rope's
  pendulum stiffness on the block, T / L, is of the order of 1 N/m, so a light, free block drifts over the
  hook within seconds and the rope's direction, and the hook's moment on the body, lag the swing: a
  restoring torque with a memory. block_mass = 0 (the default) is today's fixed anchor; a tie far stiffer
  than T / L tends to it (tested). Advanced once per step with the body state of the step's start, like
  the wakes, the rope's dashpot and the block's drag implicit (the dashpot is far stiffer than a light
  block); the hook's rope velocity is taken relative to the block's.
- ``loaded servos`` (``servo_stall_torque``, :func:`paw_joint_loads`,
  :func:`~quadruped_control.sim.servo_model.loaded_speed`): a servo's DC motor slows along its
  torque-speed line, w = w_max (1 - tau_opp / tau_stall), against the part tau_opp of its joint's load
  that opposes the motion. The load is the paw's drag seen at the joint, tau = J_P,i^T F_i (virtual
  work), computed at each step's start and used by the servos' next step (10 ms later). The power
  stroke, which pushes the water, is slowed more than the recovery, which the drag opposes less. The
  rated stall torque is 3.9 N m (the paper, section "Robot Design"); 0 (the default) leaves the rate
  limit alone. Motor torque-speed line: e.g. Hughes and Drury, "Electric Motors and Drives" (2019), ch. 3.
- ``buoyant paws`` (``paw_buoyancy_offset``): the paws' net buoyancy B_net of eq. (buoy_force),
  (buoy_torque), robot.yaml's estimate g (rho V_s - m_s) = -0.029 N of a flooded PLA shell, plus an offset
  (N per paw). An FDM-printed shell with sparse infill holds air in its cells, the printed lower links near
  the foot float, a bubble caught in the sphere adds 0.01 N per cm^3. The paws' buoyancy moment scales with
  their displacement, not their speed, and acts on roll and pitch only (gravity has no moment about the
  vertical): a floating paw opposes the tilt strokes, a sinking one helps them. The plant's paws only;
  the robot's controller feeds forward robot.yaml's estimate, as the real controller does. The rope's
  static load follows (net weight minus 4 B_net). 0 (the default) is today's model exactly.
- ``servo dead band`` (``servo_dead_band``, :func:`~quadruped_control.sim.servo_model.dead_band_command`):
  the servos' position loop ignores an error below a half-width d (rad): a hobby servo's amplifier dead
  band (1-10 us of pulse width, about 0.1-0.9 deg on the IB53BHU) plus its gear train's backlash. A joint
  stops up to d short of its command and reverses only after the command has crossed 2 d, so a stroke
  loses a share of its amplitude that grows as the stroke shrinks. In the servos, not in this plant's
  dynamics; 0 (the default) is today's model exactly.
- ``hook friction`` (``hook_friction_arm``, ``hook_friction_angle``, :func:`~.tank_dynamics.hook_friction_update`):
  the rope is tied to an eye on top of the enclosure (the paper, section "Experimental Setup"), and the body
  tilts under it. The rope's loop turning on the eye's wire (a pin of radius r under the tension T: a torque
  mu r T) and the braid bending at the knot (inter-fibre slip: the hysteretic bending of stranded cables,
  Papailiou, "On the bending stiffness of transmission line conductors", IEEE Trans. Power Delivery 12
  (1997)) resist the body's rotation relative to the rope with a dry friction, not a viscous one: the
  same torque tau_c = mu r T_0 (T_0 the rope's static tension, :meth:`TankModel.static_rope_tension`;
  ``hook_friction_arm`` = mu r in m) however slowly the body turns. Dahl's model of it: a spring of
  stiffness tau_c / theta_p for reversals smaller than the presliding angle theta_p
  (``hook_friction_angle``), sliding friction beyond. A dry friction eats the strokes' few mN m near the
  setpoint while the controller's integral winds up, and lets go once it is overcome: the stick-slip
  of a PI loop against friction (e.g. Armstrong-Helouvry, Dupont and Canudas de Wit, "A survey of models,
  analysis tools and compensation methods for the control of machines with friction", Automatica 30
  (1994)), slow near the setpoint and then past it, where far from it the strokes' larger torque hardly
  notices. Across the rope only (roll and pitch for a vertical rope); the twist is the rope torsion's.
  Advanced once per step with the body state of the step's start, like the wakes (exact for the held
  rate, so the torque never exceeds tau_c), and held through the step's RK4 stages. The light rope's
  reaction, a couple of tau_f / L on its ends, is left out (mN against the rope's newtons). A tie that has
  stuck may hold more than it slides with (``hook_friction_static_ratio`` tau_s / tau_c, 1-2 for dry fibre
  on metal; 1, the default, is Dahl's model exactly): below the Stribeck rate s_s
  (``hook_friction_stribeck_rate``, the body's turn relative to the rope; 0.02 rad/s is 60 um/s of slip on a
  3 mm wire) the limit rises towards tau_s, LuGre's Stribeck curve at Dahl's stiffness. The integral then
  winds further before the tie breaks away, and the torque it built carries the body on once the friction
  drops to tau_c. The eye is a ring in one plane, so the tie need not hold alike about every axis
  (``hook_friction_roll_ratio``, the Coulomb torque about the body's x axis over the one about the others;
  1, the default, is the isotropic tie exactly): a turn in the ring's plane slides the rope's loop along
  the wire around the ring (arm mu R_e), a turn about the wire rolls it round the wire's section (arm mu
  r_w), and a screw eye's R_e / r_w is 2-5. The paper does not say which way the eye faces, so the ratio
  may be either side of 1. It is the one candidate that acts on roll and not on pitch. The robot's tether
  hangs beside the rope, and each turn about the rope winds it round the rope and the tie: the tie then
  holds more, by the capstan law tau_c exp(mu_w |phi|) with phi the turn since the rope hung untwisted
  (``hook_friction_wrap`` mu_w, :func:`~.tank_dynamics.wound_friction_limit`; 0, the default, is the
  unwound tie exactly). It grows with the turn already made, so it is largest where Table 1's roll group
  ends its long heading changes, and falls as the tether unwinds: what the tie stored beyond its new
  limit then slips at once. arm = 0 (the default) is today's model exactly.
- ``tether bend`` (``tether_stiffness``, ``tether_relaxing_stiffness``, ``tether_relaxation_time``,
  :func:`~.tank_dynamics.tether_bend_torque`): the robot's tether (power and data, the paper's section
  "Robot Design") leaves the enclosure's top through a gland and hangs to the surface. Bent there by the
  body's tilt it resists at once; then the cable, dragged through the water under its own weight, re-hangs,
  and its jacket creeps (PVC and PU relax over seconds to minutes), so the resistance fades while the body
  holds its tilt. A standard linear solid (Zener) on the tilt theta (:func:`~.tank_dynamics.tilt_vector`,
  world axes, horizontal): the torque -k_e theta - k (theta - s), the relaxed tilt s following theta with
  the relaxation time tau, ds/dt = (theta - s) / tau, s = theta at :meth:`TankModel.attach` (the cable
  hangs relaxed at the trial's start). A 6-8 mm jacketed cable's bending stiffness EI of about
  0.002-0.05 N m^2 (soft PVC alone to copper cores) over a bending length of 0.1-0.5 m gives EI / L of
  about 0.004-0.5 N m/rad: large next to the strokes' net torque (0.01-0.04 N m), so even a tenth of it
  holds a tilt back for seconds. The controller's integral, built against the bend, then carries the body
  past its setpoint as the bend lets go: slow settling and overshoot together, the two ways the fitted
  plants miss the robot. A pure torque about the horizontal axes (the cable's weight and drag at the gland
  are left in the net weight and the body's drag); the tilt's own yaw is untouched. The spring inside the
  step's RK4, s held over the step and carried exactly after it (:func:`~.tank_dynamics.tether_relaxation_update`,
  tau >= 0.1 s, ten steps). Both stiffnesses 0 (the default) is today's model exactly.
- ``disturbance`` (``disturbance_torque_std``, ``disturbance_correlation_time``, ``disturbance_seed``,
  :func:`~.tank_dynamics.disturbance_update`): a tank is not still. The strokes set its water circulating and
  it comes back off the walls; currents and the operator moving the tether at the surface push the body. The
  strokes' net torque is 0.01-0.04 N m (docs/identification.md), so a push of a few mN m matters: a current
  of 2-3 cm/s on a 0.6 m body whose centre of pressure sits a few centimetres off its centre of mass, or a
  tug of 0.1 N on the tether 5 cm from it. Not modelled as flow: a torque d (world axes) from an
  Ornstein-Uhlenbeck process per axis, stationary standard deviation sigma and correlation time tau_d
  (dd = -d / tau_d dt + sigma sqrt(2 / tau_d) dW, stepped exactly), started at a stationary draw at
  :meth:`TankModel.attach` and held over each step in body axes at the step's start, beside the hook's
  friction. Seeded (``disturbance_seed``, its own stream apart from the IMU noise's): the same tank.yaml runs
  the same disturbance in every trial, both engines alike, and a trial's own seed (:meth:`TankParams.for_trial`:
  the robustness study's seeds, ``--seed``) draws another from it; another tank seed is another tank. sigma = 0 (the
  default) is today's model exactly. It is an input, not one of the plant's forces:
  :meth:`TankModel.held_wrench` and :meth:`TankModel.restoring_torque` leave it out.

- **The heading the IMU reports** (not a force: what the robot's VN-100 told its controller and the
  paper's Table 1). A magnetic field that rides with the body and is not calibrated out (motor magnets
  and currents; a level hard-iron calibration cannot see its vertical part) turns the magnetometer's
  heading by an angle that depends on the attitude (``imu_field_residual``, body axes, in units of the
  earth's horizontal field; :mod:`quadruped_control.sim.magnetic_heading`). Both engines give the
  controller that attitude and take the metrics from it. 0, the default, is the true attitude exactly.

Each effect has a switch (:class:`TankParams`); with all of them off the equations reduce to the paper's
eq. (trans), (rot) (tested). Parameters: ``config/tank.yaml``.
Integration: :func:`~.tank_dynamics.tank_rk4`, the classic RK4 in the SO(3) chart (the chart helpers of
:mod:`.rigid_body`) over :func:`~.tank_dynamics.tank_chart_derivative`, with the inputs and the plant's
own states (wakes, block, tie) held over the step; the batch runs the same function. The paper model's
continuous-time methods (``wrench``, ``derivative``, ``step_continuous``) raise NotImplementedError here.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Mapping, Optional, Sequence, Tuple

import numpy as np

from quadruped_common.config import ParameterError, boolean, check_keys, integer, load_config, number, vector
from quadruped_control.model import hydrodynamics
from quadruped_control.model.kinematics import _geometry, leg_kinematics_flat
from quadruped_control.model.params import RobotParams
from quadruped_control.sim.plants.added_mass import ellipsoid_added_mass, point_mass_matrix, sphere_added_mass
from quadruped_control.sim.plants.paper import FloatingBaseModel
from quadruped_control.sim.plants.rigid_body import (Mat3, RigidBodyState, StepContext, as_mat3, chart_step_end,
                                                     check_dt, diverged, joint_array)
from quadruped_control.sim.plants.tank_dynamics import TANK_CONSTANT_AT as _AT
from quadruped_control.sim.plants.tank_dynamics import (TankConstants, appendage_damping_torque, body_wake_update,
                                                        disturbance_coefficients, disturbance_update,
                                                        floating_block_update, hook_friction_update, leg_sums,
                                                        mass_solver, paw_joint_loads, paw_wake_update, rope_force,
                                                        rope_torsion_torque, rope_twist, tank_forces, tank_rk4,
                                                        tether_relaxation_update, tilt_vector,
                                                        twist_relaxation_update, whole_twist, world_to_body,
                                                        wound_friction_limit)

__all__ = ["TankModel", "TankParams", "TurnUnresolved", "VALIDITY_NOTE", "appendage_damping_torque",
           "hydrostatic_wrench", "load_tank_params", "rope_force", "rope_torsion_torque", "rope_twist",
           "torso_ellipsoid"]

#: What the tank plant can tell a roboticist today, said wherever a user runs it (the simulate command and its
#: paper-sim, robustness and schemes studies with --plant tank, the Table-1 study's report, sim.launch
#: plant:=tank), so that no result made on it is read as the robot's. The figures
#: behind it are in docs/identification.md, "Where it stands": no model predicts the settling of experiments
#: held out of its fit reliably (one draw of the twenty-seventh run met the targets, at the edge; the same
#: model's other draws did not).
VALIDITY_NOTE = ("the tank plant is not yet a validated model of the robot. config/tank.yaml (the default) holds "
                 "a priori estimates and cannot hold a tilt past about 16 deg; the sets fitted to the paper's "
                 "Table 1 (config/tank_ensemble/member_NN.yaml, config/tank_identified.yaml; --tank-yaml) predict "
                 "experiments held out of their fit with the right outcomes and rise times, but settle sooner "
                 "than the robot did (most in roll, 2-3x) and overshoot less. Check gains and stroke schemes "
                 "chosen on it in the water (docs/identification.md, \"Where it stands\")")

Vec3 = Tuple[float, float, float]


class TurnUnresolved(ParameterError, RuntimeError):
    """:meth:`TankModel.check_turn`'s refusal, found mid-run: a ParameterError (naming the keys of a set the
    plant cannot step at the turn it has reached) that is also a RuntimeError, as a diverged step is
    (:class:`~.rigid_body.DynamicsError`), so that the closed loop reports it as a failed plant step and a
    study that records failed trials records it (the batch marks the trial failed with this reason)."""


#: The plant step TankModel checks its parameters for at construction (s; TankModel.check_step_stability):
#: the 100 Hz control period. A longer step is checked again when it is asked for (TankModel.check_step).
_MAX_STEP = 0.01

#: |lambda| dt the explicit terms of a tank step may reach (:meth:`TankModel.check_step_stability`): RK4 is
#: stable to 2.785 on the negative real axis and 2.83 on the imaginary one; 2.5 leaves a margin for the
#: angles between.
_RK4_LIMIT = 2.5

#: The body rate (rad/s) at which the quadratic appendage damping's stiffness is checked: past the rates
#: of any manoeuvre (Table 1's fastest turn is under 0.5 rad/s).
_CHECK_RATE = 1.0

#: What the paper model's continuous-time methods say on the tank plant.
_PAPER_ONLY = ("TankModel.%s is the paper model's and leaves out the tank's rope, hydrostatics, added mass and "
               "candidate effects; use step (tank_dynamics.tank_rk4) or held_wrench")

#: The water's rate without the body wake: the appendage damping sees omega itself.
_STILL: Vec3 = (0.0, 0.0, 0.0)

#: The widest servo dead band tank.yaml accepts (rad, half-width; 0.1 rad = 5.7 deg): an order of magnitude
#: past a worn hobby servo's, so that a unit slip (degrees, microseconds) is refused rather than simulated
#: as servos that never move.
MAX_SERVO_DEAD_BAND = 0.1

#: The largest hook friction arm mu r tank.yaml accepts (m): mu = 1 on a 5 cm eye, ten times the bound the
#: identification gives it; a larger one is a unit slip (mm for m), not a tie.
MAX_HOOK_FRICTION_ARM = 0.05

#: The smallest presliding angle (rad) tank.yaml accepts: the friction's spring, tau_c / theta_p, is held over
#: each 10 ms step. Whether a step resolves it depends on the arm, the tension, the static and roll ratios and
#: the tether's wrap together, which TankModel.check_step_stability checks (the audit found 1 mrad with the
#: largest arm, a 3 N tension and a wound tether ringing).
MIN_HOOK_FRICTION_ANGLE = 0.001

#: The largest capstan coefficient of the tether on the rope tank.yaml accepts (per rad): 1, twice dry rubber on
#: fibre; at 2 rad of turn the tie then holds 7.4 times its unwound friction.
MAX_HOOK_FRICTION_WRAP = 1.0

#: The largest static over sliding friction ratio tank.yaml accepts: 3, past the 1.1-2 of dry fibre on metal,
#: so that a ratio of torques (N m for mN m) is refused.
MAX_HOOK_FRICTION_STATIC_RATIO = 3.0

#: The Stribeck rates tank.yaml accepts (rad/s): 0.3 um/s to 3 mm/s of slip on a 3 mm wire, past both ends
#: of the identification's bounds; a value outside them is a unit slip (deg/s or mrad/s for rad/s).
HOOK_FRICTION_STRIBECK_RATE_RANGE = (1e-4, 1.0)

#: The tie's roll over pitch friction ratios tank.yaml accepts: 0.1 to 10, past a screw eye's ring radius over
#: its wire's radius (2-5) either way round; a larger one is a tie that holds about one axis only.
HOOK_FRICTION_ROLL_RATIO_RANGE = (0.1, 10.0)
#: The stiffest tether bend tank.yaml accepts (N m/rad, either branch): four times the stiffest jacketed
#: cable's EI / L (0.05 N m^2 over 0.1 m); a larger one is a unit slip (N mm for N m), not a cable.
MAX_TETHER_STIFFNESS = 2.0

#: The time constants tank.yaml accepts (s): the relaxation times of the tether's bend and of the torsion's
#: relaxing twist, and the disturbance's correlation time. From ten 10 ms steps (each is carried exactly, but a
#: faster relaxation is a viscous damper, not a spring, and a faster disturbance white noise filtered by the
#: step) to nearly three hours (a cable that never relaxes, a push that stays).
TIME_CONSTANT_RANGE = (0.1, 10000.0)

#: The largest disturbance torque tank.yaml accepts (its standard deviation per axis, N m): ten times the
#: strokes' net torque at its largest (0.04 N m); a larger one is a unit slip (N mm for N m), not a tank.
MAX_DISTURBANCE_TORQUE = 0.4

#: The stream of a tank's random generator its disturbance draws from, beside its seed: apart from the IMU
#: noise's stream, default_rng(seed), so that the two are independent for the same seed.
DISTURBANCE_STREAM = 0x7A4B

#: The disturbance's standard normal draws come in blocks of this many steps (3 per step): the batch takes
#: each trial's block at once, the per-trial plant one row per step, the same numbers either way.
DISTURBANCE_BLOCK = 1024

#: Largest residual field at the IMU (its norm), in units of the earth's horizontal field: at 1 the levelled
#: field's horizontal part can vanish, the reported heading is undefined and some headings have no true one.
MAX_IMU_FIELD_RESIDUAL = 0.95


@dataclass(frozen=True)
class TankParams:
    """``config/tank.yaml``: effect switches and parameters (see the file for units and reasoning)."""

    suspension: bool = True
    hydrostatics: bool = True
    torso_added_mass: bool = True
    paw_added_mass: bool = True
    #: the paper's paw and body drag (off only for energy checks)
    drag: bool = True
    hook: Vec3 = (0.0, 0.0, 0.077)
    rope_length: float = 0.5
    rope_stiffness: float = 2000.0
    rope_damping: float = 150.0
    net_weight: float = 1.0
    center_of_buoyancy: Vec3 = (0.0, 0.0, 0.001)
    #: how much more buoyant each paw is than robot.yaml's estimate (N; 0: as estimated): the plant's paw
    #: buoyancy only, the controller's feedforward keeps robot.yaml's, as the robot's own controller does
    paw_buoyancy_offset: float = 0.0
    added_mass_scale: float = 1.0
    paw_added_mass_scale: float = 1.0
    #: paw drag coefficient relative to robot.yaml's C_D (the paper's CFD value)
    paw_drag_scale: float = 1.0
    #: servo speed relative to robot.yaml's no-load speed (loaded servos in water are slower)
    servo_speed_scale: float = 1.0
    #: servo bandwidth: factor on the position loop's time constant T of config/simulation.yaml (1: as there)
    servo_lag_scale: float = 1.0
    #: loaded servos: stall torque tau_stall (N m) of the servos' torque-speed line; 0: the speed does not
    #: depend on the load (:func:`~quadruped_control.sim.servo_model.loaded_speed`)
    servo_stall_torque: float = 0.0
    #: servo dead band: the half-width d (rad) of the error the servos' position loop ignores; 0: none
    #: (:func:`~quadruped_control.sim.servo_model.dead_band_command`)
    servo_dead_band: float = 0.0
    #: rotational damping of appendages per body axis: linear (N m s/rad), quadratic (N m s^2/rad^2)
    appendage_damping_linear: Vec3 = (0.0, 0.0, 0.0)
    appendage_damping_quadratic: Vec3 = (0.0, 0.0, 0.0)
    #: rope torsion about the vertical: stiffness (N m/rad) and damping (N m s/rad)
    rope_torsion_stiffness: float = 0.0
    rope_torsion_damping: float = 0.0
    #: the torsion's relaxing branch (:func:`~.tank_dynamics.rope_torsion_torque`): its stiffness k_r (N m/rad;
    #: 0: off) and relaxation time tau_r (s)
    rope_torsion_relaxing_stiffness: float = 0.0
    rope_torsion_relaxation_time: float = 10.0
    #: paw wake: fraction kappa of the paw's velocity its wake reaches, and its time constant tau_w (s)
    paw_wake_fraction: float = 0.0
    paw_wake_time_constant: float = 0.3
    #: paw wake: share s_b of the body's motion in the velocity that builds the wake (1: the paw's whole
    #: velocity; 0: the stroke's alone, the body's steady motion leaving the quasi-steady drag as it is)
    paw_wake_body_share: float = 1.0
    #: body wake: fraction kappa_b of the body's rate the water turning with it reaches (0: off), and its time
    #: constant tau_b (s)
    body_wake_fraction: float = 0.0
    body_wake_time_constant: float = 5.0
    #: floating block the rope hangs from: its mass with added mass m_b (kg; 0: the anchor is fixed), its
    #: quadratic horizontal drag c_b (N s^2/m^2) and the horizontal stiffness k_g of its tie to the gantry (N/m)
    block_mass: float = 0.0
    block_drag: float = 2.0
    block_tie_stiffness: float = 0.0
    #: hook friction: mu r (m), the Coulomb torque over the rope's static tension (0: off), and the presliding
    #: angle theta_p (rad) over which it builds up (:func:`~.tank_dynamics.hook_friction_update`)
    hook_friction_arm: float = 0.0
    hook_friction_angle: float = 0.005
    #: its static friction over the sliding one, tau_s / tau_c (1: none above it), and the Stribeck rate s_s
    #: (rad/s) of the body relative to the rope below which the static friction holds
    hook_friction_static_ratio: float = 1.0
    hook_friction_stribeck_rate: float = 0.02
    #: its Coulomb torque about the body's x (roll) axis over the one about the other axes (1: the same)
    hook_friction_roll_ratio: float = 1.0
    #: the tether's capstan friction on the rope mu_w (per rad of turn about the rope; 0: an unwound tie):
    #: the Coulomb torque is tau_c exp(mu_w |phi|) (:func:`~.tank_dynamics.wound_friction_limit`)
    hook_friction_wrap: float = 0.0
    #: the residual magnetic field at the VN-100 in body axes (FLU), in units of the earth's horizontal field:
    #: the heading the IMU reports (:mod:`quadruped_control.sim.magnetic_heading`); 0 the true heading
    imu_field_residual: Vec3 = (0.0, 0.0, 0.0)
    #: the tether bent where it leaves the body (:func:`~.tank_dynamics.tether_bend_torque`): its elastic
    #: stiffness k_e and relaxing stiffness k (N m/rad; both 0: off) and the relaxation time tau (s)
    tether_stiffness: float = 0.0
    tether_relaxing_stiffness: float = 0.0
    tether_relaxation_time: float = 10.0
    #: the tank's disturbance torque (:func:`~.tank_dynamics.disturbance_update`): its standard deviation sigma
    #: per world axis (N m; 0: off), its correlation time tau_d (s) and the seed of its generator
    disturbance_torque_std: float = 0.0
    disturbance_correlation_time: float = 10.0
    disturbance_seed: int = 0

    def __post_init__(self) -> None:
        for name in ("rope_length", "rope_stiffness"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ParameterError("tank %s must be positive and finite, got %r" % (name, value))
        for name in ("rope_damping", "added_mass_scale", "paw_added_mass_scale", "paw_drag_scale",
                     "rope_torsion_stiffness", "rope_torsion_damping", "rope_torsion_relaxing_stiffness"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ParameterError("tank %s must be finite and >= 0, got %r" % (name, value))
        if not (math.isfinite(self.servo_stall_torque) and self.servo_stall_torque >= 0.0):
            raise ParameterError("tank servo_stall_torque must be finite and >= 0 (0: off), got %r"
                                 % (self.servo_stall_torque,))
        if not (math.isfinite(self.servo_dead_band) and 0.0 <= self.servo_dead_band <= MAX_SERVO_DEAD_BAND):
            raise ParameterError("tank servo_dead_band must be a half-width in [0, %g] rad (0: off), got %r"
                                 % (MAX_SERVO_DEAD_BAND, self.servo_dead_band))
        if not (math.isfinite(self.servo_lag_scale) and self.servo_lag_scale > 0.0):
            raise ParameterError("tank servo_lag_scale must be finite and > 0, got %r" % (self.servo_lag_scale,))
        if not (math.isfinite(self.servo_speed_scale) and 0.0 < self.servo_speed_scale <= 1.0):
            raise ParameterError("tank servo_speed_scale must be in (0, 1], got %r" % (self.servo_speed_scale,))
        if not (math.isfinite(self.paw_wake_fraction) and 0.0 <= self.paw_wake_fraction < 1.0):
            raise ParameterError("tank paw_wake_fraction must be in [0, 1), got %r" % (self.paw_wake_fraction,))
        if not (math.isfinite(self.paw_wake_body_share) and 0.0 <= self.paw_wake_body_share <= 1.0):
            raise ParameterError("tank paw_wake_body_share must be in [0, 1], got %r" % (self.paw_wake_body_share,))
        if not (math.isfinite(self.paw_wake_time_constant) and self.paw_wake_time_constant >= 0.02):
            raise ParameterError("tank paw_wake_time_constant must be >= 0.02 s (two steps), got %r"
                                 % (self.paw_wake_time_constant,))
        if not (math.isfinite(self.body_wake_fraction) and 0.0 <= self.body_wake_fraction < 1.0):
            raise ParameterError("tank body_wake_fraction must be in [0, 1), got %r" % (self.body_wake_fraction,))
        if not (math.isfinite(self.body_wake_time_constant) and self.body_wake_time_constant >= 0.05):
            raise ParameterError("tank body_wake_time_constant must be >= 0.05 s (five steps), got %r"
                                 % (self.body_wake_time_constant,))
        if not (math.isfinite(self.block_mass) and (self.block_mass == 0.0 or self.block_mass >= 0.01)):
            raise ParameterError("tank block_mass must be 0 (fixed anchor) or >= 0.01 kg, got %r" % (self.block_mass,))
        for name in ("tether_stiffness", "tether_relaxing_stiffness"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0.0 <= value <= MAX_TETHER_STIFFNESS):
                raise ParameterError("tank %s must be in [0, %g] N m/rad (0: off), got %r"
                                     % (name, MAX_TETHER_STIFFNESS, value))
        low, high = TIME_CONSTANT_RANGE
        for name in ("rope_torsion_relaxation_time", "tether_relaxation_time", "disturbance_correlation_time"):
            value = getattr(self, name)
            if not (math.isfinite(value) and low <= value <= high):
                raise ParameterError("tank %s must be in [%g, %g] s, got %r" % (name, low, high, value))
        if not (math.isfinite(self.block_drag) and self.block_drag >= 0.0):
            raise ParameterError("tank block_drag must be finite and >= 0, got %r" % (self.block_drag,))
        if not (math.isfinite(self.block_tie_stiffness) and 0.0 <= self.block_tie_stiffness <= 1000.0):
            raise ParameterError("tank block_tie_stiffness must be in [0, 1000] N/m, got %r"
                                 % (self.block_tie_stiffness,))
        if not (math.isfinite(self.hook_friction_arm) and 0.0 <= self.hook_friction_arm <= MAX_HOOK_FRICTION_ARM):
            raise ParameterError("tank hook_friction_arm must be in [0, %g] m (mu times the eye's radius; 0: off), "
                                 "got %r" % (MAX_HOOK_FRICTION_ARM, self.hook_friction_arm))
        if not (math.isfinite(self.hook_friction_angle) and MIN_HOOK_FRICTION_ANGLE <= self.hook_friction_angle <= 0.5):
            raise ParameterError("tank hook_friction_angle must be in [%g, 0.5] rad, got %r"
                                 % (MIN_HOOK_FRICTION_ANGLE, self.hook_friction_angle))
        if not (math.isfinite(self.hook_friction_static_ratio)
                and 1.0 <= self.hook_friction_static_ratio <= MAX_HOOK_FRICTION_STATIC_RATIO):
            raise ParameterError("tank hook_friction_static_ratio must be in [1, %g] (static over sliding "
                                 "friction), got %r" % (MAX_HOOK_FRICTION_STATIC_RATIO,
                                                        self.hook_friction_static_ratio))
        low, high = HOOK_FRICTION_STRIBECK_RATE_RANGE
        if not (math.isfinite(self.hook_friction_stribeck_rate) and low <= self.hook_friction_stribeck_rate <= high):
            raise ParameterError("tank hook_friction_stribeck_rate must be in [%g, %g] rad/s, got %r"
                                 % (low, high, self.hook_friction_stribeck_rate))
        low, high = HOOK_FRICTION_ROLL_RATIO_RANGE
        if not (math.isfinite(self.hook_friction_roll_ratio) and low <= self.hook_friction_roll_ratio <= high):
            raise ParameterError("tank hook_friction_roll_ratio must be in [%g, %g] (the tie's friction about "
                                 "roll over pitch), got %r" % (low, high, self.hook_friction_roll_ratio))
        if not (math.isfinite(self.hook_friction_wrap) and 0.0 <= self.hook_friction_wrap <= MAX_HOOK_FRICTION_WRAP):
            raise ParameterError("tank hook_friction_wrap must be in [0, %g] per rad (the tether's friction on "
                                 "the rope; 0: off), got %r" % (MAX_HOOK_FRICTION_WRAP, self.hook_friction_wrap))
        if not math.isfinite(self.net_weight):
            raise ParameterError("tank net_weight must be finite, got %r" % (self.net_weight,))
        if not (math.isfinite(self.paw_buoyancy_offset) and abs(self.paw_buoyancy_offset) <= 1.0):
            raise ParameterError("tank paw_buoyancy_offset must be within +-1 N (a paw is 7.5 cm), got %r"
                                 % (self.paw_buoyancy_offset,))
        for name in ("hook", "center_of_buoyancy"):
            value = getattr(self, name)
            if len(value) != 3 or not all(math.isfinite(float(v)) for v in value):
                raise ParameterError("tank %s must be 3 finite numbers (m, body frame), got %r" % (name, value))
        for name in ("appendage_damping_linear", "appendage_damping_quadratic"):
            value = getattr(self, name)
            if len(value) != 3 or not all(math.isfinite(float(v)) and float(v) >= 0.0 for v in value):
                raise ParameterError("tank %s must be 3 finite numbers >= 0 (body axes), got %r" % (name, value))
        if not (math.isfinite(self.disturbance_torque_std) and 0.0 <= self.disturbance_torque_std
                <= MAX_DISTURBANCE_TORQUE):
            raise ParameterError("tank disturbance_torque_std must be in [0, %g] N m (0: off), got %r"
                                 % (MAX_DISTURBANCE_TORQUE, self.disturbance_torque_std))
        if isinstance(self.disturbance_seed, bool) or not isinstance(self.disturbance_seed, (int, np.integer)) \
                or not 0 <= self.disturbance_seed < 2 ** 32:
            raise ParameterError("tank disturbance_seed must be an integer in [0, 2^32), got %r"
                                 % (self.disturbance_seed,))
        value = self.imu_field_residual
        if len(value) != 3 or not all(math.isfinite(float(v)) for v in value) \
                or math.sqrt(sum(float(v) ** 2 for v in value)) > MAX_IMU_FIELD_RESIDUAL:
            raise ParameterError("tank imu_field_residual must be 3 finite numbers of norm at most %g (the earth's "
                                 "horizontal field), got %r" % (MAX_IMU_FIELD_RESIDUAL, value))

    @property
    def disturbed(self) -> bool:
        """Is the tank not still (a disturbance torque above 0)?"""
        return self.disturbance_torque_std > 0.0

    @property
    def heading_disturbed(self) -> bool:
        """Does the IMU report a heading other than the true one (a residual field at the IMU)?"""
        return any(float(v) != 0.0 for v in self.imu_field_residual)

    def for_trial(self, seed: int) -> "TankParams":
        """This tank for a trial of seed ``seed`` (TrialSpec.seed: the robustness study's seeds, ``--seed``):
        itself for seed 0 or a still tank; otherwise the same tank pushed by another disturbance, its seed
        drawn from (``disturbance_seed``, ``seed``) by numpy's SeedSequence, so that each trial seed is a
        draw of the tank's disturbance and the same pair is the same draw."""
        if seed == 0 or not self.disturbed:
            return self
        state = np.random.SeedSequence([int(self.disturbance_seed), int(seed)]).generate_state(1)
        return replace(self, disturbance_seed=int(state[0]))

    def with_values(self, **values: Any) -> "TankParams":
        """A copy with some fields replaced (identification, tests)."""
        return replace(self, **values)


def _optional_section(data: Mapping[str, Any], name: str) -> Any:
    """An optional section: absent or empty (YAML null, e.g. ``servos:`` with every key removed) means
    all its defaults; anything else is checked by the caller (a number or a list is still refused)."""
    value = data.get(name)
    return {} if value is None else value


def tank_params_from_dict(data: Mapping[str, Any]) -> TankParams:
    """Validate a parsed tank.yaml tree (strict types, no unknown keys, physically possible ranges,
    wider than the identification's plausible bounds) into :class:`TankParams`; ParameterError naming
    the key otherwise."""
    check_keys(data, "", ("effects", "suspension", "hydrostatics", "added_mass", "paw_drag", "servos",
                          "appendage_damping", "paw_wake", "imu", "tether", "disturbance"),
               required=("suspension", "hydrostatics", "added_mass"))
    effects = check_keys(_optional_section(data, "effects"), "effects",
                         ("suspension", "hydrostatics", "torso_added_mass", "paw_added_mass", "drag"))
    rope = check_keys(data["suspension"], "suspension",
                      ("hook", "length", "stiffness", "damping", "torsion_stiffness", "torsion_damping",
                       "torsion_relaxing_stiffness", "torsion_relaxation_time", "block_mass", "block_drag",
                       "block_tie_stiffness", "friction_arm", "friction_angle",
                       "friction_static_ratio", "friction_stribeck_rate", "friction_roll_ratio", "friction_wrap"),
                      required=("hook", "length", "stiffness", "damping"))
    hydro = check_keys(data["hydrostatics"], "hydrostatics",
                       ("net_weight", "center_of_buoyancy", "paw_buoyancy_offset"),
                       required=("net_weight", "center_of_buoyancy"))
    added = check_keys(data["added_mass"], "added_mass", ("scale", "paw_scale"), required=("scale", "paw_scale"))
    paw_drag = check_keys(_optional_section(data, "paw_drag"), "paw_drag", ("scale",))
    servos = check_keys(_optional_section(data, "servos"), "servos",
                        ("speed_scale", "lag_scale", "stall_torque", "dead_band"))
    appendage = check_keys(_optional_section(data, "appendage_damping"), "appendage_damping",
                           ("linear", "quadratic", "wake_fraction", "wake_time_constant"))
    wake = check_keys(_optional_section(data, "paw_wake"), "paw_wake", ("fraction", "time_constant", "body_share"))
    imu = check_keys(_optional_section(data, "imu"), "imu", ("field_residual",))
    tether = check_keys(_optional_section(data, "tether"), "tether",
                        ("stiffness", "relaxing_stiffness", "relaxation_time"))
    disturbance = check_keys(_optional_section(data, "disturbance"), "disturbance",
                             ("torque_std", "correlation_time", "seed"))

    def axes(section: Mapping[str, Any], key: str, high: float) -> Vec3:
        return tuple(vector(section.get(key, [0.0, 0.0, 0.0]), "appendage_damping." + key, 3,
                            0.0, high))  # type: ignore[return-value]

    def switch(name: str) -> bool:
        return boolean(effects.get(name, True), "effects." + name)

    return TankParams(
        suspension=switch("suspension"), hydrostatics=switch("hydrostatics"),
        torso_added_mass=switch("torso_added_mass"), paw_added_mass=switch("paw_added_mass"),
        drag=switch("drag"),
        hook=tuple(vector(rope["hook"], "suspension.hook", 3, -1.0, 1.0)),  # type: ignore[arg-type]
        rope_length=number(rope["length"], "suspension.length", 0.0, 20.0, low_open=True),
        rope_stiffness=number(rope["stiffness"], "suspension.stiffness", 0.0, 1e7, low_open=True),
        rope_damping=number(rope["damping"], "suspension.damping", 0.0, 1e6),
        net_weight=number(hydro["net_weight"], "hydrostatics.net_weight", -100.0, 100.0),
        center_of_buoyancy=tuple(vector(hydro["center_of_buoyancy"], "hydrostatics.center_of_buoyancy",
                                        3, -0.5, 0.5)),  # type: ignore[arg-type]
        paw_buoyancy_offset=number(hydro.get("paw_buoyancy_offset", 0.0), "hydrostatics.paw_buoyancy_offset",
                                   -1.0, 1.0),
        added_mass_scale=number(added["scale"], "added_mass.scale", 0.0, 10.0),
        paw_added_mass_scale=number(added["paw_scale"], "added_mass.paw_scale", 0.0, 10.0),
        paw_drag_scale=number(paw_drag.get("scale", 1.0), "paw_drag.scale", 0.0, 10.0),
        servo_speed_scale=number(servos.get("speed_scale", 1.0), "servos.speed_scale", 0.0, 10.0, low_open=True),
        servo_stall_torque=number(servos.get("stall_torque", 0.0), "servos.stall_torque", 0.0, 100.0),
        servo_lag_scale=number(servos.get("lag_scale", 1.0), "servos.lag_scale", 0.0, 100.0, low_open=True),
        servo_dead_band=number(servos.get("dead_band", 0.0), "servos.dead_band", 0.0, MAX_SERVO_DEAD_BAND),
        appendage_damping_linear=axes(appendage, "linear", 100.0),
        appendage_damping_quadratic=axes(appendage, "quadratic", 100.0),
        rope_torsion_stiffness=number(rope.get("torsion_stiffness", 0.0), "suspension.torsion_stiffness", 0.0, 1e4),
        rope_torsion_damping=number(rope.get("torsion_damping", 0.0), "suspension.torsion_damping", 0.0, 1e4),
        rope_torsion_relaxing_stiffness=number(rope.get("torsion_relaxing_stiffness", 0.0),
                                               "suspension.torsion_relaxing_stiffness", 0.0, 1e4),
        rope_torsion_relaxation_time=number(rope.get("torsion_relaxation_time", 10.0),
                                            "suspension.torsion_relaxation_time", *TIME_CONSTANT_RANGE),
        block_mass=number(rope.get("block_mass", 0.0), "suspension.block_mass", 0.0, 100.0),
        block_drag=number(rope.get("block_drag", 2.0), "suspension.block_drag", 0.0, 1e4),
        block_tie_stiffness=number(rope.get("block_tie_stiffness", 0.0), "suspension.block_tie_stiffness", 0.0,
                                   1000.0),
        hook_friction_arm=number(rope.get("friction_arm", 0.0), "suspension.friction_arm", 0.0, MAX_HOOK_FRICTION_ARM),
        hook_friction_angle=number(rope.get("friction_angle", 0.005), "suspension.friction_angle",
                                   MIN_HOOK_FRICTION_ANGLE, 0.5),
        hook_friction_static_ratio=number(rope.get("friction_static_ratio", 1.0), "suspension.friction_static_ratio",
                                          1.0, MAX_HOOK_FRICTION_STATIC_RATIO),
        hook_friction_stribeck_rate=number(rope.get("friction_stribeck_rate", 0.02),
                                           "suspension.friction_stribeck_rate", *HOOK_FRICTION_STRIBECK_RATE_RANGE),
        hook_friction_roll_ratio=number(rope.get("friction_roll_ratio", 1.0), "suspension.friction_roll_ratio",
                                        *HOOK_FRICTION_ROLL_RATIO_RANGE),
        hook_friction_wrap=number(rope.get("friction_wrap", 0.0), "suspension.friction_wrap", 0.0,
                                  MAX_HOOK_FRICTION_WRAP),
        paw_wake_fraction=number(wake.get("fraction", 0.0), "paw_wake.fraction", 0.0, 0.95),
        paw_wake_time_constant=number(wake.get("time_constant", 0.3), "paw_wake.time_constant", 0.02, 100.0),
        paw_wake_body_share=number(wake.get("body_share", 1.0), "paw_wake.body_share", 0.0, 1.0),
        body_wake_fraction=number(appendage.get("wake_fraction", 0.0), "appendage_damping.wake_fraction", 0.0, 0.95),
        body_wake_time_constant=number(appendage.get("wake_time_constant", 5.0), "appendage_damping.wake_time_constant",
                                       0.05, 1000.0),
        imu_field_residual=tuple(vector(imu.get("field_residual", [0.0, 0.0, 0.0]), "imu.field_residual", 3,
                                        -MAX_IMU_FIELD_RESIDUAL, MAX_IMU_FIELD_RESIDUAL)),  # type: ignore[arg-type]
        tether_stiffness=number(tether.get("stiffness", 0.0), "tether.stiffness", 0.0, MAX_TETHER_STIFFNESS),
        tether_relaxing_stiffness=number(tether.get("relaxing_stiffness", 0.0), "tether.relaxing_stiffness", 0.0,
                                         MAX_TETHER_STIFFNESS),
        tether_relaxation_time=number(tether.get("relaxation_time", 10.0), "tether.relaxation_time",
                                      *TIME_CONSTANT_RANGE),
        disturbance_torque_std=number(disturbance.get("torque_std", 0.0), "disturbance.torque_std", 0.0,
                                      MAX_DISTURBANCE_TORQUE),
        disturbance_correlation_time=number(disturbance.get("correlation_time", 10.0), "disturbance.correlation_time",
                                            *TIME_CONSTANT_RANGE),
        disturbance_seed=integer(disturbance.get("seed", 0), "disturbance.seed", 0, 2 ** 32 - 1))


def load_tank_params(path: Optional[str] = None, tree: Optional[Mapping[str, Any]] = None) -> TankParams:
    """:class:`TankParams` from ``config/tank.yaml`` (or ``path``/``tree``) through the strict loader
    (:mod:`quadruped_common.config`); ParameterError naming the file and the key if malformed."""
    if tree is not None:
        try:
            return tank_params_from_dict(tree)
        except ParameterError as exc:
            raise ParameterError("%s: %s" % (path or "tank parameters", exc)) from None
    return load_config(path, "tank.yaml", tank_params_from_dict)


def hydrostatic_wrench(R: np.ndarray, weight: float, buoyancy: float,
                       center_of_buoyancy: Sequence[float]) -> Tuple[np.ndarray, np.ndarray]:
    """Torso weight W at the centre of mass and buoyancy B at r_cb: (force world (B - W) z_hat,
    moment about the centre of mass r_cb x (B R^T z_hat), body frame)."""
    up_body = np.asarray(R, dtype=float)[2, :]
    return (np.array([0.0, 0.0, buoyancy - weight]),
            hydrodynamics.torso_buoyancy_torque_matrix(buoyancy, center_of_buoyancy) @ up_body)


def torso_ellipsoid(params: RobotParams, scale: float = 1.0) -> Tuple[float, float, float]:
    """Semi-axes (m) of the torso ellipsoid: the body's aspect ratios (``body.dimensions``), scaled so
    its volume is the robot's displaced volume m / rho (neutral buoyancy), times ``scale`` in volume."""
    dims = np.asarray(params.body_dimensions, dtype=float) / 2.0
    volume = scale * params.mass / params.rho
    factor = (volume / (4.0 / 3.0 * math.pi * float(np.prod(dims)))) ** (1.0 / 3.0)
    return tuple(float(v) for v in dims * factor)  # type: ignore[return-value]


class _TankContext(StepContext):
    """A step's inputs plus the tank's per-step constants: the mass-matrix solver and the leg sums
    (:func:`~.tank_dynamics.leg_sums`) of the paw added-mass terms."""

    __slots__ = ("mass_solver", "leg_sums")


class TankModel(FloatingBaseModel):
    """The robot hanging in the test tank: :class:`FloatingBaseModel` plus the effects of
    :class:`TankParams` (module docstring). :meth:`attach` fixes the rope's anchor above the hook."""

    name = "tank"

    def __init__(self, params: RobotParams, tank: TankParams) -> None:
        super().__init__(params)
        self.tank = tank
        self.imu_field_residual = np.array(tank.imu_field_residual, dtype=float) if tank.heading_disturbed else None
        self.drag_constant *= tank.paw_drag_scale
        if not tank.drag:
            self.drag_constant = 0.0
            self._drag = (0.0,) * 8
        self.hook = np.array(tank.hook, dtype=float)
        self.center_of_buoyancy = np.array(tank.center_of_buoyancy, dtype=float)
        # The paws' buoyancy in the water (robot.yaml's estimate plus the tank's offset): the plant's alone,
        # the controller's buoyancy feedforward keeps robot.yaml's value.
        self.net_paw_buoyancy = float(params.paw_net_buoyancy) + tank.paw_buoyancy_offset
        self.torso_weight = (params.mass - 4.0 * params.paw_mass) * params.gravity
        self.torso_buoyancy = self.torso_weight - tank.net_weight
        if tank.hydrostatics:
            # The torso's buoyancy moment joins the paw buoyancy torque in each step's U R^T z_hat
            # (StepContext): the plant's restoring matrix, B hat(r_cb).
            self._restoring_matrix = hydrodynamics.torso_buoyancy_torque_matrix(self.torso_buoyancy,
                                                                                 self.center_of_buoyancy)
            self._restoring = as_mat3(self._restoring_matrix)
        rigid = np.zeros((6, 6))
        rigid[:3, :3] = self.mass * np.eye(3)
        rigid[3:, 3:] = self.inertia
        added = np.zeros((6, 6))
        if tank.torso_added_mass and tank.added_mass_scale > 0.0:
            added = ellipsoid_added_mass(*torso_ellipsoid(params, tank.added_mass_scale), rho=params.rho)
        self.torso_added_mass = added
        #: M_RB + M_A: its Kirchhoff terms are the gyroscopic and added-mass Coriolis terms.
        self.body_mass_matrix = rigid + added
        # A flooded paw entrains the water of its whole sphere: rho V / 2 with the outer volume pi d^3 / 6.
        outer_volume = math.pi * params.paw_diameter ** 3 / 6.0
        self.paw_added_mass = (tank.paw_added_mass_scale * sphere_added_mass(outer_volume, params.rho)
                               if tank.paw_added_mass else 0.0)
        #: the rope's upper end, position and velocity (world; :func:`~.tank_dynamics.floating_block_update`),
        #: and where the block rests on its tie: plant state, set by :meth:`attach`
        self.block = np.zeros(6)
        self.block_rest = np.zeros(3)
        self._anchor: Tuple[float, ...] = (0.0,) * 6
        self.untwisted = np.eye(3)
        #: The rope's whole twist (rad) about the world vertical since :meth:`attach`, every turn counted
        #: (:func:`~.tank_dynamics.whole_twist`), at the attitude :attr:`twist_rotation` (row-major): plant
        #: state, 0 at the attitude of attach, carried to each step's end. A step counts it again from the
        #: state it is handed (which may differ from the last end by less than half a turn). Counted only where
        #: something reads it (the rope's torsion, the wound tether); 0 otherwise.
        self.twist = 0.0
        self.twist_rotation: Tuple[float, ...] = tuple(self.untwisted.ravel().tolist())
        #: The torsion's relaxed twist s (rad; :func:`~.tank_dynamics.twist_relaxation_update`): plant state, 0 at
        #: :meth:`attach`, carried to each step's end where the relaxing branch is on.
        self.twist_relaxed = 0.0
        #: Whether the torsion's relaxing branch is on (the batch asks its constants the same).
        self.relaxes_twist = bool(tank.suspension) and tank.rope_torsion_relaxing_stiffness > 0.0
        self._body_m = tuple(self.body_mass_matrix.ravel().tolist())
        #: Each paw's wake velocity (body axes, m/s; :func:`~.tank_dynamics.paw_wake_update`): plant state
        #: beside the rigid body's, zero at :meth:`attach`.
        self.wake = np.zeros((4, 3))
        #: The rate of the water turning with the body (world axes, rad/s; :func:`~.tank_dynamics.body_wake_update`):
        #: plant state, zero at :meth:`attach`.
        self.body_wake = np.zeros(3)
        #: The friction torque the hook's tie exerts on the rope (body axes, N m; the body feels its opposite;
        #: :func:`~.tank_dynamics.hook_friction_update`): plant state, zero at :meth:`attach`.
        self.hook_friction = np.zeros(3)
        #: The tether's relaxed tilt s (world axes, rad; :func:`~.tank_dynamics.tether_relaxation_update`): plant
        #: state, the tilt of the attitude of :meth:`attach`, carried to each step's end.
        self.tether_relaxed: Tuple[float, float, float] = (0.0, 0.0, 0.0)
        #: Whether this plant's tether bends (either stiffness above 0; the batch asks its constants the same).
        self.bends_tether = tank.tether_stiffness > 0.0 or tank.tether_relaxing_stiffness > 0.0
        #: The tank's disturbance torque (N m, world axes; :func:`~.tank_dynamics.disturbance_update`) held over
        #: the next step: drawn at :meth:`attach`, stepped after each step; zeros while the tank is still.
        self.disturbance = np.zeros(3)
        self._disturbance_rng: Optional[np.random.Generator] = None
        self._disturbance_draws = np.zeros((0, 3))
        self._disturbance_row = 0
        self._drag_feet = np.zeros((4, 6))
        #: The torque each joint felt from its paw's drag at the last step's start (4 x 3, N m;
        #: :func:`~.tank_dynamics.paw_joint_loads`) when the loaded-servo effect is on, else None; the
        #: simulator hands it to the servo model for its next step.
        self.joint_loads: Optional[np.ndarray] = None
        geometry = _geometry(params)
        self._frames = np.array(geometry[1], dtype=float)
        self._five_bar = tuple(float(x) for x in geometry[2:9])
        if np.any(self.body_mass_matrix[:3, :3] != np.diag(np.diag(self.body_mass_matrix[:3, :3]))) \
                or np.any(self.body_mass_matrix[:3, 3:] != 0.0):
            raise ValueError("the torso's translational mass block must be diagonal and uncoupled (mass matrix "
                             "about the centre of mass of a symmetric ellipsoid)")
        self._constants = self._build_constants()
        # tau_c of the hook friction (N m; 0: off) and the hook as the friction update takes it
        self._friction_limit = self.hook_friction_limit()
        self._hook = tuple(float(x) for x in tank.hook)
        # Only the rope's torsion (its spring reads the twist, spring and damper its reference attitude) and
        # the wound tether read the whole twist: without them it is not counted.
        self._wound = self._friction_limit > 0.0 and tank.hook_friction_wrap > 0.0
        #: Whether this plant carries :attr:`twist` (the batch reads it too, one source for both plants).
        self.counts_twist = bool(tank.suspension) and (tank.rope_torsion_stiffness > 0.0
                                                       or tank.rope_torsion_damping > 0.0 or self.relaxes_twist
                                                       or self._wound)
        # the step and the wound tether's turn check_step_stability has covered (s, rad)
        self._checked_step = _MAX_STEP
        self.checked_turn = math.pi
        self.check_step_stability()

    def check_step(self, dt: float) -> None:
        """:meth:`check_step_stability` for a step of ``dt`` longer than any checked so far (the control
        period at construction): a plant stepped at 20 Hz must resolve its stiff terms at 50 ms."""
        if dt > self._checked_step:
            self.check_step_stability(dt)
            self._checked_step = dt

    def check_turn(self, twist: float) -> None:
        """:meth:`check_step_stability` for the wound tether's grip at a turn of ``twist`` rad past any turn
        checked so far (half a turn at construction): the capstan law grows the tie's presliding stiffness
        as exp(mu_w |phi|), and the whole twist counts every turn. Checked a quarter turn ahead, so that a
        growing turn is checked once a quarter turn, not every step; :attr:`checked_turn` is the turn covered.
        Its refusal is a :class:`TurnUnresolved`."""
        if abs(twist) > self.checked_turn:
            turn = abs(twist) + 0.5 * math.pi
            try:
                self.check_step_stability(self._checked_step, turn)
            except ParameterError as exc:
                raise TurnUnresolved(str(exc)) from None
            self.checked_turn = turn

    def check_step_stability(self, dt: float = _MAX_STEP, turn: Optional[float] = None) -> None:
        """ParameterError, naming the tank.yaml keys, unless a step of ``dt`` (default the 100 Hz control
        period) resolves every stiff term of these parameters. Each is a rate of the linearised plant
        against the body's own mass and inertia (the torso's, with added mass, without the paws': the
        smaller, so the stricter):
        - in the RK4 step, |lambda| dt <= 2.5: the appendage damping c / I and, at 1 rad/s, 2 k |w| / I per axis; the
          rope's torsion c_t / I_zz and sqrt((k_t + k_r) / I_zz) (k_r its relaxing branch, at once); the rope's damping
          c / M_z and stiffness sqrt(k / M_z), and both again through the hook's arm h about the tilts (c h^2 / I,
          sqrt(k h^2 / I));
        - the hook friction's presliding spring, held over the step (:func:`~.tank_dynamics.hook_friction_update`
          takes the rate at the step's start, so body and tie advance as symplectic Euler, stable below 4):
          K dt^2 / I <= 1 at its stiffest, K = tau_c max(1, tau_s / tau_c) max(1, m_x) exp(mu_w phi) / theta_p,
          phi the tether's turn (``turn``, default :attr:`checked_turn`: half a turn until :meth:`check_turn`);
        - the floating block: :func:`~.tank_dynamics.floating_block_update` keeps the rope's elastic pull
          explicit, stable while (k + k_g) dt^2 / m_b < 4;
        - the torso's buoyancy positive: a net weight at or above the torso's weight leaves none.
        The tether's bend needs no check: at its largest (2 N m/rad per branch, MAX_TETHER_STIFFNESS) its
        sqrt(4 / I) dt is under 0.1 at 10 ms (0.4 at 50 ms), far inside RK4's stability.
        Past these the plant rings or blows up without telling (a tie that pumps energy into the swing,
        a rope that chatters), so the set is refused instead."""
        tank, limit = self.tank, _RK4_LIMIT / dt
        turn = self.checked_turn if turn is None else turn
        inertia = np.diag(self.body_mass_matrix[3:, 3:])
        tilt_inertia, heave_mass = float(min(inertia[0], inertia[1])), float(self.body_mass_matrix[2, 2])
        problems = []
        for axis, name in enumerate("xyz"):
            if tank.appendage_damping_linear[axis] / inertia[axis] > limit:
                problems.append("appendage_damping.linear[%d] (%s) = %g N m s/rad > %.3g" % (
                    axis, name, tank.appendage_damping_linear[axis], limit * inertia[axis]))
            if 2.0 * tank.appendage_damping_quadratic[axis] * _CHECK_RATE / inertia[axis] > limit:
                problems.append("appendage_damping.quadratic[%d] (%s) = %g N m s^2/rad^2 > %.3g" % (
                    axis, name, tank.appendage_damping_quadratic[axis], limit * inertia[axis] / (2.0 * _CHECK_RATE)))
        if tank.suspension:
            arm2 = float(np.dot(self.hook, self.hook))
            if tank.rope_torsion_damping / inertia[2] > limit:
                problems.append("suspension.torsion_damping = %g N m s/rad > %.3g" % (
                    tank.rope_torsion_damping, limit * inertia[2]))
            twist_stiffness = tank.rope_torsion_stiffness + tank.rope_torsion_relaxing_stiffness
            if twist_stiffness / inertia[2] > limit ** 2:
                problems.append("suspension.torsion_stiffness + torsion_relaxing_stiffness = %g N m/rad > %.3g" % (
                    twist_stiffness, limit ** 2 * inertia[2]))
            rope_mass = min(heave_mass, tilt_inertia / arm2 if arm2 > 0.0 else math.inf)  # at the hook
            if tank.rope_damping / rope_mass > limit:
                problems.append("suspension.damping = %g N s/m > %.3g" % (tank.rope_damping, limit * rope_mass))
            if tank.rope_stiffness / rope_mass > limit ** 2:
                problems.append("suspension.stiffness = %g N/m > %.3g" % (tank.rope_stiffness, limit ** 2 * rope_mass))
            if self._friction_limit > 0.0:
                stiffest = (self._friction_limit * max(1.0, tank.hook_friction_static_ratio)
                            * max(1.0, tank.hook_friction_roll_ratio) * math.exp(tank.hook_friction_wrap * turn)
                            / tank.hook_friction_angle)
                if stiffest * dt * dt / tilt_inertia > 1.0:
                    problems.append("the hook friction's presliding stiffness %.3g N m/rad > %.3g (suspension."
                                    "friction_arm, friction_angle, friction_static_ratio, friction_roll_ratio, "
                                    "friction_wrap and the rope's tension)" % (stiffest, tilt_inertia / (dt * dt)))
        pull = tank.rope_stiffness + tank.block_tie_stiffness
        if tank.suspension and tank.block_mass > 0.0 and pull * dt * dt >= 4.0 * tank.block_mass:
            problems.append("suspension.block_mass = %g kg <= (stiffness + block_tie_stiffness) * %g s^2 / 4 = %.3g"
                            % (tank.block_mass, dt * dt, pull * dt * dt / 4.0))
        if tank.hydrostatics and self.torso_buoyancy <= 0.0:
            problems.append("hydrostatics.net_weight = %g N leaves the torso (%.3g N) no buoyancy"
                            % (tank.net_weight, self.torso_weight))
        if problems:
            raise ParameterError("tank parameters a %g s step cannot resolve: %s" % (dt, "; ".join(problems)))

    # ---- set-up ------------------------------------------------------------------------------

    def static_rope_tension(self) -> float:
        """Rope tension at rest, hanging: torso net weight plus the paws' net weight (N)."""
        weight = self.tank.net_weight if self.tank.hydrostatics else 0.0
        return max(0.0, weight - 4.0 * self.net_paw_buoyancy)

    def hook_friction_limit(self) -> float:
        """The hook friction's Coulomb torque tau_c = mu r T_0 (N m): ``hook_friction_arm`` times the rope's
        static tension; 0 without the suspension or the effect."""
        if not self.tank.suspension:
            return 0.0
        return self.tank.hook_friction_arm * self.static_rope_tension()

    def attach(self, state: RigidBodyState) -> None:
        """Place the anchor straight above the hook of ``state``, the rope stretched by its static load."""
        self.joint_loads = None
        hook = state.position + state.rotation @ self.hook
        stretch = self.static_rope_tension() / self.tank.rope_stiffness
        self.block_rest = hook + np.array([0.0, 0.0, self.tank.rope_length + stretch])
        self.block = np.concatenate((self.block_rest, np.zeros(3)))  # the block at rest
        self._anchor = tuple(self.block.tolist())
        # The rope hangs untwisted in this attitude: its twist (rope torsion, wound tether) counts from here.
        self.untwisted = np.array(state.rotation, dtype=float)
        self.twist = 0.0
        self.twist_rotation = tuple(self.untwisted.ravel().tolist())
        self.twist_relaxed = 0.0  # the rope and the tether hang untwisted and relaxed
        self.wake[:] = 0.0  # still water
        self.body_wake[:] = 0.0
        self.hook_friction[:] = 0.0  # the tie unloaded
        self.tether_relaxed = tilt_vector(self.untwisted.ravel().tolist())  # the tether hangs relaxed
        if self.tank.disturbed:  # the same disturbance in every trial of this tank: its generator restarts
            self._disturbance_rng = np.random.default_rng([self.tank.disturbance_seed, DISTURBANCE_STREAM])
            self._disturbance_draws, self._disturbance_row = np.zeros((0, 3)), 0
            self.disturbance = self.tank.disturbance_torque_std * self.disturbance_noise()  # a stationary start
        self._constants = self._build_constants()

    def disturbance_noise_block(self) -> np.ndarray:
        """The next :data:`DISTURBANCE_BLOCK` steps' standard normal draws of the disturbance ((B, 3), world
        axes) from this tank's generator (restarted by :meth:`attach`): the batch takes them a block at a time,
        :meth:`disturbance_noise` a row at a time, the same numbers."""
        if self._disturbance_rng is None:
            raise RuntimeError("the tank is still (disturbance_torque_std 0) or not attached: no disturbance to draw")
        return self._disturbance_rng.standard_normal((DISTURBANCE_BLOCK, 3))

    def _untaken_disturbance_draws(self) -> None:
        """A new block of draws once every row of the current one is taken."""
        if self._disturbance_row >= len(self._disturbance_draws):
            self._disturbance_draws, self._disturbance_row = self.disturbance_noise_block(), 0

    def disturbance_noise(self) -> np.ndarray:
        """The next step's three standard normal draws of the disturbance (world axes)."""
        self._untaken_disturbance_draws()
        self._disturbance_row += 1
        return self._disturbance_draws[self._disturbance_row - 1]

    def take_disturbance_noise(self) -> np.ndarray:
        """Every draw :meth:`disturbance_noise` would give before it draws another block ((K, 3); a whole new
        block when none is left), taken: the batch steps its trials on them."""
        self._untaken_disturbance_draws()
        rest = self._disturbance_draws[self._disturbance_row:]
        self._disturbance_row = len(self._disturbance_draws)
        return rest

    def _step_disturbance(self, dt: float) -> None:
        """:func:`~.tank_dynamics.disturbance_update` over a step of ``dt`` s: the torque the next step holds."""
        decay, spread = disturbance_coefficients(self.tank.disturbance_torque_std,
                                                 self.tank.disturbance_correlation_time, dt)
        self.disturbance = disturbance_update(self.disturbance, decay, spread, self.disturbance_noise())

    @property
    def anchor(self) -> np.ndarray:
        """The rope's upper end (world, m): fixed above the hook of the last :meth:`attach`, unless the
        floating block moves it (a view of :attr:`block`)."""
        return self.block[:3]

    def mass_matrix(self, foot_positions: Sequence[Sequence[float]]) -> np.ndarray:
        """M = M_RB + M_A + sum_i M_paw(r_i) (6x6, body axes about the centre of mass)."""
        M = self.body_mass_matrix.copy()
        if self.paw_added_mass > 0.0:
            for r in foot_positions:
                M += point_mass_matrix(self.paw_added_mass, r[:3])
        return M

    def constants(self) -> TankConstants:
        """This plant's :data:`~.tank_dynamics.TankConstants` as they stand (the anchor and the rope's twist
        set by :meth:`attach` and carried by each step)."""
        return self._constants

    def _build_constants(self) -> TankConstants:
        tank = self.tank
        return (self.drag_constant, self._drag,
                (self.torso_buoyancy - self.torso_weight) if tank.hydrostatics else 0.0, bool(tank.suspension),
                tuple(float(x) for x in tank.hook), self._anchor,
                (float(tank.rope_length), float(tank.rope_stiffness), float(tank.rope_damping)),
                (float(tank.rope_torsion_stiffness), float(tank.rope_torsion_damping), self.twist,
                 float(tank.rope_torsion_relaxing_stiffness), float(tank.rope_torsion_relaxation_time),
                 self.twist_relaxed),
                self.twist_rotation,
                tuple(float(x) for x in tank.appendage_damping_linear),
                tuple(float(x) for x in tank.appendage_damping_quadratic), self._body_m, float(self.paw_added_mass),
                float(tank.paw_wake_fraction), float(tank.paw_wake_time_constant), float(tank.paw_wake_body_share),
                float(tank.body_wake_fraction), float(tank.body_wake_time_constant),
                (float(tank.tether_stiffness), float(tank.tether_relaxing_stiffness),
                 float(tank.tether_relaxation_time)) + tuple(self.tether_relaxed))

    def _mass_solver(self, sr: Sequence[float], S: Sequence[float]) -> Tuple[Tuple[float, ...], ...]:
        """:func:`~.tank_dynamics.mass_solver` of this plant (ValueError if the matrix is singular)."""
        solver = mass_solver(self._body_m, self.paw_added_mass, sr, S)
        if not all(math.isfinite(x) for x in solver[2]):
            raise ValueError("singular mass matrix (legs at %r)" % (tuple(sr),))
        return solver

    # ---- equations of motion -------------------------------------------------------------------

    def generalized_forces(self, context: "_TankContext", p: Sequence[float], v: Sequence[float], R: Mat3,
                           w: Sequence[float]) -> Tuple[float, ...]:
        """Right-hand side of eq. (tank) (:func:`~.tank_dynamics.tank_forces`)."""
        W = self.body_wake  # the water's rate in body axes, R^T W
        water = (R[0] * W[0] + R[3] * W[1] + R[6] * W[2], R[1] * W[0] + R[4] * W[1] + R[7] * W[2],
                 R[2] * W[0] + R[5] * W[1] + R[8] * W[2])
        held = (-float(self.hook_friction[0]), -float(self.hook_friction[1]), -float(self.hook_friction[2]))
        return tank_forces(self._constants, context.feet, self._wake_rows(context), water, held, context.lift,
                           context.up_torque, context.leg_sums, p[0], p[1], p[2], v[0], v[1], v[2], R, w[0], w[1], w[2])

    def _wake_rows(self, context: "_TankContext") -> Sequence[Sequence[float]]:
        """The rows the paw drag sees with the current wake (the legs' rows without a wake)."""
        if self.tank.paw_wake_fraction <= 0.0 and not self.wake.any():
            return context.feet
        feet = np.asarray(context.feet, dtype=float)
        return tuple(map(tuple, np.concatenate((feet[:, :3], feet[:, 3:] - self.wake), axis=1).tolist()))

    @staticmethod
    def _body_motion(state: RigidBodyState) -> Tuple[float, ...]:
        """(b, omega) of ``state`` as six floats, b = R^T v in the batch's order of operations (bit for bit
        with TankPlantBatch): what the paws' wake and the joint loads see at a step's start."""
        r0, r1, r2, r3, r4, r5, r6, r7, r8 = state.rotation.ravel().tolist()
        vx, vy, vz = state.velocity.tolist()
        wx, wy, wz = state.omega.tolist()
        return r0 * vx + r3 * vy + r6 * vz, r1 * vx + r4 * vy + r7 * vz, r2 * vx + r5 * vy + r8 * vz, wx, wy, wz

    def _advance_wake(self, motion: Tuple[float, ...], dt: float, context: "_TankContext") -> Sequence[Sequence[float]]:
        """:func:`~.tank_dynamics.paw_wake_update` over this step (``motion``: :meth:`_body_motion` at its
        start): the drag rows."""
        if self.tank.paw_wake_fraction <= 0.0:
            return context.feet
        paw_wake_update(context.feet, self.wake, self.tank.paw_wake_fraction, self.tank.paw_wake_time_constant,
                        self.tank.paw_wake_body_share, *motion, dt, self._drag_feet)
        return tuple(map(tuple, self._drag_feet.tolist()))

    def _step_context(self, q: Any, q_dot: Any) -> "_TankContext":
        flat = leg_kinematics_flat(q.tolist() if isinstance(q, np.ndarray) else q,
                                    q_dot.tolist() if isinstance(q_dot, np.ndarray) else q_dot, self.params)
        context = _TankContext(flat, self.net_paw_buoyancy, self._restoring)
        context.leg_sums = leg_sums(context.feet)
        context.mass_solver = self._mass_solver(context.leg_sums[0], context.leg_sums[2])
        return context

    def _update_joint_loads(self, motion: Tuple[float, ...], drag_feet: Sequence[Sequence[float]], q: Any) -> None:
        """:attr:`joint_loads` at a step's start (``motion``: :meth:`_body_motion`), the legs at ``q`` (the
        held joints), the paws seen through the rows ``drag_feet`` that the step's drag sees."""
        loads = np.zeros((4, 3))
        paw_joint_loads(np.asarray(q, dtype=float), self._frames, self._five_bar,
                        np.asarray(drag_feet, dtype=float), self._constants[_AT["drag_constant"]], *motion, loads)
        self.joint_loads = loads

    def _rk4_tank(self, state: RigidBodyState, dt: float, context: "_TankContext", q: Any = None) -> RigidBodyState:
        R0 = tuple(state.rotation.ravel().tolist())
        y0 = tuple(state.position.tolist() + state.velocity.tolist() + [0.0, 0.0, 0.0] + state.omega.tolist())
        if self.counts_twist:
            self._count_twist(R0)  # the state handed in need not be the one this plant last stepped to
        try:
            loaded = self.tank.servo_stall_torque > 0.0 and q is not None
            motion = self._body_motion(state) if loaded or self.tank.paw_wake_fraction > 0.0 else ()
            drag_feet = self._advance_wake(motion, dt, context)
            if loaded:
                self._update_joint_loads(motion, drag_feet, q)
            if self.tank.block_mass > 0.0 and self.tank.suspension:
                self._advance_block(state, R0, dt)
            water = _STILL
            if self.tank.body_wake_fraction > 0.0:
                water = body_wake_update(self.body_wake, self.tank.body_wake_fraction,
                                         self.tank.body_wake_time_constant, R0, y0[9], y0[10], y0[11], dt)
            held = _STILL
            if self._friction_limit > 0.0:
                tank = self.tank
                limit = wound_friction_limit(self._friction_limit, tank.hook_friction_wrap, self.twist)
                held = hook_friction_update(self.hook_friction, limit, tank.hook_friction_angle,
                                            tank.hook_friction_static_ratio, tank.hook_friction_stribeck_rate,
                                            tank.hook_friction_roll_ratio, y0[0:3], y0[3:6], R0, y0[9:12],
                                            self._hook, self._anchor, tank.rope_length, dt)
            if self.tank.disturbed:  # held over the step in body axes at its start, beside the hook's friction
                bx, by, bz = world_to_body(R0, *self.disturbance.tolist())
                held = (held[0] + bx, held[1] + by, held[2] + bz)
            y = tank_rk4(self._constants, context.feet, drag_feet, water, held, context.lift, context.up_torque,
                         context.leg_sums, context.mass_solver, R0, y0, dt)
        except (ValueError, OverflowError) as exc:  # math.sin(inf) etc. once the state has blown up
            raise diverged(dt, state, str(exc)) from None
        end = chart_step_end(R0, y[0:6], y[6:9], y[9:12], dt, state)
        if self.counts_twist:
            self._count_twist(end.rotation.ravel().tolist())
        if self.relaxes_twist:
            self._relax_twist(dt)
        if self.bends_tether:
            self._relax_tether(end.rotation.ravel().tolist(), dt)
        if self.tank.disturbed:
            self._step_disturbance(dt)
        return end

    def _relax_tether(self, rotation: Sequence[float], dt: float) -> None:
        """:func:`~.tank_dynamics.tether_relaxation_update` over a step that ended at ``rotation`` (row-major):
        the relaxed tilt moves, and the constants carry it."""
        k = self._constants
        at = _AT["tether"]
        self.tether_relaxed = tether_relaxation_update(rotation, k[at], dt)
        self._constants = k[:at] + (k[at][:3] + tuple(self.tether_relaxed),) + k[at + 1:]

    def _relax_twist(self, dt: float) -> None:
        """:func:`~.tank_dynamics.twist_relaxation_update` over a step whose end :attr:`twist` has been carried to:
        the relaxed twist moves, and the constants carry it."""
        k = self._constants
        at = _AT["torsion"]
        self.twist_relaxed = twist_relaxation_update(self.twist, self.twist_relaxed,
                                                     self.tank.rope_torsion_relaxation_time, dt)
        self._constants = k[:at] + (k[at][:5] + (self.twist_relaxed,),) + k[at + 1:]

    def _count_twist(self, rotation: Sequence[float]) -> None:
        """Carry :attr:`twist` to ``rotation`` (row-major; a step's start or end: the batch counts at the same
        two points, so the two plants agree to the bit) and into the constants' torsion fields. At a step's
        start it adds exactly 0 when the state is the one the last step ended at."""
        self.twist = whole_twist(rotation, self.twist_rotation, self.twist)
        self.twist_rotation = tuple(rotation)
        if self._wound and abs(self.twist) > self.checked_turn:
            self.check_turn(self.twist)
        k = self._constants
        at = _AT["torsion"]  # the torsion's (stiffness, damping, twist, ...), then the attitude the twist belongs to
        self._constants = k[:at] + (k[at][:2] + (self.twist,) + k[at][3:], self.twist_rotation) + k[at + 2:]

    def _advance_block(self, state: RigidBodyState, R0: Tuple[float, ...], dt: float) -> None:
        """:func:`~.tank_dynamics.floating_block_update` over this step (the body state of its start):
        the block moves, and the constants carry its new position and velocity."""
        tank = self.tank
        floating_block_update(self.block, self.block_rest, state.position, state.velocity, R0, state.omega,
                              self.hook, (tank.rope_length, tank.rope_stiffness, tank.rope_damping), tank.block_mass,
                              tank.block_drag, tank.block_tie_stiffness, dt)
        self._anchor = tuple(self.block.tolist())
        self._constants = self._build_constants()

    # The paper model's continuous-time interface (its force breakdown, right-hand side, joint-trajectory
    # step and generic chart RK4) knows nothing of the rope, the hydrostatics, the added mass or any effect
    # of TankParams: inherited, it would answer for another plant. The tank's own are held_wrench and step.
    def wrench(self, state: RigidBodyState, q: Any, q_dot: Any) -> Any:
        raise NotImplementedError(_PAPER_ONLY % "wrench")

    def derivative(self, state: RigidBodyState, q: Any, q_dot: Any) -> Any:
        raise NotImplementedError(_PAPER_ONLY % "derivative")

    def step_continuous(self, state: RigidBodyState, t: float, dt: float, joint_trajectory: Any) -> RigidBodyState:
        raise NotImplementedError(_PAPER_ONLY % "step_continuous")

    def _chart_derivative(self, context: Any, R0: Mat3, y: Sequence[float]) -> Tuple[float, ...]:
        raise NotImplementedError(_PAPER_ONLY % "_chart_derivative")

    def step(self, state: RigidBodyState, q: Any, q_dot: Any, dt: float) -> RigidBodyState:
        dt = check_dt(dt)
        self.check_step(dt)
        state = state.validate()
        q = joint_array(q, "q")
        context = self._step_context(q, joint_array(q_dot, "q_dot"))
        return self._rk4_tank(state, dt, context, q)

    def step_trusted(self, state: RigidBodyState, q: Any, q_dot: Any, dt: float) -> RigidBodyState:
        if dt > self._checked_step:
            self.check_step(dt)
        return self._rk4_tank(state, dt, self._step_context(q, q_dot), q)

    def restoring_torque(self, rotation: Any, q: Any) -> np.ndarray:
        """The plant's moment about the centre of mass (N m, body axes) on the robot at rest in attitude
        ``rotation`` (R_B^W) with its legs still at ``q`` (12 or 4 x 3 joint angles), the rope hanging
        straight above the hook: eq. (tank)'s right-hand side at rest, where only the hydrostatics (torso
        buoyancy at the centre of buoyancy, paw buoyancy at the feet) and the rope's static tension at
        the hook act. A static pull that holds the robot at that attitude applies its opposite. Re-attaches
        the rope to ``rotation`` (:meth:`attach`): call it on a plant that is not being stepped."""
        state = RigidBodyState(rotation=np.asarray(rotation, dtype=float)).validate()
        q = joint_array(q, "q")
        self.attach(state)
        return self.held_wrench(state, q, np.zeros_like(q))[3:6]

    def held_wrench(self, state: RigidBodyState, q: Any, q_dot: Any) -> np.ndarray:
        """eq. (tank)'s right-hand side (force in N, then torque in N m; body axes, about the centre of mass)
        on the body held at rest at ``state``'s position and attitude, its legs at ``q`` moving at
        ``q_dot`` (12 or 4 x 3; the joints as held over a step), the paws' wake and the rope's anchor as
        they stand: what a clamp that holds the body still takes up, less the reaction to the legs'
        accelerations through the mass matrix (zero on average over a periodic stroke). The torque the
        strokes deliver on a bench (:mod:`quadruped_control.sim.plants.clamped`)."""
        context = self._step_context(joint_array(q, "q"), joint_array(q_dot, "q_dot"))
        forces = self.generalized_forces(context, tuple(state.position.tolist()), (0.0, 0.0, 0.0),
                                         as_mat3(state.rotation), (0.0, 0.0, 0.0))
        return np.array(forces, dtype=float)

    # ---- energy ------------------------------------------------------------------------------

    def kinetic_energy(self, state: RigidBodyState, q: Any = None) -> float:
        """1/2 nu^T M nu with the legs at ``q`` (nominal if None is not allowed: pass the pose)."""
        legs = self.leg_input(q, np.zeros((4, 3)))
        nu = np.concatenate((state.rotation.T @ state.velocity, state.omega))
        return 0.5 * float(nu @ self.mass_matrix(legs.foot_positions.tolist()) @ nu)

    def potential_energy(self, state: RigidBodyState, q: Any) -> float:
        """Paw buoyancy + torso weight and buoyancy + elastic rope energy (its twist's relaxing branch against
        the relaxed twist as it stands) + the tether's bend (both branches, against the relaxed tilt as it
        stands), J. The rope's twist is counted from :attr:`twist`: call it on
        the state the plant last stepped to (or one within half a turn)."""
        energy = super().potential_energy(state, q)
        R, p = state.rotation, state.position
        if self.tank.hydrostatics:
            energy += self.torso_weight * p[2] - self.torso_buoyancy * (p[2] + float(R[2, :] @ self.center_of_buoyancy))
        if self.tank.suspension:
            stretch = float(np.linalg.norm(self.anchor - (p + R @ self.hook))) - self.tank.rope_length
            if stretch > 0.0:
                energy += 0.5 * self.tank.rope_stiffness * stretch * stretch
            twist = whole_twist(R.ravel().tolist(), self.twist_rotation, self.twist)
            energy += 0.5 * self.tank.rope_torsion_stiffness * twist * twist
            if self.relaxes_twist:
                energy += 0.5 * self.tank.rope_torsion_relaxing_stiffness * (twist - self.twist_relaxed) ** 2
        if self.bends_tether:
            theta = np.array(tilt_vector(R.ravel().tolist()))
            bent = theta - np.array(self.tether_relaxed)
            energy += 0.5 * (self.tank.tether_stiffness * float(theta @ theta)
                             + self.tank.tether_relaxing_stiffness * float(bent @ bent))
        return energy
