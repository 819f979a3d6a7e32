"""The public API: what the packages list, and numpydoc on every public function.

Public means: listed in ``__all__`` of a module whose name has no leading
underscore (private modules such as ``markov.chain.kernels`` are internals).
"""
from __future__ import annotations

import ast
import importlib
import inspect
import pkgutil
import subprocess
import sys
import textwrap

import pytest

PACKAGES = ("markov", "symbolic", "nasch")


def _public_modules():
    out = []
    for pkg in PACKAGES:
        out.append(pkg)
        root = importlib.import_module(pkg)
        for info in pkgutil.walk_packages(root.__path__, prefix=f"{pkg}."):
            if not any(part.startswith("_") for part in info.name.split(".")):
                out.append(info.name)
    return out


def _public_functions():
    """Functions in ``__all__``, and the public methods of the classes there.

    A method that overrides one of a library class (click's ``Group``) keeps
    that library's documentation.
    """
    for name in _public_modules():
        module = importlib.import_module(name)
        for attr in getattr(module, "__all__", ()):
            obj = getattr(module, attr)
            if inspect.isfunction(obj) and obj.__module__ == name:
                yield f"{name}.{attr}", obj
            elif inspect.isclass(obj) and obj.__module__ == name:
                inherited = {m for base in obj.__mro__[1:]
                             if not base.__module__.startswith(PACKAGES) for m in vars(base)}
                for method, func in vars(obj).items():
                    if (inspect.isfunction(func) and not method.startswith("_")
                            and method not in inherited):
                        yield f"{name}.{attr}.{method}", func


def _returns_a_value(func) -> bool:
    """Whether the function's own body returns or yields something other than None."""
    body = ast.parse(textwrap.dedent(inspect.getsource(func))).body[0]
    nested = {id(n) for inner in ast.walk(body) if inner is not body
              and isinstance(inner, (ast.FunctionDef, ast.Lambda)) for n in ast.walk(inner)}
    for node in ast.walk(body):
        if id(node) in nested or not isinstance(node, (ast.Return, ast.Yield)):
            continue
        if node.value is not None and not (isinstance(node.value, ast.Constant)
                                           and node.value.value is None):
            return True
    return False


FUNCTIONS = dict(_public_functions())


@pytest.mark.parametrize("name", sorted(FUNCTIONS))
def test_public_function_has_numpydoc_parameters_and_returns(name):
    func = FUNCTIONS[name]
    doc = inspect.getdoc(func) or ""
    params = [p for p in inspect.signature(func).parameters if p not in ("self", "cls")]
    # click commands are documented by their --help; the decorated function is not called
    if hasattr(func, "__click_params__"):
        return
    if params:
        assert "Parameters\n----------" in doc, f"{name}: no Parameters section"
    if _returns_a_value(func):
        assert ("Returns\n-------" in doc or "Yields\n------" in doc), f"{name}: no Returns"


def test_the_packages_list_what_a_user_needs():
    import markov
    import symbolic

    for name in ("Ring", "RingChain", "Solution", "solve", "load_solution", "stationary",
                 "StationaryResult", "simulate", "NaschError", "ConvergenceError"):
        assert name in markov.__all__ and getattr(markov, name) is not None
    for name in ("approximate", "Approximation", "exact_solution", "equations"):
        assert name in symbolic.__all__ and getattr(symbolic, name) is not None
    # internals stay out of the front door
    assert not {"KeyIndex", "rank_keys", "orbit_size", "canonical"} & set(markov.__all__)


def test_import_symbolic_loads_no_sympy():
    code = "import symbolic, sys; print('sympy' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "False"
