"""The identification's searches over parameter sets (each set: coordinate name -> value, scaled to [0, 1] by
its bounds, :data:`~.identify_parameters.BOUNDS`): the Morris screening (:func:`screen`), the CMA-ES fit
(:func:`fit`, seeded), the compass search that polishes its best set (:func:`polish`), the one-factor baseline
(:func:`baseline`) and the choice of distinct sets for an ensemble (:func:`distinct_best`). Each takes
``evaluate(sets, cases, tag)`` (an :class:`~.identify_objective.Evaluator`) and returns the results it asked
for; the same seed gives the same search.
"""
from __future__ import annotations

import math
import warnings
from typing import Any, Callable, Dict, List, Sequence, Tuple

import numpy as np

from quadruped_control.studies import StudyError
from quadruped_control.studies.identify_parameters import BOUNDS, PARAMETERS

__all__ = ["baseline", "best_on", "distinct_best", "fit", "improvements", "morris_sets", "polish", "screen",
           "to_unit", "to_values"]

def to_values(x: Sequence[float], names: Sequence[str], fixed: Dict[str, float]) -> Dict[str, float]:
    values = dict(fixed)
    for name, u in zip(names, x):
        low, high = BOUNDS[name]
        values[name] = low + min(1.0, max(0.0, float(u))) * (high - low)
    return values


def to_unit(values: Dict[str, float], names: Sequence[str]) -> List[float]:
    """``values`` of ``names`` scaled to [0, 1] by their bounds: the inverse of :func:`to_values`."""
    return [(values[n] - BOUNDS[n][0]) / (BOUNDS[n][1] - BOUNDS[n][0]) for n in names]


def morris_sets(problem: Dict[str, Any], trajectories: int, seed: int) -> np.ndarray:
    """The Morris design (SALib, 4 levels) of ``problem``, the same for the same ``seed``.

    SALib 1.5 seeds numpy's global generator only ``if seed:``, so ``seed=0`` (the study's default) drew
    a new design at every run: the identifications of stops 23 and 24 cannot be repeated exactly. The
    global generator is seeded here for every seed, then SALib is called."""
    from SALib.sample import morris as morris_sample

    np.random.seed(seed)
    return morris_sample.sample(problem, trajectories, num_levels=4, seed=seed)


def screen(evaluate: Callable, nominal: Dict[str, float], trajectories: int, seed: int,
           cases: Sequence[int]) -> Dict[str, Any]:
    """Morris elementary effects of every parameter on the objective (SALib, 4 levels)."""
    from SALib.analyze import morris as morris_analyze

    names = [name for name, _, _ in PARAMETERS]
    problem = {"num_vars": len(names), "names": names, "bounds": [[low, high] for _, low, high in PARAMETERS]}
    X = morris_sets(problem, trajectories, seed)
    sets = [dict(zip(names, map(float, row))) for row in X]
    results = evaluate(sets, cases, "scr")
    # A trajectory with a set that could not run every experiment is left out whole: its elementary effects
    # would measure FAILED_CASE_COST, not the parameters' effect; the others are still a Morris design.
    steps = len(names) + 1
    kept = [j for j in range(len(results) // steps)
            if not any(r.get("failed") for r in results[j * steps:(j + 1) * steps])]
    if not kept:
        raise StudyError("identify: every screening trajectory has a set that could not run every experiment")
    rows = [j * steps + i for j in kept for i in range(steps)]
    Y = np.array([results[k]["objective"] for k in rows])
    with warnings.catch_warnings():
        # one trajectory has no spread: numpy warns of its standard deviation, reported here as None
        for message in ("Degrees of freedom", "invalid value encountered"):
            warnings.filterwarnings("ignore", message, RuntimeWarning)
        analysis = morris_analyze.analyze(problem, X[rows], Y, num_levels=4, seed=seed)
    finite = [float(v) if math.isfinite(v) else None for v in analysis["sigma"]]
    return {"names": names, "mu_star": [float(v) for v in analysis["mu_star"]], "sigma": finite, "sets": len(sets),
            "trajectories": len(results) // steps, "trajectories_dropped": len(results) // steps - len(kept),
            "best": min(results, key=lambda r: r["objective"]), "results": results}


def best_on(results: Sequence[Dict[str, Any]], subset: Sequence[int]) -> Dict[str, Any]:
    """The result whose objective over the experiments ``subset`` (the sum of their ``costs``) is lowest. A
    fold's fit starts from the screening's best set *on its training groups*: the best on all experiments
    would let the held-out group choose the start."""
    return min(results, key=lambda r: sum(dict(zip(r["cases"], r["costs"]))[k] for k in subset))


def fit(evaluate: Callable, names: Sequence[str], fixed: Dict[str, float], start: Dict[str, float], budget: int,
        popsize: int, seed: int, cases: Sequence[int], tag: str, sigma: float = 0.25) -> List[Dict[str, Any]]:
    """CMA-ES over ``names`` (scaled to [0, 1]) from ``start`` with step ``sigma`` (of the scaled range), the
    others at ``fixed``: every evaluated set, best first. The same ``seed`` (>= 0) gives the same fit."""
    import cma

    x0 = to_unit(start, names)
    if seed < 0:
        raise StudyError("identify: the fit's seed must be >= 0, got %d" % seed)
    # pycma reads a seed of 0 (or None) as "seed from the clock" (cma.CMAOptions("seed")), and the study's
    # default seed is 0: before this mapping every full fit at --seed 0 drew a new search. pycma gets
    # seed + 1, never 0.
    es = cma.CMAEvolutionStrategy(x0, sigma, {"bounds": [0.0, 1.0], "popsize": popsize, "seed": seed + 1,
                                             "maxfevals": budget, "verbose": -9})
    evaluated: List[Dict[str, Any]] = []
    while not es.stop() and len(evaluated) < budget:
        X = es.ask()
        results = evaluate([to_values(x, names, fixed) for x in X], cases, tag)
        es.tell(X, [r["objective"] for r in results])
        evaluated += results
    return sorted(evaluated, key=lambda r: r["objective"])


def polish(evaluate: Callable, names: Sequence[str], fixed: Dict[str, float], best: Dict[str, Any], budget: int,
           cases: Sequence[int], tag: str, step: float = 0.125, smallest: float = 1.0 / 64.0) -> List[Dict[str, Any]]:
    """A compass search (a coordinate pattern search) from ``best``, the best result of a fit over ``names``:
    each round moves every parameter up and down by ``step`` of its scaled range (clipped to its bounds; a
    move that the bound cancels, or that lands on a set seen before, is not evaluated), all as one batch.
    The best move replaces ``best`` if its objective is lower; otherwise the step halves. It stops when the
    step falls below ``smallest`` or the next round would exceed ``budget`` sets. Returns every set it
    evaluated (``best`` not among them).

    Why: the fits' CMA-ES budgets (600 sets in ten dimensions) end long before the search converges, and
    the best set then still improves along single axes (a seed-1 full fit gained 2.9 when its servo dead band
    was set to its bound). What it showed (docs/identification.md):
    polished folds fit their training groups better and predict the held-out group worse. Written here
    rather than taken from scipy: scipy's bounded local methods (Powell, Nelder-Mead) ask for one set at a
    time, and the evaluator runs a batch of sets on all workers at once."""
    if not 0.0 < smallest <= step <= 1.0:
        raise StudyError("identify: the polish needs 0 < smallest <= step <= 1, got %g and %g" % (smallest, step))
    x = to_unit(best["values"], names)
    current = best["objective"]
    evaluated: List[Dict[str, Any]] = []
    def key(u: List[float]) -> Tuple[float, ...]:  # the same set, whatever the last bits of its steps
        return tuple(round(v, 12) for v in u)

    # x is always the best set seen, so a set seen before (the one x came from, one step back) cannot be better
    seen = {key(x)}
    while step >= smallest:
        moves = []
        for i in range(len(x)):
            for sign in (1.0, -1.0):
                moved = x[:i] + [min(1.0, max(0.0, x[i] + sign * step))] + x[i + 1:]
                if key(moved) not in seen:
                    moves.append(moved)
        if len(evaluated) + len(moves) > budget:
            break
        if not moves:
            step /= 2.0
            continue
        seen.update(key(m) for m in moves)
        results = evaluate([to_values(m, names, fixed) for m in moves], cases, tag)
        evaluated += results
        i = min(range(len(results)), key=lambda k: results[k]["objective"])
        if results[i]["objective"] < current:
            x, current = moves[i], results[i]["objective"]
        else:
            step /= 2.0
    return evaluated


def improvements(objectives: Sequence[float]) -> List[Tuple[int, float]]:
    """Where a search's best so far fell: ``(n, objective)`` for each set that beat every set before it, ``n``
    its place (from 1) in the order the search asked for them. A best found in the search's last generation
    says the search was still improving when its budget ran out (docs/identification.md)."""
    out: List[Tuple[int, float]] = []
    for n, value in enumerate(objectives, 1):
        if not out or value < out[-1][1]:
            out.append((n, float(value)))
    return out


def baseline(evaluate: Callable, nominal: Dict[str, float], cases: Sequence[int], points: int,
             tag: str) -> Dict[str, Any]:
    """config/tank.yaml with the paw drag scale, one factor that slows everything, fitted on a grid over
    [0.05, 1.6] (wider than its plausible bounds: a slow-down factor, not a physical estimate)."""
    sets = [dict(nominal, paw_drag_scale=float(v)) for v in np.geomspace(0.05, 1.6, points)]
    return min(evaluate(sets, cases, tag), key=lambda r: r["objective"])


def distinct_best(results: Sequence[Dict[str, Any]], names: Sequence[str], size: int) -> List[Dict[str, Any]]:
    """The first ``size`` results (best first) whose values of ``names``, rounded to 4 digits, differ: a
    search revisits sets that differ only in their last bits, which would fill an ensemble with copies."""
    chosen, seen = [], set()
    for result in results:
        key = tuple(round(result["values"][n], 4) for n in names)
        if key not in seen:
            seen.add(key)
            chosen.append(result)
        if len(chosen) >= size:
            break
    return chosen
