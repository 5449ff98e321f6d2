"""``python -m vasc_pipeline [overrides]``: one run, or a sweep with ``+sweep=NAME``.

A finished sweep is reduced (summary.zarr, figures, trees); ``+stage=reduce
output_dir=...`` only reduces the complete runs already there.

Thin on purpose (SPEC section 8): Hydra composes the config, and
:func:`vasc_pipeline.orchestrate.main` (a plain function that tests call directly) does
the rest and returns the exit status.
"""

import sys

import hydra

from vasc_pipeline import config

config.register_schema()


@hydra.main(config_path=str(config.CONFIG_DIR), config_name="config", version_base="1.3")
def _main(cfg) -> None:
    from vasc_pipeline.orchestrate import main

    status = main(cfg)
    if status:
        sys.exit(status)


if __name__ == "__main__":
    _main()
