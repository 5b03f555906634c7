"""3-vectors and 3x3 matrices on plain floats, for the float cores that run as Python and compiled.

A :data:`Vec3` is a tuple of three floats; a :class:`Mat3` a named tuple of nine, row-major. The
helpers are :func:`~quadruped_common.jit.jitable` (compiled callers inline them) and each computes
its components in the order written in its docstring, so an expression written with them rounds
exactly as the same expression written out component by component.
"""
from __future__ import annotations

from typing import NamedTuple, Sequence, Tuple

from quadruped_common.jit import hypot3, jitable

__all__ = ["Mat3", "Vec3", "ZERO", "add", "column", "cross", "dot", "mat3", "mat_vec", "norm", "row", "scale",
           "sub", "transpose_times"]

Vec3 = Tuple[float, float, float]

#: The zero vector.
ZERO: Vec3 = (0.0, 0.0, 0.0)


class Mat3(NamedTuple):
    """A 3x3 matrix, row-major: ``xy`` is row x, column y."""

    xx: float
    xy: float
    xz: float
    yx: float
    yy: float
    yz: float
    zx: float
    zy: float
    zz: float


@jitable
def mat3(values: Sequence[float]) -> Mat3:
    """The :class:`Mat3` of nine row-major values (a tuple, a list or an array row)."""
    return Mat3(values[0], values[1], values[2], values[3], values[4], values[5], values[6], values[7], values[8])


@jitable
def add(a: Vec3, b: Vec3) -> Vec3:
    """a + b."""
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


@jitable
def sub(a: Vec3, b: Vec3) -> Vec3:
    """a - b."""
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@jitable
def scale(s: float, a: Vec3) -> Vec3:
    """s a, componentwise s * a_k."""
    return (s * a[0], s * a[1], s * a[2])


@jitable
def dot(a: Vec3, b: Vec3) -> float:
    """a . b = a_0 b_0 + a_1 b_1 + a_2 b_2, summed left to right."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@jitable
def cross(a: Vec3, b: Vec3) -> Vec3:
    """a x b = (a_1 b_2 - a_2 b_1, a_2 b_0 - a_0 b_2, a_0 b_1 - a_1 b_0)."""
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@jitable
def norm(a: Vec3) -> float:
    """|a| (:func:`~quadruped_common.jit.hypot3`: the same bits compiled or not)."""
    return hypot3(a[0], a[1], a[2])


@jitable
def row(M: Mat3, i: int) -> Vec3:
    """Row ``i`` of M."""
    return (M[3 * i], M[3 * i + 1], M[3 * i + 2])


@jitable
def column(M: Mat3, j: int) -> Vec3:
    """Column ``j`` of M."""
    return (M[j], M[3 + j], M[6 + j])


@jitable
def mat_vec(M: Mat3, v: Vec3) -> Vec3:
    """M v, each component the :func:`dot` of a row of M with v."""
    return (dot(row(M, 0), v), dot(row(M, 1), v), dot(row(M, 2), v))


@jitable
def transpose_times(A: Mat3, B: Mat3) -> Mat3:
    """A^T B: entry (i, j) is the :func:`dot` of column i of A with column j of B."""
    a0, a1, a2 = column(A, 0), column(A, 1), column(A, 2)
    b0, b1, b2 = column(B, 0), column(B, 1), column(B, 2)
    return Mat3(dot(a0, b0), dot(a0, b1), dot(a0, b2), dot(a1, b0), dot(a1, b1), dot(a1, b2), dot(a2, b0),
                dot(a2, b1), dot(a2, b2))
