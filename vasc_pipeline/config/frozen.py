"""Validated configs are frozen: checked once, at the boundary, then read but never changed.

Every config dataclass derives from :class:`Settings`. :func:`vasc_pipeline.config.validate`
returns a frozen copy, its lists read-only (:class:`ReadOnlyList`); the engine and the
planner take such a config as it is, without checking it again, and anything else is
validated first. A changed config is derived
with :func:`dataclasses.replace` (the new object is not frozen) and validated in its turn.
Freezing is by instance, not by class, so that Hydra and OmegaConf build and merge the same
dataclasses as before.
"""

from __future__ import annotations

import copy
from dataclasses import FrozenInstanceError, fields, is_dataclass
from typing import Any, TypeVar

__all__ = ["Settings", "ReadOnlyList", "is_frozen", "thawed"]

_FLAG = "_frozen"
T = TypeVar("T")


def _refuse(self, *args, **kwargs):
    raise TypeError("a validated config is frozen, its lists too; derive a changed one with dataclasses.replace(...)")


class ReadOnlyList(list):
    """A list of a validated config: equal to the list it was made from (so a run's identity is
    unchanged), but every change is refused."""

    __setitem__ = __delitem__ = __iadd__ = __imul__ = _refuse
    append = extend = insert = pop = remove = clear = sort = reverse = _refuse

    def __reduce__(self):  # pickled (to a worker) and copied as a ReadOnlyList, without append
        return (ReadOnlyList, (list(self),))


class Settings:
    """Base of the config dataclasses: assignment is refused once :func:`_freeze` marked the instance."""

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


def _lists(value: Any, kind: type) -> Any:
    """``value`` with every (nested) list made a ``kind``."""
    if isinstance(value, list):
        return kind(_lists(v, kind) for v in value)
    return value


def _freeze(cfg: T) -> T:
    """Mark ``cfg`` and its nested sections read-only, lists included (in place), and return it.
    Only :func:`vasc_pipeline.config.validate` calls it: a frozen config is taken as validated."""
    for section in _sections(cfg):
        for f in fields(section):
            object.__setattr__(section, f.name, _lists(getattr(section, f.name), ReadOnlyList))
        object.__setattr__(section, _FLAG, True)
    return cfg


def is_frozen(cfg: Any) -> bool:
    """Whether ``cfg`` is a validated config (frozen by :func:`vasc_pipeline.config.validate`)."""
    return bool(getattr(cfg, "__dict__", {}).get(_FLAG, False))


def thawed(cfg: T) -> T:
    """A deep copy of ``cfg`` that can be changed (its sections and lists may have been frozen)."""
    out = copy.deepcopy(cfg)
    for section in _sections(out):
        section.__dict__.pop(_FLAG, None)
        for f in fields(section):
            setattr(section, f.name, _lists(getattr(section, f.name), list))
    return out
