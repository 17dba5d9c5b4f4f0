"""The env's one reference is its docstring; docs/environment.md renders it, not a copy."""

import inspect
from pathlib import Path

from biped_constraint_env.env import ConstrainedBipedEnv

DOC = Path(__file__).resolve().parents[1] / "docs" / "environment.md"
MARK = "<!-- rendered from the docstring: do not edit below this line -->\n\n"
RENDER = (
    'python -c "import inspect, pathlib, biped_constraint_env.env as e; p = pathlib.Path('
    "'docs/environment.md'); t = p.read_text(); m = '" + MARK.strip() + "'; "
    "p.write_text(t[: t.index(m) + len(m)] + chr(10) * 2 + inspect.getdoc(e.ConstrainedBipedEnv)"
    ' + chr(10))"'
)


def test_the_environment_page_renders_the_env_docstring():
    text = DOC.read_text()
    assert MARK in text
    rendered = text.split(MARK, 1)[1]
    assert rendered == inspect.getdoc(ConstrainedBipedEnv) + "\n", f"render it again: {RENDER}"
