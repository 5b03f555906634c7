"""Reachable foot workspace of one leg and its longest strokes per direction (used by the coordinated
stroke scheme, :mod:`quadruped_control.control.strokes.coordinated`).

All legs share one workspace in their leg frame (eq. (ee_body): r^B = o_i + M_i p^L, the IK of section
"Leg Inverse Kinematics" works on p^L), so it is computed once per robot geometry:

- a grid of leg-frame points at spacing ``cell`` (m) around the nominal foot position; a point is
  *inside with margin* when the IK (eq. (ik_theta3), (ik_theta1245)) reaches it with every servo angle at
  least ``joint_margin`` (rad) inside its range, and its six grid neighbours are reachable too (about one
  cell of Cartesian margin to the reach limits of the five-bar);
- for a set of unit directions spread evenly over the sphere (a Fibonacci lattice), the grid point from
  which a straight stroke along that direction stays inside the longest, and that length (the *chord*).
  Ties go to the point nearest the nominal foot position.

The grid costs about 70 000 IK evaluations (~0.6 s); results are cached per geometry. Lookups are cheap
(:meth:`Workspace.inside`, :meth:`Workspace.best_start`).
"""
from __future__ import annotations

import math
from typing import Dict, Hashable, Tuple

import numpy as np

from quadruped_common.robot import MIRROR_DIAG
from quadruped_control.model.kinematics import UnreachableError, joint_angles_floats
from quadruped_control.model.params import RobotParams

__all__ = ["Workspace", "fibonacci_directions", "leg_workspace"]

Vec3 = Tuple[float, float, float]

#: Half-extent of the searched box around the nominal foot position (leg frame), m. The five-bar reaches
#: a3 + a1 (0.19 m) from its motors, so 0.22 m contains the whole workspace.
_SEARCH_HALF_EXTENT = 0.22


def fibonacci_directions(count: int) -> np.ndarray:
    """``count`` unit vectors spread evenly over the sphere (Fibonacci lattice), shape (count, 3)."""
    k = np.arange(count, dtype=float) + 0.5
    z = 1.0 - 2.0 * k / count
    radius = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    angle = math.pi * (3.0 - math.sqrt(5.0)) * k
    return np.column_stack((radius * np.cos(angle), radius * np.sin(angle), z))


class Workspace:
    """Leg-frame workspace grid with margin and the longest stroke per direction (see the module docstring).

    ``leg1_robot``: robot parameters (leg 1's IK is used; every leg has the same workspace in its frame);
    ``cell`` (m), ``joint_margin`` (rad), ``directions``: size of the direction set.
    """

    def __init__(self, robot: RobotParams, cell: float = 0.01, joint_margin: float = math.radians(5.0),
                 directions: int = 256, radius: float = math.inf) -> None:
        if not (math.isfinite(cell) and 0.002 <= cell <= 0.05):
            raise ValueError("workspace cell must be within [0.002, 0.05] m, got %r" % (cell,))
        if not (math.isfinite(joint_margin) and 0.0 <= joint_margin <= math.radians(30.0)):
            raise ValueError("joint margin must be within [0, 30] deg, got %r rad" % (joint_margin,))
        self.cell = float(cell)
        self.joint_margin = float(joint_margin)
        self._robot = robot
        limits = robot.joint_limits
        self._bounds = tuple((lo + joint_margin, hi - joint_margin)
                             for lo, hi in (limits.theta1, limits.theta2, limits.theta3))
        centre = np.asarray(robot.nominal_foot_leg, dtype=float)
        n = int(math.ceil(_SEARCH_HALF_EXTENT / cell))
        self.origin = centre - n * cell          # leg-frame position of grid index (0, 0, 0)
        self.shape = (2 * n + 1,) * 3
        reachable = np.zeros(self.shape, dtype=bool)
        mx, my, mz = MIRROR_DIAG[1]
        ox, oy, oz = robot.leg_origins[1].tolist()
        axis = [self.origin[d] + cell * np.arange(self.shape[d]) for d in range(3)]
        for i, x in enumerate(axis[0].tolist()):
            for j, y in enumerate(axis[1].tolist()):
                for k, z in enumerate(axis[2].tolist()):
                    reachable[i, j, k] = self._within_margin(ox + mx * x, oy + my * y, oz + mz * z)
        inside = reachable.copy()
        inside[1:, :, :] &= reachable[:-1, :, :]
        inside[:-1, :, :] &= reachable[1:, :, :]
        inside[:, 1:, :] &= reachable[:, :-1, :]
        inside[:, :-1, :] &= reachable[:, 1:, :]
        inside[:, :, 1:] &= reachable[:, :, :-1]
        inside[:, :, :-1] &= reachable[:, :, 1:]
        inside[0, :, :] = inside[-1, :, :] = False
        inside[:, 0, :] = inside[:, -1, :] = False
        inside[:, :, 0] = inside[:, :, -1] = False
        if math.isfinite(radius):  # only the part of the workspace within ``radius`` of the nominal point
            ii, jj, kk = np.indices(self.shape)
            offsets = np.stack((ii, jj, kk), axis=-1) * cell + self.origin - centre
            inside &= np.linalg.norm(offsets, axis=-1) <= radius
        self.grid = inside
        self.directions = fibonacci_directions(directions)
        self.start_points, self.chords = self._longest_strokes(centre)

    def _within_margin(self, x: float, y: float, z: float) -> bool:
        try:
            angles = joint_angles_floats(x, y, z, 1, self._robot)
        except UnreachableError:
            return False
        return all(lo <= a <= hi for a, (lo, hi) in zip(angles, self._bounds))

    def _longest_strokes(self, centre: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Per direction: the grid point with the longest straight run inside the grid, and its length."""
        cells = np.argwhere(self.grid)
        points = self.origin + self.cell * cells
        distance_to_centre = np.linalg.norm(points - centre, axis=1)
        max_steps = int(2 * _SEARCH_HALF_EXTENT / self.cell) + 2
        starts = np.empty((len(self.directions), 3))
        chords = np.empty(len(self.directions))
        limit = np.array(self.shape) - 1
        for index, direction in enumerate(self.directions):
            length = np.zeros(len(cells))
            running = np.ones(len(cells), dtype=bool)
            for step in range(1, max_steps):
                probe = np.rint(cells + step * direction).astype(int)
                ok = running & np.all((probe >= 0) & (probe <= limit), axis=1)
                ok[ok] = self.grid[probe[ok, 0], probe[ok, 1], probe[ok, 2]]
                running = ok
                if not running.any():
                    break
                length[running] = step
            best = np.lexsort((distance_to_centre, -length))[0]
            starts[index] = points[best]
            chords[index] = length[best] * self.cell
        return starts, chords

    # ---- lookups (leg frame) ---------------------------------------------------------------

    def inside(self, x: float, y: float, z: float) -> bool:
        """Whether the leg-frame point lies in a grid cell that is inside with margin."""
        cell, (gx, gy, gz) = self.cell, self.origin.tolist()
        i, j, k = int(round((x - gx) / cell)), int(round((y - gy) / cell)), int(round((z - gz) / cell))
        n0, n1, n2 = self.shape
        return 0 <= i < n0 and 0 <= j < n1 and 0 <= k < n2 and bool(self.grid[i, j, k])

    def best_start(self, dx: float, dy: float, dz: float) -> Tuple[Vec3, float]:
        """Start point (leg frame) and chord length (m) of the longest stroke along the leg-frame direction
        nearest (dx, dy, dz) (need not be unit). Zero direction: the nominal point and 0."""
        norm = math.hypot(dx, dy, dz)
        if not (norm > 1e-12 and math.isfinite(norm)):
            x, y, z = self._robot.nominal_foot_leg.tolist()
            return (x, y, z), 0.0
        index = int(np.argmax(self.directions @ np.array((dx / norm, dy / norm, dz / norm))))
        x, y, z = self.start_points[index].tolist()
        return (x, y, z), float(self.chords[index])

    def chord_from(self, x: float, y: float, z: float, dx: float, dy: float, dz: float) -> float:
        """Length (m, in cell steps) of the straight run inside the grid from a leg-frame point along a direction."""
        norm = math.hypot(dx, dy, dz)
        if not (norm > 1e-12 and math.isfinite(norm)) or not self.inside(x, y, z):
            return 0.0
        ux, uy, uz = self.cell * dx / norm, self.cell * dy / norm, self.cell * dz / norm
        steps = 0
        while self.inside(x + (steps + 1) * ux, y + (steps + 1) * uy, z + (steps + 1) * uz):
            steps += 1
        return steps * self.cell


def _geometry_key(robot: RobotParams) -> Tuple[Hashable, ...]:
    """What a leg's workspace depends on: the five-bar, the hip offsets, the servo ranges, the nominal
    foot and the leg origin."""
    limits = robot.joint_limits
    return (robot.five_bar, (robot.l_y, robot.l_z), (limits.theta1, limits.theta2, limits.theta3),
            tuple(np.asarray(robot.nominal_foot_leg, dtype=float).tolist()),
            tuple(np.asarray(robot.leg_origins[1], dtype=float).tolist()))


_CACHE: Dict[Tuple[Hashable, ...], Workspace] = {}


def leg_workspace(robot: RobotParams, cell: float = 0.01, joint_margin: float = math.radians(5.0),
                  radius: float = math.inf) -> Workspace:
    """The (cached) :class:`Workspace` of this robot's legs."""
    key = _geometry_key(robot) + (float(cell), float(joint_margin), float(radius))
    workspace = _CACHE.get(key)
    if workspace is None:
        workspace = _CACHE[key] = Workspace(robot, cell, joint_margin, radius=radius)
    return workspace
