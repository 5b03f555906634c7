"""Every command the README and the docs pages it leads to show works as written, so they cannot rot.

Each ```bash / ```sh fence of DOCUMENTS is split into commands, and each command goes to a check:

* ``python -m MODULE ARGS`` and ``.venv/bin/python benchmarks/X.py ARGS``: ``--help`` runs under this
  interpreter (the venv's), and ARGS are parsed by the module's own argparse parser (nothing else of the
  program runs), so a flag or a positional the parser does not take fails;
* ``rosrun underwater_quadruped NODE _param:=v``: ``nodes/NODE`` exists, and the module it runs reads
  ``~param``;
* ``roslaunch underwater_quadruped X.launch a:=b``: every ``a`` is an ``<arg>`` of ``launch/X.launch``,
  and every ``<arg>`` without a default is given;
* ``make TARGET``: a target of the Makefile; ``bash scripts/X.sh --flag``: the script exists and handles
  ``--flag``; ``--rostest NAME``: ``tests/rostest/NAME.test`` exists;
* ``rosservice call`` / ``rostopic pub`` / ``rostopic echo`` / ``rqt_plot`` / ``rosmsg show``: the node,
  its service, the topic (subscribed, or published) with that type, the message and its field are in the
  code;
* shell set-up lines (``source``, ``export``, ``sudo cp``, ``rosdep``, ...) only have their repository
  paths checked.

Anything else fails as "command not covered by a check", so a new kind of command needs a new check.
The tables of the README (nodes and their parameters, launch files and their arguments) and every
relative link are checked against the code too. No ROS master is needed.

PYTEST_DONT_REWRITE: the checks' own messages say what is wrong; pytest's rewriting would bury them.
"""
from __future__ import annotations

import argparse
import contextlib
import glob
import importlib
import io
import os
import re
import runpy
import shlex
import sys
import warnings
import xml.etree.ElementTree as ET
from typing import Callable, Dict, List, Optional, Sequence, Tuple
from unittest import mock

import pytest
import yaml

from tests.repo import REPO_ROOT

PACKAGE = "underwater_quadruped"
#: the README and every docs page: the commands this file keeps honest
DOCUMENTS = ("README.md",) + tuple(sorted(os.path.relpath(p, REPO_ROOT)
                                          for p in glob.glob(os.path.join(REPO_ROOT, "docs", "*.md"))))
#: the README's contract: its first fence, exactly
TWO_COMMANDS = ["bash scripts/run_main.sh", "bash scripts/run_tests.sh"]
#: top folders of the repository: a token starting with one of these names a file that must exist
REPO_DIRS = ("benchmarks", "cfg", "config", "docs", "env-hooks", "launch", "nodes", "quadruped_common",
             "quadruped_control", "quadruped_drivers", "quadruped_msgs", "rosdep", "scripts", "tests", "urdf")
#: shell words that only set up the environment: their repository paths are checked, nothing else
SETUP_COMMANDS = ("cd", "mkdir", "echo", "tee", "export", "sudo", "udevadm", "usermod", "cp", "rosdep",
                  "catkin_make", "catkin", "git", "ls")
#: environment variables a command may set: ROS's own, and the project's (checked against scripts/)
ROS_ENVIRONMENT = ("ROS_MASTER_URI", "ROS_IP", "ROS_NAMESPACE", "ROS_HOSTNAME")


def read(path: str) -> str:
    with open(os.path.join(REPO_ROOT, path), encoding="utf-8") as stream:
        return stream.read()


# --- the documents' fences ------------------------------------------------------------------------

FENCE = re.compile(r"^```(\S*)[^\n]*\n(.*?)^```", re.M | re.S)


def fences(path: str) -> List[Tuple[str, str]]:
    """(language, body) of every fenced block of ``path``."""
    return [(match.group(1), match.group(2)) for match in FENCE.finditer(read(path))]


def command_lines(body: str) -> List[str]:
    """The commands of a shell fence: continuations joined, comments and blank lines left out."""
    return [line for line in (" ".join(part.strip() for part in chunk.split("\\\n"))
                              for chunk in re.split(r"(?<!\\)\n", body)) if line.strip()
            and not line.strip().startswith("#")]


def split_commands(line: str) -> List[List[str]]:
    """The simple commands of one line (split at ``&&``, ``;``, ``|``), each as its words."""
    lexer = shlex.shlex(line, posix=True, punctuation_chars=";&|")
    lexer.whitespace_split = True
    lexer.commenters = "#"
    commands: List[List[str]] = [[]]
    for word in lexer:
        if word in (";", "&&", "||", "|", "&"):
            commands.append([])
        else:
            commands[-1].append(word)
    return [words for words in commands if words]


def documented_commands() -> List[Tuple[str, str, List[str]]]:
    """(document, line, words) of every command of every shell fence of DOCUMENTS."""
    found = []
    for path in DOCUMENTS:
        if not os.path.exists(os.path.join(REPO_ROOT, path)):
            continue
        for language, body in fences(path):
            if language not in ("bash", "sh", "shell"):
                continue
            for line in command_lines(body):
                for words in split_commands(line):
                    found.append((path, line, words))
    return found


# --- what the repository declares ---------------------------------------------------------------

def module_path(module: str) -> Optional[str]:
    base = os.path.join(REPO_ROOT, *module.split("."))
    for candidate in (base + ".py", os.path.join(base, "__main__.py")):
        if os.path.exists(candidate):
            return candidate
    return None


def node_module(executable: str) -> str:
    """The module an executable of nodes/ runs (its ``from MODULE import main``)."""
    path = os.path.join(REPO_ROOT, "nodes", executable)
    assert os.path.exists(path), "no executable nodes/%s" % executable
    match = re.search(r"^from (\S+) import main", read(os.path.join("nodes", executable)), re.M)
    assert match, "nodes/%s does not say which module it runs" % executable
    return match.group(1)


def node_source(executable: str) -> str:
    module = node_module(executable)
    path = module_path(module)
    assert path, "nodes/%s runs %s, which does not exist" % (executable, module)
    return read(os.path.relpath(path, REPO_ROOT))


def launch_args(name: str) -> Dict[str, bool]:
    """The <arg>s of launch/NAME declared for the caller: name -> has a default."""
    path = os.path.join(REPO_ROOT, "launch", name)
    assert os.path.exists(path), "no launch file launch/%s" % name
    return {arg.get("name"): arg.get("default") is not None
            for arg in ET.parse(path).getroot().iter("arg") if arg.get("value") is None}


def launch_nodes() -> Dict[str, str]:
    """Node name -> executable, over every launch file of the package."""
    nodes = {}
    for path in glob.glob(os.path.join(REPO_ROOT, "launch", "*.launch")):
        for node in ET.parse(path).getroot().iter("node"):
            if node.get("pkg") == PACKAGE:
                nodes[node.get("name")] = node.get("type")
    return nodes


def make_targets() -> List[str]:
    return [name for name in re.findall(r"^([A-Za-z0-9_.-]+)\s*:(?!=)", read("Makefile"), re.M)
            if not name.startswith(".")]


def message_fields(message: str) -> Dict[str, str]:
    path = os.path.join("quadruped_msgs", "msg", message + ".msg")
    assert os.path.exists(os.path.join(REPO_ROOT, path)), "no message %s (%s)" % (message, path)
    fields = {}
    for line in read(path).splitlines():
        words = line.split("#")[0].split()
        if len(words) >= 2 and "=" not in words[1]:
            fields[words[1]] = words[0]
    return fields


def package_sources() -> str:
    texts = []
    for folder in ("quadruped_common", "quadruped_control", "quadruped_drivers"):
        for path in glob.glob(os.path.join(REPO_ROOT, folder, "**", "*.py"), recursive=True):
            with open(path, encoding="utf-8") as stream:
                texts.append(stream.read())
    return "\n".join(texts)


# --- running a program's own parser ------------------------------------------------------------------

class _Parsed(Exception):
    def __init__(self, namespace: argparse.Namespace, extras: List[str]):
        super().__init__("parsed")
        self.namespace, self.extras = namespace, extras


def parse_with_own_parser(run: Callable[[], object], argv: Sequence[str], program: str) -> argparse.Namespace:
    """Run a program until its (outermost) argparse parser has parsed ``argv``, and stop it there."""
    original = argparse.ArgumentParser.parse_known_args
    depth = [0]

    def parse_known_args(self, args=None, namespace=None):
        depth[0] += 1
        try:
            namespace, extras = original(self, args, namespace)
        finally:
            depth[0] -= 1
        if depth[0] == 0:
            raise _Parsed(namespace, extras)
        return namespace, extras

    errors = io.StringIO()
    with mock.patch.object(argparse.ArgumentParser, "parse_known_args", parse_known_args), \
            mock.patch.object(sys, "argv", [program] + list(argv)), contextlib.redirect_stderr(errors):
        try:
            run()
        except _Parsed as parsed:
            assert not parsed.extras, "%s does not take %s" % (program, " ".join(parsed.extras))
            return parsed.namespace
        except SystemExit as stop:
            raise AssertionError("%s %s: its parser refused the arguments (exit %s): %s"
                                 % (program, " ".join(argv), stop.code, errors.getvalue().strip()))
    raise AssertionError("%s never parsed its arguments" % program)


def run_module_as_main(module: str) -> None:
    """``python -m module``, in this process. pytest's assertion rewriter is set aside meanwhile: it claims
    modules named like tests (``studies/step_test.py``) and cannot hand their code to runpy."""
    finders = [finder for finder in sys.meta_path if type(finder).__name__ != "AssertionRewritingHook"]
    with mock.patch.object(sys, "meta_path", finders), warnings.catch_warnings():
        # runpy's note that the module was imported before (by another test) is no problem here
        warnings.filterwarnings("ignore", message=".*found in sys.modules", category=RuntimeWarning)
        runpy.run_module(module, run_name="__main__", alter_sys=False)


def check_help(run: Callable[[], object], program: str) -> None:
    """``program --help``, in this process (the venv's interpreter): it prints its usage and exits 0."""
    output, errors = io.StringIO(), io.StringIO()
    with mock.patch.object(sys, "argv", [program, "--help"]), contextlib.redirect_stdout(output), \
            contextlib.redirect_stderr(errors):
        try:
            run()
        except SystemExit as stop:
            assert stop.code in (0, None) and "usage" in output.getvalue(), \
                "%s --help failed (exit %s): %s" % (program, stop.code, errors.getvalue().strip()[-2000:])
            return
    raise AssertionError("%s --help did not stop after printing its usage" % program)


def check_python(words: List[str]) -> None:
    """``python -m MODULE ARGS`` / ``python FILE.py ARGS``: --help works, the parser takes ARGS."""
    rest = words[1:]
    if rest[:1] == ["-m"]:
        module, args = rest[1], rest[2:]
        if module == "pytest":
            for target in args:
                if not target.startswith("-"):
                    assert os.path.exists(os.path.join(REPO_ROOT, target.split("::")[0])), \
                        "pytest target %s does not exist" % target
            return
        assert module_path(module), "no module %s in the repository" % module
        check_help(lambda: run_module_as_main(module), module)
        parse_with_own_parser(lambda: run_module_as_main(module), args, module)
        return
    script, args = rest[0], rest[1:]
    assert script.endswith(".py") and os.path.exists(os.path.join(REPO_ROOT, script)), \
        "no script %s" % script
    source = read(script)
    if "ArgumentParser" not in source:  # a script without options: it must take none, and compile
        assert not args, "%s takes no arguments" % script
        compile(source, script, "exec")
        return
    check_help(lambda: runpy.run_path(os.path.join(REPO_ROOT, script), run_name="__main__"), script)
    parse_with_own_parser(lambda: runpy.run_path(os.path.join(REPO_ROOT, script), run_name="__main__"),
                          args, script)


def check_bash(words: List[str]) -> None:
    script, args = words[1], words[2:]
    path = os.path.join(REPO_ROOT, script)
    assert os.path.isfile(path), "no script %s" % script
    text = "\n".join(line for line in read(script).splitlines() if not line.lstrip().startswith("#"))
    for index, arg in enumerate(args):
        if arg.startswith("--"):
            flag = arg.split("=")[0]
            assert re.search(r"(^|[\s|(\"'])%s([\s|)\"'=]|$)" % re.escape(flag), text, re.M), \
                "%s does not handle %s" % (script, flag)
        if arg == "--rostest":
            name = args[index + 1]
            assert os.path.exists(os.path.join(REPO_ROOT, "tests", "rostest", name + ".test")), \
                "no rostest tests/rostest/%s.test" % name
    for arg in args:
        if not arg.startswith("-") and arg.split("/")[0] in REPO_DIRS:
            assert os.path.exists(os.path.join(REPO_ROOT, arg)), "%s: no file %s" % (script, arg)


def check_roslaunch(words: List[str]) -> None:
    args = [word for word in words[1:] if not word.startswith("-")]
    assert args[0] == PACKAGE, "roslaunch of another package: %s" % args[0]
    declared = launch_args(args[1])
    given = {}
    for arg in args[2:]:
        assert ":=" in arg, "%s: %s is not name:=value" % (args[1], arg)
        name, value = arg.split(":=", 1)
        assert name in declared, "%s has no argument %s (it has: %s)" % (args[1], name, ", ".join(sorted(declared)))
        given[name] = value
    missing = [name for name, has_default in declared.items() if not has_default and name not in given]
    assert not missing, "%s needs %s" % (args[1], ", ".join(missing))


def check_rosrun(words: List[str]) -> None:
    assert words[1] == PACKAGE, "rosrun of another package: %s" % words[1]
    source = node_source(words[2])
    for arg in words[3:]:
        if arg.startswith("_") and ":=" in arg:
            name = arg[1:].split(":=")[0]
            assert "~" + name in source, "%s does not read ~%s" % (words[2], name)


def service_request_fields(service: str) -> Dict[str, str]:
    """The request fields of the package's service type ``service`` (quadruped_msgs/srv/)."""
    path = os.path.join("quadruped_msgs", "srv", service + ".srv")
    assert os.path.exists(os.path.join(REPO_ROOT, path)), "no service type %s (%s)" % (service, path)
    fields = {}
    for line in read(path).split("---")[0].splitlines():
        words = line.split("#")[0].split()
        if len(words) >= 2 and "=" not in words[1]:
            fields[words[1]] = words[0]
    return fields


def check_rosservice(words: List[str]) -> None:
    assert words[1] == "call", "rosservice %s: only 'call' is checked" % words[1]
    parts = words[2].strip("/").split("/")
    assert len(parts) in (1, 2), "service %s: expected /service or /node/service" % words[2]
    if len(parts) == 1:  # a node's public service (relative name): Service("name", SetBool, ...)
        assert words[3:] and words[3] in ("true", "false"), "SetBool takes true or false, not %s" % words[3:]
        pattern = r"Service\(\s*[\"']%s[\"'],\s*SetBool" % re.escape(parts[0])
        assert re.search(pattern, package_sources()), \
            "no node offers the SetBool service %s" % words[2]
        return
    node, service = parts
    nodes = launch_nodes()
    assert node in nodes, "no node %s in launch/ (nodes: %s)" % (node, ", ".join(sorted(nodes)))
    offered = re.search(r"Service\(\s*[\"']~%s[\"'],\s*(\w+)" % re.escape(service), node_source(nodes[node]))
    assert offered, "%s has no SetBool service ~%s" % (node, service)
    kind = offered.group(1)
    if kind == "SetBool":
        assert words[3:] and words[3] in ("true", "false"), "SetBool takes true or false, not %s" % words[3:]
    elif kind == "Trigger":
        assert not words[3:], "Trigger takes no request, not %s" % words[3:]
    else:  # the package's own type (quadruped_msgs/srv/): a YAML mapping of its request's fields
        request = yaml.safe_load(words[3]) if words[3:] else {}
        fields = service_request_fields(kind)
        assert isinstance(request, dict) and set(request) <= set(fields), \
            "%s takes %s, not %s" % (kind, ", ".join(fields), words[3:])


def check_rostopic(words: List[str]) -> None:
    names = [word for word in words[2:] if word.startswith("/")]
    assert names, "rostopic %s: no /topic" % " ".join(words[1:])
    topic = names[0].lstrip("/")
    sources = package_sources()
    if words[1] == "pub":
        message = words[words.index(names[0]) + 1].split("/")[-1]
        assert re.search(r"Subscriber\(\s*[\"']%s[\"'],\s*%s\b" % (re.escape(topic), message), sources), \
            "nothing subscribes to %s as %s" % (topic, message)
    elif words[1] in ("echo", "hz"):
        assert re.search(r"Publisher\(\s*[\"']%s[\"']" % re.escape(topic), sources), "nothing publishes %s" % topic
    else:
        raise AssertionError("rostopic %s: not covered by a check" % words[1])


#: the field types rqt_plot draws
NUMERIC = re.compile(r"^(float(32|64)|u?int(8|16|32|64)|bool|byte|char)$")


def type_fields(message: str) -> Dict[str, str]:
    """Field name -> type (``pkg/Name`` or a primitive) of message type ``pkg/Name``: the package's own from
    quadruped_msgs/msg/, another package's from its generated Python class."""
    package, _, name = message.rpartition("/")
    if package == PACKAGE:
        return {field: kind if "/" in kind or not kind[:1].isupper() else
                ("std_msgs/Header" if kind == "Header" else "%s/%s" % (PACKAGE, kind))
                for field, kind in message_fields(name).items()}
    try:
        cls = getattr(importlib.import_module(package + ".msg"), name)
    except (ImportError, AttributeError):
        raise AssertionError("no Python message class %s (ROS's messages not installed?)" % message) from None
    return dict(zip(cls.__slots__, cls._slot_types))


def published_type(topic: str) -> Optional[str]:
    """``pkg/Name`` of what the package publishes on ``topic`` (Publisher("topic", Name)), None for nothing."""
    sources = package_sources()
    match = re.search(r"Publisher\(\s*[\"']%s[\"'],\s*(\w+)" % re.escape(topic), sources)
    if not match:
        return None
    name = match.group(1)
    if os.path.exists(os.path.join(REPO_ROOT, "quadruped_msgs", "msg", name + ".msg")):
        return "%s/%s" % (PACKAGE, name)
    imported = re.search(r"^from (\w+)\.msg import [^\n]*\b%s\b" % name, sources, re.M)
    assert imported, "%s is published as %s, imported from no message package" % (topic, name)
    return "%s/%s" % (imported.group(1), name)


def check_rqt_plot(words: List[str]) -> None:
    """Each /topic/field/...: the longest topic prefix the package publishes, its fields down to a number."""
    for arg in words[1:]:
        parts = arg.strip("/").split("/")
        found = [(k, published_type("/".join(parts[:k]))) for k in range(len(parts) - 1, 0, -1)]
        found = [(k, kind) for k, kind in found if kind]
        assert found, "nothing publishes %s" % arg
        k, kind = found[0]
        for field in parts[k:]:
            fields = type_fields(kind)
            assert field.split("[")[0] in fields, "%s has no field %s" % (kind, field)
            kind = fields[field.split("[")[0]].split("[")[0]
        assert NUMERIC.match(kind), "%s is a %s, not a number rqt_plot draws" % (arg, kind)


def check_rosmsg(words: List[str]) -> None:
    assert words[1] == "show"
    package, message = words[2].split("/")
    assert package == PACKAGE, "message of another package: %s" % words[2]
    message_fields(message)


def check_source(words: List[str]) -> None:
    target = words[1]
    if target.split("/")[0] in REPO_DIRS:
        assert os.path.isfile(os.path.join(REPO_ROOT, target)), "no file %s" % target
    else:  # a workspace's set-up: the one scripts/paths.sh makes (<clone>_ws) or an install prefix
        assert target.endswith("/setup.bash"), "source of %s: not covered by a check" % target
        if "_ws/" in target:
            assert "_ws}" in read("scripts/paths.sh"), "scripts/paths.sh no longer makes <clone>_ws"


def check_setup(words: List[str]) -> None:
    if words[0] == "export":
        for assignment in words[1:]:
            name = assignment.split("=")[0]
            assert project_variable(name), "export of %s: not a variable the stack reads" % name
    for word in words[1:]:
        if word.split("/")[0] in REPO_DIRS and "/" in word:
            assert os.path.exists(os.path.join(REPO_ROOT, word.split("=")[-1])), "no file %s" % word


def check_make(words: List[str]) -> None:
    targets = make_targets()
    for target in words[1:]:
        assert target in targets, "the Makefile has no target %s (it has: %s)" % (target, ", ".join(targets))


def project_variable(name: str) -> bool:
    """An environment variable the stack or its scripts read: ROS's own, or a UQ_* one of scripts/ or benchmarks/."""
    if name in ROS_ENVIRONMENT:
        return True
    scripts = (glob.glob(os.path.join(REPO_ROOT, "scripts", "*"))
               + glob.glob(os.path.join(REPO_ROOT, "benchmarks", "*.sh")))
    return name.startswith("UQ_") and any(name in read(os.path.relpath(path, REPO_ROOT)) for path in scripts)


def check(words: List[str]) -> None:
    while words and re.match(r"^[A-Z_][A-Z0-9_]*=", words[0]):  # VAR=value before a command
        name = words[0].split("=")[0]
        assert project_variable(name), "%s: not a variable the stack reads" % name
        words = words[1:]
    program = words[0]
    checker = CHECKS.get(program) or (check_setup if program in SETUP_COMMANDS else None)
    if checker is None:
        raise AssertionError("command not covered by a check: %s" % " ".join(words))
    checker(words)


#: the check of each program a documented command may start with
CHECKS: Dict[str, Callable[[List[str]], None]] = {
    "python": check_python, "python3": check_python, ".venv/bin/python": check_python, "bash": check_bash,
    "make": check_make, "roslaunch": check_roslaunch, "rosrun": check_rosrun, "rosservice": check_rosservice,
    "rostopic": check_rostopic, "rqt_plot": check_rqt_plot, "rosmsg": check_rosmsg, "source": check_source,
    ".": check_source,
}


COMMANDS = documented_commands()


@pytest.mark.parametrize("document, line, words", COMMANDS,
                         ids=["%s: %s" % (path, " ".join(words))[:120] for path, _, words in COMMANDS])
def test_documented_command(document: str, line: str, words: List[str]) -> None:
    try:
        check(words)
    except AssertionError as error:
        if str(error).startswith("command not covered"):
            pytest.fail("README command not covered by a check (%s): %s" % (document, " ".join(words)))
        raise AssertionError("%s: `%s`: %s" % (document, " ".join(words), error)) from None


def test_readme_starts_with_the_two_commands() -> None:
    language, body = fences("README.md")[0]
    assert language == "bash"
    assert [line.split("#")[0].strip() for line in command_lines(body)] == TWO_COMMANDS


def test_readme_is_short() -> None:
    assert len(read("README.md").splitlines()) <= 200


def test_every_fence_says_its_language() -> None:
    """A command cannot hide from the checks in an untagged fence; only shell fences hold commands."""
    for path in DOCUMENTS:
        if os.path.exists(os.path.join(REPO_ROOT, path)):
            for language, body in fences(path):
                assert language in ("bash", "sh", "shell", "text", "yaml", "xml"), \
                    "%s: a fence without a known language: %s" % (path, body[:80])


def test_no_path_outside_the_repository() -> None:
    for path in DOCUMENTS:
        if os.path.exists(os.path.join(REPO_ROOT, path)):
            text = read(path)
            assert "/work/" not in text and "../shared" not in text, "%s names a path outside the repository" % path


def test_links_resolve() -> None:
    for path in DOCUMENTS:
        if not os.path.exists(os.path.join(REPO_ROOT, path)):
            continue
        for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", read(path)):
            if "://" in target:
                continue
            resolved = os.path.normpath(os.path.join(REPO_ROOT, os.path.dirname(path), target))
            assert os.path.exists(resolved), "%s links to %s, which does not exist" % (path, target)


def test_docs_index_lists_every_page() -> None:
    index = read("docs/README.md")
    for page in sorted(glob.glob(os.path.join(REPO_ROOT, "docs", "*.md"))):
        name = os.path.basename(page)
        if name != "README.md":
            assert "(%s)" % name in index, "docs/README.md does not link %s" % name


def readme_table(heading: str) -> List[List[str]]:
    """The rows (cells) of the first table under the README's ``## heading``."""
    section = read("README.md").split("\n## %s\n" % heading, 1)[1].split("\n## ", 1)[0]
    rows = [line for line in section.splitlines() if line.startswith("|")]
    return [[cell.strip() for cell in row.strip("|").split("|")] for row in rows[2:]]


def test_node_table_matches_the_code() -> None:
    rows = readme_table("Nodes")
    nodes = launch_nodes()
    assert sorted(nodes) == sorted(re.match(r"`(\w+)`", row[0]).group(1) for row in rows), \
        "the node table and the launch files name different nodes"
    for row in rows:
        name = re.match(r"`(\w+)`", row[0]).group(1)
        executable = nodes[name]
        assert executable in row[0], "%s runs %s" % (name, executable)
        module = node_module(executable)
        assert row[1] == "`%s`" % os.path.relpath(module_path(module), REPO_ROOT), "%s is %s" % (name, module)
        source = node_source(executable)
        for topic in re.findall(r"`/?([a-z_]+(?:/[a-z_]+)?)`", row[2]):
            assert re.search(r"Subscriber\(\s*[\"']%s[\"']" % topic, source), "%s does not subscribe %s" % (name, topic)
        for topic in re.findall(r"`(/?[a-z_]+(?:/[a-z_]+)?)`", row[3]):
            assert re.search(r"Publisher\(\s*[\"']%s[\"']" % topic, source), "%s does not publish %s" % (name, topic)
        for service in re.findall(r"`~(\w+)`", row[4]):
            assert re.search(r"Service\(\s*[\"']~%s[\"']" % service, source), "%s has no service ~%s" % (name, service)
        for parameter in re.findall(r"`~(\w+)`", row[5]):
            assert "~" + parameter in source, "%s does not read ~%s" % (name, parameter)


def test_launch_table_matches_the_launch_files() -> None:
    listed = set()
    for row in readme_table("Launch files"):
        files = re.findall(r"`(\w+\.launch)`", row[0])
        arguments = [word for word in re.findall(r"`(\w+)`", row[2])]
        declared = set()
        for name in files:
            declared |= set(launch_args(name))
            listed.add(name)
        for argument in arguments:
            assert argument in declared, "%s has no argument %s" % (" / ".join(files), argument)
    on_disk = {os.path.basename(path) for path in glob.glob(os.path.join(REPO_ROOT, "launch", "*.launch"))}
    assert listed == on_disk, "launch files not in the README's table: %s" % sorted(on_disk - listed)


def test_config_table_covers_config() -> None:
    text = read("README.md")
    for path in sorted(glob.glob(os.path.join(REPO_ROOT, "config", "*"))):
        name = os.path.relpath(path, REPO_ROOT) + ("/" if os.path.isdir(path) else "")
        assert "`%s`" % name in text, "the README's configuration table does not say what %s holds" % name


def test_the_check_bites() -> None:
    """The checks fail on what they exist to catch, and say so."""
    bad = [("roslaunch underwater_quadruped sim.launch rol:=45", "has no argument rol"),
           ("roslaunch underwater_quadruped sim_maneuver.launch roll:=45", "needs bag_dir"),
           ("python -m quadruped_control.analysis.bag_report out/x.bag --out o --from-setpoint-change",
            "does not take --from-setpoint-change"),
           ("python -m quadruped_control.studies.step_test /data/bags/uq.bag out/step_test",
            "does not take out/step_test"),
           ("bash scripts/run_tests.sh --no-such-flag", "does not handle --no-such-flag"),
           ("bash scripts/run_tests.sh --rostest no_such_test", "no rostest"),
           ("make no-such-target", "no target no-such-target"),
           ("bash scripts/nothing.sh", "no script"),
           ("rosservice call /attitude_controller/disarm true", "no SetBool service ~disarm"),
           ("rosservice call /e_stop true", "no node offers the SetBool service /e_stop"),
           ("rosservice call /attitude_controller/save_gains '{file: /tmp/g.yaml}'", "SaveGains takes path"),
           ("rostopic pub -1 /attitude_setpoint geometry_msgs/Vector3Stamped '{}'", "nothing subscribes"),
           ("rqt_plot /controller_state/geodesic_err", "no field geodesic_err"),
           ("rqt_plot /telemetry/rpy_deg/vector/w", "no field w"),
           ("rqt_plot /telemetry/rpy_deg/vector", "not a number"),
           ("rosrun underwater_quadruped vn100_node _prot:=/dev/ttyUSB0", "does not read ~prot"),
           ("UQ_NO_SUCH_VARIABLE=1 bash scripts/run_main.sh", "not a variable"),
           ("curl http://example.org", "command not covered by a check")]
    for line, what in bad:
        with pytest.raises(AssertionError, match=re.escape(what)):
            check(split_commands(line)[0])
