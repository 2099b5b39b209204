"""The benchmark pages name the commit they were measured on, and the stale check finds the pages
whose code changed since (benchmarks/pages.py)."""
import subprocess

from benchmarks.pages import DOCS, PAGES, ROOT, read_stamp, stale_pages, write_page


def test_every_benchmark_page_is_listed_stamped_and_has_real_inputs():
    pages = {p.name for p in DOCS.glob("bench_*.md")}
    assert pages == set(PAGES), f"pages without an entry in PAGES or entries without a page: {pages ^ set(PAGES)}"
    for name, page in PAGES.items():
        st = read_stamp(DOCS / name)
        assert st is not None, f"docs/{name} names no commit (benchmarks.pages.write_page writes the stamp)"
        missing = [p for p in page.inputs if not (ROOT / p).exists()]
        assert not missing, (name, missing)


def _git(root, *args):
    subprocess.run(["git", *args], cwd=root, check=True, capture_output=True,
                   env={"GIT_AUTHOR_NAME": "t", "GIT_AUTHOR_EMAIL": "t@t", "GIT_COMMITTER_NAME": "t",
                        "GIT_COMMITTER_EMAIL": "t@t", "PATH": "/usr/bin:/bin"})


def test_stale_check_known_answer(tmp_path):
    """A page stamped on a clean tree is current; a change to one of its inputs (uncommitted, then
    committed) makes it stale naming that file; a change elsewhere does not; re-writing it makes it
    current again; a run with uncommitted input changes is reported until re-run clean."""
    _git(tmp_path, "init", "-q")
    (tmp_path / "docs").mkdir()
    (tmp_path / "stages/costmap").mkdir(parents=True)
    (tmp_path / "stages/costmap/build.py").write_text("x = 1\n")
    (tmp_path / "README.md").write_text("hi\n")
    _git(tmp_path, "add", ".")
    _git(tmp_path, "commit", "-qm", "a")
    write_page("bench_spatial.md", "# bench\n\n| a |\n", root=tmp_path)
    _git(tmp_path, "add", ".")
    _git(tmp_path, "commit", "-qm", "page")
    assert "bench_spatial.md" not in stale_pages(tmp_path)
    (tmp_path / "README.md").write_text("changed\n")
    assert "bench_spatial.md" not in stale_pages(tmp_path)  # not an input
    (tmp_path / "stages/costmap/build.py").write_text("x = 2\n")
    assert stale_pages(tmp_path)["bench_spatial.md"] == ["stages/costmap/build.py"]
    _git(tmp_path, "commit", "-qam", "b")
    assert stale_pages(tmp_path)["bench_spatial.md"] == ["stages/costmap/build.py"]
    write_page("bench_spatial.md", (tmp_path / "docs/bench_spatial.md").read_text(), root=tmp_path)
    assert "bench_spatial.md" not in stale_pages(tmp_path)
    assert (tmp_path / "docs/bench_spatial.md").read_text().count("bench-page:") == 1  # one stamp, replaced
    (tmp_path / "stages/costmap/build.py").write_text("x = 3\n")
    write_page("bench_spatial.md", "# bench\n", root=tmp_path)  # measured with uncommitted changes
    assert read_stamp(tmp_path / "docs/bench_spatial.md")["dirty"]
    assert stale_pages(tmp_path)["bench_spatial.md"][0] == "measured with uncommitted changes"
    # pages that do not exist are listed too
    assert stale_pages(tmp_path)["bench_real.md"] == ["page missing"]
