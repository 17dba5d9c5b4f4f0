"""The joystick example (examples/drive_command.py): set_command drives a command policy."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "drive_command.py"
STOPPER = ROOT / "policies" / "ppo_command_stop_50hz"


def _example():
    spec = importlib.util.spec_from_file_location("drive_command", EXAMPLE)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _seconds(out: str) -> dict[int, tuple[float, float]]:
    """{second k: (command held at its start, hip speed over [k, k + 1])} from the printout."""
    rows = {}
    for line in out.splitlines():
        parts = line.split()
        if len(parts) == 3 and "-" in parts[0] and parts[0].split("-")[0].isdigit():
            rows[int(parts[0].split("-")[0])] = (float(parts[1]), float(parts[2]))
    return rows


def test_the_committed_policy_follows_the_drive_but_walks_on_at_a_zero_command(capsys):
    rc = _example().main([str(ROOT / "policies" / "ppo_command_50hz"), "--seed", "3"])
    rows = _seconds(capsys.readouterr().out)
    assert sorted(rows) == list(range(26))  # the whole drive, no fall
    assert all(abs(rows[k][1] - 1.5) < 0.2 for k in range(3, 8))
    assert all(abs(rows[k][1] - 1.0) < 0.2 for k in range(20, 26))
    assert rows[12][0] == 0.0 and rows[12][1] > 0.3 and rc == 1  # told 0, still walking


def test_the_committed_policy_that_stops_comes_to_rest_and_walks_again(capsys):
    """Its own env's joystick options (deadband 0.2 m/s, ramp 1.5 m/s^2), no flag given."""
    rc = _example().main([str(STOPPER), "--seed", "3"])
    out = capsys.readouterr().out
    rows = _seconds(out)
    assert "'deadband': 0.2, 'ramp_m_s2': 1.5" in out
    assert rows[8][0] > 1.0 and rows[9][0] == 0.0  # the ramp: 1.5 m/s to 0 in 1 s from 8 s
    assert all(abs(rows[k][1]) < 0.05 for k in range(10, 16)) and "stop: at rest, drift" in out
    assert all(rows[k][1] > 0.9 for k in range(18, 26)) and rc == 0


def test_the_example_refuses_a_policy_of_another_task():
    with pytest.raises(SystemExit):
        _example().main([str(ROOT / "policies" / "ppo_gait_50hz")])
