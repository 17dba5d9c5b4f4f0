"""One direction of dependency: jit (how the core is compiled) and validation (argument
checks) -> model -> kinematics -> dynamics -> contact -> modes -> hybrid -> the simulator
(state -> options -> stepper -> advance -> simulator, its Python API) -> the env's parts
(tasks, actions, starts, rewards, gait, command, observation, reference, perturbations,
terminations) ->
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
    "twin",
    "render",
    "tasks",
    "actions",
    "starts",
    "rewards",
    "gait",
    "command",
    "clock",
    "observation",
    "reference",
    "perturbations",
    "terminations",
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


def test_the_core_period_only_sequences_its_parts():
    """EnvCore.period: at most 25 lines and 3 branches; the hooks it runs are lists built once
    from the settings, so no period step reads a feature switch."""
    tree = ast.parse((PKG / "core.py").read_text())
    core = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == "EnvCore")
    methods = {f.name: f for f in core.body if isinstance(f, ast.FunctionDef)}
    branches = (ast.If, ast.For, ast.While, ast.IfExp, ast.Try, ast.Match)
    period = methods["period"]
    assert period.end_lineno - period.lineno + 1 <= 25
    assert sum(isinstance(n, branches) for n in ast.walk(period)) <= 3
    for name in ("_before_period", "observation"):  # each runs its part list, no switch
        ifs = [n for n in ast.walk(methods[name]) if isinstance(n, ast.If)]
        assert ifs == [] or all(
            "skip" in ast.unparse(n.test)
            or "rows" in ast.unparse(n.test)
            or "_blocks" in ast.unparse(n.test)
            for n in ifs
        ), name


def test_the_action_kind_is_read_in_one_file():
    """Only actions.py reads which mapping the actions are (its kind, PD or torque, and where
    its targets are about); the core and the settings ask its part and settings."""
    import re

    for path in sorted(PKG.glob("*.py")):
        if path.name != "actions.py":
            text = path.read_text()
            assert not re.search(r"\.pd\b|\.around\b|action\.kind", text), path.name


def test_core_never_imports_gymnasium():
    for module in LAYERS[: LAYERS.index("simulator") + 1]:
        path = PKG / f"{module}.py"
        if path.exists():
            assert "gymnasium" not in path.read_text(), module


def _training_graph() -> dict[str, set[str]]:
    """training/'s modules and the training modules each imports (function-level too)."""
    root = PKG.parent / "training"
    mods = {".".join(p.relative_to(root.parent).with_suffix("").parts): p
            for p in root.rglob("*.py")}  # fmt: skip
    graph = {}
    for name, path in mods.items():
        deps = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module:
                deps.add(node.module)
                deps.update(f"{node.module}.{a.name}" for a in node.names)
            elif isinstance(node, ast.Import):
                deps.update(a.name for a in node.names)
        graph[name] = {d.removesuffix(".__init__") for d in deps if d in mods} - {name}
    return graph


def _assert_acyclic(graph: dict[str, set[str]], what: str) -> None:
    """AssertionError naming the first circle of ``graph`` (node -> the nodes it imports)."""
    state: dict[str, int] = {}

    def visit(m, path):
        if state.get(m) == 1:
            raise AssertionError(f"{what}: {' -> '.join([*path, m])}")
        if state.get(m) == 2:
            return
        state[m] = 1
        for d in sorted(graph.get(m, ())):
            visit(d, [*path, m])
        state[m] = 2

    for m in sorted(graph):
        visit(m, [])


def test_training_has_no_import_circle():
    _assert_acyclic(_training_graph(), "import circle")


def test_every_reward_kind_has_its_part():
    """The reward kinds (their terms registered by the kinds' own modules, which the env
    imports) are parts chosen by name (rewards.REWARD_PARTS)."""
    import biped_constraint_env.env  # noqa: F401  (imports every reward kind's module)
    from biped_constraint_env.rewards import REWARD_KINDS, REWARD_PARTS

    assert set(REWARD_PARTS) == set(REWARD_KINDS)


def test_trainings_folders_have_no_import_circle():
    """The rooms of training/ (its folders) depend one way: no folder imports a folder that
    imports it back (evaluation reads ppo's policies; ppo runs episodes from plumbing)."""
    rooms: dict[str, set[str]] = {}
    for m, deps in _training_graph().items():
        room = m.split(".")[1]
        rooms.setdefault(room, set()).update(d.split(".")[1] for d in deps)
    _assert_acyclic({r: deps - {r} for r, deps in rooms.items()}, "folder circle")
