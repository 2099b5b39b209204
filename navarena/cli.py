"""The ``navarena`` command, one entry point for both products.

Consumer subcommands (what you run on a finished data root or a release) are this package's own
and work wherever the library is installed. Producer subcommands (``run``: the pipeline, with Hydra
overrides; ``release``: a release folder from a data root) belong to the pipeline project, the
repository's ``pipeline/`` and ``stages/``: they are imported by name when the pipeline is
importable (a checkout set up with ``make setup``), and otherwise say in one line how to get it.
"""
from __future__ import annotations

import importlib
import sys

from navcore.optional import MissingPackage

CONSUMER = {"inspect": ("navarena.inspect_scene", "a 3DGS file before any run: format, size, extent, up axis, picture"),
            "doctor": ("navarena.doctor", "what this machine has: Python, packages, GPU, gsplat, FFmpeg, extras"),
            "eval": ("navarena.evaluate", "evaluate an agent in closed loop on a data root or a release"),
            "train": ("navarena.train", "train a learned baseline (behaviour cloning + DAgger) on a data root or release"),
            "train-rl": ("navarena.train_rl", "fine-tune a learned baseline with PPO (after BC + DAgger) in the batched environment"),
            "train-stop": ("navarena.train_stop", "train ObjectNav's stop verifier (which categories a STOP succeeds for)"),
            "card": ("navarena.card", "a training run's model card: ship it, add figures, write its markdown"),
            "serve-agent": ("navarena.serve_agent", "serve an agent over the agent-server protocol"),
            "export-lerobot": ("navarena.lerobot", "a split of a data root as a LeRobot dataset"),
            "render-episodes": ("navarena.render_episodes", "episode videos and an HTML report"),
            "verify-release": ("navarena.verify_release", "check a release folder (files, tables, episodes)")}
"""Subcommands of the library: module (with main(argv)) and one line of help."""

PRODUCER = {"run": ("pipeline.__main__", "the pipeline; Hydra overrides as arguments, e.g.\n"
                    "                   navarena run scenes=real_indoor stages=[costmap] costmap.resolution=0.02\n"
                    "                   (navarena run --help: Hydra's help; --cfg job: the resolved config)"),
            "release": ("pipeline.release.__main__", "assemble a release folder from a finished data root"),
            "check-costmap": ("pipeline.check_costmap",
                              "the render check of a data root's costmaps: FP / FN estimates, no ground truth")}
"""Subcommands of the pipeline project (a checkout): module (with main(argv)) and help."""

PIPELINE_HOME = "https://github.com/EI-Nav/NavArena"
GET_PIPELINE = (f"navarena {{cmd}}: the pipeline is not part of the installed library; clone {PIPELINE_HOME} and run "
                "`make setup` there (docs/getting-started.md), then run `navarena {cmd}` from that venv")

USAGE = """usage: navarena COMMAND [ARGS ...]     (navarena COMMAND --help)
       navarena [run] [OVERRIDES ...]     (the pipeline, from a checkout)
       navarena --version

NavArena: navigation benchmarks from frozen 3D Gaussian Splatting scenes.

commands on a finished data root or release (the library):
{consumer}
commands of the pipeline project (a checkout: make setup):
{producer}
Every configuration key: docs/configuration.md. Documentation: docs/index.md.
"""


def usage() -> str:
    line = lambda table: "\n".join(f"  {name:<16} {text}" for name, (_, text) in table.items())  # noqa: E731
    return USAGE.format(consumer=line(CONSUMER), producer=line(PRODUCER))


def version() -> str:
    """``navarena X.Y.Z (commit abc1234[, modified])``: the installed distribution's version (one
    source: pyproject.toml) and, from a git checkout, its commit."""
    import subprocess
    from pathlib import Path

    import navarena

    v = navarena.__version__

    here = Path(__file__).resolve().parent.parent
    commit = ""
    if (here / ".git").exists():
        try:
            run = lambda *a: subprocess.run(["git", *a], cwd=here, capture_output=True, text=True, timeout=10)  # noqa: E731
            sha = run("rev-parse", "--short", "HEAD").stdout.strip()
            dirty = bool(run("status", "--porcelain", "--untracked-files=no").stdout.strip())
            commit = f" (commit {sha}{', modified' if dirty else ''})" if sha else ""
        except (OSError, subprocess.SubprocessError):
            commit = ""
    return f"navarena {v}{commit}"


def _producer(name: str):
    """The pipeline's module of a producer subcommand, or None when the pipeline is not importable."""
    try:
        return importlib.import_module(PRODUCER[name][0])
    except ModuleNotFoundError as e:
        if e.name in ("pipeline", "stages") or (e.name or "").startswith(("pipeline.", "stages.")):
            return None
        raise


def main(argv: list[str] | None = None) -> None:
    """Dispatch ``navarena COMMAND ARGS``; exits with the command's status."""
    args = sys.argv[1:] if argv is None else list(argv)
    if not args or args[0] in ("-h", "--help", "help"):
        print(usage())
        return
    if args[0] in ("-V", "--version"):
        print(version())
        return
    try:
        code = _dispatch(args)
    except KeyboardInterrupt:  # Ctrl-C outside a command's own handling (imports, loading): no traceback
        print(f"\nnavarena {args[0]}: interrupted", file=sys.stderr)
        sys.exit(130)
    except MissingPackage as e:  # a feature used without its extra: what to install, no traceback
        print(f"navarena {args[0]}: {e}", file=sys.stderr)
        sys.exit(2)
    if isinstance(code, int) and code:  # the commands that report failure by their exit status
        sys.exit(code)


def help_all(build_parser, argv: list[str] | None) -> bool:
    """A subcommand's --help-all: when argv (or the command line) asks for it, the help of
    build_parser(show_all=True), every option with the finer knobs, is printed; True when it was."""
    if "--help-all" not in (sys.argv[1:] if argv is None else argv):
        return False
    build_parser(show_all=True).print_help()
    return True


def _dispatch(args: list[str]):
    if args[0] in CONSUMER:
        code = importlib.import_module(CONSUMER[args[0]][0]).main(args[1:])
    else:
        # plain `navarena key=value ...` is `navarena run key=value ...`
        name, rest = (args[0], args[1:]) if args[0] in PRODUCER else ("run", args)
        if name == "run" and args[0] != "run" and "=" not in args[0] and not args[0].startswith(("-", "+", "~")):
            print(f"navarena: unknown command {args[0]!r}\n\n{usage()}", file=sys.stderr)
            sys.exit(2)
        module = _producer(name)
        if module is None:
            print(GET_PIPELINE.format(cmd=name), file=sys.stderr)
            sys.exit(2)
        code = module.main(rest)
    return code


if __name__ == "__main__":
    main()
