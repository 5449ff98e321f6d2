"""The config is validated once, at the boundary, into a frozen run config that the engine and
the planner take as it is; the schema's defaults are the composed defaults."""

from __future__ import annotations

import pickle
from dataclasses import FrozenInstanceError, asdict, replace

import pytest

from vasc_pipeline import config, engine
from vasc_pipeline.config import checks
from vasc_pipeline.config.frozen import is_frozen
from vasc_pipeline.pipeline import planning

pytestmark = pytest.mark.unit


def test_the_schema_defaults_are_the_composed_defaults():
    """The schema's defaults are the paper's model (``model=paper``; the default model's keys are
    per tissue and method, which the schema cannot say), all but the heart's exclusion grid, which
    its group sets: the schema's null serves every tissue, so a sphere or a box built in code
    keeps its exclusion term on its supply grid."""
    assert config.compose([]).model.name == "physiological"
    schema_defaults, composed = asdict(config.RunConfig()), asdict(config.compose(["model=paper"], check=False))
    assert composed["tissue"].pop("exclusion_voxel_size") == config.HEART_EXCLUSION_VOXEL_SIZE
    assert schema_defaults["tissue"].pop("exclusion_voxel_size") is None
    assert schema_defaults == composed
    for name in ("sphere", "box", "plane2d"):
        assert config.compose([f"tissue={name}"]).tissue.exclusion_voxel_size is None
        assert (
            config.validate(config.RunConfig(tissue=config.TissueConfig(name=name))).tissue.exclusion_voxel_size is None
        )


def test_a_stored_config_takes_the_keys_it_lacks_at_their_values_before_them():
    """A store written before a key existed ran what the key's neutral value does, not today's default."""
    stored = {k: v for k, v in asdict(config.compose(["anneal=fast_v1", "tissue.exclusion_voxel_size=null"])).items()}
    for section, key in (("anneal", "coarse_exclusion_factor"), ("anneal", "steps_exponent"), ("tissue", "labels")):
        del stored[section][key]
    old = config.from_stored(stored)
    assert old.anneal.coarse_exclusion_factor is None and old.anneal.steps_exponent == 2.0
    today = config.RunConfig().anneal.coarse_exclusion_factor  # the schema's default (fast's), whatever it is now
    assert today is not None and config.to_run_config(stored).anneal.coarse_exclusion_factor == today  # not that run


def test_the_other_presets_state_what_they_differ_in():
    """With `fast` the schema's defaults, `paper` and `fast_v1` must say every value of theirs."""
    paper = config.compose(["anneal=paper"]).anneal
    assert (paper.T_start, paper.T_end, paper.steps_at_1000, paper.steps_exponent) == (1e10, 1e-5, 1e9, 2.0)
    assert (paper.p_swap, paper.p_local, paper.adapt_steps, paper.supply_T_start, paper.polish) == (
        0.5,
        0.0,
        False,
        None,
        False,
    )
    assert paper.cold_from is paper.coarse_exclusion_factor is None
    v1 = config.compose(["anneal=fast_v1"]).anneal
    assert (v1.steps_at_1000, v1.steps_exponent, v1.supply_phase, v1.acceptance_target) == (1e8, 2.0, 0.5, 0.3)
    assert v1.cold_from is v1.coarse_exclusion_factor is None and v1.full_width_phase == 1.0


def test_a_validated_config_is_frozen_and_validated_once():
    cfg = config.compose(["n_terminals=64"])
    assert is_frozen(cfg) and is_frozen(cfg.anneal) and is_frozen(cfg.cluster)
    with pytest.raises(FrozenInstanceError, match=r"AnnealConfig\.steps: a validated config is frozen"):
        cfg.anneal.steps = 5
    assert config.validate(cfg) is cfg
    changed = replace(cfg, n_terminals=128)
    assert not is_frozen(changed)
    again = config.validate(changed)
    assert is_frozen(again) and again.n_terminals == 128 and cfg.n_terminals == 64
    assert is_frozen(pickle.loads(pickle.dumps(cfg)))  # as a job reaches a worker


def test_a_derived_config_is_validated_in_its_turn():
    cfg = config.compose(["n_terminals=64"])
    with pytest.raises(config.ConfigError, match=r"n_terminals must be an integer in \[2, 1e\+08\]"):
        config.validate(replace(cfg, n_terminals=1))
    with pytest.raises(config.ConfigError, match=r"n_terminals must be an integer in \[2, 1e\+08\], got 64\.5"):
        config.validate(replace(cfg, n_terminals=64.5))
    whole = config.validate(replace(cfg, n_terminals=64.0, seed=3.0))  # a count written as a float
    assert (whole.n_terminals, whole.seed) == (64, 3) and isinstance(whole.n_terminals, int)


def test_a_swept_key_and_its_axis_share_one_rule():
    messages = []
    for overrides in (["n_terminals=1"], ["sweep.n_terminals=[16,1]"], ["anneal.steps=0"], ["sweep.steps=[0]"]):
        with pytest.raises(config.ConfigError) as info:
            config.compose(["tissue=sphere", *overrides])
        messages.append(str(info.value))
    assert messages == [
        "n_terminals must be an integer in [2, 1e+08], got 1",
        "sweep.n_terminals[1] must be an integer in [2, 1e+08], got 1",
        "anneal.steps must be an integer in [1, 1e+15] (proposed moves per run), got 0",
        "sweep.steps[0] must be an integer in [1, 1e+15] (proposed moves per run), got 0",
    ]


@pytest.fixture
def validations(monkeypatch):
    """How many times validate() checks a config (a frozen one is not checked)."""
    calls = []
    check = checks._validate_method  # called once by every validation that checks
    monkeypatch.setattr(checks, "_validate_method", lambda cfg: (calls.append(1), check(cfg))[1])
    return calls


def test_the_engine_takes_a_validated_config_as_it_is(validations):
    cfg = config.compose(["tissue=sphere", "n_terminals=16"])
    validations.clear()
    engine.build_problem(cfg)
    assert validations == []
    engine.build_problem(replace(cfg, seed=1))  # not validated: checked here
    assert validations == [1]


def test_the_planner_validates_each_job_once(validations, tmp_path):
    cfg = config.compose(["tissue=sphere", "n_terminals=16", "sweep.seeds=[0,1,2]", f"output_dir={tmp_path}"])
    validations.clear()
    p = planning.plan(cfg)
    assert len(p.jobs) == 3 and len(validations) == 3  # the base config was validated by compose
    assert all(is_frozen(j.run_config()) for j in p.jobs)
    assert all(j.run_config() is j.run_config() for j in p.jobs)
