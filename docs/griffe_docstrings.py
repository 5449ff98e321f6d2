"""A griffe extension for the API pages: docstrings write units as ``voxel [0, 0, 0] [m]``,
which Markdown reads as a reference link to a target ``m``; escape the second bracket so it
stays text. Docs-only: the package's source is not touched."""

import re

import griffe

_REF_LIKE = re.compile(r"\] \[")


class EscapeUnitBrackets(griffe.Extension):
    def on_instance(self, *, obj, **kwargs) -> None:
        if obj.docstring is not None:
            obj.docstring.value = _REF_LIKE.sub(r"] \\[", obj.docstring.value)
