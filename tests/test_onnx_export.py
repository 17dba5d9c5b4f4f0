"""export-onnx: a policy as one ONNX graph whose onnxruntime actions equal the network's."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("onnxruntime")
pytest.importorskip("onnxscript")

from training.ppo import policy_io  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
POLICIES = sorted(p.name for p in (ROOT / "policies").iterdir())


@pytest.mark.parametrize("name", POLICIES)
def test_every_committed_policy_exports_and_onnxruntime_acts_as_the_network(name, tmp_path):
    import onnxruntime as ort
    import torch

    from training.ppo.onnx_export import TOLERANCE

    out = tmp_path / "sub" / f"{name}.onnx"  # a missing folder is made
    assert policy_io.main(["export-onnx", str(ROOT / "policies" / name), str(out)]) == 0
    policy, norm, cfg, _ = policy_io.load_policy(ROOT / "policies" / name)
    session = ort.InferenceSession(str(out), providers=["CPUExecutionProvider"])
    d = cfg.obs_dim()
    assert [i.name for i in session.get_inputs()] == ["obs"]
    rng = np.random.default_rng(123)  # not the export's own check's observations
    scale = np.sqrt(norm.var) if norm.enabled else 1.0
    obs = rng.normal(0.0, 1.5, (500, d)) * scale + (norm.mean if norm.enabled else 0.0)
    if cfg.settings().command is not None:
        obs[::3, -1] = 0.0  # zero commands: a stop policy's other actors
    action, env_action = session.run(["action", "env_action"], {"obs": obs})
    with torch.no_grad():
        want, _ = policy.predict(norm(obs), deterministic=True)
    assert action.shape == (500, 5) and np.abs(action - want).max() <= TOLERANCE
    torques = policy_io.policy_batch_actor(policy, norm, cfg)(obs)
    gear = float(np.max(cfg.action_map().gear))
    assert np.abs(env_action - torques).max() <= TOLERANCE * gear
    one, _ = session.run(["action", "env_action"], {"obs": obs[:1]})  # any batch size
    np.testing.assert_allclose(one, action[:1], atol=1e-6)


def test_export_refuses_in_one_line_before_loading(tmp_path, capsys):
    taken = tmp_path / "taken.onnx"
    taken.write_bytes(b"mine")
    for args, words in (
        ([str(ROOT / "policies" / "ppo_gait_50hz"), str(taken)], "exists"),
        ([str(ROOT / "policies" / "ppo_gait_50hz"), str(tmp_path / "x.txt")], ".onnx"),
        ([str(tmp_path / "nope"), str(tmp_path / "y.onnx")], "no such directory"),
    ):
        with pytest.raises(SystemExit) as e:
            policy_io.main(["export-onnx", *args])
        assert e.value.code == 2
        err = capsys.readouterr().err
        assert words in err and "Traceback" not in err, err
    assert taken.read_bytes() == b"mine" and not (tmp_path / "y.onnx").exists()


def test_a_residual_on_the_model_controller_is_refused(tmp_path, capsys):
    run = tmp_path / "residual"
    shutil.copytree(ROOT / "policies" / "ppo_gait_50hz", run,
                    ignore=shutil.ignore_patterns("figures"))  # fmt: skip
    lines = (run / "config.toml").read_text().splitlines()
    lines = [ln for ln in lines if not ln.startswith("base_controller")]
    (run / "config.toml").write_text('base_controller = "model"\n' + "\n".join(lines) + "\n")
    with pytest.raises(SystemExit):
        policy_io.main(["export-onnx", str(run), str(tmp_path / "r.onnx")])
    err = capsys.readouterr().err
    assert "model controller" in err and not (tmp_path / "r.onnx").exists()
