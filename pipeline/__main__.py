"""CLI: ``python -m pipeline [overrides]`` or ``navarena [overrides]`` (Hydra)."""
from __future__ import annotations

import sys

import hydra

from pipeline.config import register_configs

register_configs()


@hydra.main(config_path="../conf", config_name="config", version_base="1.3")
def _app(cfg) -> None:
    from pipeline.executor import main_cfg

    code = main_cfg(cfg)
    if code:
        sys.exit(code)


def main() -> None:
    _app()


if __name__ == "__main__":
    main()
