"""The forms of a config key's entry in the key table (:mod:`vasc_pipeline.config.keys`).

A :class:`Key` holds what the page, ``--help`` and :func:`~vasc_pipeline.config.validate` say and
check about one key; its accepted values are a :class:`Range`, a :class:`OneOf` or a
:class:`Rule` (a callable with its description). Each check refuses a value with a
:class:`ConfigError` naming the key, the value and what is accepted, and says in the page's words
what it accepts (:attr:`doc`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Optional, Union

from .errors import ConfigError

__all__ = [
    "BOOLEAN",
    "EVERY",
    "Key",
    "NON_NEGATIVE",
    "OneOf",
    "POSITIVE",
    "PROBABILITY",
    "Range",
    "Rule",
    "SHARE",
    "format_value",
    "mesh_units",
    "packing_on",
    "page_bound",
    "plural",
    "supply_schedule_on",
    "tissue_names",
]

EVERY = "every"  # Key.tissues: a key every tissue reads


def format_value(value: Any) -> str:
    """A value as the page writes it: ``null``, ``true``, ``100 000``, ``2.1e-3``, ``1.0``, `` `heart` ``."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f"`{value}`"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(format_value(v).strip("`") for v in value) + "]"
    if isinstance(value, int):
        return f"{value:,}".replace(",", " ") if value >= 10_000 else str(value)
    return _number(value)


def _number(value: float) -> str:
    """A float in the shortest form that reads back exactly: 0.9, 218.0, 1e4, 2.1e-3, 1e30."""
    if value == 0 or 1e-2 <= abs(value) < 1e4:
        return repr(value)
    for digits in range(17):
        text = f"{value:.{digits}e}"
        if float(text) == value:
            break
    mantissa, exponent = text.split("e")
    return f"{mantissa}e{int(exponent)}"


def _bound_message(value: float) -> str:
    """A bound in an error message: 1e+07 for a power of ten from a million on, else 100000, 0.5."""
    if isinstance(value, int) and value >= 10**6 and float(f"{value:.0e}") == value:
        return f"{value:.0e}"
    return f"{value:g}"


def page_bound(value: float) -> str:
    """A bound on the page: 1e7 for a large power of ten, 0.05, 4."""
    if isinstance(value, int) and value >= 10**5 and float(f"{value:.0e}") == value:
        return f"{value:.0e}".replace("e+0", "e").replace("e+", "e")
    return f"{value:g}"


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


@dataclass(frozen=True)
class Range:
    """Numbers between ``lo`` and ``hi`` (either may be None: unbounded), each end closed unless
    open; ``integer``: integers only (never a bool); ``null``: None accepted too; ``why`` follows
    the accepted range in the error message, ``says`` (if given) replaces its words there."""

    lo: Optional[float] = None
    hi: Optional[float] = None
    lo_open: bool = False
    hi_open: bool = False
    integer: bool = False
    null: bool = False
    why: str = ""
    says: str = ""

    def ok(self, value: Any) -> bool:
        if value is None:
            return self.null
        if not (_is_int(value) if self.integer else _is_number(value) and math.isfinite(value)):
            return False
        if self.lo is not None and not (value > self.lo if self.lo_open else value >= self.lo):
            return False
        return self.hi is None or (value < self.hi if self.hi_open else value <= self.hi)

    def check(self, name: str, value: Any) -> Any:
        if not self.ok(value):
            raise ConfigError(f"{name} must {self.words()}{self.why}, got {value!r}")
        return value

    def words(self) -> str:
        """What the error message says is accepted: ``lie in (0, 1)``, ``be an integer >= 0``."""
        if self.says:
            return self.says
        null = ", or null" if self.null else ""
        if self.lo is not None and self.hi is not None:
            interval = (
                f"{'(' if self.lo_open else '['}{_bound_message(self.lo)}, "
                f"{_bound_message(self.hi)}{')' if self.hi_open else ']'}"
            )
            return (f"be an integer in {interval}" if self.integer else f"lie in {interval}") + null
        kind = "an integer" if self.integer else "a finite number"
        if self.lo is not None:
            return f"be {kind} {'>' if self.lo_open else '>='} {_bound_message(self.lo)}{null}"
        if self.hi is not None:
            return f"be {kind} {'<' if self.hi_open else '<='} {_bound_message(self.hi)}{null}"
        return f"be {kind}{null}"

    @property
    def doc(self) -> str:
        """What the page says is accepted: ``(0, 1)``, ``integer ≥ 0``, ``> 0, or null``."""
        null = ", or null" if self.null else ""
        kind = "integer " if self.integer else ""
        if self.lo is not None and self.hi is not None:
            lo, hi = page_bound(self.lo), page_bound(self.hi)
            interval = f"{'(' if self.lo_open else '['}{lo}, {hi}{')' if self.hi_open else ']'}"
            return f"{kind}{'in ' if kind else ''}{interval}{null}"
        if self.lo is not None:
            return f"{kind}{'>' if self.lo_open else '≥'} {page_bound(self.lo)}{null}"
        if self.hi is not None:
            return f"{kind}{'<' if self.hi_open else '≤'} {page_bound(self.hi)}{null}"
        return f"{kind or 'a finite number'}{null}".strip()

    def refused(self) -> list[Any]:
        """Values just outside the range (for the tests: each must be refused)."""
        out: list[Any] = [] if self.null else [None]
        step = 1 if self.integer else 1e-9
        if self.lo is not None:
            out.append(self.lo if self.lo_open else self.lo - step)
        if self.hi is not None:
            out.append(self.hi if self.hi_open else self.hi + step)
        if self.integer:
            out.append(True)
        return out


@dataclass(frozen=True)
class OneOf:
    """One of ``options`` (a tuple, or a callable giving it when the key is checked: a list that
    lives in a module :mod:`vasc_pipeline.config` must not import); ``null``: None accepted too.
    ``unknown``: the message's noun for the style ``model.name: unknown model 'x'; accepted: ...``."""

    options: Union[tuple, Callable[[], tuple]]
    null: bool = False
    why: str = ""
    unknown: str = ""

    def values(self) -> tuple:
        return self.options() if callable(self.options) else self.options

    def check(self, name: str, value: Any) -> Any:
        values = self.values()
        if (value is None and self.null) or any(value == v and type(value) is type(v) for v in values):
            return value
        listed = ", ".join(format_value(v).strip("`") for v in values)
        if self.unknown:
            raise ConfigError(f"{name}: unknown {self.unknown} {value!r}; accepted: {listed}{self.why}")
        null = ", or null" if self.null else ""
        raise ConfigError(f"{name} must be one of {listed}{null}{self.why}, got {value!r}")

    @property
    def doc(self) -> str:
        return ", ".join(format_value(v) for v in self.values()) + (", or null" if self.null else "")

    def refused(self) -> list[Any]:
        return ([] if self.null else [None]) + ["no such option"]


@dataclass(frozen=True)
class Rule:
    """The values a key accepts: numbers of ``kind`` (an int may be written 1e5) passing ``ok``;
    ``accepted`` in the error message, ``doc`` on the page, ``outside`` refused values (for the
    tests); ``null``: None accepted too (the key's, not its sweep axis's)."""

    kind: type
    ok: Callable[[Any], bool]
    accepted: str
    doc: str = ""
    outside: tuple = ()
    null: bool = False

    def check(self, name: str, value: Any) -> Any:
        """``value`` as ``kind``; a :class:`ConfigError` naming ``name`` when it is not accepted."""
        if value is None and self.null:
            return None
        if self.kind is int:  # an int, or a float that is one (1e5); never a bool
            number = _is_int(value) or (isinstance(value, float) and value.is_integer())
        else:
            number = _is_number(value)
        try:
            ok = number and self.ok(self.kind(value))
        except OverflowError:  # an integer beyond the float range
            ok = False
        if not ok:
            raise ConfigError(f"{name} must be {self.accepted}, got {value!r}")
        return self.kind(value)

    def refused(self) -> list[Any]:
        return ([] if self.null else [None]) + list(self.outside)


Check = Union[Range, OneOf, Rule]


@dataclass(frozen=True)
class Key:
    """One config key: its ``unit``, ``default`` (``{}`` stands for the schema's default, which the
    page fills in: the default has one home), ``accepted`` (``{}`` stands for the check's own
    words), ``what`` it does, the ``tissues`` that read it (tissue keys), and the ``check``
    :func:`~vasc_pipeline.config.validate` applies (None: checked elsewhere, or by code that a
    table cannot express), only where ``applies(cfg)``."""

    name: str
    unit: str
    what: str
    default: str = "{}"
    accepted: str = "{}"
    check: Optional[Check] = None
    tissues: Union[str, tuple[str, ...], None] = None
    applies: Optional[Callable[[Any], bool]] = None

    @property
    def section(self) -> str:
        """The page's table the key is listed in: its group, or ``top``."""
        head = self.name.split(".")[0]
        return head if head in SECTIONS else "top"

    def accepted_doc(self) -> str:
        return self.accepted.replace("{}", self.check.doc) if self.check is not None else self.accepted


SECTIONS = ("tissue", "physics", "anneal", "terminals", "method", "extend", "checkpoint", "sweep", "cluster")


# Shared by the key table's sections (config/keys*.py).
POSITIVE = Range(0, lo_open=True)
NON_NEGATIVE = Range(0)
SHARE = Range(0, 1, lo_open=True, hi_open=True)  # a share strictly between none and all
PROBABILITY = Range(0, 1)
BOOLEAN = OneOf((True, False))


def tissue_names() -> tuple:
    from ..model.tissue import TISSUES  # the model imports the config: looked up when checked

    return tuple(sorted(TISSUES))


def viscosity_laws() -> tuple:
    from ..model.physics import VISCOSITY_LAWS

    return VISCOSITY_LAWS


def mesh_units() -> tuple:
    from ..model.tissue.surfaces import MESH_UNITS

    return tuple(MESH_UNITS)


def packing_on(cfg) -> bool:
    return cfg.anneal.packing_steps_per_terminal > 0


def supply_schedule_on(cfg) -> bool:
    return cfg.anneal.supply_T_start is not None


def plural(doc: str) -> str:
    """``integer in [2, 1e8]`` as ``integers in [2, 1e8]``, ``> 0`` as ``numbers > 0``."""
    return doc.replace("integer", "integers", 1) if doc.startswith("integer") else f"numbers {doc}"
