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
