"""The benchmark pages name the commit they were measured on, and the stale check finds the pages
whose code changed since (benchmarks/pages.py)."""
import subprocess

from benchmarks.pages import PAGES, PAGES_DIR, ROOT, Page, read_stamp, stale_pages, write_page


def test_every_benchmark_page_is_listed_stamped_and_has_real_inputs():
    pages = {p.name for p in (ROOT / PAGES_DIR).glob("bench_*.md")}
    assert not list((ROOT / "docs").glob("bench_*.md")), "benchmark pages live in docs/benchmarks/, beside their index"
    assert pages == set(PAGES), f"pages without an entry in PAGES or entries without a page: {pages ^ set(PAGES)}"
    for name, page in PAGES.items():
        st = read_stamp(ROOT / PAGES_DIR / name)
        assert st is not None, f"{PAGES_DIR}/{name} names no commit (benchmarks.pages.write_page writes the stamp)"
        missing = [p for p in page.inputs if not (ROOT / p).exists()]
        assert not missing, (name, missing)


def _git(root, *args):
    subprocess.run(["git", *args], cwd=root, check=True, capture_output=True,
                   env={"GIT_AUTHOR_NAME": "t", "GIT_AUTHOR_EMAIL": "t@t", "GIT_COMMITTER_NAME": "t",
                        "GIT_COMMITTER_EMAIL": "t@t", "PATH": "/usr/bin:/bin"})


def test_stale_check_known_answer(tmp_path, monkeypatch):
    """A page stamped on a clean tree is current. Its stage's hash changing (a version bump, a new
    default) or its code changing makes it stale, naming why; a function moved between its files,
    a comment, a docstring or a file elsewhere does not; re-writing it makes it current again; a run
    with uncommitted code changes is reported until re-run clean."""
    _git(tmp_path, "init", "-q")
    (tmp_path / PAGES_DIR).mkdir(parents=True)
    bench = tmp_path / "benchmarks/map"
    bench.mkdir(parents=True)
    (bench / "spatial.py").write_text("import os\n\ndef f():\n    return 1\n\n\ndef g():\n    return 2\n")
    (bench / "helpers.py").write_text("X = 1\n")
    (tmp_path / "README.md").write_text("hi\n")
    _git(tmp_path, "add", ".")
    _git(tmp_path, "commit", "-qm", "a")
    monkeypatch.setitem(PAGES, "bench_spatial.md", Page("make bench-spatial", ("benchmarks/map",), ("costmap",)))
    hashes = {"costmap": "aaaa"}
    write_page("bench_spatial.md", "# bench\n\n| a |\n", root=tmp_path, stage_hashes=hashes)
    _git(tmp_path, "add", ".")
    _git(tmp_path, "commit", "-qm", "page")
    stale = lambda: stale_pages(tmp_path, stage_hashes=hashes)  # noqa: E731
    assert "bench_spatial.md" not in stale()
    (tmp_path / "README.md").write_text("changed\n")
    assert "bench_spatial.md" not in stale()  # not an input
    # a refactor: g moves to another file of the inputs, a comment and a docstring appear, an import goes
    (bench / "spatial.py").write_text('def f():\n    """One."""\n    return 1  # one\n')
    (bench / "helpers.py").write_text("X = 1\n\n\ndef g():\n    return 2\n")
    _git(tmp_path, "commit", "-qam", "refactor")
    assert "bench_spatial.md" not in stale()
    hashes["costmap"] = "bbbb"  # the stage's version or config changed
    assert stale()["bench_spatial.md"] == ["stage costmap: aaaa -> bbbb"]
    hashes["costmap"] = "aaaa"
    (bench / "spatial.py").write_text("def f():\n    return 3\n")
    assert stale()["bench_spatial.md"] == ["code of benchmarks/map"]
    _git(tmp_path, "commit", "-qam", "b")
    write_page("bench_spatial.md", (tmp_path / "docs/benchmarks/bench_spatial.md").read_text(), root=tmp_path, stage_hashes=hashes)
    assert "bench_spatial.md" not in stale()
    page = (tmp_path / "docs/benchmarks/bench_spatial.md").read_text()
    assert page.count("bench-page:") == 1 and page.count("bench-inputs:") == 1 and page.count("Measured on") == 1
    (bench / "spatial.py").write_text("def f():\n    return 4\n")
    write_page("bench_spatial.md", "# bench\n", root=tmp_path, stage_hashes=hashes)  # measured with uncommitted changes
    assert read_stamp(tmp_path / "docs/benchmarks/bench_spatial.md")["dirty"]
    assert stale()["bench_spatial.md"][0] == "measured with uncommitted changes"
    # pages that do not exist are listed too
    assert stale()["bench_real.md"] == ["page missing"]


def test_pages_follow_stages_by_their_hash_not_their_code():
    """Stage code is no page's code: a page measuring a stage's outputs follows the stage's hash
    (its version, config and upstream), which a refactor of the stage's code does not change; the
    hashes are those of the pipeline's markers, the same in every process."""
    from benchmarks.pages import default_stage_hashes

    assert not [(n, p) for n, page in PAGES.items() for p in page.code if p.startswith("stages")]
    hashes = default_stage_hashes()
    assert set(hashes) >= {s for page in PAGES.values() for s in page.stages}
    assert hashes == default_stage_hashes()


def _tables(text: str) -> list[list[str]]:
    """The markdown tables of a page: each a list of its rows (header first)."""
    out, cur = [], []
    for line in text.splitlines() + [""]:
        if line.startswith("|"):
            cur.append(line.strip())
        elif cur:
            out.append(cur)
            cur = []
    return out


def test_hand_written_pages_include_the_generated_figures_instead_of_copying_them():
    """A benchmark page's tables reach a hand-written page only through a snippet include of their
    section (`--8<-- "benchmarks/bench_x.md:table-N"`, markers written by write_page): no hand-written
    page holds a table with a generated table's header or one of its rows, and every include names a
    page and a section that exist (so `make bench-stale` covers every figure the tables show)."""
    import re

    generated = {p.name: p.read_text() for p in (ROOT / PAGES_DIR).glob("bench_*.md")}
    headers, rows = {}, {}
    for name, text in generated.items():
        for table in _tables(text):
            headers[table[0]] = name
            rows.update({r: name for r in table[2:]})
    written = [p for p in (ROOT / "docs").rglob("*.md") if not p.name.startswith("bench_")] + [ROOT / "README.md"]
    copies, broken = [], []
    for page in written:
        text = page.read_text()
        for table in _tables(text):
            if table[0] in headers:
                copies.append(f"{page.relative_to(ROOT)}: a table headed as {headers[table[0]]}'s: {table[0][:60]}")
            copies += [f"{page.relative_to(ROOT)}: a row of {rows[r]}: {r[:60]}" for r in table[2:] if r in rows]
        for target, section in re.findall(r'^--8<-- "benchmarks/(bench_[a-z_]+\.md):([a-z0-9-]+)"', text, re.M):
            if f"[start:{section}]" not in generated.get(target, ""):
                broken.append(f"{page.relative_to(ROOT)}: {target}:{section}")
    assert not copies, "include the section instead (python -m benchmarks.pages mark):\n" + "\n".join(copies)
    assert not broken, broken


FIGURE = __import__("re").compile(
    r"(?<![\w.,])(\d{1,3}(?:,\d{3})+(?![\d.])|\d[\d,]*\.\d+\s?(?:x|s|ms|us|frames/s|steps/s|%|KB|MB|GiB|dB)"
    r"|\d{3,}\s?(?:s|frames/s|steps/s))(?![\w/])")
"""A measured figure as the pages write it: 3,282 / 1.77x / 60.9 % / 395 s / 111.6 dB."""


def _distinctive(token: str) -> bool:
    """Three significant digits or more and not a round number (2,000 episodes is a setting, 2,459 a
    measurement)."""
    digits = "".join(c for c in token if c.isdigit()).lstrip("0")
    return len(digits) >= 3 and not digits.endswith("00")


def test_hand_written_prose_holds_no_figure_of_a_benchmark_page():
    """The figures of a benchmark page reach the guides through its tables' includes (or a link),
    never retyped into prose or a hand-made table, where they drift when the page is re-measured: no
    distinctive figure of a generated page (three significant digits, not round, with its unit) in a
    hand-written page."""
    generated: dict[str, str] = {}
    for p in sorted((ROOT / PAGES_DIR).glob("bench_*.md")):
        for m in FIGURE.finditer(p.read_text()):
            if _distinctive(m[0]):
                generated.setdefault(m[0], p.name)
    written = [p for p in (ROOT / "docs").rglob("*.md") if "benchmarks" not in p.relative_to(ROOT / "docs").parts]
    copies = []
    for page in [*written, ROOT / "README.md"]:
        # the Baselines section of evaluation.md is generated too (from the model cards), lines kept
        # and a guide's own measurements (`<!-- own-figures: how they were measured -->`, up to the next
        # heading) are not a page's
        text = __import__("re").sub(r"<!-- baselines:begin.*?<!-- baselines:end -->|<!-- own-figures:.*?(?=^#|\Z)",
                                    lambda m: "\n" * m[0].count("\n"), page.read_text(), flags=__import__("re").S | __import__("re").M)
        copies += [f"{page.relative_to(ROOT)}:{text[:m.start()].count(chr(10)) + 1}: {m[0]} (from {generated[m[0]]})"
                   for m in FIGURE.finditer(text) if m[0] in generated]
    assert not copies, "include the page's table or link to it instead:\n" + "\n".join(copies)


def test_section_markers_wrap_every_table_and_are_idempotent():
    from benchmarks.pages import mark_sections

    page = "# t\n\n| a | b |\n|---|---|\n| 1 | 2 |\n\ntext\n\n| c |\n|---|\n| 3 |"
    once = mark_sections(page)
    assert once == mark_sections(once)
    assert once.count("[start:table-1]") == once.count("[end:table-2]") == 1
    assert once.index("[start:table-1]") < once.index("| a | b |") < once.index("[end:table-1]") < once.index("text")
