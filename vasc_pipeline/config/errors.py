"""The configuration's error: a value out of its accepted range, the message naming the field."""

from __future__ import annotations

__all__ = ["ConfigError"]


class ConfigError(ValueError):
    """A configuration value out of its accepted range; the message names the field."""
