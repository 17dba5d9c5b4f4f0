"""The first compile is never silent: a line when it begins, then one every few seconds."""

from __future__ import annotations

import io
import time

from numba import njit
from numba.core import event

from biped_constraint_env import _first_use


def test_a_compile_says_so_and_a_long_one_keeps_saying_so(monkeypatch):
    monkeypatch.setattr(_first_use, "HEARTBEAT_S", 0.2)
    out = io.StringIO()
    note = _first_use.CompileNote(out)
    note.on_start(None)
    note.on_start(None)  # nested: one stretch
    time.sleep(0.9)
    note.on_end(None)
    note.on_end(None)
    lines = out.getvalue().splitlines()
    assert "compiling the simulator core" in lines[0]
    assert len([x for x in lines if "still compiling" in x]) >= 3
    time.sleep(0.5)  # nothing compiles: nothing more is said
    assert out.getvalue().splitlines() == lines
    note.wake.set()


def test_a_real_compile_is_heard_and_a_cached_call_is_not():
    out = io.StringIO()
    note = _first_use.CompileNote(out)

    @njit(cache=False)
    def twice(x):
        return 2 * x

    with event.install_listener("numba:compile", note):
        assert twice(3) == 6  # compiles
    assert "compiling the simulator core" in out.getvalue()
    quiet = io.StringIO()
    note2 = _first_use.CompileNote(quiet)
    with event.install_listener("numba:compile", note2):
        assert twice(4) == 8  # compiled already: no event
    assert quiet.getvalue() == ""
    note.wake.set()


def test_the_package_listens_for_compiles():
    import numba.core.event as ev

    assert _first_use.NOTE in ev._registered["numba:compile"]
