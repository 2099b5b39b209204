"""CLI: ``python -m pipeline [overrides]`` or ``navarena [overrides]`` (Hydra); ``navarena
render-episodes ...``, ``navarena export-lerobot ...``, ``navarena release ...`` and ``navarena
verify-release DIR`` are tools over a finished data root or release."""
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


TOOLS = {"render-episodes": "navarena.render_episodes", "export-lerobot": "navarena.lerobot",
         "release": "pipeline.release.__main__", "verify-release": "navarena.verify_release"}
"""Subcommands beside the Hydra pipeline run: ``navarena render-episodes --help``."""


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] in TOOLS:
        import importlib

        code = importlib.import_module(TOOLS[sys.argv[1]]).main(sys.argv[2:])
        if isinstance(code, int) and code:  # the tools that report failure by their exit status
            sys.exit(code)
        return
    _app()


if __name__ == "__main__":
    main()
