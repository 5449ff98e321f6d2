"""The key table: one entry per config key, the one home of its unit, accepted range and meaning.

:data:`KEYS` drives :func:`~vasc_pipeline.config.validate` (each entry's ``check``), the key
list of ``python -m vasc_pipeline --help`` and the key tables of ``docs/configuration.md``
(:mod:`vasc_pipeline.config.keypage`; ``python -m vasc_pipeline.config.keypage --write
docs/configuration.md`` writes them, a test fails when the page and the table differ). Defaults
are the schema's (:mod:`vasc_pipeline.config.schema`, :mod:`vasc_pipeline.config.pipeline`): an
entry's ``default`` text only says where a group sets another value, ``{}`` standing for the
schema's.
"""

from __future__ import annotations

import dataclasses
import typing
from typing import Any

from .keys_pipeline import PIPELINE_KEYS
from .keys_run import RUN_KEYS
from .keys_tissue import TISSUE_KEYS
from .keyspec import Key, OneOf
from .rules import SWEPT_KEYS
from .schema import (
    MODELS,
    STAGES,
)

__all__ = ["KEYS", "KEY_OF", "schema_defaults"]

# The run's own keys; the sections' entries are in keys_tissue, keys_run and keys_pipeline.
_TOP_KEYS: tuple[Key, ...] = (
    Key(
        "n_terminals",
        "1",
        "N, the number of terminals",
        default="{} (`tissue=plane2d`: 64)",
        accepted="{}",
        check=SWEPT_KEYS["n_terminals"],
    ),
    Key("seed", "–", "the run's random stream", accepted="{}", check=SWEPT_KEYS["seeds"]),
    Key(
        "output_dir",
        "path",
        "where runs, summary, figures and trees go ([Results](results.md))",
        default="{} (each sweep sets its own)",
        accepted="a non-empty path",
    ),
    Key(
        "stage",
        "–",
        ("run the sweep then reduce it, only reduce the runs already there, or grow the whole tree below them"),
        accepted="{} (`+stage=reduce`, `+stage=extend`)",
        check=OneOf(STAGES),
    ),
    Key(
        "model.name",
        "–",
        (
            "which model the physics and tissue keys spell: `model=paper` sets the paper's values, "
            "`model=physiological` those of [The two models](model.md#the-two-models) (for the anneal "
            "also the bifurcations' reach, `conf/model_method/`, and on the heart the split, "
            "`conf/model_tissue/`); every key a model sets stays overridable after it"
        ),
        default="`physiological` (the group `model=...` sets it; the schema's own: {})",
        accepted="{}",
        check=OneOf(MODELS, unknown="model", why=" (model=...)"),
    ),
)
KEYS: tuple[Key, ...] = (*_TOP_KEYS, *TISSUE_KEYS, *RUN_KEYS, *PIPELINE_KEYS)
KEY_OF = {key.name: key for key in KEYS}


def schema_defaults(cls: type | None = None, prefix: str = "") -> dict[str, Any]:
    """Every key of the schema's dataclasses (``RunConfig`` and its sections, ``sweep`` too,
    which is optional), dotted, with its default."""
    from .schema import RunConfig

    cls = cls or RunConfig
    hints = typing.get_type_hints(cls)
    instance, out = cls(), {}
    for field in dataclasses.fields(cls):
        kinds = [t for t in (typing.get_args(hints[field.name]) or (hints[field.name],)) if t is not type(None)]
        if len(kinds) == 1 and dataclasses.is_dataclass(kinds[0]):
            out.update(schema_defaults(kinds[0], f"{prefix}{field.name}."))
        else:
            out[f"{prefix}{field.name}"] = getattr(instance, field.name)
    return out
