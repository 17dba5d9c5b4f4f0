"""One direction of dependency: jit (how the core is compiled) and validation (argument
checks) -> model -> kinematics -> dynamics -> contact -> modes -> hybrid -> the simulator
(state -> options -> stepper -> advance -> simulator, its Python API) -> the env's parts
(tasks, actions, starts, restarts, rewards, gait, observation, reference, perturbations) ->
settings (all the env's arguments, validated once) -> tracking -> period (the compiled control
period) -> core (N rows around it: starts, reasons, rewards, info) -> env (its one-row case) ->
vector_env.
Each module may import only modules of lower or equal rank."""

import ast
from pathlib import Path

import pytest

import biped_constraint_env

LAYERS = [
    "_first_use",
    "jit",
    "validation",
    "units",
    "planar",
    "integrators",
    "model",
    "kinematics",
    "dynamics",
    "contact",
    "modes",
    "hybrid",
    "state",
    "options",
    "stepper",
    "advance",
    "simulator",
    "render",
    "tasks",
    "actions",
    "starts",
    "restarts",
    "rewards",
    "gait",
    "clock",
    "observation",
    "reference",
    "perturbations",
    "settings",
    "tracking",
    "period",
    "core",
    "env",
    "vector_env",
    "__init__",
]
PKG = Path(biped_constraint_env.__file__).parent


def _imports(path):
    tree = ast.parse(path.read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level == 1 and node.module:
                yield node.module.split(".")[0]
            elif node.module and node.module.startswith("biped_constraint_env."):
                yield node.module.split(".")[1]


@pytest.mark.parametrize("module", [p.stem for p in sorted(PKG.glob("*.py"))])
def test_no_upward_imports(module):
    assert module in LAYERS, f"{module} is not placed in LAYERS"
    rank = LAYERS.index(module)
    for dep in _imports(PKG / f"{module}.py"):
        assert LAYERS.index(dep) <= rank, f"{module} imports upward from {dep}"


def test_core_never_imports_gymnasium():
    for module in LAYERS[: LAYERS.index("simulator") + 1]:
        path = PKG / f"{module}.py"
        if path.exists():
            assert "gymnasium" not in path.read_text(), module
