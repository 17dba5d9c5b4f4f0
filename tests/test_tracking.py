"""The tracking task's env options: reward terms, PD-target actions, reference-state starts."""

import gymnasium as gym
import numpy as np
import pytest

import biped_constraint_env  # noqa: F401
from biped_constraint_env.actions import PD_FIXED_POSE_RAD, PD_KD, PD_KP
from biped_constraint_env.env import ConstrainedBipedEnv
from biped_constraint_env.reference import load_reference
from biped_constraint_env.rewards import REWARD_KINDS
from biped_constraint_env.starts import split_reference

TRACK = {"reward": "tracking", "start": {"reference": 0.5, "midstride": 0.5},
         "action": {"kind": "pd", "around": "reference", "range": 0.5},
         "observation": ["phase"]}  # fmt: skip
MIXED_AND_REFERENCE = {"reference": 0.5, "rest": 0.25, "midstride": 0.25}
TERMS = {t.name: t for t in REWARD_KINDS["tracking"]}


def _at_clock(env) -> np.ndarray:
    """The reference's q and q-dot at the env's contact clock (row 0)."""
    return env.core.tracking.rows()[0, :12]


KERNEL_TERMS = tuple(t for t in TERMS if TERMS[t].kernel is not None)
TRACK_KEYS = tuple(f"reward_{t}" for t in TERMS)


def _at_reference_row(env, row):
    """Reset ``env`` at reference row ``row`` with its clock (reference-state start)."""
    u = env.unwrapped
    ref = u.core.tracking.ref
    u.reset(seed=0, options={"q": ref.q[row], "qd": ref.qd[row], "mode": int(ref.mode[row])})
    c = u.core.clock
    c.first[0], c.mode[0], c.j[0] = bool(ref.first[row]), ref.mode[row], ref.j[row]
    return ref


def test_kernel_terms_are_their_weights_on_the_reference_and_fall_as_documented():
    env = ConstrainedBipedEnv(reward="tracking")
    env.reset(seed=0)
    tr = env.core.tracking
    rows = tr.rows()
    q, qd, hip = rows[:, :6].copy(), rows[:, 6:12].copy(), rows[:, 12:16].copy()
    on = tr.reward(q, qd, hip, np.array([0]), np.array([True]))[0]
    for c, name in enumerate(KERNEL_TERMS):
        assert on[c] == pytest.approx(TERMS[name].weight)
    assert on[-1] == pytest.approx(1.0)  # the weights sum to one
    # an error of e in one quantity scales its term by exp(-k e^2), the others unchanged
    errors = {"pose": (q, 0.3), "velocity": (qd, 2.0)}
    for name, (arr, e) in errors.items():
        moved = arr.copy()
        moved[0, 2] += e
        args = {"pose": (moved, qd), "velocity": (q, moved)}[name]
        out = tr.reward(*args, hip, np.array([0]), np.array([True]))[0]
        c = KERNEL_TERMS.index(name)
        want = TERMS[name].weight * np.exp(-TERMS[name].kernel * e**2)
        assert out[c] == pytest.approx(want)
        others = [k for k in range(len(KERNEL_TERMS)) if k != c]
        np.testing.assert_allclose(out[others], on[others])
    for col, name, e in ((1, "hip_height", 0.05), (2, "hip_speed", 0.4)):
        moved = hip.copy()
        moved[0, col] += e
        out = tr.reward(q, qd, moved, np.array([0]), np.array([True]))[0]
        want = TERMS[name].weight * np.exp(-TERMS[name].kernel * e**2)
        assert out[KERNEL_TERMS.index(name)] == pytest.approx(want)
    # an angle off by a full turn is on the reference (wrapped)
    turned = q.copy()
    turned[0, 3] += 2 * np.pi
    out = tr.reward(turned, qd, hip, np.array([0]), np.array([True]))[0]
    assert out[0] == pytest.approx(TERMS["pose"].weight)
    # a period ended by an event earns its steps only
    dead = tr.reward(q, qd, hip, np.array([1]), np.array([False]))[0]
    np.testing.assert_array_equal(dead[:-2], 0.0)
    assert dead[-2] == dead[-1] == TERMS["step"].weight


def test_env_reward_is_the_sum_of_the_tracking_terms_in_info():
    env = gym.make("ConstrainedBiped-v0", reward="tracking", start="reference",
                   action={"kind": "pd", "around": "reference"})  # fmt: skip
    env.reset(seed=1)
    seen = 0
    for _ in range(40):
        obs, r, term, trunc, info = env.step(np.zeros(5, np.float32))
        terms = [info[k] for k in TRACK_KEYS]
        assert r == pytest.approx(sum(terms))
        assert all(t >= 0 for t in terms)  # positive terms: ending early never pays
        seen += 1
        if term:
            break
    assert seen >= 1


@pytest.mark.parametrize("offset", [None, [0.2, -0.1, 0.0, 0.3, -0.5]])
def test_pd_targets_give_the_documented_torques(offset):
    off = np.zeros(5) if offset is None else np.array(offset)
    for around in ("fixed", "reference"):
        env = ConstrainedBipedEnv(action={"kind": "pd", "around": around, "range": 0.5,
                                          "offset": offset})  # fmt: skip
        env.reset(seed=3)
        st = env.state
        pose = env.core.tracking.rows()[0, 1:6] if around == "reference" else PD_FIXED_POSE_RAD
        rate = env.core.tracking.rows()[0, 7:12] if around == "reference" else 0.0
        a = np.array([0.2, -0.4, 1.0, 0.0, -1.0], np.float32)
        _, _, _, _, info = env.step(a)
        target = pose + off + 0.5 * a.astype(np.float64)
        want = PD_KP * (target - st.q[1:]) + PD_KD * (rate - st.qd[1:])
        np.testing.assert_allclose(info["torque"], np.clip(want, -150, 150))
    assert env.action_space.high.tolist() == [1.0] * 5
    env = ConstrainedBipedEnv(action={"kind": "pd", "out_of_range": "raise"})
    env.reset(seed=0)
    with pytest.raises(ValueError, match="exceeds the PD-target bound"):  # the env's policy
        env.step(np.full(5, 1.5))


@pytest.mark.parametrize(
    "kw",
    [
        TRACK,
        {"action": "pd"},
        {
            "action": {"kind": "pd", "offset": [0.2, 0, 0, 0, 0]},
            "start": {"reference": 0.3, "midstride": 0.7},
        },
    ],
)
def test_tracking_options_single_equals_batched(kw):
    n = 5
    venv = gym.make_vec("ConstrainedBiped-v0", num_envs=n,
                        vectorization_mode="vector_entry_point", **kw)  # fmt: skip
    envs = [gym.make("ConstrainedBiped-v0", **kw) for _ in range(n)]
    ov, _ = venv.reset(seed=7)
    np.testing.assert_array_equal(ov, [e.reset(seed=7 + i)[0] for i, e in enumerate(envs)])
    rng = np.random.default_rng(0)
    done = np.zeros(n, bool)
    ends = 0
    for _ in range(200):
        a = rng.uniform(-0.3, 0.3, (n, 5)).astype(np.float32)
        ov, rv, tv, _, iv = venv.step(a)
        for i, e in enumerate(envs):
            if done[i]:  # NEXT_STEP autoreset: the batch resets this slot, ignoring its action
                (o, _), r, t = e.reset(), 0.0, False
            else:
                o, r, t, _, info = e.step(a[i])
                np.testing.assert_array_equal(info.get("torque"), iv.get("torque", [None] * n)[i])
            np.testing.assert_array_equal(o, ov[i])
            assert r == rv[i]
            done[i] = t
        ends += int(tv.sum())
    assert ends >= 3  # resets were exercised (reference-state starts among them)


def test_reference_state_starts_are_recorded_states_with_their_clock():
    env = ConstrainedBipedEnv(start="reference", observation=["phase"])
    ref = load_reference("midstride")
    rows = np.concatenate([ref.q, ref.qd], axis=1)
    for seed in range(20):
        obs, info = env.reset(seed=seed)
        st = env.state
        k = np.flatnonzero(np.all(rows == np.concatenate([st.q, st.qd]), axis=1))
        assert k.size >= 1, "the start is not a recorded reference state"
        k = k[0]
        assert int(st.mode) == ref.mode[k] and info["mode"] == ref.mode[k]
        c = env.core.clock
        assert (c.first[0], c.mode[0], c.j[0]) == (bool(ref.first[k]), ref.mode[k], ref.j[k])
        first = ref.step[k] == 0  # the recording's first step, else the gait's phase
        assert env.core.tracking.first[0] == first
        np.testing.assert_array_equal(_at_clock(env), ref.lookup(first, ref.mode[k], ref.j[k])[:12])
        if first or ref.step[k] == ref.gait_step:
            np.testing.assert_array_equal(_at_clock(env), rows[k])


def test_the_reference_components_weight_is_its_fraction_and_zero_keeps_the_own_starts():
    assert split_reference((("reference", 0.5), ("rest", 0.25), ("midstride", 0.25))) == (
        0.5, (("rest", 0.5), ("midstride", 0.5)))  # fmt: skip
    assert split_reference((("reference", 0.3), ("stride", 0.7))) == (0.3, "stride")
    assert split_reference("reference") == (1.0, None)
    assert split_reference((("stride", 0.5), ("midstride", 0.5)))[0] == 0.0
    plain = ConstrainedBipedEnv()
    off = ConstrainedBipedEnv(reward="tracking", start={"reference": 0.0, "midstride": 1.0})
    for seed in range(5):
        np.testing.assert_array_equal(plain.reset(seed=seed)[0], off.reset(seed=seed)[0])
    half = ConstrainedBipedEnv(start={"reference": 0.5, "midstride": 0.5})
    ref_q = load_reference("midstride").q
    on_ref = 0
    for seed in range(200):
        half.reset(seed=seed)
        on_ref += bool(np.any(np.all(ref_q == half.state.q, axis=1)))
    assert 75 <= on_ref <= 125  # binomial(200, 0.5): +-3.5 sigma


def test_a_start_follows_its_own_references_first_step_else_the_nearest_gait_state():
    # a mid-stride start with the mid-stride reference: the teacher's walk from such a start
    env = ConstrainedBipedEnv(reward="tracking", observation=["phase"])
    obs, _ = env.reset(seed=0)
    assert env.core.tracking.first[0] and env.core.clock.j[0] == 0 and env.core.clock.mode[0] == 2
    np.testing.assert_array_equal(_at_clock(env), env.core.tracking.ref.tables[(1, 2)][0, :12])
    for _ in range(400):  # the first step completes: the gait's phases from then on
        obs, _, term, _, info = env.step(np.zeros(5))
        if info["steps_completed"] or term:
            break
    assert not env.core.tracking.first[0] or term
    # a mid-stride start with the rest reference: the gait's nearest state of model 2
    env = ConstrainedBipedEnv(start="mixed", reference="rest", reward="tracking",
                              observation=["phase"])  # fmt: skip
    for seed in range(10):
        obs, info = env.reset(seed=seed)
        if info["mode"] == 2:
            break
    table = env.core.tracking.ref.tables[(0, 2)]
    j = int(np.argmin(np.sum((table[:, :6] - env.state.q) ** 2, axis=1)))
    assert not env.core.tracking.first[0] and env.core.clock.j[0] == j
    np.testing.assert_array_equal(_at_clock(env), table[j, :12])
    assert obs[25] == pytest.approx(j * env.dt)  # the time in the model follows the clock
    # a start at rest with the rest reference: its first step
    env.reset(seed=0, options={"q": np.array([0.0, -0.1, 0.1, -0.3, -0.4, 0.7])})
    assert env.core.tracking.first[0] and env.core.clock.j[0] == 0


def test_mixed_starts_follow_the_recording_of_their_own_kind():
    """``start="mixed"`` (``reference="own"``): a start at rest follows the rest recording's
    first step, a mid-stride start the mid-stride recording's."""
    env = ConstrainedBipedEnv(start="mixed", reward="tracking", observation=["phase"])
    assert env.settings.reference == "own"
    tr = env.core.tracking
    kinds = {ref.start: i for i, ref in enumerate(tr.refs)}
    seen = set()
    for seed in range(20):
        obs, info = env.reset(seed=seed)
        kind = "rest" if info["mode"] == 1 else "midstride"
        seen.add(kind)
        ref = tr.refs[kinds[kind]]
        assert tr.which[0] == kinds[kind] and tr.first[0] and env.core.clock.j[0] == 0
        np.testing.assert_array_equal(_at_clock(env), ref.tables[(1, info["mode"])][0, :12])
    assert seen == {"rest", "midstride"}
    venv = gym.make_vec("ConstrainedBiped-v0", 4, vectorization_mode="vector_entry_point",
                        start=MIXED_AND_REFERENCE, reward="tracking",
                        observation=["phase"])  # fmt: skip
    envs = [gym.make("ConstrainedBiped-v0", start=MIXED_AND_REFERENCE,
                     reward="tracking", observation=["phase"]) for _ in range(4)]  # fmt: skip
    vo, _ = venv.reset(seed=3)
    np.testing.assert_array_equal(vo, [e.reset(seed=3 + i)[0] for i, e in enumerate(envs)])


def test_default_env_is_unchanged_by_the_tracking_options_defaults():
    a = ConstrainedBipedEnv()
    b = ConstrainedBipedEnv(reward="env", action="torque", start="midstride")
    assert a.core.tracking is None and a.core.clock is None
    oa, _ = a.reset(seed=4)
    ob, _ = b.reset(seed=4)
    np.testing.assert_array_equal(oa, ob)
    tau = np.array([5.0, -3.0, 2.0, 1.0, 0.0])
    ra = a.step(tau)
    rb = b.step(tau)
    np.testing.assert_array_equal(ra[0], rb[0])
    assert ra[1] == rb[1] and "reward_pose" not in ra[4] and "torque" not in ra[4]


@pytest.mark.parametrize(
    "kw, name",
    [({"reward": "imitate"}, "reward"),
     ({"start": {"reference": -0.5, "midstride": 1.0}}, "'reference'"),
     ({"start": {"rsi": 0.5}}, "'reference': 0.5"),
     ({"action": "pos"}, "action"),
     ({"action": {"kind": "pd", "around": "teacher"}}, "around"),
     ({"action": {"kind": "pd", "range": 0.0}}, "range"),
     ({"reference": "backwards"}, "reference"), ({"reference_obs": 1}, "reference_obs"),
     ({"action": {"kind": "pd", "offset": [0.2, 0, 0, 0]}}, "offset"),
     ({"action": {"kind": "pd", "offset": [1.5, 0, 0, 0, 0]}}, "offset"),
     ({"action": {"kind": "pd", "gain": 2.0}}, "gain_scale"),
     ({"action": {"kind": "torque", "range": 0.5}}, "PD settings"),
     ({"reward": {"kind": "tracking", "weights": {"pos": 1.0}}}, "pose"),
     ({"reward": {"kind": "tracking", "weights": {"ctrl": 0.2}}}, "ctrl")],
)  # fmt: skip
def test_bad_tracking_options_are_refused_by_name(kw, name):
    with pytest.raises(ValueError, match=name):
        ConstrainedBipedEnv(**kw)


def test_the_reference_clock_counts_its_own_periods_at_any_control_period():
    """At dt = 20 ms the clock's j periods are 4 j of the 5 ms reference's rows."""
    import gymnasium as gym

    fine = gym.make("ConstrainedBiped-v0", task="track", start="midstride").unwrapped
    coarse = gym.make("ConstrainedBiped-v0", task="track", start="midstride", dt=0.02).unwrapped
    for env in (fine, coarse):
        env.reset(seed=0)
    tf, tc = fine.core.tracking, coarse.core.tracking
    assert tc._per == 4.0 and tf._per == 1.0
    for j in (0, 3, 10):
        tf.clock.j[:] = 4 * j
        tc.clock.j[:] = j
        tf.clock.mode[:] = tc.clock.mode[:] = 2
        tf.first[:] = tc.first[:] = False
        np.testing.assert_array_equal(tf.rows(), tc.rows())


def test_pd_offsets_by_model_apply_in_the_current_model():
    """``action["offset"]`` with one row per model: the targets' offset is the row of the
    model the env is in (here the stance ankle's only on the toe, models 2 and 3)."""
    rows = [[0.0] * 5, [0.2, 0, 0, 0, 0], [0.2, 0, 0, 0, 0], [0.0] * 5]
    a = np.array([0.1, -0.2, 0.3, 0.0, -0.1], np.float32)
    for start, mode, off in (("rest", 1, 0.0), ("midstride", 2, 0.2)):
        env = ConstrainedBipedEnv(start=start, action={"kind": "pd", "offset": rows})
        assert env.settings.action.offset_by_model
        _, info = env.reset(seed=2)
        st = env.state
        assert info["mode"] == mode
        _, _, _, _, info = env.step(a)
        target = np.array(PD_FIXED_POSE_RAD) + [off, 0, 0, 0, 0] + a.astype(np.float64)
        want = PD_KP * (target - st.q[1:]) + PD_KD * (0.0 - st.qd[1:])
        np.testing.assert_allclose(info["torque"], np.clip(want, -150, 150))
    with pytest.raises(ValueError, match="offset"):
        ConstrainedBipedEnv(action={"kind": "pd", "offset": rows[:3]})
