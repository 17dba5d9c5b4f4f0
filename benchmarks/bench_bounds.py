"""CPU time of one 30 s episode at the bounds of the settings that scale the work.

    python -m benchmarks.bench_bounds

Every setting that multiplies the simulator's work is bounded where the env validates it
(``biped_constraint_env.tasks``: the control period, the integration step, the step
tolerance; ``biped_constraint_env.actions``: the PD update period), the same bound in a
config file, a flag and ``gym.make``. This times the model-based walker (a Python controller
in the loop, one env, one thread) for up to 30 s of simulated time at each bound and
prints the CPU seconds per 30 simulated seconds.
"""

from __future__ import annotations

import time

from training.plumbing.common import CliParser, command


def cases() -> dict[str, dict]:
    from biped_constraint_env.tasks import MIN_DT_S, MIN_STEP_S, MIN_STEP_TOL

    return {
        "the default (5 ms periods, error-controlled steps, tolerance 2e-4)": {},
        f"control period {MIN_DT_S * 1e3:g} ms (the shortest)": {"dt": MIN_DT_S},
        f"RK4 steps of {MIN_STEP_S * 1e6:g} us (the shortest)": {
            "physics": {"integrator": "rk4", "substeps": round(0.005 / MIN_STEP_S)}},
        f"step_tol {MIN_STEP_TOL:g} (the smallest)": {"physics": {"step_tol": MIN_STEP_TOL}},
    }  # fmt: skip


@command("bench_bounds")
def main(argv=None) -> int:
    ap = CliParser(description=__doc__.splitlines()[0])
    ap.parse_args(argv)
    import gymnasium as gym

    import biped_constraint_env  # noqa: F401
    from training.controller.model_controller import controller_from

    print("| setting | simulated [s] | periods | CPU [s] | CPU per 30 s [s] |")
    print("|---|---|---|---|---|")
    for name, kw in cases().items():
        env = gym.make("ConstrainedBiped-v0", **kw, max_episode_steps=10**6)  # 30 s below
        ctl = controller_from("model:teacher_robust")
        obs, info = env.reset(seed=0)
        env.step(ctl(obs))  # compile outside the timing
        obs, info = env.reset(seed=0)
        t0, n = time.process_time(), 0
        while True:
            obs, _, term, trunc, info = env.step(ctl(obs))
            n += 1
            if term or trunc or info["t"] >= 30.0:
                break
        cpu = time.process_time() - t0
        print(f"| {name} | {info['t']:.1f} | {n} | {cpu:.2f} | "
              f"{30 * cpu / max(info['t'], 1e-9):.1f} |", flush=True)  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
