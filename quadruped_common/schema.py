"""One declaration per configuration parameter, read by the loader, the range checks and the docs.

A :class:`Schema` is the table of one file in ``config/``: each :class:`Param` gives its yaml key (dotted; a
``<name>`` part stands for every key of a mapping whose keys the schema lists, e.g. ``joints.<joint>.min_us``),
type, unit, closed or open range, default when optional, source tag and meaning. :meth:`Schema.read` checks a
parsed file against it (no unknown or missing key, every value typed and in range; ParameterError naming the
key) and :meth:`Schema.table` is the file's table in docs/configuration.md (a test keeps the two equal). Checks
that tie several values together stay in each file's builder.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Union

from quadruped_common.config import ParameterError, boolean, check_keys, integer, number, string, vector

__all__ = ["Param", "Schema", "range_text"]

#: Where a value comes from (the tags the configuration files' comments use).
SOURCES = ("paper", "estimate", "choice", "")
KINDS = ("number", "integer", "boolean", "string", "vector", "list")


@dataclass(frozen=True)
class Param:
    """One parameter: ``key`` in the file, ``unit``, ``meaning``, ``kind`` (number, integer, boolean, string,
    vector of ``length`` numbers, or list: any YAML list, checked by its builder), range [low, high] (ends open on
    request; per item for a vector), ``choices`` of a string, ``default`` (None: required, unless ``optional``:
    then an absent value reads as None), ``source`` tag, and ``check``: a further test of the value (its
    problem, or None)."""

    key: str
    unit: str
    meaning: str
    low: float = -math.inf
    high: float = math.inf
    kind: str = "number"
    length: Optional[int] = None
    choices: Tuple[str, ...] = ()
    low_open: bool = False
    high_open: bool = False
    default: Any = None
    source: str = ""
    check: Optional[Callable[[Any], Optional[str]]] = None
    optional: bool = False

    def __post_init__(self) -> None:
        if self.kind not in KINDS or self.source not in SOURCES:
            raise ValueError("parameter %s: kind %r / source %r unknown" % (self.key, self.kind, self.source))

    @property
    def required(self) -> bool:
        """Must the file hold it (no default)?"""
        return self.default is None and not self.optional

    def read(self, value: Any, key: str, what: str = "parameter") -> Any:
        """``value`` as this parameter's type within its range; ParameterError naming ``key`` otherwise."""
        if self.kind == "boolean":
            result: Any = boolean(value, key, what=what)
        elif self.kind == "integer":
            result = integer(value, key, int(max(self.low, -2 ** 63)), int(min(self.high, 2 ** 63)), what=what)
        elif self.kind == "string":
            result = string(value, key, self.choices or None, what=what)
        elif self.kind == "vector":
            result = vector(value, key, self.length, what=what)
            for i, item in enumerate(result):
                number(item, "%s[%d]" % (key, i), self.low, self.high, self.low_open, self.high_open, what=what)
        elif self.kind == "list":
            if not isinstance(value, list):
                raise ParameterError("%s '%s' must be a list, got %r" % (what, key, value))
            result = value
        else:
            result = number(value, key, self.low, self.high, self.low_open, self.high_open, what=what)
        problem = self.check(result) if self.check is not None else None
        if problem:
            raise ParameterError("%s '%s' = %r: %s" % (what, key, value, problem))
        return result


def range_text(low: float, high: float, low_open: bool = False, high_open: bool = False) -> str:
    """``[low, high]`` with open ends as parentheses; ``any`` when unbounded."""
    if low == -math.inf and high == math.inf:
        return "any"
    return "%s%g, %g%s" % ("(" if low_open else "[", low, high, ")" if high_open else "]")


_Node = Dict[str, Union["_Node", Param]]


class Schema:
    """The parameters of one configuration file (module docstring). ``names`` lists the keys each ``<name>``
    part of a key stands for; all of them must be present in the file (None: named freely, every key the
    file's mapping holds). ``what`` starts the messages' noun ("missing <what> 'key'")."""

    def __init__(self, file: str, params: Sequence[Param],
                 names: Optional[Mapping[str, Optional[Sequence[str]]]] = None, what: str = "parameter"):
        self.file = file
        self.what = what
        self.params: Tuple[Param, ...] = tuple(params)
        self.names: Dict[str, Optional[Tuple[str, ...]]] = {
            k: None if v is None else tuple(v) for k, v in (names or {}).items()}
        self._root: _Node = {}
        for param in self.params:
            node = self._root
            parts = param.key.split(".")
            for part in parts[:-1]:
                child = node.setdefault(part, {})
                if isinstance(child, Param):
                    raise ValueError("%s: %s is both a parameter and a section" % (file, part))
                node = child
            if parts[-1] in node:
                raise ValueError("%s: parameter %s declared twice" % (file, param.key))
            node[parts[-1]] = param
            for part in parts:
                if part.startswith("<") and part[1:-1] not in self.names:
                    raise ValueError("%s: no names for %s in %s" % (file, part, param.key))

    def __getitem__(self, key: str) -> Param:
        """The parameter whose key (as declared, with ``<name>`` parts) is ``key``."""
        for param in self.params:
            if param.key == key:
                return param
        raise KeyError(key)

    def read(self, tree: Any) -> Dict[str, Any]:
        """Every parameter's value from a parsed file, by key with ``<name>`` parts filled in (defaults for the
        optional ones it does not hold); ParameterError naming the key on any problem."""
        values: Dict[str, Any] = {}
        self._walk(tree, "", self._root, values)
        return values

    def _walk(self, tree: Any, prefix: str, node: _Node, out: Dict[str, Any]) -> None:
        wildcard = next((part for part in node if part.startswith("<")), None)
        if wildcard is not None:
            names = self.names[wildcard[1:-1]]
            if names is None:  # named freely: the keys the file holds
                names = tuple(tree) if isinstance(tree, Mapping) else ()
            tree = check_keys(tree, prefix.rstrip("."), names, names, what=self.what)
            children: List[Tuple[str, Any]] = [(name, node[wildcard]) for name in names]
        else:
            if tree is None and prefix and not _any_required(node):
                tree = {}  # an empty optional section: its defaults
            required = [part for part, child in node.items() if isinstance(child, Param) and child.required]
            tree = check_keys(tree, prefix.rstrip("."), list(node), required, what=self.what)
            children = list(node.items())
        for part, child in children:
            key = prefix + part
            if isinstance(child, Param):
                out[key] = child.read(tree[part], key, self.what) if part in tree else child.default
            else:  # a missing section: its first missing parameter is named
                self._walk(tree.get(part, {}), key + ".", child, out)

    def table(self) -> str:
        """The file's parameters as a Markdown table (docs/configuration.md)."""
        lines = ["| key | unit | range | default | source | meaning |", "|---|---|---|---|---|---|"]
        for p in self.params:
            if p.kind == "string" and p.choices:
                span = " / ".join(p.choices)
            elif p.kind in ("number", "integer", "vector"):
                span = range_text(p.low, p.high, p.low_open, p.high_open)
                span = span if p.length is None else "%d x %s" % (p.length, span)
            else:
                span = p.kind
            shown = str(p.default).lower() if isinstance(p.default, bool) else p.default  # YAML's spelling
            default = "required" if p.required else "optional" if p.default is None else "`%s`" % (shown,)
            lines.append("| `%s` | %s | %s | %s | %s | %s |" % (p.key, p.unit or "-", span, default,
                                                               p.source or "-", p.meaning.replace("|", "/")))
        return "\n".join(lines) + "\n"


def _any_required(node: Union[_Node, Param]) -> bool:
    if isinstance(node, Param):
        return node.required
    return any(_any_required(child) for child in node.values())
