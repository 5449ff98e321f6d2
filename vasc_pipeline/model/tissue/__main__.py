"""``python -m vasc_pipeline.model.tissue OUT.nii.gz [N_TERMINALS]``: the shipped heart as a label map;
``python -m vasc_pipeline.model.tissue OUT.stl``: as closed surfaces (also .obj, .ply, .vtp).

Writes :func:`vasc_pipeline.model.tissue.images.write_heart`'s NIfTI label map (1 myocardium,
2 cavities, 3 the open space above the base) and its ostia as ``<stem>.inlets.json``, for
``tissue=mask`` to read back into the same tissue; or
:func:`vasc_pipeline.model.tissue.surfaces.write_heart_surfaces`' outer surface, ``<stem>.lv``
and ``<stem>.rv`` cavity surfaces and ostia, for ``tissue=surface``.

An entry module of its own: the package imports ``images`` before runpy could run it as
``__main__``, which made ``python -m vasc_pipeline.model.tissue.images`` warn that the module
was already in ``sys.modules``.
"""

from __future__ import annotations

import sys

from .images import is_label_map, write_heart
from .surfaces import is_surface, write_heart_surfaces

USAGE = "usage: python -m vasc_pipeline.model.tissue OUT.nii.gz [N_TERMINALS]  |  OUT.stl (.obj, .ply, .vtp)"


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) == 1 and is_surface(args[0]):
        organ, cavities, inlets = write_heart_surfaces(args[0])
        print("\n".join(str(p) for p in (organ, *cavities, inlets)))
        return 0
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
