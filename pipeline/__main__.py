"""CLI: ``python -m pipeline [overrides]`` or ``navarena [overrides]`` (Hydra)."""
from __future__ import annotations

import sys

import hydra

from pipeline.config import CONF_DIR, register_configs

register_configs()


# an absolute path: the console script and `python -m pipeline` find the same conf/
@hydra.main(config_path=str(CONF_DIR), config_name="config", version_base="1.3")
def _app(cfg) -> None:
    from pipeline.executor import main_cfg

    code = main_cfg(cfg)
    if code:
        sys.exit(code)


def main() -> None:
    _app()


if __name__ == "__main__":
    main()
