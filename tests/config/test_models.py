"""The model group: ``model=paper`` (the paper read literally) and ``model=physiological``."""

from __future__ import annotations

from dataclasses import asdict

import pytest

from vasc_pipeline.config import ConfigError, compose, from_stored
from vasc_pipeline.config.identity import config_hash

PHYSIOLOGICAL = {
    "physics.gamma": 7 / 3,
    "physics.r_cutoff": 2e-4,
    "physics.r_cutoff_ramp": 2e-4,
    "physics.viscosity_law": "pries_in_vivo",
    "physics.A_p": 1e-9,
    "tissue.bifurcation_reach": 0.0,
}


def value(cfg, dotted):
    section, key = dotted.split(".")
    return getattr(getattr(cfg, section), key)


def test_the_paper_model_is_the_one_stores_were_grown_with():
    paper = compose(["model=paper"])
    assert (paper.physics.gamma, paper.physics.r_cutoff, paper.tissue.bifurcation_reach) == (2.1, 1e-5, None)
    assert (paper.physics.r_cutoff_ramp, paper.physics.viscosity_law, paper.physics.A_p) == (0.0, "constant", 0.0)
    assert paper.tissue.inlet_share is None and paper.tissue.inlet_assignment == "random"
    stored_before = asdict(paper)
    del stored_before["model"]  # a store written before the model group existed
    assert config_hash(stored_before) == config_hash(asdict(paper))
    assert from_stored(stored_before).model.name == "paper"


@pytest.mark.parametrize("tissue", ["heart", "sphere", "box"])
def test_the_physiological_model_sets_its_keys_on_every_tissue_and_each_stays_overridable(tissue):
    cfg = compose(["model=physiological", f"tissue={tissue}"])
    assert cfg.model.name == "physiological"
    for key, expected in PHYSIOLOGICAL.items():
        assert value(cfg, key) == (expected if isinstance(expected, str) else pytest.approx(expected)), key
    heart = tissue == "heart"  # the split between the two arteries is the heart's
    assert cfg.tissue.inlet_share == ([0.62, 0.38] if heart else None)
    assert cfg.tissue.inlet_share_tolerance == (0.15 if heart else None)
    assert config_hash(asdict(cfg)) != config_hash(asdict(compose(["model=paper", f"tissue={tissue}"])))
    assert compose(["model=physiological", "physics.gamma=2.1"]).physics.gamma == 2.1


def test_the_cco_growth_takes_the_physiological_physics_but_not_the_anneals_confinements():
    cfg = compose(["model=physiological", "method=cco"])
    assert cfg.physics.gamma == pytest.approx(7 / 3) and cfg.physics.r_cutoff == 2e-4
    assert cfg.tissue.bifurcation_reach is None and cfg.tissue.inlet_share is None  # the anneal's keys


def test_a_tissue_keeps_what_it_sets_itself_under_either_model():
    for model in ("paper", "physiological"):
        assert compose([f"model={model}", "+sweep=convergence"]).physics.gamma == 3.0  # the paper's 2-D test


def test_an_unknown_model_is_refused_naming_the_accepted_ones():
    with pytest.raises(ConfigError, match="paper.*physiological|physiological.*paper"):
        compose(["model=nonsense"])
    with pytest.raises(ConfigError, match="model.name: unknown model 'nonsense'; accepted: paper, physiological"):
        compose(["model.name=nonsense"])
