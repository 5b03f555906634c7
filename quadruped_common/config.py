"""The one strict YAML loader of every configuration file, and the typed accessors the schemas use.

Every file in ``config/`` (robot, controller, hardware, servo calibration, simulation, vn100) is read by
:func:`load_yaml` and turned into a typed, validated object by a ``*_from_dict`` builder through
:func:`load_config`. Whatever is in the file, the result is either that object or a
:class:`ParameterError` whose message starts with the file name and names the key (dotted path, list
items as ``key[3]``); never a raw traceback, never a silently wrong value:

* the file: at most :data:`MAX_FILE_BYTES`, UTF-8 (a BOM is allowed), one YAML document whose top level
  is a mapping;
* keys: plain strings only (``1:``, ``true:``, ``null:``, merge keys ``<<`` and complex keys are refused:
  mixed key types break lookups), no key twice in one mapping (YAML's "last one wins" silently replaced
  e.g. ``body.mass`` 4.9 by a second 49.0);
* values: null, booleans, integers up to 2**63, floats, strings, lists and mappings only (no
  timestamps, binary, sets, custom tags); no aliases (``*name``: recursion and "billion laughs"
  bombs), nesting at most :data:`MAX_DEPTH` deep.

The typed accessors (:func:`number`, :func:`integer`, :func:`boolean`, :func:`string`,
:func:`vector`, :func:`check_keys`) refuse bool-for-number, NaN/inf unless allowed, and anything outside
its closed bounds, naming the key.

Where the files live is decided by :func:`config_dir` alone.
"""
from __future__ import annotations

import functools
import logging
import math
import os
from typing import Any, Callable, Collection, Dict, List, Mapping, Optional, Sequence, TypeVar

import yaml
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode

__all__ = [
    "MAX_DEPTH",
    "MAX_FILE_BYTES",
    "ParameterError",
    "boolean",
    "check_keys",
    "config_dir",
    "config_path",
    "integer",
    "load_config",
    "load_yaml",
    "lookup",
    "number",
    "parse_yaml",
    "string",
    "vector",
]

T = TypeVar("T")

#: Largest configuration file accepted (the biggest real one is a few kB).
MAX_FILE_BYTES = 1 << 20
#: Deepest nesting of lists/mappings accepted (the real files nest 3 deep).
MAX_DEPTH = 32
#: Largest integer magnitude accepted (digits are checked before conversion).
MAX_INT = 1 << 63

_TAG = "tag:yaml.org,2002:"


class ParameterError(ValueError):
    """A configuration value is missing, malformed or physically impossible."""


#: The catkin package whose ``config/`` folder holds the default configuration files.
PACKAGE = "underwater_quadruped"


@functools.lru_cache(maxsize=None)
def config_dir() -> str:
    """The package's ``config/`` folder, from the same tree as this code.

    A source tree or devel space: ``config/`` beside the Python packages. An install space
    (``<prefix>/lib/python3/dist-packages``): ``<prefix>/share/underwater_quadruped/config``. Only when
    neither exists is the ROS package path asked (rospkg). When the ROS package path names another tree
    (a second checkout or worktree with another workspace sourced), this code's own tree still wins and
    the mismatch is logged once as a warning. ParameterError when no ``config/`` is found.
    """
    return _find_config_dir(os.path.abspath(__file__))


def _own_config_dirs(module_file: str) -> List[str]:
    """Where the tree that holds ``module_file`` (this module) keeps ``config/``: source tree, install space."""
    packages = os.path.dirname(os.path.dirname(module_file))
    candidates = [os.path.join(packages, "config")]
    parts = packages.split(os.sep)
    if len(parts) >= 3 and parts[-3] == "lib" and parts[-1] in ("dist-packages", "site-packages"):
        prefix = os.sep.join(parts[:-3])
        candidates.append(os.path.join(prefix, "share", PACKAGE, "config"))
    return candidates


def _ros_package_config_dir(tried: List[str]) -> Optional[str]:
    """``config/`` of the package on ROS_PACKAGE_PATH, or None (the reason appended to ``tried``)."""
    try:
        import rospkg  # pylint: disable=import-outside-toplevel (optional: ROS's package path)
    except ImportError:
        tried.append("rospkg not importable")
        return None
    try:
        candidate = os.path.join(rospkg.RosPack().get_path(PACKAGE), "config")
    except rospkg.ResourceNotFound:
        tried.append("package %s not on ROS_PACKAGE_PATH" % PACKAGE)
        return None
    if os.path.isdir(candidate):
        return candidate
    tried.append("%s has no config/ folder" % os.path.dirname(candidate))
    return None


def _find_config_dir(module_file: str) -> str:
    tried: List[str] = []
    own = next((d for d in _own_config_dirs(module_file) if os.path.isdir(d)), None)
    ros = _ros_package_config_dir(tried)
    if own is not None:
        if ros is not None and os.path.realpath(ros) != os.path.realpath(own):
            logging.getLogger(__name__).warning(
                "configuration read from %s, the tree of this code; the ROS package path names another "
                "tree, %s, whose config/ is not used", own, ros)
        return own
    if ros is not None:
        return ros
    tried.extend("no %s" % d for d in _own_config_dirs(module_file))
    raise ParameterError("cannot find the config/ folder of %s (%s)" % (PACKAGE, "; ".join(tried)))


def config_path(name: str) -> str:
    """Absolute path of a file in the package's ``config/`` folder."""
    return os.path.join(config_dir(), name)


# --------------------------------------------------------------------------------------------------
# Parsing
# --------------------------------------------------------------------------------------------------

class _Refused(Exception):
    """Internal: the document is well-formed YAML but not an acceptable configuration."""


class _Composer(yaml.SafeLoader):
    """PyYAML's safe composer, refusing aliases and limiting the nesting depth."""

    def __init__(self, stream: str) -> None:
        super().__init__(stream)
        self._depth = 0

    def compose_node(self, parent: Optional[Node], index: Any) -> Node:  # type: ignore[override]
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            raise _Refused("line %d: aliases (*%s) are not allowed in configuration files"
                           % (event.start_mark.line + 1, event.anchor))
        self._depth += 1
        try:
            if self._depth > MAX_DEPTH:
                raise _Refused("line %d: nested more than %d levels deep"
                               % (self.peek_event().start_mark.line + 1, MAX_DEPTH))
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1


def _where(path: str) -> str:
    return "'%s'" % path if path else "the top level"


def _scalar(node: ScalarNode, path: str, constructor: yaml.constructor.SafeConstructor) -> Any:
    tag = node.tag
    line = node.start_mark.line + 1
    if tag == _TAG + "str":
        return node.value
    if tag == _TAG + "null":
        return None
    if tag == _TAG + "bool":
        return constructor.construct_yaml_bool(node)
    if tag == _TAG + "int":
        digits = sum(ch.isdigit() for ch in node.value)
        value = None if digits > 40 else constructor.construct_yaml_int(node)
        if value is None or abs(value) > MAX_INT:
            raise _Refused("%s (line %d): integer %s... is too large" % (_where(path), line, node.value[:20]))
        return value
    if tag == _TAG + "float":
        return constructor.construct_yaml_float(node)
    raise _Refused("%s (line %d): unsupported YAML type %s" % (_where(path), line, tag))


def _build(node: Node, path: str, constructor: yaml.constructor.SafeConstructor) -> Any:
    if isinstance(node, ScalarNode):
        return _scalar(node, path, constructor)
    if isinstance(node, SequenceNode):
        if node.tag != _TAG + "seq":
            raise _Refused("%s: unsupported YAML type %s" % (_where(path), node.tag))
        return [_build(item, "%s[%d]" % (path, index), constructor) for index, item in enumerate(node.value)]
    if isinstance(node, MappingNode):
        if node.tag != _TAG + "map":
            raise _Refused("%s: unsupported YAML type %s" % (_where(path), node.tag))
        out: Dict[str, Any] = {}
        first_line: Dict[str, int] = {}
        for key_node, value_node in node.value:
            line = key_node.start_mark.line + 1
            if not (isinstance(key_node, ScalarNode) and key_node.tag == _TAG + "str"):
                shown = key_node.value if isinstance(key_node, ScalarNode) else "(a %s)" % type(key_node).__name__
                raise _Refused("%s (line %d): key %r is not a string (quote it, e.g. \"%s\":)"
                               % (_where(path), line, shown, shown))
            key = key_node.value
            dotted = "%s.%s" % (path, key) if path else key
            if key in out:
                raise _Refused("duplicate key '%s' (line %d; first at line %d)" % (dotted, line, first_line[key]))
            first_line[key] = line
            out[key] = _build(value_node, dotted, constructor)
        return out
    raise _Refused("%s: unsupported YAML node %r" % (_where(path), node))  # pragma: no cover


def parse_yaml(text: str) -> Any:
    """Parse one YAML document under the rules of the module docstring (ParameterError, no file name)."""
    loader = _Composer(text)
    try:
        node = loader.get_single_node()
        if node is None:
            return None
        return _build(node, "", yaml.constructor.SafeConstructor())
    except _Refused as exc:
        raise ParameterError(str(exc)) from None
    except yaml.YAMLError as exc:
        raise ParameterError("not valid YAML: %s" % exc) from None
    except RecursionError:  # pragma: no cover - MAX_DEPTH stops it first
        raise ParameterError("nested too deeply") from None
    finally:
        loader.dispose()


def load_yaml(path: str) -> Dict[str, Any]:
    """Read a configuration file into plain dicts/lists/scalars; ParameterError "<path>: ..." on any problem."""
    try:
        with open(path, "rb") as stream:
            raw = stream.read(MAX_FILE_BYTES + 1)
    except (OSError, ValueError) as exc:
        raise ParameterError("cannot read %s: %s" % (path, exc)) from None
    if len(raw) > MAX_FILE_BYTES:
        raise ParameterError("%s: larger than %d bytes, not a configuration file" % (path, MAX_FILE_BYTES))
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ParameterError("%s: not UTF-8 text (byte 0x%02x at offset %d)"
                             % (path, raw[exc.start], exc.start)) from None
    try:
        data = parse_yaml(text)
    except ParameterError as exc:
        raise ParameterError("%s: %s" % (path, exc)) from None
    if not isinstance(data, dict):
        raise ParameterError("%s: must contain a mapping at the top level" % path)
    return data


def load_config(path: Optional[str], default_name: str, build: Callable[[Dict[str, Any]], T]) -> T:
    """Read ``path`` (default: ``default_name`` in :func:`config_dir`) and ``build`` the typed object from it.

    Every ParameterError names the file (once); any other exception of a builder on a malformed tree
    (a schema that missed a case) is turned into a ParameterError naming the file as well.
    """
    path = path or config_path(default_name)
    tree = load_yaml(path)
    try:
        return build(tree)
    except ParameterError as exc:
        if path in str(exc):
            raise
        raise ParameterError("%s: %s" % (path, exc)) from None
    except (TypeError, ValueError, KeyError, IndexError, AttributeError, OverflowError, ZeroDivisionError) as exc:
        raise ParameterError("%s: invalid configuration (%s: %s)" % (path, type(exc).__name__, exc)) from None


# --------------------------------------------------------------------------------------------------
# Typed accessors (used by every schema)
# --------------------------------------------------------------------------------------------------

def lookup(tree: Mapping[str, Any], dotted: str, what: str = "parameter") -> Any:
    """The value at ``dotted`` ("a.b.c") in a parsed YAML tree; ParameterError "missing <what> ..." if absent."""
    node: Any = tree
    for part in dotted.split("."):
        if not isinstance(node, Mapping) or part not in node:
            raise ParameterError("missing %s '%s'" % (what, dotted))
        node = node[part]
    return node


def number(value: Any, key: str, low: float = -math.inf, high: float = math.inf, low_open: bool = False,
           high_open: bool = False, what: str = "parameter") -> float:
    """``value`` as a finite float within [low, high] (ends open on request); ParameterError naming ``key``.

    Booleans are not numbers here (YAML ``true`` is not 1).
    """
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ParameterError("%s '%s' must be a number, got %r" % (what, key, value))
    try:
        result = float(value)
    except OverflowError:
        raise ParameterError("%s '%s' = %d is too large" % (what, key, value)) from None
    if not math.isfinite(result):
        raise ParameterError("%s '%s' must be finite, got %r" % (what, key, value))
    if (result <= low if low_open else result < low) or (result >= high if high_open else result > high):
        raise ParameterError("%s '%s' = %g is outside %s%g, %g%s" % (what, key, result, "(" if low_open else "[",
                                                                     low, high, ")" if high_open else "]"))
    return result


def integer(value: Any, key: str, low: int, high: int, what: str = "parameter") -> int:
    """``value`` as an int within [low, high]; ParameterError naming ``key`` (bools and floats refused)."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise ParameterError("%s '%s' must be an integer, got %r" % (what, key, value))
    if not low <= value <= high:
        raise ParameterError("%s '%s' = %d is outside [%d, %d]" % (what, key, value, low, high))
    return int(value)


def boolean(value: Any, key: str, what: str = "parameter") -> bool:
    """``value`` if it is true or false; ParameterError naming ``key`` otherwise (1/0 refused)."""
    if not isinstance(value, bool):
        raise ParameterError("%s '%s' must be true or false, got %r" % (what, key, value))
    return value


def string(value: Any, key: str, choices: Optional[Collection[str]] = None, what: str = "parameter") -> str:
    """``value`` if it is a non-empty string (one of ``choices`` when given); ParameterError otherwise."""
    if not isinstance(value, str) or not value:
        raise ParameterError("%s '%s' must be a non-empty string, got %r" % (what, key, value))
    if choices is not None and value not in choices:
        raise ParameterError("%s '%s' must be one of %s, got %r" % (what, key, ", ".join(sorted(choices)), value))
    return value


def vector(value: Any, key: str, length: Optional[int] = None, low: float = -math.inf, high: float = math.inf,
           what: str = "parameter") -> List[float]:
    """``value`` as a list of finite floats in [low, high] (``length`` of them when given)."""
    if not isinstance(value, Sequence) or isinstance(value, str) or (length is not None and len(value) != length):
        raise ParameterError("%s '%s' must be a list of %s numbers, got %r"
                             % (what, key, length if length is not None else "", value))
    return [number(item, "%s[%d]" % (key, index), low, high, what=what) for index, item in enumerate(value)]


def check_keys(tree: Any, key: str, allowed: Collection[str], required: Collection[str] = (),
               what: str = "parameter") -> Mapping[str, Any]:
    """``tree`` if it is a mapping whose keys are all in ``allowed`` and include ``required``."""
    if not isinstance(tree, Mapping):
        raise ParameterError("%s '%s' must be a mapping, got %r" % (what, key or "(top level)", tree))
    prefix = key + "." if key else ""
    for name in tree:
        if name not in allowed:
            raise ParameterError("unknown %s '%s%s' (allowed: %s)" % (what, prefix, name, ", ".join(sorted(allowed))))
    for name in required:
        if name not in tree:
            raise ParameterError("missing %s '%s%s'" % (what, prefix, name))
    return tree
