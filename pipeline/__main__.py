"""The ``navarena`` command: ``navarena run [overrides]`` runs the pipeline (Hydra; plain
``navarena [overrides]`` and ``python -m pipeline [overrides]`` too); the other subcommands are
tools over a scene file, this machine, a finished data root or a release (``navarena --help``)."""
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


TOOLS = {"inspect": ("pipeline.inspect_scene", "a 3DGS file before any run: format, size, extent, up axis, picture"),
         "doctor": ("navarena.doctor", "what this machine has: Python, packages, GPU, gsplat, FFmpeg, extras"),
         "export-lerobot": ("navarena.lerobot", "a split of a data root as a LeRobot dataset"),
         "render-episodes": ("navarena.render_episodes", "episode videos and an HTML report"),
         "serve-agent": ("stages.evaluate.protocol.cli", "serve an agent over the agent-server protocol"),
         "release": ("pipeline.release.__main__", "assemble a release folder from a finished data root"),
         "verify-release": ("navarena.verify_release", "check a release folder (files, tables, episodes)")}
"""Subcommands beside the pipeline run: module (with main(argv)) and one line of help."""

USAGE = """usage: navarena [run] [OVERRIDES ...]
       navarena COMMAND [ARGS ...]     (navarena COMMAND --help)

NavArena: navigation benchmarks from frozen 3D Gaussian Splatting scenes.

commands:
  run              the pipeline; Hydra overrides as arguments, e.g.
                   navarena run scenes=real_indoor stages=[costmap] costmap.resolution=0.02
                   (navarena run --help: Hydra's help; --cfg job: the resolved config)
{tools}
Every configuration key: docs/configuration.md. Documentation: make docs, docs/index.md.
"""


def usage() -> str:
    return USAGE.format(tools="\n".join(f"  {name:<16} {line}" for name, (_, line) in TOOLS.items()))


def main() -> None:
    args = sys.argv[1:]
    if args and args[0] in ("-h", "--help", "help"):
        print(usage())
        return
    if args and args[0] in TOOLS:
        import importlib

        code = importlib.import_module(TOOLS[args[0]][0]).main(args[1:])
        if isinstance(code, int) and code:  # the tools that report failure by their exit status
            sys.exit(code)
        return
    if args and args[0] == "run":
        sys.argv = [sys.argv[0], *args[1:]]
    elif args and "=" not in args[0] and not args[0].startswith("-"):
        print(f"navarena: unknown command {args[0]!r}\n\n{usage()}", file=sys.stderr)
        sys.exit(2)
    _app()


if __name__ == "__main__":
    main()
