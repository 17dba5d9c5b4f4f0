"""Evaluate a trained policy (a run directory or the committed one) on seeded episodes.

    python -m training.evaluation.evaluate POLICY_DIR [--episodes 200] [--seed 500000]
        [--which final]
        [--start midstride|rest] [--compare] [--out DIR]

Runs N seeded episodes of the policy's env (its config; by default the walking task of
ConstrainedBiped-v0, default physics, strict checks) with the deterministic network, all at
once in the batched env, and prints per row the success rate (at least 20 complete strict
steps in the 30 s) with its 95% Wilson interval, completed steps (mean, std, min), distance,
speed, cost of transport and the ends tallied. The default is 200 episodes on the report
seeds 500000-500199, which no training, selection or development choice reads
(:data:`training.ppo.config.REPORT_SEED_OFFSET`).
``--start`` picks the start (default: the config's; a policy trained on both starts is
evaluated mid-stride); from rest the gait-initiation figures are printed too. With
``--compare`` it runs, on the same seeds: the imitation result alone (the run's ``imitation``
snapshot, when the policy was warm-started from a teacher), the teacher (the model
controller) alone, the policy under 3x the reset noise and under a push, the Table 2 open
loop, and the network and the teacher from rest (1x and 3x reset noise) with their
gait-initiation figures. Writes ``evaluation.json``, ``figures/best.gif`` and Fig. 6-style
strips of the best and the worst episode into ``runs/evaluate/NAME_WHICH_START`` (or
``--out``): written into a temporary folder and renamed into place when complete, so an
interrupted evaluation leaves the previous output or none.

The policy is loaded from weights (safetensors) and plain data (TOML, JSON, npz): nothing in
POLICY_DIR is unpickled (:mod:`training.ppo.policy_io`).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from biped_constraint_env.settings import with_keys
from biped_constraint_env.tasks import EPISODE_S, MAX_DT_S, MIN_DT_S
from training.plumbing.common import CliParser, command, float_in, int_in
from training.plumbing.outputs import check_command_output, command_output, write_file
from training.plumbing.rollouts import (
    COMPARE_PUSH,
    TABLE_HEADER,
    batched_row,
    run_episodes,
    summarize,
    table_row,
)
from training.plumbing.safe_files import UntrustedFileError
from training.plumbing.stats import MIN_STEPS, format_success
from training.ppo.config import REPORT_EPISODES, REPORT_SEED_OFFSET
from training.ppo.policy_io import (
    SNAPSHOTS,
    available,
    json_text,
    load_policy,
    policy_actor,
    policy_batch_actor,
    published_snapshot,
)

GIF_MAX_FRAMES = 500
MIN_STEPS_FROM_REST = MIN_STEPS
"""Complete steps in a 30 s episode from rest that count as a successful start and walk."""


def open_loop_baselines() -> list[dict]:
    """The Table 2 open loop (paper preset, and the accurate default), run now."""
    from training.paper.open_loop import OpenLoopConfig, run

    rows = []
    for label, kw in (
        ("Table 2 open loop from rest, task='paper'", {}),
        (
            "Table 2 open loop from rest, default preset, 2 ms",
            {"preset": "default", "dt": 0.002, "max_periods": 5000},
        ),
        (
            "Table 2 open loop from rest, the walking task (5 ms, the row changes at each switch)",
            {"preset": "default", "dt": 0.005, "stop_at_switch": True, "max_periods": 6000},
        ),
    ):
        out = run(OpenLoopConfig(gif=False, progress=False, **kw), record_frames=False)
        eps = [
            {
                "seed": 0,
                "steps_completed": out["steps_completed"],
                "distance_m": out["distance_m"],
                "speed_m_s": float("nan"),
                "torque_cost": float("nan"),
                "return": float("nan"),
                "t_s": out["t_end_s"],
                "end": out["end_reason"],
            }
        ]
        rows.append(summarize(label, eps))
    return rows


def figures(actor, cfg, seed_best: int, seed_worst: int, eps_by_seed: dict, out_dir: Path):
    """GIF (real time, 50 fps, at most GIF_MAX_FRAMES frames) and strips of two episodes."""
    from training.plumbing import plots

    for name, seed in (("best", seed_best), ("worst", seed_worst)):
        frames, images = [], []

        def record(env, _k, frames=frames, images=images, name=name):
            u = env.unwrapped
            # one frame per 20 ms of simulated time (real-time GIF at 50 fps, whatever dt)
            if frames and u.state.t < frames[-1]["t"] + 0.02 - 1e-9:
                return
            frames.append({"t": u.state.t, "keypoints": u.keypoints()})
            if name == "best" and len(images) < GIF_MAX_FRAMES:
                images.append(env.render())

        run_episodes(
            actor, cfg.env_kwargs(), [seed], cfg.env_id, record=record, episode_s=EPISODE_S
        )
        if images:
            plots.save_gif(images, out_dir / "figures" / f"{name}.gif", fps=50)
        e = eps_by_seed[seed]
        plots.stick_strip(
            frames[: 15 * 50],  # the first 15 s
            out_dir / "figures" / f"{name}_strip.png",
            f"{name} episode (seed {seed}): {e['steps_completed']} steps, "
            f"{e['distance_m']:.2f} m in {e['t_s']:.1f} s, {e['end'].replace('_', ' ')}; "
            f"shown: the first {min(15.0, e['t_s']):.1f} s",
            every=max(min(len(frames), 750) // 30, 1),
        )


STRIP_S = 2.0
"""The start-from-rest strips show at least the first this many seconds [s] ..."""
STRIP_MAX_S = 4.0
"""... and on to just after the first step, at most this many [s]."""


def rest_strip(actor, cfg, path: Path, who: str, seed: int) -> None:
    """Figure: the start from rest of episode ``seed``.

    Stick figures, centre of mass and pressure over ``STRIP_S``, or until just after its first
    step where that is later (at most :data:`STRIP_MAX_S`).
    """
    from training.plumbing import plots
    from training.plumbing.rollouts import com_and_cop

    frames = []

    def record(env, _k):
        u = env.unwrapped
        if u.state.t <= STRIP_MAX_S:
            com, cop = com_and_cop(env)
            st = u.state
            frames.append(
                {"t": st.t, "keypoints": u.keypoints(), "com": com, "cop": cop, "mode": st.mode}
            )

    kw = {**cfg.env_kwargs(), "start": "rest"}
    (ep,) = run_episodes(actor, kw, [seed], cfg.env_id, record=record, episode_s=EPISODE_S)
    first = f"first step at {ep['step_t_s'][0]:.2f} s" if ep["step_t_s"] else "no step"
    cut = STRIP_S if not ep["step_t_s"] else min(max(STRIP_S, ep["step_t_s"][0] + 0.1),
                                                 STRIP_MAX_S)  # fmt: skip
    plots.initiation_strip(
        [f for f in frames if f["t"] <= cut + 1e-9],
        path,
        f"{who} from rest, the paper's Fig. 2 posture (episode seed {seed}): first {cut:.2f} s; "
        f"{first}, {ep['steps_completed']} steps in the episode",
    )


def controller_batch(spec: str, n: int):
    """Obs (n, 24) -> torques (n, 5) of ``n`` model controllers, one per episode.

    Each keeps its own start phase.
    """
    from training.controller.model_controller import controller_from

    ctrls = [controller_from(spec) for _ in range(n)]

    def act(obs: np.ndarray) -> np.ndarray:
        return np.stack([c(o) for c, o in zip(ctrls, obs, strict=True)])

    return act


def _rest_rows(batch, cfg, seeds) -> tuple[list[dict], str]:
    """The network and the teacher from rest (1x and 3x reset noise), with initiation figures."""
    from training.controller.model_controller import TEACHER

    spec = cfg.teacher if "+" in cfg.teacher else TEACHER  # a teacher with its start phase
    kw = with_keys(cfg.env_kwargs(), "start", kind="rest")
    noisy = with_keys(kw, "start", reset_noise_scale=3 * cfg.settings().start.reset_noise_scale)
    rows = []
    who = (("policy", lambda: batch), (f"model controller ({spec!r})",
           lambda: controller_batch(spec, len(seeds))))  # fmt: skip
    for label, make in who:
        for suffix, env_kw in (("", kw), (", 3x reset noise", noisy)):
            rows.append(batched_row(f"{label} from rest{suffix}", make(), env_kw, seeds,
                                    cfg.env_id, rest=True))  # fmt: skip
    return rows, spec


def _rows_compare(run_dir: Path, actor, batch, cfg, seeds, out_dir: Path) -> list[dict]:
    """The ``--compare`` rows: stresses of the policy, imitation alone, teacher, Table 2."""
    from training.controller.model_controller import controller_from

    kw = cfg.env_kwargs()
    noisy = with_keys(kw, "start", reset_noise_scale=3 * cfg.settings().start.reset_noise_scale)
    pushed = {**kw, "perturbations": COMPARE_PUSH}
    what = f"push {COMPARE_PUSH['push_impulse_ns']} N s at {COMPARE_PUSH['push_at_s']} s"
    rows = [batched_row("policy, 3x reset noise", batch, noisy, seeds, cfg.env_id)]
    rows.append(batched_row(f"policy, {what}", batch, pushed, seeds, cfg.env_id))
    if available(run_dir, "imitation"):
        policy, norm, _, _ = load_policy(run_dir, "imitation")
        rows.append(
            batched_row(
                "imitation alone (DART + DAgger, before PPO)",
                policy_batch_actor(policy, norm, cfg),
                kw,
                seeds,
                cfg.env_id,
            )
        )
    spec = cfg.teacher or "model"
    rows.append(
        batched_row(
            f"model controller ({spec!r}, the teacher) alone",
            controller_batch(spec, len(seeds)),
            kw,
            seeds,
            cfg.env_id,
        )
    )
    rows.append(batched_row(f"model controller, {what}", controller_batch(spec, len(seeds)),
                            pushed, seeds, cfg.env_id))  # fmt: skip
    rest, spec = _rest_rows(batch, cfg, seeds)
    rows += rest
    rest_strip(controller_from(spec), cfg, out_dir / "figures" / "rest_start_teacher.png",
               "the teacher", seeds[0])  # fmt: skip
    print("Table 2 open loop from rest (paper preset; default physics at 2 ms; walking task)")
    return rows + open_loop_baselines()


@command("evaluate", "nothing was written (the --out folder is as it was)")
def main(argv: Sequence[str] | None = None) -> int:
    """Evaluate and write the outputs."""
    ap = CliParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_dir", type=Path, nargs="?", help="a run directory or a committed policy")
    ap.add_argument(
        "--controller", default=None, metavar="model:NAME[+NAME]",
        help="evaluate a shipped model controller instead (e.g. model:teacher_robust+start_rest)",
    )  # fmt: skip
    ap.add_argument(
        "--episodes", type=int_in(1, 100_000), default=REPORT_EPISODES,
        help=f"episodes per row (default {REPORT_EPISODES})",
    )  # fmt: skip
    ap.add_argument(
        "--seed", type=int_in(0, 2**31 - 1), default=REPORT_SEED_OFFSET,
        help=f"episode i uses seed + i (default {REPORT_SEED_OFFSET}: the report seeds)",
    )  # fmt: skip
    ap.add_argument(
        "--which", default=None, choices=sorted(SNAPSHOTS),
        help="snapshot (default: the one the policy publishes: its published.json, else best/ "
        "when the run selected one, else final/)",
    )  # fmt: skip
    ap.add_argument(
        "--start",
        choices=["midstride", "rest"],
        default=None,
        help="episode start (default: the config's; mid-stride for a policy trained on both)",
    )
    ap.add_argument(
        "--dt",
        type=float_in(MIN_DT_S, MAX_DT_S),
        default=None,
        help="control period [s] (default: config)",
    )
    ap.add_argument("--hold", action="store_true", help="hold each action through model switches")
    ap.add_argument("--compare", action="store_true", help="also run the baselines and stresses")
    ap.add_argument(
        "--robustness", action="store_true",
        help="also the robustness rows (pushes, reset noise, masses, K, sensor noise) and figure",
    )  # fmt: skip
    ap.add_argument(
        "--out",
        type=Path,
        default=None,
        help="output folder, replaced when complete (default: runs/evaluate/NAME_WHICH_START)",
    )
    args = ap.parse_args(argv)
    if (args.run_dir is None) == (args.controller is None):
        ap.error("give a run directory or --controller, not both")
    if args.controller and args.compare:
        ap.error("--compare needs a run directory (its teacher, imitation and stresses)")
    if args.run_dir is not None and not args.run_dir.is_dir():  # before anything is loaded
        ap.error(f"{args.run_dir}: no such directory" if not args.run_dir.exists()
                 else f"{args.run_dir}: not a run directory")  # fmt: skip
    if args.out is not None:
        try:
            check_command_output(args.out, "evaluate")
        except UntrustedFileError as e:
            ap.error(f"--out: {e}")
    t0 = time.time()
    print(f"loading {args.run_dir or args.controller} and the simulator", flush=True)
    import torch

    torch.set_num_threads(1)
    try:
        loop = _controller_loop(args) if args.controller else _policy_loop(args)
    except (FileNotFoundError, UntrustedFileError, ValueError) as e:
        ap.error(str(e))
    import biped_constraint_env  # noqa: F401  (compiles on a machine's first run)

    cfg = loop["cfg"]
    start = args.start or cfg.evaluation_start()
    env = with_keys(cfg.env, "start", kind=start)
    if args.dt is not None:
        env["dt"] = args.dt
    if args.hold:
        env = with_keys(env, "physics", stop_at_switch=False)
    cfg = replace(cfg, env=env)
    loop["cfg"] = cfg
    name = args.run_dir.resolve().name if args.run_dir else args.controller.replace(":", "_")
    out = args.out or Path("runs") / "evaluate" / f"{name}_{args.which or 'controller'}_{start}"
    try:
        with command_output(out, "evaluate") as co:
            _evaluate(args, loop, start, Path(co.dir().where()), t0, out)
    except UntrustedFileError as e:
        ap.error(f"--out: {e}")
    print(f"wrote {out}")
    return 0


def _policy_loop(args) -> dict:
    """What runs for a run directory: its network (and the config it was trained with)."""
    why = "given by --which"
    if args.which is None:
        args.which, why = published_snapshot(args.run_dir)
    args.why = why
    print(f"snapshot: {args.which}/ ({why})", flush=True)
    policy, norm, cfg, state = load_policy(args.run_dir, args.which)
    label = "policy" + ("" if cfg.base_controller == "" else " (residual on the model controller)")
    return {
        "cfg": cfg, "label": label, "policy": (policy, norm),
        "what": f"{state.get('num_timesteps', 0)} PPO env steps",
    }  # fmt: skip


def _controller_loop(args) -> dict:
    """What runs for ``--controller``: the model controller on the default walking task."""
    from training.controller.model_controller import controller_from
    from training.ppo.config import PPOConfig

    controller_from(args.controller)  # refuses an unknown name here
    PPOConfig(teacher=args.controller).check_untrusted()  # shipped names only
    cfg = PPOConfig(env={"start": "mixed"})
    return {"cfg": cfg, "label": f"model controller ({args.controller!r})", "policy": None,
            "what": "a model controller"}  # fmt: skip


def _robustness_rows(args, loop, batch, cfg, seeds, label, in_the_loop, out_dir) -> list[dict]:
    """The ``--robustness`` rows, written with their figure into ``out_dir``."""
    from training.evaluation import robustness

    def make():  # a fresh batch actor per condition (controllers keep per-episode phases)
        return batch if loop["policy"] else controller_batch(args.controller, len(seeds))

    print(f"robustness: {len(robustness.conditions(0.0))} conditions", flush=True)
    rob = robustness.run(make, cfg.env_kwargs(), seeds, cfg.env_id, label)
    title = (
        f"{label}: {len(seeds)} episodes per condition (seeds {seeds[0]}-{seeds[-1]}), strict "
        f"physics; in the loop: {in_the_loop}"
    )
    robustness.figure(rob, out_dir / "figures" / "robustness.png", title)
    summary = {"seeds": seeds, "in_the_loop": in_the_loop, "rows": robustness.compact(rob)}
    text = json_text(summary, indent=None).strip().replace('{"group"', '\n{"group"')
    write_file(out_dir / "robustness.json", text + "\n")
    print("\n" + robustness.markdown(rob), flush=True)
    return rob


def _evaluate(args, loop: dict, start, out_dir, t0, shown=None) -> None:
    """Run the rows and write the outputs into ``out_dir`` (a fresh temporary directory)."""
    from training.controller.model_controller import controller_from

    cfg = loop["cfg"]
    in_the_loop = cfg.in_the_loop() if loop["policy"] else f"the {loop['label']}"
    print(
        f"loaded in {time.time() - t0:.0f} s ({loop['what']}); {args.episodes} episodes of up "
        f"to 30 s each; in the loop: {in_the_loop}",
        flush=True,
    )
    (out_dir / "figures").mkdir(parents=True, exist_ok=True)
    seeds = list(range(args.seed, args.seed + args.episodes))
    if loop["policy"]:
        actor = policy_actor(*loop["policy"], cfg)
        batch = policy_batch_actor(*loop["policy"], cfg)
    else:
        actor = controller_from(args.controller)
        batch = controller_batch(args.controller, len(seeds))
    label = f"{loop['label']} ({start} start)"
    protocol = None
    if cfg.env_kwargs().get("task") == "command":  # the command task's own protocol first
        from training.plumbing import command_protocol

        print("the command task's protocol: start, tracking, stop and restart, sequences",
              flush=True)  # fmt: skip
        protocol = command_protocol.run_protocol(batch, cfg.env_kwargs(), seeds, cfg.env_id)
        if args.robustness:  # the push table (size x direction x phase), slopes, the model
            pushes = command_protocol.push_rows(batch, cfg.env_kwargs(), seeds, cfg.env_id)
            command_protocol.push_figure(pushes, out_dir / "figures" / "pushes.png")
            protocol += pushes
            for rows in (command_protocol.slope_rows, command_protocol.model_rows):
                protocol += rows(batch, cfg.env_kwargs(), seeds, cfg.env_id)
        print("\n" + command_protocol.markdown(protocol), flush=True)
    print(TABLE_HEADER, flush=True)
    main_row = batched_row(label, batch, cfg.env_kwargs(), seeds, cfg.env_id, start == "rest")
    rows = [main_row]
    if args.compare:
        rows += _rows_compare(args.run_dir, actor, batch, cfg, seeds, out_dir)
    if args.robustness:
        rob = _robustness_rows(args, loop, batch, cfg, seeds, label, in_the_loop, out_dir)
        rows += [{k: v for k, v in r.items() if k != "episodes"} for r in rob]  # summaries
    steps = np.array([e["steps_completed"] for e in main_row["episodes"]], dtype=float)
    dist = np.array([e["distance_m"] for e in main_row["episodes"]])
    order = np.argsort(steps + 1e-3 * dist)
    by_seed = {e["seed"]: e for e in main_row["episodes"]}
    print("writing the GIF and the strips", flush=True)
    figures(actor, cfg, seeds[order[-1]], seeds[order[0]], by_seed, out_dir)
    if args.compare or start == "rest":
        rest_strip(
            actor, cfg, out_dir / "figures" / "rest_start_network.png", "the network", seeds[0]
        )  # the first report episode, as its table
    summary = {
        "which": args.which,
        "why": getattr(args, "why", ""),
        "start": start,
        "in_the_loop": in_the_loop,
        "env_kwargs": cfg.env_kwargs(),
        "seeds": seeds,
        "results": rows,
    }
    if protocol is not None:
        summary["command_protocol"] = protocol
    write_file(out_dir / "evaluation.json", json_text(summary))
    print(
        f"\n{args.episodes} seeded episodes (seeds {seeds[0]}-{seeds[-1]}), "
        f"{cfg.env_id} {cfg.env_kwargs().get('task') or 'walk'} task, {start} start, strict "
        f"physics; "
        f"in the loop: {in_the_loop}:"
    )
    print(TABLE_HEADER)
    for r in rows:
        print(table_row(r))
    init = [r for r in rows if "initiation" in r]
    if init:
        print(f"\ngait initiation from rest (success: >= {MIN_STEPS_FROM_REST} steps in 30 s):")
        print("| controller | success | first step at [s] (mean, max) | first step [m] | "
              "steps to 90% of the steady speed (mean, max) |")  # fmt: skip
        print("|---|---|---|---|---|")
        for r in init:
            i = r["initiation"]
            print(
                f"| {r['controller']} | {format_success(r['success'])} | "
                f"{_num(i['t_first_step_s_mean'])}, {_num(i['t_first_step_s_max'])} | "
                f"{_num(i['first_step_m_mean'])} | {_num(i['steps_to_90pct_speed_mean'], 1)}, "
                f"{_num(i['steps_to_90pct_speed_max'], 0)} |"
            )
    names = ["best.gif", "best_strip.png", "worst_strip.png"]
    if args.compare or start == "rest":
        names.append("rest_start_network.png")
    if args.compare:
        names.append("rest_start_teacher.png")
    print(
        f"\nfigures: {shown / 'figures'} ({', '.join(names)}); "
        f"summary: {shown / 'evaluation.json'}; {time.time() - t0:.0f} s"
    )


def _num(x, digits: int = 2) -> str:
    """A table cell: the number, or "-" where it is undefined (no episode took a step)."""
    if x is None or (isinstance(x, float) and not np.isfinite(x)):
        return "-"
    return f"{x:.{digits}f}"


if __name__ == "__main__":
    raise SystemExit(main())
