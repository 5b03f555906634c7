"""The identification's parameter table, read from the tank schema (:mod:`quadruped_control.sim.plants.tank_params`).

Each fitted coordinate is a :class:`~quadruped_control.sim.plants.tank_params.Fit` of one tank parameter, named
after it (``center_of_buoyancy_z``, ``appendage_damping_linear_xy``; ``servo_stall_torque_inverse`` fits 1 / the
stall torque, so that "off" lies inside its bounds). This module maps a set of coordinate values onto
:class:`TankParams` (:func:`tank_overrides`), reads them back from a tank (:func:`nominal_values`), and writes them
into a tank.yaml text (:func:`update_tank_yaml`).
"""
from __future__ import annotations

import math
import re
from typing import Any, Dict, List, Tuple

from quadruped_control.sim.plants.tank_params import Fit, TankParameter, TankParams, fit_coordinates

__all__ = ["BOUNDS", "PARAMETERS", "PLACES", "field_value", "nominal_values", "tank_overrides", "update_tank_yaml"]

#: Every coordinate the identification can fit -> (its tank parameter, its :class:`Fit`), in the schema's order.
PLACES: Dict[str, Tuple[TankParameter, Fit]] = {name: (spec, fit) for name, spec, fit in fit_coordinates()}

#: (name, low, high) of every coordinate, in the schema's order (the screening's Morris design depends on it).
PARAMETERS: Tuple[Tuple[str, float, float], ...] = tuple((name, fit.low, fit.high) for name, (_, fit) in PLACES.items())

#: Each coordinate's (low, high): :data:`PARAMETERS` by name.
BOUNDS: Dict[str, Tuple[float, float]] = {name: (low, high) for name, low, high in PARAMETERS}


def field_value(name: str, value: float) -> float:
    """What the tank parameter of coordinate ``name`` holds for the coordinate's ``value``: the value, or for a
    reciprocal 1 / value (0 for 0; its own inverse)."""
    if PLACES[name][1].reciprocal:
        return 1.0 / float(value) if value > 0.0 else 0.0
    return float(value)


def tank_overrides(values: Dict[str, float]) -> Tuple[Tuple[str, Any], ...]:
    """TankParams overrides (field, value) of a (possibly partial) set of coordinate values. A vector's components
    that no given coordinate sets are 0 (the studies give it whole sets)."""
    fields: Dict[str, Any] = {}
    for name, _, _ in PARAMETERS:
        if name in values:
            spec, fit = PLACES[name]
            value = field_value(name, values[name])
            if fit.components:
                vector = fields.setdefault(spec.name, [0.0, 0.0, 0.0])
                for component in fit.components:
                    vector[component] = value
            else:
                fields[spec.name] = value
    return tuple((field, tuple(value) if isinstance(value, list) else value) for field, value in fields.items())


def nominal_values(tank: TankParams) -> Dict[str, float]:
    """The coordinates' values in ``tank`` (config/tank.yaml), clipped into their bounds."""
    out = {}
    for name, low, high in PARAMETERS:
        spec, fit = PLACES[name]
        value = getattr(tank, spec.name)
        if fit.components:
            value = value[fit.components[0]]
        out[name] = float(min(high, max(low, field_value(name, value))))
    return out


#: Every value is written with 17 significant digits, so that a written set reproduces the fit's trials bit
#: for bit (their limit cycles turn a rounding in the fourth digit into other outcomes).
_EXACT = "%.17g"


def _vector_parts(line: str) -> List[str]:
    """The three components of a tank.yaml vector line (``key: [x, y, z]  # comment``), as written."""
    match = re.match(r"^\s*[A-Za-z_]+:\s*\[([^\]]*)\]", line)
    parts = [part.strip() for part in match.group(1).split(",")] if match else []
    try:
        if len(parts) == 3 and all(math.isfinite(float(part)) for part in parts):
            return parts
    except ValueError:
        pass
    raise ValueError("tank.yaml: %r is not a vector of three numbers" % line.strip())


def update_tank_yaml(text: str, values: Dict[str, float], note: str) -> str:
    """config/tank.yaml text with the identified values in place (comments of other lines kept); each
    replaced line is marked ``# [identified] <note>``. A vector's line is written whole, its components
    that no parameter in ``values`` sets as ``text`` had them: a fit of some components (``identify_bags
    --parameters appendage_damping_linear_z``) keeps the others the fit ran with. A scalar whose key ``text`` lacks
    (a file written before the key existed, such as an older ensemble member given as ``--tank-yaml``) gets its
    line at the end of its section (the section too, if that is missing); a vector without its line is a
    ValueError."""
    lines_of: Dict[Tuple[str, str], List[str]] = {}  # (section, key) -> the coordinates on that line
    for name, _, _ in PARAMETERS:
        spec = PLACES[name][0]
        lines_of.setdefault((spec.section, spec.name), []).append(name)
    lines = text.splitlines()
    section = None
    done = set()
    for i, line in enumerate(lines):
        stripped = line.strip()
        if line and not line[0].isspace() and stripped.endswith(":"):
            section = stripped[:-1]
            continue
        names = lines_of.get((section or "", stripped.split(":", 1)[0]), [])
        given = [name for name in names if name in values]
        if not given:
            continue
        if PLACES[given[0]][1].components:
            parts = _vector_parts(line)
            for name in given:
                for component in PLACES[name][1].components:
                    parts[component] = _EXACT % field_value(name, values[name])
            value = "[%s]" % ", ".join(parts)
        else:
            value = _EXACT % field_value(given[0], values[given[0]])
        indent = line[:len(line) - len(line.lstrip())]
        lines[i] = "%s%s: %s  # [identified] %s" % (indent, stripped.split(":", 1)[0], value, note)
        done.update(given)
    missing = [n for n in values if n not in done]
    vectors = [n for n in missing if PLACES[n][1].components]
    if vectors:  # a vector's other components are the file's: without its line there are none to keep
        raise ValueError("tank.yaml has no line for %s" % ", ".join(vectors))
    for name in missing:  # a file written before the key existed (an older fit's ensemble member)
        _insert_line(lines, PLACES[name][0].section, "  %s: %s  # [identified] %s" % (
            PLACES[name][0].name, _EXACT % field_value(name, values[name]), note))
    return "\n".join(lines) + "\n"


def _insert_line(lines: List[str], section: str, line: str) -> None:
    """``line`` appended to the block of top-level ``section`` in the yaml ``lines`` (in place; before the blank
    lines and the next section's own comments that end it), or a new section at the end."""
    header = "%s:" % section
    start = next((i for i, text in enumerate(lines) if text.rstrip() == header), None)
    if start is None:
        lines.extend(["", header, line])
        return
    end = next((i for i in range(start + 1, len(lines)) if lines[i] and not lines[i][0].isspace()
                and not lines[i].startswith("#")), len(lines))
    while end > start + 1 and (not lines[end - 1].strip() or lines[end - 1].startswith("#")):
        end -= 1
    lines.insert(end, line)
