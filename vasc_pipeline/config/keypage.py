"""The key table (:data:`~vasc_pipeline.config.keys.KEYS`) as text: the key tables of
``docs/configuration.md`` and the key list of ``python -m vasc_pipeline --help``.

The page's tables stand between markers, ``<!-- keys: SECTION -->`` and ``<!-- /keys -->``;
everything outside them is the page's own prose. ``python -m vasc_pipeline.config.keypage
--write docs/configuration.md`` rewrites the tables from the key table; ``--check`` exits 1 when they differ.
"""

from __future__ import annotations

import argparse
import re
import sys
import textwrap
from pathlib import Path
from typing import Any

from .keys import KEYS, schema_defaults
from .keyspec import EVERY, SECTIONS, Key, format_value

__all__ = ["anneal_presets", "help_text", "main", "page_with_tables", "section_table"]

_MARKERS = re.compile(r"(<!-- keys: (\w+) -->\n)(.*?)(<!-- /keys -->)", re.DOTALL)


def anneal_presets() -> dict[str, dict[str, Any]]:
    """The anneal presets of ``conf/anneal/`` other than the schema's own, each as the keys it sets."""
    from omegaconf import OmegaConf

    from .schema import CONFIG_DIR, AnnealConfig

    own = AnnealConfig().name
    files = sorted((CONFIG_DIR / "anneal").glob("*.yaml"))
    return {f.stem: OmegaConf.to_container(OmegaConf.load(f)) for f in files if f.stem != own}


def _default(key: Key, value: Any) -> str:
    return key.default.replace("{}", format_value(value))


def _preset_value(preset: dict[str, Any], key: Key, schema_value: Any) -> str:
    value = preset.get(key.name.split(".", 1)[1], schema_value)
    if isinstance(schema_value, float) and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)  # as the schema's field holds it
    return format_value(value)


def section_table(section: str) -> str:
    """The Markdown table of one section's keys, as the page holds it."""
    from .schema import AnnealConfig

    defaults = schema_defaults()
    keys = [k for k in KEYS if k.section == section]
    head = ["key", "unit", "default", "accepted", "what"]
    presets = anneal_presets() if section == "anneal" else {}
    if section == "tissue":
        head.insert(4, "read by")
    if presets:
        head[2:3] = [f"`{AnnealConfig().name}` (schema)", *(f"`{name}`" for name in presets)]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for key in keys:
        value = defaults[key.name]
        row = [f"`{key.name}`", key.unit, _default(key, value)]
        row += [_preset_value(p, key, value) for p in presets.values()]
        row.append(key.accepted_doc())
        if section == "tissue":
            row.append(key.tissues if key.tissues == EVERY else ", ".join(key.tissues or ()))
        row.append(key.what)
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines) + "\n"


def page_with_tables(page: str) -> str:
    """``page`` with every marked key table written from the key table (the prose as it is)."""
    found = [m.group(2) for m in _MARKERS.finditer(page)]
    missing = [s for s in ("top", *SECTIONS) if s not in found]
    if missing or len(found) != len(set(found)) or any(s not in ("top", *SECTIONS) for s in found):
        raise ValueError(f"the page must mark each section's table once; missing {missing}, found {found}")
    return _MARKERS.sub(lambda m: f"{m.group(1)}\n{section_table(m.group(2))}\n{m.group(4)}", page)


def _plain(text: str) -> str:
    """Markdown as terminal text: links as their words, no backticks."""
    return re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", text).replace("`", "")


def help_text(width: int = 100) -> str:
    """Every key with its unit and accepted values, by section, for ``--help``."""
    lines = []
    for section in ("top", *SECTIONS):
        lines.append(f"  {section + '.*' if section != 'top' else 'top level'}:")
        for key in (k for k in KEYS if k.section == section):
            unit = f" [{key.unit}]" if key.unit not in ("–", "1") else ""
            lines += textwrap.wrap(
                f"{key.name}{unit}: {_plain(key.accepted_doc())}",
                width=width,
                initial_indent="    ",
                subsequent_indent="        ",
            )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m vasc_pipeline.config.keypage", description="Write or check the key tables of a page."
    )
    parser.add_argument("page", type=Path, nargs="?", default=Path("docs/configuration.md"))
    what = parser.add_mutually_exclusive_group(required=True)
    what.add_argument("--write", action="store_true", help="rewrite the page's key tables from the key table")
    what.add_argument("--check", action="store_true", help="exit 1 when the page's key tables differ from it")
    args = parser.parse_args(argv)
    page = args.page.read_text(encoding="utf-8")
    written = page_with_tables(page)
    if args.write:
        if written != page:
            args.page.write_text(written, encoding="utf-8")
        return 0
    if written != page:
        sys.stderr.write(f"{args.page}: its key tables differ from vasc_pipeline.config.keys; --write them\n")
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
