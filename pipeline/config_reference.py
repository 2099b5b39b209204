"""The configuration reference (docs/configuration.md), generated from the config dataclasses, and
the command-line reference (docs/reference/cli.md), from the commands' own help.

One source of truth: every key's type and default come from the dataclass field, its meaning from
the string literal written right under the field (the attribute docstring, read with `ast`); a
nested section's meaning is its class docstring. `missing()` lists the keys without one (a test
keeps it empty); `markdown()` is the page, `main` writes it or checks it is current:

    python -m pipeline.config_reference [--check] [--out docs/configuration.md]
"""
from __future__ import annotations

import argparse
import ast
import dataclasses
import inspect
import sys
import textwrap
import typing
from dataclasses import MISSING, dataclass
from functools import lru_cache
from pathlib import Path

OUT = Path(__file__).resolve().parents[1] / "docs" / "configuration.md"
CLI_OUT = OUT.parent / "reference" / "cli.md"
DATA_OUT = OUT.parent / "reference" / "data.md"


@dataclass(frozen=True)
class Key:
    path: str
    type: str
    default: str
    doc: str
    section: bool = False
    """A nested config section (its doc is the class docstring)."""


@lru_cache(maxsize=None)
def field_docs(cls: type) -> dict[str, str]:
    """{field name: the string literal right under its annotated assignment} of a dataclass and its bases."""
    out: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        if not dataclasses.is_dataclass(klass):
            continue
        try:
            tree = ast.parse(textwrap.dedent(inspect.getsource(klass)))
        except (OSError, TypeError):
            continue
        body = tree.body[0].body
        for node, nxt in zip(body, body[1:] + [None]):
            if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name) and isinstance(nxt, ast.Expr) \
                    and isinstance(nxt.value, ast.Constant) and isinstance(nxt.value.value, str):
                out[node.target.id] = inspect.cleandoc(nxt.value.value)
    return out


def _type_name(tp) -> str:
    if isinstance(tp, type) and not typing.get_args(tp):
        return tp.__name__
    s = str(tp).replace("typing.", "").replace("NoneType", "None")
    return s.replace("Optional[", "").rstrip("]") + " | None" if s.startswith("Optional[") else s


def _default(f: dataclasses.Field):
    if f.default is not MISSING:
        return f.default
    if f.default_factory is not MISSING:
        return f.default_factory()
    return MISSING


def _fmt(v) -> str:
    if v is MISSING:
        return "(required)"
    if v is None:
        return "null"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, str):
        return f'"{v}"' if v else '""'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_fmt(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k}: {_fmt(x)}" for k, x in v.items()) + "}"
    return str(v)


def keys(cls: type | None = None, prefix: str = "") -> list[Key]:
    """Every key of the config (NavArenaConfig by default), depth first, sections before their keys."""
    if cls is None:
        from pipeline.config import NavArenaConfig

        cls = NavArenaConfig
    hints = typing.get_type_hints(cls)
    docs = field_docs(cls)
    out: list[Key] = []
    for f in dataclasses.fields(cls):
        path = f"{prefix}{f.name}"
        tp = hints.get(f.name, f.type)
        value = _default(f)
        if dataclasses.is_dataclass(tp):
            doc = docs.get(f.name) or inspect.cleandoc(tp.__doc__ or "")
            if doc.startswith(f"{tp.__name__}("):  # dataclass's generated signature: no docstring
                doc = ""
            out.append(Key(path, tp.__name__, "", doc, section=True))
            out += keys(tp, path + ".")
            continue
        args = typing.get_args(tp)
        if typing.get_origin(tp) is dict and len(args) == 2 and dataclasses.is_dataclass(args[1]):
            out.append(Key(path, f"dict[str, {args[1].__name__}]", _fmt(value), docs.get(f.name, ""), section=True))
            out += keys(args[1], path + ".<name>.")
            continue
        out.append(Key(path, _type_name(tp), _fmt(value), docs.get(f.name, "")))
    return out


def missing() -> list[str]:
    """Keys (and sections) without a description."""
    return [k.path for k in keys() if not k.doc.strip()]


def _cell(s: str) -> str:
    return " ".join(s.split()).replace("|", "\\|")


def markdown() -> str:
    ks = keys()
    top = [k for k in ks if "." not in k.path]
    L = ["# Configuration reference", "",
         "Every key of the pipeline's configuration, generated from the config dataclasses "
         "(`pipeline/config.py` and the stage modules: one source of truth) by "
         "`python -m pipeline.config_reference`; a test fails when a key has no description or this page is "
         "not current. Set any key on the command line (`navarena run costmap.resolution=0.02`), in a preset "
         "(`conf/preset/`) or in a config group file (`conf/`). Units are in the descriptions (metres, seconds, "
         "degrees unless said).", "",
         "## Top-level keys", "", "| key | type | default | meaning |", "|---|---|---|---|"]
    for k in top:
        if not k.section:
            L.append(f"| `{k.path}` | `{_cell(k.type)}` | `{_cell(k.default)}` | {_cell(k.doc)} |")
    for s in [k for k in top if k.section]:
        L += ["", f"## `{s.path}`", "", s.doc, "", "| key | type | default | meaning |", "|---|---|---|---|"]
        for k in ks:
            if k.path.startswith(s.path + ".") and not k.section:
                L.append(f"| `{k.path}` | `{_cell(k.type)}` | `{_cell(k.default)}` | {_cell(k.doc)} |")
            elif k.path.startswith(s.path + ".") and k.section:
                L.append(f"| **`{k.path}`** | section | | {_cell(k.doc)} |")
    return "\n".join(L) + "\n"


def command_help(name: str) -> str:
    """`navarena NAME --help` as printed in an 100-column terminal."""
    import contextlib
    import importlib
    import io
    import os

    from navarena.cli import CONSUMER, PRODUCER

    old = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "100"
    buf = io.StringIO()
    try:
        with contextlib.redirect_stdout(buf), contextlib.suppress(SystemExit):
            importlib.import_module({**CONSUMER, **PRODUCER}[name][0]).main(["--help"])
    finally:
        if old is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = old
    return buf.getvalue().rstrip()


def cli_markdown() -> str:
    """docs/reference/cli.md: `navarena --help` and every subcommand's help."""
    from navarena.cli import CONSUMER, PRODUCER, usage

    L = ["# Command line", "",
         "`navarena` is installed with the library (`pip install navarena`; in a checkout `.venv/bin/navarena`, and "
         "`python -m navarena`). Its `run` and `release` commands are the pipeline project's (a checkout); "
         "`python -m pipeline` is `navarena run`. Generated "
         "from the commands' own help by `python -m pipeline.config_reference`.", "", "```text", usage().rstrip(), "```", "",
         "## navarena run", "",
         "The pipeline. Arguments are Hydra overrides: `key=value` for any key of the "
         "[configuration](../configuration.md), `group=option` for a config group (`scenes=real_indoor`, "
         "`embodiment=stretch`, `task=[pointnav,objectnav]`, `executor=slurm`, `planner=rrtconnect`), `+preset=paper` "
         "or `+preset=habitat` for a preset. `navarena run --cfg job` prints the resolved config, `navarena run --help` "
         "Hydra's help. Exit status: 0; 1 when a (stage, scene) failed or the run was refused (`allow_failures=true`: "
         "0); 2 for an unknown configuration key.", ""]
    for name in [*CONSUMER, *(n for n in PRODUCER if n != "run")]:
        L += [f"## navarena {name}", "", "```text", command_help(name), "```", ""]
    return "\n".join(L)


def data_markdown() -> str:
    """docs/reference/data.md: the stage graph (what each stage needs, the config sections whose
    change recomputes it, GPU use), the data layout (navcore/io/layout.yaml) and the table schemas."""
    import yaml

    from navcore.instances import INSTANCE_SCHEMA
    from navcore.io.episode_schema import field_table
    from pipeline.graph import DEFAULT_STAGES, STAGES

    L = ["# Stages, data layout and schemas", "",
         "Generated from the stage graph (`pipeline/graph.py`), the layout (`navcore/io/layout.yaml`) and the "
         "schemas (`navcore/io/episode_schema.py`, `navcore/instances.py`) by `python -m pipeline.config_reference`.",
         "", "## The stage graph", "",
         "One Dask task per (stage, scene); a stage runs after its own scene's upstream stages only. A stage is "
         "recomputed when its config sections, its version or an upstream stage changed (the marker's hash).", "",
         "```text"]
    width = max(len(st.name) for st in STAGES) + 1
    for st in STAGES:
        arrow = " <- " + ", ".join(st.needs) if st.needs else ""
        L.append(f"{st.name:<{width}}{arrow}".rstrip())
    L += ["```", "", "`stages=[episodes]` also selects `objectnav_episodes` (a stage's `part_of`): one step for users, "
          "split so that PointNav and ImageNav do not wait for semantics.", "",
          "| stage | needs | config sections (and what else it hashes) | version | GPU | default |",
          "|---|---|---|---|---|---|"]
    for st in STAGES:
        also = f" + {' '.join((st.inputs.__doc__ or '').split(':')[0].split())}" if st.inputs else ""  # its first words
        L.append(f"| `{st.name}` | {', '.join(st.needs) or '-'} | {', '.join(f'`{c}`' for c in st.config) or '-'}{also} | "
                 f"{st.version} | {'yes' if st.gpu else ''} | {'yes' if st.name in DEFAULT_STAGES else 'no'} |")
    from navcore.io.catalog import LAYOUT_FILE

    layout = yaml.safe_load(LAYOUT_FILE.read_text())
    L += ["", "## The data layout", "", "Logical dataset names (what stages and tools ask the catalog for) and "
          "where they live under the data root (`{root}`).", "", "| dataset | path | type |", "|---|---|---|"]
    for name, e in (layout.get("datasets") or layout).items():
        if isinstance(e, dict) and "path" in e:
            L.append(f"| `{name}` | `{e['path']}` | {e.get('type', '')} |")
        elif isinstance(e, str):
            L.append(f"| `{name}` | `{e}` | folder |")
    for title, kind in (("Episodes (`05_episodes`, one row per episode)", "episodes"),
                        ("Expert trajectories (`06_trajectories`, one row per 20 Hz step)", "trajectories")):
        L += ["", f"## {title}", "", *field_table(kind)]
    L += ["", "## ObjectNav instances (`04_semantics/{scene_id}/instances.parquet`)", "", "| column | type |", "|---|---|"]
    L += [f"| `{f.name}` | `{f.type}` |" for f in INSTANCE_SCHEMA]
    return "\n".join(L) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=str(OUT))
    ap.add_argument("--check", action="store_true", help="exit 1 when the page is not current or a key has no description")
    a = ap.parse_args(argv)
    text, gaps, cli, data = markdown(), missing(), cli_markdown(), data_markdown()
    if a.check:
        # the CLI page is checked for its commands only: argparse's layout varies between Python versions
        stale = not Path(a.out).is_file() or Path(a.out).read_text() != text or not CLI_OUT.is_file() or \
            not DATA_OUT.is_file() or DATA_OUT.read_text() != data or \
            [x for x in cli.splitlines() if x.startswith("## ")] != [x for x in CLI_OUT.read_text().splitlines()
                                                                     if x.startswith("## ")]
        for g in gaps:
            print(f"no description: {g}", file=sys.stderr)
        if stale:
            print(f"{a.out} or {CLI_OUT} is not current: python -m pipeline.config_reference", file=sys.stderr)
        return 1 if gaps or stale else 0
    Path(a.out).write_text(text)
    CLI_OUT.write_text(cli)
    DATA_OUT.write_text(data)
    print(f"{a.out}: {sum(not k.section for k in keys())} keys, {len(gaps)} without a description; {CLI_OUT}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

