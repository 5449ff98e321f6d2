"""Validated configs are frozen: checked once, at the boundary, then read but never changed.

Every config dataclass derives from :class:`Settings`. :func:`vasc_pipeline.config.validate`
returns a frozen copy (:func:`freeze`); the engine and the planner take such a config as it is,
without checking it again, and anything else is validated first. A changed config is derived
with :func:`dataclasses.replace` (the new object is not frozen) and validated in its turn.
Freezing is by instance, not by class, so that Hydra and OmegaConf build and merge the same
dataclasses as before.
"""

from __future__ import annotations

import copy
from dataclasses import FrozenInstanceError, fields, is_dataclass
from typing import Any, TypeVar

__all__ = ["Settings", "freeze", "is_frozen", "thawed"]

_FLAG = "_frozen"
T = TypeVar("T")


class Settings:
    """Base of the config dataclasses: assignment is refused once :func:`freeze` marked the instance."""

    def __setattr__(self, name: str, value: Any) -> None:
        if self.__dict__.get(_FLAG, False):
            raise FrozenInstanceError(
                f"cannot assign {type(self).__name__}.{name}: a validated config is frozen; derive a changed "
                "one with dataclasses.replace(...) and validate it"
            )
        object.__setattr__(self, name, value)


def _sections(cfg: Any):
    """``cfg`` and every config dataclass nested in it."""
    yield cfg
    for f in fields(cfg):
        value = getattr(cfg, f.name)
        if is_dataclass(value) and not isinstance(value, type):
            yield from _sections(value)


def freeze(cfg: T) -> T:
    """Mark ``cfg`` and its nested sections read-only (in place) and return it."""
    for section in _sections(cfg):
        object.__setattr__(section, _FLAG, True)
    return cfg


def is_frozen(cfg: Any) -> bool:
    """Whether ``cfg`` was frozen by :func:`freeze` (i.e. validated)."""
    return bool(getattr(cfg, "__dict__", {}).get(_FLAG, False))


def thawed(cfg: T) -> T:
    """A deep copy of ``cfg`` that can be changed (its sections may have been frozen)."""
    out = copy.deepcopy(cfg)
    for section in _sections(out):
        section.__dict__.pop(_FLAG, None)
    return out
