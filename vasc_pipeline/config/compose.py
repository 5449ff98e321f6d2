"""Composing a run config from ``conf/`` as the command line does (Hydra), outside Hydra's app:
the schema registered as ``base_config``, the ``+sweep=single`` rule, counts written as floats
taken as integers, and Hydra's errors in one line."""

from __future__ import annotations

import re
from typing import Any

from .checks import validate
from .schema import CONFIG_DIR, ConfigError, RunConfig, SweepConfig, to_run_config

__all__ = [
    "compose",
    "integral_counts",
    "register_schema",
    "with_sweep_group",
    "hydra_error_message",
    "SINGLE_SWEEP",
]


def register_schema() -> None:
    """Register :class:`RunConfig` as Hydra's ``base_config`` (types and keys are checked on merge),
    and the resolver ``${vasc_pipeline_keys:}`` that writes the key table's list into ``--help``
    (conf/config.yaml's ``hydra.help.template``)."""
    from hydra.core.config_store import ConfigStore
    from omegaconf import OmegaConf

    ConfigStore.instance().store(name="base_config", node=RunConfig)
    if not OmegaConf.has_resolver("vasc_pipeline_keys"):
        OmegaConf.register_new_resolver("vasc_pipeline_keys", _key_list)


def _key_list() -> str:
    from .keypage import help_text

    return help_text()


SINGLE_SWEEP = "single"  # conf/sweep/single.yaml: the base config's one job, axes from the command line


def with_sweep_group(overrides: list[str] | tuple[str, ...]) -> list[str]:
    """``overrides`` with ``+sweep=single`` in front when they set a ``sweep.*`` key without
    choosing a sweep: ``sweep.seeds=[0,1,2,3]`` alone then runs the base config with those
    seeds, where Hydra would fail on a key under the absent ``sweep`` node."""
    keys = [o.lstrip("+~").partition("=")[0].partition("@")[0] for o in overrides if not o.startswith("-")]
    if "sweep" not in keys and any(k.startswith("sweep.") for k in keys):
        return [f"+sweep={SINGLE_SWEEP}", *overrides]
    return list(overrides)


def _count_keys() -> set[str]:
    """The dotted keys of the schema that hold a count (an int, or a list of ints)."""
    import typing

    out: set[str] = set()

    def walk(cls: type, prefix: str) -> None:
        for name, hint in typing.get_type_hints(cls).items():
            args = [a for a in typing.get_args(hint) if a is not type(None)]
            kind = args[0] if typing.get_origin(hint) is typing.Union and len(args) == 1 else hint
            if hasattr(kind, "__dataclass_fields__"):
                walk(kind, f"{prefix}{name}.")
            elif kind is int or (typing.get_origin(kind) is list and typing.get_args(kind) == (int,)):
                out.add(prefix + name)

    walk(RunConfig, "")
    return out


def _integral(key: str, text: str) -> str:
    """``text`` of a count as an integer literal when it is a float literal of an integer (``1e5``);
    ConfigError naming ``key`` when it is a float literal of a fraction; anything else unchanged."""
    from decimal import Decimal, InvalidOperation

    t = text.strip()
    if not re.fullmatch(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?", t) or re.fullmatch(r"[+-]?\d+", t):
        return text
    try:
        value = Decimal(t)
    except InvalidOperation:
        return text
    if value != value.to_integral_value():
        raise ConfigError(f"{key} must be an integer (a count), got {t}")
    return str(int(value))


def integral_counts(overrides: list[str] | tuple[str, ...]) -> list[str]:
    """``overrides`` with every count written as a float (``anneal.steps=1e5``,
    ``sweep.steps=[1e4,1e5]``, as the docs write step counts) given as the integer it is; a
    fraction (``anneal.steps=1.5e5+0.5``, i.e. 150000.5) is refused naming the key."""
    counts = _count_keys()
    out = []
    for o in overrides:
        key, eq, value = o.partition("=")
        name = key.lstrip("+~").partition("@")[0]
        if not eq or name not in counts:
            out.append(o)
            continue
        v = value.strip()
        if v.startswith("[") and v.endswith("]"):
            items = [_integral(f"{name}[{i}]", x) for i, x in enumerate(v[1:-1].split(","))] if v[1:-1].strip() else []
            value = "[" + ",".join(items) + "]"
        else:
            value = _integral(name, value)
        out.append(f"{key}={value}")
    return out


def compose(overrides: list[str] | tuple[str, ...] = (), config_name: str = "config", check: bool = True) -> RunConfig:
    """Resolved run config from Hydra overrides, e.g. ``compose(["tissue=plane2d", "n_terminals=64"])``.

    A Hydra-level error (unknown key or group option, wrong type, unparsable override) is a
    :class:`ConfigError` listing what is accepted; ``check=False`` skips :func:`validate`.
    ``sweep.*`` keys without ``+sweep=NAME`` select the ``single`` sweep (:func:`with_sweep_group`).
    """
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    register_schema()
    if GlobalHydra.instance().is_initialized():
        GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
            cfg = hydra_compose(config_name=config_name, overrides=with_sweep_group(integral_counts(overrides)))
    except (HydraException, OmegaConfBaseException) as exc:
        raise ConfigError(hydra_error_message(exc)) from exc
    cfg = to_run_config(cfg)
    return validate(cfg) if check else cfg


def _schema_keys(path: list[str]) -> list[str] | None:
    """The config keys accepted under a dotted path of the schema (None: not a section)."""
    node: Any = RunConfig()
    for part in path:
        node = getattr(node, part, None)
        if node is None and part == "sweep":  # optional group: its schema's defaults
            node = SweepConfig()
    return list(node.__dataclass_fields__) if hasattr(node, "__dataclass_fields__") else None


def hydra_error_message(exc: BaseException) -> str:
    """One paragraph for a Hydra composition error, naming the key and what is accepted."""
    text = str(exc).split("\nConfig search path:")[0].strip()
    if "Available options in" in text:  # an unknown group option: Hydra lists the group's options
        head, _, options = text.partition("Available options in")
        group, _, names = options.partition(":")
        accepted = ", ".join(n.strip() for n in names.split() if n.strip())
        head = head.strip().removeprefix("In 'config': ")
        return f"{head}; accepted options for {group.strip()}: {accepted}"
    cause = exc.__cause__ or exc
    key = getattr(cause, "full_key", None)
    if key:
        parts = str(key).split(".")
        kind = type(cause).__name__
        if kind in ("ConfigAttributeError", "ConfigKeyError"):
            accepted = _schema_keys(parts[:-1])
            where = ".".join(parts[:-1]) or "the top level"
            return f"unknown config key {key!r}" + (
                f"; accepted keys at {where}: {', '.join(accepted)}" if accepted else ""
            )
        first = str(cause).splitlines()[0]
        return f"{key}: {first}"
    return text.replace("\n", " ")
