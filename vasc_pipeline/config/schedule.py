"""A run's schedule in steps: where its phases begin and end, computed once from the config.

Every count is in proposed moves (steps) from 0. The run is ``total`` steps: first the
packing phase (``pack`` steps, :mod:`vasc_pipeline.kernel.packing`), then the tree anneal
(``tree`` steps), whose shares (the cold part, supply's own schedule, full-width terminal
moves, the coarse exclusion map, the phases of a tree in parts) are fixed here. The engine
builds one :class:`Schedule` per problem (:func:`vasc_pipeline.engine.build_problem`) and
copies it into the kernel's ``Model`` as flat numbers; validation and planning, which need
only the run's length, call :func:`scheduled_steps` and :func:`packing_steps`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .schema import RunConfig

__all__ = ["Schedule", "scheduled_steps", "packing_steps"]


def scheduled_steps(cfg: RunConfig) -> int:
    """Proposed moves of a run: ``anneal.steps`` exactly when given, else the schedule's default
    ``steps_at_1000 * (N / 1000)^steps_exponent``. A CCO run (``method=cco``) counts terminals
    added instead: N.
    """
    if cfg.method.name == "cco":
        return int(cfg.n_terminals)
    if cfg.anneal.steps is not None:
        return int(cfg.anneal.steps)
    return max(1, int(round(cfg.anneal.steps_at_1000 * (cfg.n_terminals / 1000.0) ** cfg.anneal.steps_exponent)))


def packing_steps(cfg: RunConfig) -> int:
    """Proposals of the packing phase (the first of the run's steps): per terminal times N."""
    return int(round(cfg.anneal.packing_steps_per_terminal * cfg.n_terminals))


@dataclass(frozen=True)
class Schedule:
    """A run's phases in steps (ints; the kernel takes them as floats).

    ``cold``, ``supply`` and ``full_width`` count steps of the tree anneal (from ``pack`` on):
    before its cold part (the whole tree anneal without one), of supply's own temperature
    schedule (0: none) and with half the terminal moves at full width. ``coarse`` is the
    (global) step at which the coarse exclusion map gives way to the true one (0: none);
    ``part_phases`` the phases of a tree in parts (``anneal.parts`` > 1).
    """

    total: int
    pack: int
    cold: int
    supply: int
    full_width: int
    coarse: int
    part_phases: int

    @property
    def tree(self) -> int:
        """Steps of the tree anneal (after the packing phase)."""
        return self.total - self.pack

    @classmethod
    def of(cls, cfg: RunConfig, *, exclusion: bool) -> Schedule:
        """The schedule of a validated config; ``exclusion``: whether the exclusion term is
        annealed (the coarse map serves it alone: without it there is no coarse phase)."""
        a = cfg.anneal
        total, pack = scheduled_steps(cfg), packing_steps(cfg)

        def tree_steps(share: float) -> int:  # a share of the tree anneal's steps
            return int(round(share * (total - pack)))

        coarse = a.coarse_exclusion_factor is not None and exclusion
        return cls(
            total=total,
            pack=pack,
            cold=tree_steps(1.0 - a.cold_share) if a.cold_from is not None else tree_steps(1.0),
            supply=tree_steps(a.supply_phase) if a.supply_T_start is not None else 0,
            full_width=tree_steps(a.full_width_phase),
            coarse=pack + tree_steps(a.coarse_exclusion_phase) if coarse else 0,
            part_phases=int(a.part_phases),
        )

    def phase_ends(self) -> np.ndarray:
        """The global step at which each phase of a tree in parts ends: ``part_phases`` equal
        shares of the tree anneal, and the end of the coarse map's phase, so that no phase
        straddles a change of model (int64, ascending, all after ``pack``)."""
        pack, total = self.pack, self.total
        ends = pack + (total - pack) * np.arange(1, self.part_phases + 1, dtype=np.int64) // self.part_phases
        if pack < self.coarse < total:
            ends = np.union1d(ends, [self.coarse])
        return np.unique(ends[ends > pack])
