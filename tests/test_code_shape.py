"""The code on the robot's path reads as the paper: no function in control/ or model/ returns more than six
values as a bare tuple (a named tuple, one value with named fields, is how a larger result travels)."""
import ast
import os
from typing import List

from tests.repo import REPO_ROOT

#: the folders of what runs on the robot's control path
ROBOT_PATH = (os.path.join("quadruped_control", "control"), os.path.join("quadruped_control", "model"))
MOST_VALUES = 6


def long_returns(source: str, name: str) -> List[str]:
    """``name:line`` of each return of ``source`` whose value holds a tuple literal of more than MOST_VALUES."""
    found = []
    for node in ast.walk(ast.parse(source, name)):
        if isinstance(node, ast.Return) and node.value is not None:
            if any(isinstance(sub, ast.Tuple) and len(sub.elts) > MOST_VALUES for sub in ast.walk(node.value)):
                found.append("%s:%d" % (name, node.lineno))
    return found


def test_no_function_on_the_robots_path_returns_more_than_six_values() -> None:
    found = []
    for folder in ROBOT_PATH:
        for root, _dirs, files in os.walk(os.path.join(REPO_ROOT, folder)):
            for file in sorted(f for f in files if f.endswith(".py")):
                path = os.path.join(root, file)
                with open(path, encoding="utf-8") as stream:
                    found += long_returns(stream.read(), os.path.relpath(path, REPO_ROOT))
    assert found == [], "bare tuples of more than %d values returned (name them): %s" % (MOST_VALUES, found)


def test_the_check_bites() -> None:
    assert long_returns("def f():\n    return 1, 2, 3, 4, 5, 6, 7\n", "m.py") == ["m.py:2"]
    assert long_returns("def f():\n    return g((1, 2, 3, 4, 5, 6, 7))\n", "m.py") == ["m.py:2"]
    assert long_returns("def f():\n    return Row(1, 2, 3, 4, 5, 6, 7)\n", "m.py") == []
