"""The gains in force written back as a gain set of a controller.yaml (the controller's ``~save_gains``).

A saved set holds every live-tunable value (:data:`quadruped_common.tunables.TUNABLES`: K_p, K_i, K_d, K_aw,
tau_max, t_rec, t_pow_max), so it reproduces them whatever the file's top-level defaults. Where it goes:

* a new file: the whole configuration in force (:func:`config_tree`: the other settings too, the stroke
  scheme as ``stroke.scheme``) with this one gain set;
* an existing controller.yaml: the set is added to its ``gain_sets`` by editing the text (comments and
  every other line kept; the file's other settings stay its own, the stroke scheme is not part of a set).

Refused (:class:`~quadruped_common.config.ParameterError`, nothing written) unless ``overwrite``: a set of
that name already in the file, and any change of the shipped ``config/controller.yaml``. Always refused: a
relative path, a name that is no plain key, a file whose result would not load. The result is checked
before it is written: it parses to the intended tree, passes :func:`controller_config_from_dict` (every
set of the file, as ``~gain_set`` loads it) and gives the values in force back. The write is atomic.
"""
from __future__ import annotations

import dataclasses
import os
import re
import tempfile
from typing import Any, Dict, List, Optional, Tuple

import yaml

from quadruped_common.config import ParameterError, config_path, parse_yaml
from quadruped_common.tunables import TUNABLES
from quadruped_control.control.controller_config import CONTROLLER_SCHEMA, ControllerConfig, controller_config_from_dict

__all__ = ["config_tree", "gain_set_values", "save_gain_set"]

_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
#: top-level keys of controller.yaml, each a ControllerConfig field of the same name (pairs as lists)
_PLAIN = tuple(p.key for p in CONTROLLER_SCHEMA.params if "." not in p.key)


def gain_set_values(config: ControllerConfig) -> Dict[str, float]:
    """The live-tunable values of ``config`` as a gain set (name -> value, in the order of TUNABLES)."""
    values = dict(dataclasses.asdict(config.gains), tau_max=config.tau_max, t_rec=config.t_rec,
                  t_pow_max=config.t_pow_max)
    return {t.name: float(values[t.name]) for t in TUNABLES}


def config_tree(config: ControllerConfig, name: str) -> Dict[str, Any]:
    """A controller.yaml tree of ``config`` whose only gain set is ``name``: loaded with that set it gives
    ``config`` back."""
    tree: Dict[str, Any] = {"gain_sets": {name: gain_set_values(config)}}
    tree.update((key, getattr(config, key)) for key in _PLAIN)
    tree["pairs"] = [list(pair) for pair in config.pairs]  # YAML has no tuples
    tree["stroke"] = {"scheme": config.stroke_scheme, "coordinated": dataclasses.asdict(config.coordinated)}
    return tree


def _set_text(name: str, values: Dict[str, float], indent: str, note: str) -> List[str]:
    body = yaml.safe_dump({name: values}, default_flow_style=False, sort_keys=False).splitlines()
    return [indent + "# " + line for line in note.splitlines()] + [indent + line for line in body]


def _content(line: str) -> bool:
    """Whether a line holds YAML content (not blank, not a comment)."""
    return bool(line.strip()) and not line.lstrip().startswith("#")


def _indent(line: str) -> str:
    return line[:len(line) - len(line.lstrip())]


def _with_set(text: str, name: str, values: Dict[str, float], note: str) -> str:
    """``text`` (a controller.yaml) with the set ``name`` added to its block ``gain_sets:``, or put in place of
    the set of that name."""
    lines = text.splitlines()
    start = next((i for i, line in enumerate(lines) if re.match(r"^gain_sets:\s*(#.*)?$", line)), None)
    if start is None:
        raise ParameterError("no block 'gain_sets:' at the start of a line")
    end = start + 1  # one past the last line of the block
    for i in range(start + 1, len(lines)):
        if _content(lines[i]):
            if not lines[i][0].isspace():
                break
            end = i + 1
    children = [line for line in lines[start + 1:end] if _content(line)]
    indent = _indent(children[0]) if children else "  "
    at = end
    old = next((i for i in range(start + 1, end) if re.match(r"^%s%s\s*:" % (indent, re.escape(name)), lines[i])), None)
    if old is not None:  # its lines: up to the next sibling key (comments before that one are the sibling's)
        stop = old + 1
        for i in range(old + 1, end):
            if _content(lines[i]) and len(_indent(lines[i])) <= len(indent):
                break
            if _content(lines[i]):
                stop = i + 1
        del lines[old:stop]
        at = old
    lines[at:at] = _set_text(name, values, indent, note)
    return "\n".join(lines) + "\n"


def _check(tree: Any, name: str, config: ControllerConfig) -> ControllerConfig:
    """``tree`` loaded with gain set ``name`` as ``~gain_set`` loads it, checked to give ``config``'s values."""
    loaded = controller_config_from_dict(tree, name)
    if gain_set_values(loaded) != gain_set_values(config):
        raise ParameterError("gain set '%s' would load as %s, not %s" % (name, gain_set_values(loaded),
                                                                           gain_set_values(config)))
    return loaded


def _edited(text: str, config: ControllerConfig, path: str, name: str, overwrite: bool, note: str) -> Tuple[str, str]:
    """The text of the existing controller.yaml ``path`` (``text``) with the set added, and what was done."""
    tree = parse_yaml(text)
    sets = tree.get("gain_sets") if isinstance(tree, dict) else None
    if not isinstance(sets, dict):
        raise ParameterError("%s has no mapping gain_sets: not a controller.yaml" % path)
    if name in sets and not overwrite:
        raise ParameterError("%s already has a gain set '%s' (%s): choose another name, or set overwrite to replace "
                             "it" % (path, name, sets[name]))
    values = gain_set_values(config)
    try:
        new_text = _with_set(text, name, values, note)
        intended = dict(tree, gain_sets=dict(sets, **{name: values}))
        if parse_yaml(new_text) != intended:
            raise ParameterError("the edited text does not parse to the intended gain sets")
        scheme = _check(intended, name, config).stroke_scheme
    except ParameterError as exc:
        raise ParameterError("cannot add gain set '%s' to %s: %s; save to a new file instead" % (name, path, exc)) \
            from None
    done = "replaced in %s" % path if name in sets else "added to %s" % path
    if scheme != config.stroke_scheme:
        done += " (the stroke scheme %s is no part of a gain set: add stroke_scheme:=%s)" % (
            (config.stroke_scheme,) * 2)
    return new_text, done


def _new(config: ControllerConfig, name: str, note: str) -> str:
    """The text of a new controller.yaml: the configuration in force, with the one gain set ``name``."""
    tree = config_tree(config, name)
    rest = {key: value for key, value in tree.items() if key != "gain_sets"}
    text = "\n".join(["# Attitude controller configuration (config/controller.yaml's keys, docs/configuration.md).",
                      "", "gain_sets:"] + _set_text(name, tree["gain_sets"][name], "  ", note)) + "\n" + \
        yaml.safe_dump(rest, default_flow_style=None, sort_keys=False)
    if parse_yaml(text) != tree or _check(tree, name, config) != config:
        raise ParameterError("the written configuration would not load as the one in force")
    return text


def _write_atomically(path: str, text: str) -> None:
    """``text`` into ``path`` through a temporary file beside it (its mode kept, else 0644)."""
    handle, temporary = tempfile.mkstemp(prefix=".%s." % os.path.basename(path), dir=os.path.dirname(path))
    try:
        with os.fdopen(handle, "w", encoding="utf-8") as stream:
            stream.write(text)
        os.chmod(temporary, os.stat(path).st_mode & 0o7777 if os.path.exists(path) else 0o644)
        os.replace(temporary, path)
    except BaseException:
        if os.path.exists(temporary):
            os.unlink(temporary)
        raise


def save_gain_set(config: ControllerConfig, path: str, name: str, overwrite: bool = False, note: str = "",
                  shipped: Optional[str] = None) -> str:
    """Write the live-tunable values of ``config`` as gain set ``name`` to the controller.yaml ``path`` (module
    docstring: a new file, or a set added to an existing one); ``note``: a comment above the set;
    ``shipped``: the file never changed without ``overwrite`` (default: the package's
    config/controller.yaml). Returns what was done, in one line; ParameterError (nothing written) when
    refused, OSError when the file cannot be read or written."""
    if not _NAME.match(name or ""):
        raise ParameterError("gain set name %r: letters, digits and _ only, not starting with a digit" % (name,))
    if not os.path.isabs(path or ""):
        raise ParameterError("give an absolute path for the gain file, not %r" % (path,))
    if os.path.exists(path):
        if os.path.realpath(path) == os.path.realpath(shipped or config_path("controller.yaml")) and not overwrite:
            raise ParameterError("%s is the shipped configuration: save to a file of your own (then load it with "
                                 "controller_yaml:=FILE gain_set:=%s), or set overwrite to change it" % (path, name))
        with open(path, encoding="utf-8") as stream:
            text, done = _edited(stream.read(), config, path, name, overwrite, note)
    else:
        text, done = _new(config, name, note), "written to the new file %s" % path
        os.makedirs(os.path.dirname(path), exist_ok=True)
    _write_atomically(path, text)
    return "gain set '%s' (%s) %s: load it with controller_yaml:=%s gain_set:=%s" % (
        name, " ".join("%s %.6g" % kv for kv in gain_set_values(config).items()), done, path, name)
