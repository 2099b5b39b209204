"""The pipeline's command: ``python -m pipeline [overrides]`` and ``navarena run [overrides]`` (the
``navarena`` entry point, navarena/cli.py, dispatches here) run the configured stages (Hydra)."""
from __future__ import annotations

import sys

import hydra

from pipeline.config import CONF_DIR, register_configs, unknown_keys_message, unknown_override_keys

register_configs()


# an absolute path: the console script and `python -m pipeline` find the same conf/
@hydra.main(config_path=str(CONF_DIR), config_name="config", version_base="1.3")
def _app(cfg) -> None:
    from pipeline.executor import main_cfg

    code = main_cfg(cfg)
    if code:
        sys.exit(code)


def main(argv: list[str] | None = None) -> None:
    """Run the pipeline with Hydra overrides (``navarena run ARGS`` and ``python -m pipeline ARGS``)."""
    if argv is not None:
        sys.argv = [sys.argv[0], *argv]
    unknown = unknown_override_keys(sys.argv[1:])
    if unknown:  # before Hydra, whose refusal ("use +key") names no close key and exits 1
        from rich.console import Console
        from rich.markup import escape

        Console(stderr=True).print(f"[red]navarena[/]: {escape(unknown_keys_message(unknown))}")
        sys.exit(2)
    _app()


if __name__ == "__main__":
    main()
