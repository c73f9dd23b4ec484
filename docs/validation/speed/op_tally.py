"""Static tally of the arithmetic operators and calls in the averaged step's scalar kernels (all branches).

``python docs/validation/speed/op_tally.py``: for each function, the ``ast.BinOp`` nodes by operator (and
augmented assignments) and the calls by name in its source, the check of the hand count in README.md here
(which takes one branch, folds constants and counts a repeated subexpression once).
"""

import ast
import inspect

from pectoral_gym.model import dynamics, stepping

FUNCTIONS = {stepping: ("_rotate", "_rk4", "_stable_step", "_driven"),
             dynamics: ("_undamped_accel", "body_accel", "oscillating_square_mean", "rate_bound")}


def tally(function) -> tuple[dict[str, int], dict[str, int]]:
    """Operators and calls in the source of ``function`` (a numba dispatcher's Python function)."""
    tree = ast.parse(inspect.getsource(getattr(function, "py_func", function)))
    operators: dict[str, int] = {}
    calls: dict[str, int] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.BinOp | ast.AugAssign):
            name = type(node.op).__name__ + ("=" if isinstance(node, ast.AugAssign) else "")
            operators[name] = operators.get(name, 0) + 1
        elif isinstance(node, ast.Call):
            func = node.func
            name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "?")
            calls[name] = calls.get(name, 0) + 1
    return operators, calls


for module, names in FUNCTIONS.items():
    for name in names:
        operators, calls = tally(getattr(module, name))
        print(f"{name:24s} {sum(operators.values()):4d} operators {operators}  calls {calls}")
