"""The test-tank plant: the paper's model plus the tank the experiments ran in (:class:`TankModel`).

Contract: ``TankModel(robot, tank)`` is a :class:`~quadruped_control.sim.plants.paper.FloatingBaseModel` whose
``step`` integrates eq. (tank) (body axes about the centre of mass: added mass, the rope from the hook, torso
weight and buoyancy at separate centres, and the candidate effects of :class:`~.tank_params.TankParams`, each off
by default) with :func:`~.tank_dynamics.tank_rk4`, the same function the batch runs
(:mod:`.tank_batch`). With every effect off it is the paper's eq. (trans), (rot). It refuses, naming the
tank.yaml keys, a set a step cannot resolve (:meth:`TankModel.check_step_stability`). The paper model's
continuous-time methods (``wrench``, ``derivative``, ``step_continuous``) raise NotImplementedError here.
The equations, each effect's physics and its sources: docs/tank_model.md.
"""
from __future__ import annotations

import math
from typing import Any, Optional, Sequence, Tuple

import numpy as np

from quadruped_common.config import ParameterError
from quadruped_control.model import hydrodynamics
from quadruped_control.model.kinematics import _geometry, leg_kinematics_rows
from quadruped_control.model.params import RobotParams
from quadruped_control.sim.plants.added_mass import ellipsoid_added_mass, point_mass_matrix, sphere_added_mass
from quadruped_control.sim.plants.paper import FloatingBaseModel
from quadruped_control.sim.plants.rigid_body import (Mat3, RigidBodyState, StepContext, as_mat3, chart_step_end,
                                                     check_dt, diverged, joint_array)
from quadruped_control.sim.plants.tank_dynamics import TANK_CONSTANT_AT as _AT
from quadruped_control.sim.plants.tank_dynamics import (TankConstants, body_wake_update, disturbance_coefficients,
                                                        disturbance_update, floating_block_update, hook_friction_update,
                                                        leg_sums, mass_solver, paw_joint_loads, paw_wake_update,
                                                        tank_forces, tank_rk4, tether_relaxation_update, tilt_vector,
                                                        twist_relaxation_update, whole_twist, world_to_body,
                                                        wound_friction_limit)
from quadruped_control.sim.plants.tank_params import TankParams
from quadruped_control.sim.plants.tank_stability import MAX_STEP, unresolved_terms

__all__ = ["DISTURBANCE_BLOCK", "DISTURBANCE_STREAM", "TankModel", "TurnUnresolved", "VALIDITY_NOTE",
           "hydrostatic_wrench", "torso_ellipsoid"]

#: What the tank plant can tell a roboticist today, said wherever a user runs it (the simulate command and its
#: paper-sim, robustness and schemes studies with --plant tank, the Table-1 study's report, sim.launch
#: plant:=tank), so that no result made on it is read as the robot's. The figures
#: behind it are in docs/identification.md, "Where it stands": no model predicts the settling of experiments
#: held out of its fit reliably (one draw of one fit met the targets, at the edge; the same model's other
#: draws did not).
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


#: What the paper model's continuous-time methods say on the tank plant.
_PAPER_ONLY = ("TankModel.%s is the paper model's and leaves out the tank's rope, hydrostatics, added mass and "
               "candidate effects; use step (tank_dynamics.tank_rk4) or held_wrench")

#: The water's rate without the body wake: the appendage damping sees omega itself.
_STILL: Vec3 = (0.0, 0.0, 0.0)

#: The stream of a tank's random generator its disturbance draws from, beside its seed: apart from the IMU
#: noise's stream, default_rng(seed), so that the two are independent for the same seed.
DISTURBANCE_STREAM = 0x7A4B

#: The disturbance's standard normal draws come in blocks of this many steps (3 per step): the batch takes
#: each trial's block at once, the per-trial plant one row per step, the same numbers either way.
DISTURBANCE_BLOCK = 1024

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
        self._frames = np.array(geometry.frame_rows, dtype=float)
        self._five_bar = geometry.five_bar_hip
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
        self._checked_step = MAX_STEP
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

    def check_step_stability(self, dt: float = MAX_STEP, turn: Optional[float] = None) -> None:
        """ParameterError, naming the tank.yaml keys, unless a step of ``dt`` (default the 100 Hz control period)
        resolves every stiff term of these parameters at the tether's turn ``turn`` (default :attr:`checked_turn`):
        :func:`~.tank_stability.unresolved_terms`."""
        problems = unresolved_terms(self, dt, self.checked_turn if turn is None else turn)
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
        rows = leg_kinematics_rows(q.tolist() if isinstance(q, np.ndarray) else q,
                                    q_dot.tolist() if isinstance(q_dot, np.ndarray) else q_dot, self.params)
        context = _TankContext(rows, self.net_paw_buoyancy, self._restoring)
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
