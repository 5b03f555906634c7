"""Optional compilation with numba of the simulator's scalar cores: one source, compiled or plain.

The batched simulator steps thousands of trials; per trial and step it runs the same few hundred float
operations as the per-trial plants. Vectorised over trials with numpy, each of those operations is a
separate pass over memory with its own call overhead; compiled with numba, a loop over the trials runs
the plain scalar functions themselves. So the model's scalar functions are written once, in the subset
of Python that both CPython and numba's nopython mode run (floats, tuples, small arrays, ``math``):

- :func:`jitable` marks such a function. It returns the function unchanged, so every Python caller
  (the robot's controller, the per-trial simulator) runs exactly the code it ran before; compiled code
  that calls it compiles it inline (numba's ``register_jitable``, applied when numba is first loaded).
- :func:`trial_step` marks a jitable function that advances one trial of a batch and returns whether
  the trial is still good. Compiled, it is the function itself; plain Python callers get it wrapped so
  that any exception (``math.sin(inf)``, ``1 / 0``, where compiled code gives inf or nan) returns False:
  a failing trial fails alone on both paths, and the compiled loops carry no try/except (which cost them
  5-10 %).
- :func:`kernel` compiles a function for Python callers (``numba.njit``) on its first call, with numpy's
  floating-point error model (a division by zero in a diverging trial gives inf or nan, which the
  caller flags, instead of raising inside the loop) and the compiled code cached on disk. numba is
  imported then and not before, so the robot's nodes, which import the model, never load it.

Without numba (the robot's Python 3.8 environment, which never runs the batch) both return the function
unchanged and everything runs as plain Python, slowly but with the same results; ``UQ_NO_JIT=1``
forces that path (the tests compare the two).

numba's on-disk cache is invalidated by the modification time of the kernel's own file only, not of
the functions it inlines from other files, so a stale kernel could survive a change in, say, the drag
law. The cache therefore lives in a folder named by a hash of every source file a kernel can reach
(:func:`source_fingerprint` of :data:`KERNEL_SOURCES`): any change there starts a fresh cache, which
costs about two minutes of compilation on first use (the plants', the controller's and the servos'
loops).
"""
from __future__ import annotations

import functools
import hashlib
import importlib.util
import math
import os
from typing import Any, Callable, List, Optional, Sequence, Tuple, TypeVar

__all__ = ["AVAILABLE", "KERNEL_SOURCES", "hypot2", "hypot3", "jitable", "kernel", "source_fingerprint", "trial_step"]

F = TypeVar("F", bound=Callable)

#: True when :func:`kernel` compiles (numba installed and UQ_NO_JIT unset). numba itself is imported
#: only when a kernel is first called: the robot's nodes, which import the model through this module,
#: never load it (about 0.5 s and tens of MB per process).
AVAILABLE = os.environ.get("UQ_NO_JIT", "") != "1" and importlib.util.find_spec("numba") is not None

#: The functions marked :func:`jitable`, registered with numba when it is first loaded.
_JITABLE: List[Callable] = []
#: (plain-Python wrapper, function) of each :func:`trial_step`: compiled callers get the function.
_TRIAL_STEPS: List[Tuple[Callable, Callable]] = []
_numba: Any = None


def _load_numba() -> Any:
    """numba, imported once, with the cache folder set and every :func:`jitable` function registered."""
    global _numba
    if _numba is None:
        import numba
        from numba.extending import overload, register_jitable

        # Read by numba when a cached dispatcher is created, so set before any kernel.
        numba.config.CACHE_DIR = _cache_dir()

        for function in _JITABLE:
            register_jitable(function)
        for wrapper, function in _TRIAL_STEPS:
            # What register_jitable does, for the wrapper's name: compiled code calling it runs the function.
            overload(wrapper, strict=False)(_implementation_of(function))
        _numba = numba
    return _numba


def _implementation_of(function: Callable) -> Callable:
    def typer(*args: Any, **kwargs: Any) -> Callable:  # noqa: ARG001 (numba passes the argument types)
        return function
    return typer


#: The folders whose code a kernel can reach (the floors below the simulator, and the simulator).
KERNEL_SOURCES = ("quadruped_common", os.path.join("quadruped_control", "model"),
                  os.path.join("quadruped_control", "control"), os.path.join("quadruped_control", "sim"))


def source_fingerprint(folders: Sequence[str] = KERNEL_SOURCES, root: Optional[str] = None) -> str:
    """sha256 (16 hex digits) of the Python sources under ``folders`` (relative to ``root``, default the
    folder that holds the packages), by path and content."""
    root = root or os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    digest = hashlib.sha256()
    for package in folders:
        for folder, dirs, files in os.walk(os.path.join(root, package)):
            dirs[:] = sorted(d for d in dirs if d != "__pycache__")
            for name in sorted(files):
                if name.endswith(".py"):
                    path = os.path.join(folder, name)
                    digest.update(os.path.relpath(path, root).encode())
                    with open(path, "rb") as handle:
                        digest.update(handle.read())
    return digest.hexdigest()[:16]


def _cache_dir() -> str:
    base = os.environ.get("UQ_JIT_CACHE") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"),
        "underwater_quadruped", "numba")
    return os.path.join(base, source_fingerprint())


def hypot2(x: float, y: float) -> float:
    """sqrt(x^2 + y^2), the same bits in Python and in compiled code (see :func:`hypot3`)."""
    return math.sqrt(x * x + y * y)


def hypot3(x: float, y: float, z: float) -> float:
    """sqrt(x^2 + y^2 + z^2), the same bits in Python and in compiled code.

    Not ``math.hypot``: CPython computes it with its own extra-precise algorithm (which also differs
    between Python versions: the robot runs 3.8), numba with the C library's ``hypot``; the last bits
    differ, and a chaotic limit cycle (the paper plant's Table 1 runs) turns that into a different trial.
    Squares, sums and ``sqrt`` are IEEE operations, rounded the same everywhere (no fused multiply-add
    without fastmath). Every argument here is a physical quantity of order 1 (metres, rad/s, rotation
    elements), far from where the squares would overflow (1e154) or underflow (1e-154)."""
    return math.sqrt(x * x + y * y + z * z)


def jitable(function: F) -> F:
    """``function`` unchanged; callable from compiled code too (module docstring)."""
    _JITABLE.append(function)
    if _numba is not None:  # defined after numba was loaded: register now
        from numba.extending import register_jitable
        register_jitable(function)
    return function


def trial_step(function: F) -> F:
    """``function`` (one trial's step, returning False when the trial failed) for compiled callers; for
    plain Python callers, the same with any exception turned into False (module docstring)."""
    @functools.wraps(function)
    def guarded(*args: Any) -> Any:
        try:
            return function(*args)
        except Exception:  # noqa: BLE001 (any failure of one trial fails that trial only)
            return False

    _TRIAL_STEPS.append((guarded, function))
    if _numba is not None:  # defined after numba was loaded: register now
        from numba.extending import overload
        overload(guarded, strict=False)(_implementation_of(function))
    return guarded  # type: ignore[return-value]


jitable(hypot2)
jitable(hypot3)


class _Kernel:
    """A function compiled on its first call (module docstring); ``py_func`` is the plain function."""

    def __init__(self, function: Callable) -> None:
        self.py_func = function
        self._compiled: Optional[Callable] = None
        self.__doc__ = function.__doc__
        self.__name__ = getattr(function, "__name__", "kernel")

    def __call__(self, *args: Any) -> Any:
        compiled = self._compiled
        if compiled is None:
            compiled = self._compiled = _load_numba().njit(cache=True, error_model="numpy")(self.py_func)
        return compiled(*args)


def kernel(function: F) -> F:
    """``function`` compiled for Python callers on its first call (module docstring); unchanged without
    numba. The plain function stays reachable as ``.py_func`` either way (the tests run both)."""
    if not AVAILABLE:
        function.py_func = function  # type: ignore[attr-defined]
        return function
    return _Kernel(function)  # type: ignore[return-value]
