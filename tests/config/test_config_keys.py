"""The key table (vasc_pipeline.config.keys): it covers the schema, the page is written from it,
and every range it holds is what validate refuses outside."""

from __future__ import annotations

import inspect
import os
import subprocess
import sys
from dataclasses import replace

import pytest
from helpers import REPO

from vasc_pipeline import config
from vasc_pipeline.config.frozen import thawed
from vasc_pipeline.config.keypage import help_text, page_with_tables
from vasc_pipeline.config.keys import KEY_OF, KEYS, schema_defaults
from vasc_pipeline.config.keyspec import EVERY, OneOf, Range

PAGE = REPO / "docs" / "configuration.md"

# Schema keys deliberately left out of the key table, each with the reason (none today).
LEFT_OUT: dict[str, str] = {}


def test_the_table_lists_every_key_of_the_schema_once():
    names = [k.name for k in KEYS]
    assert len(names) == len(set(names)), sorted({n for n in names if names.count(n) > 1})
    missing = sorted(set(schema_defaults()) - set(names) - set(LEFT_OUT))
    assert not missing, f"schema keys missing from vasc_pipeline.config.keys.KEYS: {missing}"
    unknown = sorted(set(names) - set(schema_defaults()))
    assert not unknown, f"KEYS lists keys the schema does not hold: {unknown}"


def test_the_page_is_written_from_the_table():
    page = PAGE.read_text(encoding="utf-8")
    assert page_with_tables(page) == page, (
        "docs/configuration.md differs from the key table: "
        "python -m vasc_pipeline.config.keypage --write docs/configuration.md"
    )


def test_a_drifted_page_is_found():
    page = PAGE.read_text(encoding="utf-8")
    drifted = page.replace("| `anneal.p_swap` | 1 | 0.3 |", "| `anneal.p_swap` | 1 | 0.4 |")
    assert drifted != page and page_with_tables(drifted) == page


def test_every_template_holds_the_value_it_stands_for():
    for key in KEYS:
        assert key.default.count("{}") == 1, key.name  # the schema's default, written in by the page
        if key.check is not None:
            assert key.accepted.count("{}") == 1, key.name  # the check's own words
        else:
            assert "{}" not in key.accepted, key.name


def test_the_tissues_of_a_key_are_those_whose_builder_reads_it():
    from vasc_pipeline.model.tissue import TISSUES

    read_by = {name: set(inspect.signature(build).parameters) for name, build in TISSUES.items()}
    for key in (k for k in KEYS if k.section == "tissue"):
        leaf = key.name.split(".")[1]
        readers = sorted(name for name, params in read_by.items() if leaf in params)
        if leaf in config.TISSUE_KEYS_OF_EVERY_TISSUE or readers == sorted(TISSUES):
            assert key.tissues == EVERY, key.name
        else:
            assert sorted(key.tissues) == readers, key.name


def test_the_schema_anneal_defaults_are_the_fast_preset():
    """The page's `fast` (schema) column is the schema's default; conf/anneal/fast.yaml must agree."""
    from omegaconf import OmegaConf

    fast = OmegaConf.to_container(OmegaConf.load(config.CONFIG_DIR / "anneal" / "fast.yaml"))
    defaults = schema_defaults()
    assert {k: v for k, v in fast.items() if defaults[f"anneal.{k}"] != v} == {}


def test_help_lists_every_key_with_its_accepted_values():
    text = help_text()
    for key in KEYS:
        assert key.name in text, key.name
    assert "anneal.p_swap: [0, 1]" in text and "physics.gamma: [1, 4]" in text


@pytest.mark.integration
def test_the_command_help_lists_the_keys(tmp_path):
    repo = str(REPO)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([repo, os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run(
        [sys.executable, "-m", "vasc_pipeline", "--help"], cwd=tmp_path, env=env, capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr
    assert "== Every key [unit]: accepted values ==" in done.stdout
    assert "    anneal.p_swap: [0, 1]" in done.stdout and "checkpoint.every_seconds [s]: (0, 604800]" in done.stdout
    assert "== The config" in done.stdout and "tissue: box, heart, mask, plane2d, sphere" in done.stdout


def _base(key):
    """A config every check of ``key`` applies to."""
    overrides = ["tissue=sphere", "n_terminals=64"]
    if key.name.startswith("anneal.packing_T"):
        overrides.append("anneal.packing_steps_per_terminal=2")
    if key.tissues not in (None, EVERY):
        overrides[0] = f"tissue={key.tissues[0]}"
    return thawed(config.compose(overrides, check=False))


def _with(cfg, name, value):
    *path, leaf = name.split(".")
    node = cfg
    for part in path:
        node = getattr(node, part)
    setattr(node, leaf, value)
    return cfg


CHECKED = [k for k in KEYS if k.check is not None]


@pytest.mark.parametrize("key", CHECKED, ids=[k.name for k in CHECKED])
def test_a_value_just_outside_a_range_is_refused_naming_the_key(key):
    values = key.check.refused()
    assert values
    for value in values:
        with pytest.raises(config.ConfigError, match=key.name.replace(".", r"\.")):
            config.validate(_with(_base(key), key.name, value))


@pytest.mark.parametrize("key", CHECKED, ids=[k.name for k in CHECKED])
def test_the_default_passes_its_own_check(key):
    value = schema_defaults()[key.name]
    key.check.check(key.name, value)


def test_range_words_on_the_page_and_in_messages():
    assert Range(0, 1, lo_open=True, hi_open=True).doc == "(0, 1)"
    assert Range(0, lo_open=True, null=True).doc == "> 0, or null"
    assert Range(1, 10**7, integer=True).doc == "integer in [1, 1e7]"
    assert Range(0, integer=True).doc == "integer ≥ 0"
    assert OneOf(("a", "b"), null=True).doc == "`a`, `b`, or null"
    with pytest.raises(config.ConfigError, match=r"^x must be an integer in \[1, 1e\+07\], got 0$"):
        Range(1, 10**7, integer=True).check("x", 0)
    with pytest.raises(config.ConfigError, match=r"^x must lie in \(0, 1\] \(why\), got 1\.5$"):
        Range(0, 1, lo_open=True, why=" (why)").check("x", 1.5)
    with pytest.raises(config.ConfigError, match=r"^x: unknown model 'y'; accepted: a, b$"):
        OneOf(("a", "b"), unknown="model").check("x", "y")


def test_a_key_checked_only_where_it_applies():
    """anneal.packing_T_start is read only with a packing phase: elsewhere any value passes, as before."""
    cfg = thawed(config.compose(["tissue=sphere", "n_terminals=64"], check=False))
    config.validate(replace(cfg, anneal=replace(cfg.anneal, packing_T_start=0.0)))
    assert KEY_OF["anneal.packing_T_start"].applies is not None
