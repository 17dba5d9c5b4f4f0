"""The robustness protocol's conditions and its compact record."""

from training.evaluation.robustness import (
    EPISODE_FIELDS,
    PUSH_IMPULSES_NS,
    compact,
    conditions,
    markdown,
)


def test_conditions_cover_pushes_both_ways_noise_model_and_sensors():
    rows = conditions(0.01)
    names = [name for _, name, _ in rows]
    assert names[0] == "nominal" and len(set(names)) == len(names)
    pushes = [kw["perturbations"]["push_impulse_ns"] for g, _, kw in rows if g == "push"]
    assert sorted(pushes) == sorted([s * p for p in PUSH_IMPULSES_NS for s in (1, -1)])
    noise = [kw["start"]["reset_noise_scale"] for g, _, kw in rows if g == "reset noise"]
    assert noise == [0.03, 0.05]


def test_compact_keeps_the_summary_and_one_list_per_episode():
    ep = {"seed": 5, "steps_completed": 21, "distance_m": 20.5, "end": "time_limit",
          "step_t_s": [1.0] * 21}  # fmt: skip
    row = {"condition": "nominal", "group": "nominal", "ends": {"time_limit": 1},
           "success": {"successes": 1, "episodes": 1, "rate": 1.0, "ci95": (0.2, 1.0)},
           "episodes": [ep]}  # fmt: skip
    (out,) = compact([row])
    assert out["episodes"] == [[5, 21, 20.5, "time_limit"]]
    assert out["episode_fields"] == list(EPISODE_FIELDS) and out["success"] == row["success"]
    assert "nominal" in markdown([out])
