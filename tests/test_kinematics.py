import numpy as np
import pytest

from biped_constraint_env import kinematics as kin

FD_STEP = 1e-6
ATOL_FD = 1e-7  # central difference: O(h^2) truncation + O(eps/h) round-off for O(1) lengths

POINTS = [(0, -0.5), (0, -0.25), (1, 1.5), (2, 0.75), (3, 1.5), (4, 0.3), (5, -0.25), (5, 0.25)]


def test_upright_posture_keypoints(chain):
    pts = kin.keypoints(chain, np.zeros(6))
    names = kin.KEYPOINT_NAMES
    assert pts[names.index("hip")] == pytest.approx([-0.25, 3.0])
    for foot in ("stance", "swing"):
        assert pts[names.index(f"{foot}_toe")] == pytest.approx([0.0, 0.0], abs=1e-12)
        assert pts[names.index(f"{foot}_heel")] == pytest.approx([-0.5, 0.0], abs=1e-12)
    assert kin.link_angles(np.zeros(6)) == pytest.approx(
        [0, np.pi / 2, np.pi / 2, 3 * np.pi / 2, 3 * np.pi / 2, 2 * np.pi]
    )


@pytest.mark.parametrize("link,s", POINTS)
def test_jacobian_times_qd_matches_finite_difference(chain, rng, link, s):
    q, qd = rng.normal(size=6), rng.normal(size=6)
    fd = (
        kin.point_position(chain, q + FD_STEP * qd, link, s)
        - kin.point_position(chain, q - FD_STEP * qd, link, s)
    ) / (2 * FD_STEP)
    assert kin.point_jacobian(chain, q, link, s) @ qd == pytest.approx(fd, abs=ATOL_FD)
    assert kin.point_velocity(chain, q, qd, link, s) == pytest.approx(fd, abs=ATOL_FD)


@pytest.mark.parametrize("link,s", POINTS)
def test_exact_jdot_qd_matches_finite_difference(chain, rng, link, s):
    q, qd = rng.normal(size=6), rng.normal(size=6)

    def jqd(x):
        return kin.point_jacobian(chain, x, link, s) @ qd

    fd = (jqd(q + FD_STEP * qd) - jqd(q - FD_STEP * qd)) / (2 * FD_STEP)
    assert kin.point_bias_acceleration(chain, q, qd, link, s) == pytest.approx(fd, abs=1e-6)


def test_paper_finite_difference_jdot_is_first_order(chain, rng):
    q, qd = rng.normal(size=6), rng.normal(size=6)
    exact = kin.point_bias_acceleration(chain, q, qd, 5, -0.25)
    errs = [
        np.linalg.norm(kin.point_bias_acceleration_fd(chain, q, qd, 5, -0.25, h) - exact)
        for h in (4e-3, 2e-3, 1e-3)
    ]
    assert errs[0] > 1e-4  # visibly wrong at the paper's scale of steps
    ratios = [errs[0] / errs[1], errs[1] / errs[2]]
    assert ratios == pytest.approx([2.0, 2.0], rel=0.05)  # O(h)


def test_bad_inputs_raise(chain):
    with pytest.raises(ValueError, match="q"):
        kin.point_jacobian(chain, np.zeros(5), 1, 0.0)
    with pytest.raises(ValueError, match="q"):
        kin.point_position(chain, np.full(6, np.nan), 1, 0.0)
    with pytest.raises(ValueError, match="link"):
        kin.point_position(chain, np.zeros(6), 6, 0.0)


def test_acceleration_refill_equals_a_full_pass(chain, rng):
    """nb_fk_accelerations on a pass at (q, qd, 0) gives nb_fk's table at (q, qd, qdd) exactly."""
    for _ in range(20):
        q, qd, qdd = rng.normal(size=6), rng.normal(size=6), rng.normal(size=6) * 10
        full = np.empty((6, kin.NK))
        kin.nb_fk(chain.packed, q, qd, qdd, 0.0, full)
        refill = np.empty((6, kin.NK))
        kin.nb_fk(chain.packed, q, qd, np.zeros(6), 0.0, refill)
        kin.nb_fk_accelerations(chain.packed, qdd, refill)
        assert np.array_equal(full, refill)
