"""Shared test helpers: seeded problem builders (configs composed as users compose them)."""

from __future__ import annotations

from vasc_pipeline import config, engine


def make_problem(*overrides: str):
    """A validated Problem from Hydra-style overrides."""
    return engine.build_problem(config.compose(list(overrides)))
