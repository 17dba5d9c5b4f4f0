import dataclasses

import numpy as np
import pytest

from biped_constraint_env.model import PAPER_LINKS, LinkParams, paper_biped


def test_paper_values(params):
    assert params.total_mass_kg == pytest.approx(5.0)
    foot = params.links[0]
    assert foot.inertia_com_kgm2 == pytest.approx(0.5 * (3 * 0.25 + 0.25) / 12)
    assert params.gravity_mps2 == 9.8
    assert params.chain(0).heel_toe_split_m == 0.5


@pytest.mark.parametrize(
    "field,value",
    [
        ("mass_kg", -1.0),
        ("length_m", 0.0),
        ("radius_m", np.nan),
        ("damping_nms_per_rad", -0.1),
        ("mass_kg", np.inf),
    ],
)
def test_link_validation_names_field(field, value):
    kw = dataclasses.asdict(PAPER_LINKS[1])
    kw[field] = value
    with pytest.raises(ValueError, match=field):
        LinkParams(**kw)


@pytest.mark.parametrize(
    "field,value",
    [
        ("gravity_mps2", 0.0),
        ("friction_ratio", -1.0),
        ("heel_toe_split_m", np.nan),
        ("friction_ratio", "a"),
    ],
)
def test_biped_validation_names_field(field, value):
    with pytest.raises(ValueError, match=field):
        paper_biped(**{field: value})


def test_links_must_be_six():
    with pytest.raises(ValueError, match="links"):
        paper_biped(links=PAPER_LINKS[:5])


def test_reversed_chain_keeps_each_physical_joint_damping():
    links = tuple(
        dataclasses.replace(lk, damping_nms_per_rad=float(i)) for i, lk in enumerate(PAPER_LINKS)
    )
    p = paper_biped(links=links)
    assert p.chain(0).joint_damping_nms_per_rad == (0, 1, 2, 3, 4, 5)
    # joint j of the reversed chain is the paper's joint 6 - j; the toe pivot keeps D_0
    assert p.chain(1).joint_damping_nms_per_rad == (0, 5, 4, 3, 2, 1)
    assert p.chain(1).links == tuple(reversed(links))


def test_model_is_frozen(params):
    with pytest.raises(dataclasses.FrozenInstanceError):
        params.gravity_mps2 = 1.0
    assert not params.chain(0).packed.flags.writeable
