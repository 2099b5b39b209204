"""The benchmark pages under docs/: each names the commit its figures were measured on and the
inputs they depend on, and `make bench-stale` lists the pages whose inputs changed since.

A page's inputs are what its figures are a function of:
- the pipeline stages whose outputs it measures, by the hash the pipeline keys its markers with
  (pipeline.graph.config_hashes on the default config: each stage's version, config sections and
  upstream hashes), so a refactor that keeps every stage's output bytes keeps the page fresh and a
  version bump or a changed default makes it stale;
- its code: the benchmark's own module and what it times beside stage outputs (the renderer for a
  frames/s figure, the orchestration for the fault suite), by a digest of their top-level
  definitions (code_digest: a function moved between files, an import or a comment changed, is no
  change).

A page ends with a stamp written by ``write_page``:

    Measured on commit `c4c884e` (2026-11-26) with `make bench-spatial`.
    <!-- bench-page: commit=c4c884e1... dirty=0 date=2026-11-26 -->
    <!-- bench-inputs: {"code": "9f3c...", "stages": {"costmap": "2f6d..."}} -->

``dirty=1`` says the run had uncommitted changes in the page's code (the figures then belong to
the commit that lands them, and the check reports the page until it is re-run on a clean tree).
PAGES names, for every docs/benchmarks/bench_*.md, the command that refreshes it, its stages and its code;
a test checks that every page is listed and stamped.

    python -m benchmarks.pages stale [--strict]     # the stale pages and the changed files
    python -m benchmarks.pages list                 # every page with its commit and command
    python -m benchmarks.pages mark                 # section markers around every page's tables
"""
from __future__ import annotations

import argparse
import ast
import datetime
import hashlib
import json
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PAGES_DIR = "docs/benchmarks"
"""Where the pages live, beside their index (relative to a project root)."""
STAMP_RE = re.compile(r"<!-- bench-page: commit=(?P<commit>[0-9a-f]{7,40}) dirty=(?P<dirty>[01]) "
                      r"date=(?P<date>[0-9-]+) -->(\n<!-- bench-inputs: (?P<inputs>\{.*\}) -->)?")

ALL_STAGES = ("synthesize", "ingest", "voxelize", "align", "costmap", "screen", "episodes", "goal_images", "semantics",
              "asset", "objectnav_episodes", "export")


@dataclass(frozen=True)
class Page:
    command: str
    code: tuple[str, ...]
    """Files or folders whose code the figures depend on beside stage outputs (the benchmark's own first)."""
    stages: tuple[str, ...] = ()
    """Pipeline stages whose outputs the figures measure (a stage's hash covers its upstream)."""
    captured: bool = False
    """The figures measure scenes read from files only: keyed by the captured scenes' chain
    (pipeline.graph.StageHashes.captured), which a generator setting does not change."""

    @property
    def inputs(self) -> tuple[str, ...]:
        return self.code


_RENDER = ("navcore/render",)
PAGES: dict[str, Page] = {
    "bench_spatial.md": Page("make bench-spatial", ("benchmarks/map/spatial.py",), ("costmap",)),
    "bench_episodes.md": Page("make bench-episodes", ("benchmarks/dataset/episodes.py",),
                              ("episodes", "goal_images", "objectnav_episodes")),
    "bench_eval.md": Page("make bench-eval", ("benchmarks/closed_loop/eval.py", "navcore/eval", *_RENDER),
                          ("episodes", "objectnav_episodes")),
    "bench_real.md": Page("make bench-real", ("benchmarks/captures/real.py", "benchmarks/captures/scan_truth.py",
                                              "catalogs/real_indoor.yaml"), ("costmap", "screen", "episodes"), captured=True),
    # frames of the aligned scenes at poses the costmap allows (the episodes stage only names the embodiment)
    "bench_realism.md": Page("make bench-realism", ("benchmarks/captures/realism.py", *_RENDER), ("synthesize", "costmap")),
    "bench_density.md": Page("make bench-density", ("benchmarks/captures/density.py", "benchmarks/captures/scan_truth.py"),
                             ("costmap",), captured=True),
    "bench_screening.md": Page("make bench-screening", ("benchmarks/captures/screening.py", *_RENDER), ("screen",)),
    "bench_reflections.md": Page("python -m benchmarks.map.reflections --docs",
                                 ("benchmarks/map/reflections.py", "benchmarks/map/spatial.py"), ("align",)),
    "bench_semantics.md": Page("make bench-semantics", ("benchmarks/goals/semantics.py",), ("semantics",)),
    "bench_semantics_real.md": Page("make bench-semantics", ("benchmarks/goals/semantics_real.py",), ("semantics",), captured=True),
    "bench_semantics_detector.md": Page("make bench-semantics", ("benchmarks/goals/semantics_detector.py",
                                                                 "benchmarks/goals/semantics_real.py", "navcore/models"),
                                        ("semantics",), captured=True),
    "bench_semantics_views.md": Page("python -m benchmarks.goals.semantics_views --data DATA --docs",
                                     ("benchmarks/goals/semantics_views.py",), ("semantics",)),
    "bench_blind_views.md": Page("python -m benchmarks.dataset.blind_views --docs docs/benchmarks/bench_blind_views.md",
                                 ("benchmarks/dataset/blind_views.py", *_RENDER), ("episodes",), captured=True),
    "bench_faults.md": Page("make test-faults", ("tests/faults/suite.py", "tests/faults/faults.py",
                                                 "tests/faults/fuzz_frames.py",
                                                 "tests/faults/fuzz_readers.py", "tests/test_faults.py", "pipeline",
                                                 "navcore/io", "navcore/gaussians/formats", "navcore/eval/protocol"),
                            ALL_STAGES),
    "bench_gpu.md": Page("make bench-gpu", ("benchmarks/gpu/bench_gpu.py", "benchmarks/gpu/render_gpu.py",
                                            "benchmarks/goals/semantics.py", "benchmarks/goals/open_vocab_timing.py",
                                            "benchmarks/closed_loop/eval.py", "benchmarks/map/voxelize_gpu.py", *_RENDER,
                                            "navcore/voxels", "navcore/eval"),
                         ("voxelize", "semantics", "episodes", "objectnav_episodes")),
    "bench_multi_gpu.md": Page("make bench-multi-gpu", ("benchmarks/gpu/multi_gpu.py", "pipeline", *_RENDER, "navcore/eval"),
                               ("voxelize", "semantics", "goal_images", "episodes", "objectnav_episodes")),
    "bench_tour.md": Page("make bench-tour", ("benchmarks/usage/tour.py", "navarena", "pipeline"),
                          ALL_STAGES),
    "bench_release.md": Page("make bench-release", ("benchmarks/publishing/release.py", "pipeline/release",
                                                    "navarena/verify_release.py", "navcore/io/release.py"), ("export",)),
    "bench_scale.md": Page("make bench-scale", ("benchmarks/scale/suite.py", "benchmarks/scale/bench_scale.py",
                                                "benchmarks/dataset/storage.py",
                                                "benchmarks/scale/render_cpu.py", "pipeline", *_RENDER), ALL_STAGES),
}


def _strip_docstring(node):
    body = getattr(node, "body", None)
    if isinstance(body, list) and body and isinstance(body[0], ast.Expr) and isinstance(getattr(body[0], "value", None), ast.Constant) \
            and isinstance(body[0].value.value, str):
        node.body = body[1:] or [ast.Pass()]
    for child in ast.iter_child_nodes(node):
        _strip_docstring(child)
    return node


def code_digest(paths: tuple[str, ...], root: Path = ROOT) -> str:
    """A digest of the code under `paths` that ignores where each definition lives: the sorted
    AST dumps (docstrings, comments and imports left out) of every module's top-level statements,
    and the bytes of any other file. Moving a function between the files of the inputs keeps it."""
    parts = []
    for p in paths:
        base = root / p
        files = sorted(base.rglob("*")) if base.is_dir() else [base]
        for f in files:
            if not f.is_file() or "__pycache__" in f.parts:
                continue
            if f.suffix == ".py":
                tree = ast.parse(f.read_text())
                parts += [ast.dump(_strip_docstring(n)) for n in tree.body
                          if not isinstance(n, (ast.Import, ast.ImportFrom))
                          and not (isinstance(n, ast.Expr) and isinstance(getattr(n, "value", None), ast.Constant))]
            elif f.suffix in (".yaml", ".yml", ".md", ".json", ".toml"):
                parts.append(hashlib.sha256(f.read_bytes()).hexdigest())
    return hashlib.sha256("\n".join(sorted(parts)).encode()).hexdigest()[:16]


def default_stage_hashes() -> dict[str, str]:
    """Every stage's hash on the default config, as the pipeline keys its markers (a
    pipeline.graph.StageHashes: `.captured` holds the captured scenes' chain)."""
    from hydra import compose, initialize_config_dir

    from pipeline.config import CONF_DIR, register_configs
    from pipeline.graph import config_hashes

    register_configs()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return config_hashes(compose(config_name="config"))


def page_inputs(name: str, root: Path = ROOT, stage_hashes: dict[str, str] | None = None) -> dict:
    """{"code": digest, "stages": {stage: hash}} of page `name` now."""
    page = PAGES[name]
    hashes = stage_hashes if stage_hashes is not None else (default_stage_hashes() if page.stages else {})
    if page.captured:
        hashes = getattr(hashes, "captured", hashes)
    return {"code": code_digest(page.code, root), "stages": {s: hashes[s] for s in page.stages}}


def _git(*args: str, cwd: Path = ROOT) -> str:
    return subprocess.run(["git", *args], cwd=cwd, check=True, capture_output=True, text=True).stdout.strip()


def stamp(name: str, root: Path = ROOT, date: str | None = None, stage_hashes: dict[str, str] | None = None) -> str:
    """The lines that end page ``name``: the commit of ``root``'s HEAD, whether the page's code
    had uncommitted changes, the date, the command and the page's inputs."""
    page = PAGES[name]
    commit = _git("rev-parse", "HEAD", cwd=root)
    dirty = bool(_git("status", "--porcelain", "--", *page.code, cwd=root))
    date = date or datetime.date.today().isoformat()
    note = " plus uncommitted changes" if dirty else ""
    inputs = json.dumps(page_inputs(name, root, stage_hashes), sort_keys=True)
    return (f"Measured on commit `{commit[:7]}`{note} ({date}) with `{page.command}`; `make bench-stale` lists "
            f"the pages whose inputs changed since.\n<!-- bench-page: commit={commit} dirty={int(dirty)} date={date} -->\n"
            f"<!-- bench-inputs: {inputs} -->\n")


SECTION_LINE = re.compile(r"<!-- --8<-- \[(?:start|end):[a-z0-9-]+\] -->")


def mark_sections(markdown: str) -> str:
    """Every table of a page between snippet section markers, `table-1`, `table-2`, ... in page
    order, so that a hand-written page includes a generated table instead of copying it:

        --8<-- "benchmarks/bench_episodes.md:table-1"

    (pymdownx.snippets, mkdocs.yml). Idempotent: markers already there are replaced."""
    lines = [line for line in markdown.split("\n") if not SECTION_LINE.fullmatch(line)]
    out, n, inside = [], 0, False
    for line in lines:
        table = line.startswith("|")
        if table and not inside:
            n += 1
            out.append(f"<!-- --8<-- [start:table-{n}] -->")
        elif not table and inside:
            out.append(f"<!-- --8<-- [end:table-{n}] -->")
        inside = table
        out.append(line)
    if inside:
        out.append(f"<!-- --8<-- [end:table-{n}] -->")
    return "\n".join(out)


def write_page(name: str, markdown: str, root: Path = ROOT, stage_hashes: dict[str, str] | None = None) -> Path:
    """Write docs/benchmarks/<name> (a page of PAGES) with its tables' section markers and its stamp;
    returns the path."""
    if name not in PAGES:
        raise KeyError(f"{name} is not a benchmark page of benchmarks.pages.PAGES")
    path = root / PAGES_DIR / name
    body = re.sub(r"Measured on commit `[0-9a-f]+`[^\n]*\n(?=<!-- bench-page)", "", markdown)
    body = mark_sections(STAMP_RE.sub("", body).rstrip()) + "\n\n"
    path.write_text(body + stamp(name, root, stage_hashes=stage_hashes))
    return path


def mark_pages(root: Path = ROOT) -> list[str]:
    """Section markers into every page as it stands (its figures and stamp untouched: a page
    measured before write_page emitted them); the pages changed."""
    changed = []
    for name in PAGES:
        path = root / PAGES_DIR / name
        if not path.is_file():
            continue
        text = path.read_text()
        m = re.search(r"Measured on commit `[0-9a-f]+`[^\n]*\n(?=<!-- bench-page)", text) or STAMP_RE.search(text)
        head, tail = (text[:m.start()], text[m.start():]) if m else (text, "")
        new = mark_sections(head.rstrip()) + "\n\n" + tail if m else mark_sections(text)
        if new != text:
            path.write_text(new)
            changed.append(name)
    return changed


def read_stamp(path: Path) -> dict | None:
    """{'commit', 'dirty', 'date', 'inputs'} of a page (inputs None for a page stamped before pages
    were keyed to their inputs), or None when it carries no stamp."""
    m = STAMP_RE.search(path.read_text())
    if m is None:
        return None
    return {"commit": m["commit"], "dirty": m["dirty"] == "1", "date": m["date"],
            "inputs": json.loads(m["inputs"]) if m["inputs"] else None}


def stale_pages(root: Path = ROOT, stage_hashes: dict[str, str] | None = None) -> dict[str, list[str]]:
    """Page name -> why it is stale: its stages' hashes or its code changed since it was measured
    (uncommitted changes included), or a missing / unkeyed stamp, or a run with uncommitted code."""
    hashes = stage_hashes
    out: dict[str, list[str]] = {}
    for name, page in PAGES.items():
        path = root / PAGES_DIR / name
        if not path.exists():
            out[name] = ["page missing"]
            continue
        st = read_stamp(path)
        if st is None:
            out[name] = ["no bench-page stamp"]
            continue
        if st["inputs"] is None:
            out[name] = ["measured before pages were keyed to their inputs (stage hashes, code digest)"]
            continue
        if hashes is None and page.stages:
            hashes = default_stage_hashes()
        now, then = page_inputs(name, root, hashes or {}), st["inputs"]
        why = [f"stage {s}: {then.get('stages', {}).get(s)} -> {h}" for s, h in now["stages"].items()
               if then.get("stages", {}).get(s) != h]
        if now["code"] != then.get("code"):
            why.append(f"code of {', '.join(page.code)}")
        if st["dirty"]:
            why.insert(0, "measured with uncommitted changes")
        if why:
            out[name] = why
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("what", choices=("stale", "list", "mark"))
    ap.add_argument("--strict", action="store_true", help="exit 1 when a page is stale")
    args = ap.parse_args(argv)
    if args.what == "mark":
        print("section markers into:", *mark_pages() or ["none (every page has them)"])
        return 0
    if args.what == "list":
        for name, page in PAGES.items():
            st = read_stamp(ROOT / PAGES_DIR / name) if (ROOT / PAGES_DIR / name).exists() else None
            print(f"{name:28s} {st['commit'][:7] if st else '-':8s} {st['date'] if st else '-':11s} {page.command}")
        return 0
    stale = stale_pages()
    for name, why in stale.items():
        shown = why[:8] + ([f"... {len(why) - 8} more"] if len(why) > 8 else [])
        print(f"{name}: re-run `{PAGES[name].command}`\n    " + "\n    ".join(shown))
    print(f"{len(stale)} of {len(PAGES)} benchmark pages stale" if stale else "every benchmark page is current")
    return 1 if stale and args.strict else 0


if __name__ == "__main__":
    sys.exit(main())
