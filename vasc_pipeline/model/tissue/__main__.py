"""``python -m vasc_pipeline.model.tissue OUT.nii.gz [N_TERMINALS]``: the shipped heart as a label map.

Writes :func:`vasc_pipeline.model.tissue.images.write_heart`'s NIfTI label map (1 myocardium,
2 cavities, 3 the open space above the base) and its ostia as ``<stem>.inlets.json``, for
``tissue=mask`` to read back into the same tissue.

An entry module of its own: the package imports ``images`` before runpy could run it as
``__main__``, which made ``python -m vasc_pipeline.model.tissue.images`` warn that the module
was already in ``sys.modules``.
"""

from __future__ import annotations

import sys

from .images import is_label_map, write_heart

USAGE = "usage: python -m vasc_pipeline.model.tissue OUT.nii.gz [N_TERMINALS]"


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if not 1 <= len(args) <= 2 or args[0] in ("-h", "--help") or not is_label_map(args[0]):
        print(USAGE, file=sys.stderr)
        return 2
    if len(args) > 1 and not args[1].isdigit():
        print(f"{USAGE}\nN_TERMINALS must be a whole number, got {args[1]!r}", file=sys.stderr)
        return 2
    image, inlets = write_heart(args[0], int(args[1]) if len(args) > 1 else 200)
    print(f"{image}\n{inlets}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
