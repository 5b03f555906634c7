"""The diagnostic_aggregator analyzer file (``config/diagnostics_analyzers.yaml``): validation and the
matching rules of diagnostic_aggregator's GenericAnalyzer, so tests can check that every status the
stack publishes lands in exactly one analyzer without running the aggregator. No rospy.

GenericAnalyzer matches a status whose name (leading '/' removed) equals one of ``name`` / ``expected``,
starts with one of ``startswith``, contains one of ``contains``, or matches one of ``regex``
(``re.search``). AnalyzerGroup nests analyzers under its ``path``.
"""
from __future__ import annotations

import re
from typing import Any, Dict, List, Mapping, Optional

from quadruped_common.config import ParameterError, config_path, load_yaml

GENERIC = "diagnostic_aggregator/GenericAnalyzer"
GROUP = "diagnostic_aggregator/AnalyzerGroup"
MATCHERS = ("name", "expected", "startswith", "contains", "regex")


def _strings(spec: Mapping[str, Any], key: str, where: str) -> List[str]:
    value = spec.get(key, [])
    value = [value] if isinstance(value, str) else value
    if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
        raise ParameterError("%s: '%s' must be a string or a list of non-empty strings, got %r" % (where, key, value))
    return value


def validate_analyzers(tree: Mapping[str, Any], where: str = "analyzers") -> Dict[str, Any]:
    """Check every analyzer (type, path, at least one matcher, valid regexes); the tree unchanged."""
    if not isinstance(tree, Mapping) or not tree:
        raise ParameterError("%s must be a non-empty mapping of analyzers" % where)
    for key, spec in tree.items():
        here = "%s.%s" % (where, key)
        if not isinstance(spec, Mapping):
            raise ParameterError("%s must be a mapping" % here)
        if not isinstance(spec.get("path"), str) or not spec["path"]:
            raise ParameterError("%s needs a 'path'" % here)
        kind = spec.get("type")
        if kind == GROUP:
            validate_analyzers(spec.get("analyzers"), here + ".analyzers")
        elif kind == GENERIC:
            if not any(_strings(spec, m, here) for m in MATCHERS):
                raise ParameterError("%s matches nothing: give one of %s" % (here, ", ".join(MATCHERS)))
            for pattern in _strings(spec, "regex", here):
                try:
                    re.compile(pattern)
                except re.error as exc:
                    raise ParameterError("%s: bad regex %r: %s" % (here, pattern, exc)) from None
        else:
            raise ParameterError("%s: type must be %s or %s, got %r" % (here, GENERIC, GROUP, kind))
    return dict(tree)


def load_analyzers(path: Optional[str] = None) -> Dict[str, Any]:
    """The ``analyzers`` mapping of the analyzer file (default: the package's config/)."""
    path = path or config_path("diagnostics_analyzers.yaml")
    tree = load_yaml(path)
    if "analyzers" not in tree:
        raise ParameterError("%s: missing 'analyzers'" % path)
    try:
        return validate_analyzers(tree["analyzers"])
    except ParameterError as exc:
        raise ParameterError("%s: %s" % (path, exc)) from None


def matching_paths(status_name: str, analyzers: Mapping[str, Any], prefix: str = "") -> List[str]:
    """Paths (e.g. ``/Sensors/IMU (VN-100)``) of every GenericAnalyzer that takes ``status_name``."""
    name = status_name.lstrip("/")
    found = []
    for spec in analyzers.values():
        path = "%s/%s" % (prefix, spec["path"])
        if spec["type"] == GROUP:
            found.extend(matching_paths(name, spec["analyzers"], path))
            continue
        if (name in spec.get("name", []) + spec.get("expected", [])
                or any(name.startswith(s) for s in _strings(spec, "startswith", path))
                or any(s in name for s in _strings(spec, "contains", path))
                or any(re.search(r, name) for r in _strings(spec, "regex", path))):
            found.append(path)
    return found
