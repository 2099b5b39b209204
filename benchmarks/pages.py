"""The benchmark pages under docs/: each names the commit its figures were measured on, and
`make bench-stale` lists the pages whose code inputs changed since that commit.

A page ends with a stamp written by ``write_page``:

    Measured on commit `c4c884e` (2026-11-26) with `make bench-spatial`.
    <!-- bench-page: commit=c4c884e1... dirty=0 date=2026-11-26 -->

``dirty=1`` says the run had uncommitted changes in the page's inputs (the figures then belong to
the commit that lands them, and the check reports the page until it is re-run on a clean tree).
PAGES names, for every docs/bench_*.md, the command that refreshes it and the code it measures
(paths of files or folders); a test checks that every page is listed and stamped.

    python -m benchmarks.pages stale [--strict]     # the stale pages and the changed files
    python -m benchmarks.pages list                 # every page with its commit and command
"""
from __future__ import annotations

import argparse
import datetime
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
STAMP_RE = re.compile(r"<!-- bench-page: commit=(?P<commit>[0-9a-f]{7,40}) dirty=(?P<dirty>[01]) "
                      r"date=(?P<date>[0-9-]+) -->")

_SPATIAL = ("stages/costmap", "stages/align", "navcore/voxels", "navcore/nav/costmap.py", "navcore/gaussians",
            "stages/synthesize")
_PIPELINE = ("pipeline", "conf", "stages", "navcore")


@dataclass(frozen=True)
class Page:
    command: str
    inputs: tuple[str, ...]


PAGES: dict[str, Page] = {
    "bench_spatial.md": Page("make bench-spatial", _SPATIAL + ("benchmarks/map/spatial.py",)),
    "bench_episodes.md": Page("make bench-episodes", _PIPELINE + ("benchmarks/dataset/episodes.py",)),
    "bench_eval.md": Page("make bench-eval", _PIPELINE + ("benchmarks/closed_loop/eval.py",)),
    "bench_real.md": Page("make bench-real", _PIPELINE + ("benchmarks/captures/real.py", "benchmarks/captures/scan_truth.py",
                                                          "catalogs/real_indoor.yaml")),
    "bench_screening.md": Page("make bench-screening", _SPATIAL + ("stages/screen", "navcore/nav/screening.py",
                                                                   "navcore/render", "benchmarks/captures/screening.py")),
    "bench_reflections.md": Page("python -m benchmarks.map.reflections --docs",
                                 ("stages/align", "stages/synthesize", "navcore/gaussians",
                                  "benchmarks/map/reflections.py", "benchmarks/map/spatial.py")),
    "bench_semantics.md": Page("make bench-semantics", ("stages/semantics", "navcore/instances.py", "navcore/render",
                                                        "stages/synthesize", "benchmarks/goals/semantics.py")),
    "bench_semantics_real.md": Page("make bench-semantics", ("stages/semantics", "navcore/instances.py",
                                                             "navcore/labels", "benchmarks/goals/semantics_real.py")),
    "bench_semantics_detector.md": Page("make bench-semantics",
                                        ("stages/semantics", "navcore/instances.py", "navcore/labels", "navcore/io/models.py",
                                         "benchmarks/goals/semantics_detector.py", "benchmarks/goals/semantics_real.py")),
    "bench_semantics_views.md": Page("python -m benchmarks.goals.semantics_views --data DATA",
                                     ("stages/semantics", "navcore/instances.py", "benchmarks/goals/semantics_views.py")),
    "bench_blind_views.md": Page("python -m benchmarks.dataset.blind_views --docs docs/bench_blind_views.md",
                                 ("stages/costmap", "stages/episodes", "navcore/render", "navcore/gaussians/content.py",
                                  "benchmarks/dataset/blind_views.py")),
    "bench_faults.md": Page("make test-faults", ("pipeline", "navcore/io", "navcore/gaussians/formats",
                                                 "benchmarks/robustness/faults.py", "benchmarks/robustness/fuzz_frames.py",
                                                 "benchmarks/robustness/fuzz_readers.py", "tests/test_faults.py")),
    "bench_gpu.md": Page("make bench-gpu", ("navcore/render", "navcore/voxels", "stages/semantics", "stages/evaluate",
                                            "benchmarks/gpu/bench_gpu.py", "benchmarks/gpu/multi_gpu.py",
                                            "benchmarks/gpu/render_gpu.py")),
    "bench_release.md": Page("make bench-release", ("pipeline/release", "navarena/verify_release.py", "navcore/io/release.py",
                                                    "navcore/nav/eval_set.py", "benchmarks/publishing/release.py")),
    "bench_scale.md": Page("make bench-scale", _PIPELINE + ("benchmarks/scale/bench_scale.py", "benchmarks/dataset/storage.py",
                                                            "benchmarks/scale/render_cpu.py")),
}


def _git(*args: str, cwd: Path = ROOT) -> str:
    return subprocess.run(["git", *args], cwd=cwd, check=True, capture_output=True, text=True).stdout.strip()


def stamp(name: str, root: Path = ROOT, date: str | None = None) -> str:
    """The lines that end page ``name``: the commit of ``root``'s HEAD, whether the page's inputs
    had uncommitted changes, the date and the command."""
    page = PAGES[name]
    commit = _git("rev-parse", "HEAD", cwd=root)
    dirty = bool(_git("status", "--porcelain", "--", *page.inputs, cwd=root))
    date = date or datetime.date.today().isoformat()
    note = " plus uncommitted changes" if dirty else ""
    return (f"Measured on commit `{commit[:7]}`{note} ({date}) with `{page.command}`; `make bench-stale` lists "
            f"the pages whose code changed since.\n<!-- bench-page: commit={commit} dirty={int(dirty)} date={date} -->\n")


def write_page(name: str, markdown: str, root: Path = ROOT) -> Path:
    """Write docs/<name> (a page of PAGES) with its stamp; returns the path."""
    if name not in PAGES:
        raise KeyError(f"{name} is not a benchmark page of benchmarks.pages.PAGES")
    path = root / "docs" / name
    body = STAMP_RE.sub("", markdown).rstrip() + "\n\n"
    path.write_text(body + stamp(name, root))
    return path


def read_stamp(path: Path) -> dict | None:
    """{'commit', 'dirty', 'date'} of a page, or None when it carries no stamp."""
    m = STAMP_RE.search(path.read_text())
    return None if m is None else {"commit": m["commit"], "dirty": m["dirty"] == "1", "date": m["date"]}


def changed_inputs(commit: str, inputs: tuple[str, ...], root: Path = ROOT) -> list[str]:
    """Input files whose content changed between `commit` and the working tree; a file only moved
    (a rename with identical content, e.g. benchmarks/ regrouped into sections) is not a change."""
    under = lambda path: any(path == i or path.startswith(i.rstrip("/") + "/") for i in inputs)  # noqa: E731
    out = []
    for line in _git("diff", "--name-status", "-M", commit, cwd=root).splitlines():
        status, *paths = line.split("\t")
        if status == "R100":
            continue
        out += [p for p in paths[-1:] if under(p)] + [p for p in paths[:-1] if under(p) and status.startswith("R")]
    return out


def stale_pages(root: Path = ROOT) -> dict[str, list[str]]:
    """Page name -> why it is stale: the input files changed between its commit and the working
    tree (uncommitted changes included), or a missing / unknown stamp, or a dirty run."""
    out: dict[str, list[str]] = {}
    for name, page in PAGES.items():
        path = root / "docs" / name
        if not path.exists():
            out[name] = ["page missing"]
            continue
        st = read_stamp(path)
        if st is None:
            out[name] = ["no bench-page stamp"]
            continue
        try:
            changed = changed_inputs(st["commit"], page.inputs, root)
            changed += _git("ls-files", "--others", "--exclude-standard", "--", *page.inputs, cwd=root).splitlines()
        except subprocess.CalledProcessError:
            out[name] = [f"commit {st['commit'][:7]} is not in this repository's history"]
            continue
        why = sorted(set(changed))
        if st["dirty"]:
            why.insert(0, "measured with uncommitted changes")
        if why:
            out[name] = why
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("what", choices=("stale", "list"))
    ap.add_argument("--strict", action="store_true", help="exit 1 when a page is stale")
    args = ap.parse_args(argv)
    if args.what == "list":
        for name, page in PAGES.items():
            st = read_stamp(DOCS / name) if (DOCS / name).exists() else None
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
