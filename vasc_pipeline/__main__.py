"""``python -m vasc_pipeline [overrides]``: one run, or a sweep with ``+sweep=NAME``.

A finished sweep is reduced (summary.zarr, figures, trees); ``+stage=reduce
output_dir=...`` only reduces the complete runs already there, and ``+stage=extend
output_dir=...`` grows the whole tree below them (``extended/<run_id>.zarr``).

Thin on purpose (everything it does is a plain function a test can call): Hydra composes the config, and
:func:`vasc_pipeline.pipeline.orchestrate.main` (a plain function that tests call directly) does
the rest and returns the exit status.
"""

import sys

import hydra

from vasc_pipeline import config

config.register_schema()


@hydra.main(config_path=str(config.CONFIG_DIR), config_name="config", version_base="1.3")
def _main(cfg) -> None:
    from vasc_pipeline.pipeline.orchestrate import main

    status = main(cfg)
    if status == 2:  # bad input: nothing ran, so Hydra's log directory of this run goes too
        from hydra.core.hydra_config import HydraConfig

        from vasc_pipeline.pipeline.outdir import forget_refused_run

        forget_refused_run(HydraConfig.get().runtime.output_dir)
    if status:
        sys.exit(status)


def _check_overrides(args: list[str]) -> None:
    """Hydra-level errors (unknown key or group option, wrong type) exit 2 listing what is accepted.

    Hydra itself reports them with status 1, which the README reserves for failed runs. Only
    plain overrides are checked here; Hydra's own flags (--help, --cfg, ...) go to Hydra.
    """
    if any(a.startswith("-") for a in args):
        return
    try:
        config.compose(args, check=False)
    except config.ConfigError as exc:
        sys.stderr.write(
            f"vasc_pipeline: error: {exc}\nNothing was run; existing results were left as they "
            "were. python -m vasc_pipeline --help lists the config groups and keys.\n"
        )
        sys.exit(2)


if __name__ == "__main__":
    sys.argv[1:] = config.with_sweep_group(sys.argv[1:])
    _check_overrides(sys.argv[1:])
    try:  # counts written as floats (anneal.steps=1e5) as the integers they are, for Hydra
        sys.argv[1:] = config.integral_counts(sys.argv[1:])
    except config.ConfigError as exc:
        sys.stderr.write(f"vasc_pipeline: error: {exc}\nNothing was run; existing results were left as they were.\n")
        sys.exit(2)
    _main()
