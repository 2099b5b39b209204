"""The documentation: the site builds with --strict, the configuration reference covers every key
and is current, the README stays short; the pages' code blocks run in tests/test_docs_run.py."""
import os
import re
import subprocess
import sys

import pytest


def test_config_reference_covers_every_key_and_is_current(project_root):
    from pipeline.config_reference import keys, markdown, missing

    assert missing() == []  # every key and section has a description
    page = (project_root / "docs" / "configuration.md").read_text()
    assert page == markdown(), "docs/configuration.md is not current: python -m pipeline.config_reference"
    assert len([k for k in keys() if not k.section]) > 300
    for key in ("costmap.resolution", "semantics.detector.camera_height", "evaluate.agent", "allow_failures"):
        assert f"| `{key}` |" in page
    from navarena.cli import CONSUMER
    from pipeline.config_reference import CLI_OUT, DATA_OUT, cli_markdown, data_markdown

    assert DATA_OUT.read_text() == data_markdown(), "docs/reference/data.md is not current"
    cli, page = cli_markdown(), CLI_OUT.read_text()  # argparse's layout varies with Python: the commands must match
    assert [x for x in cli.splitlines() if x.startswith("## ")] == [x for x in page.splitlines() if x.startswith("## ")]
    assert all(f"## navarena {name}" in page and f"usage: navarena {name}" in page for name in [*CONSUMER, "release"])


def test_config_reference_reads_field_docstrings():
    from dataclasses import dataclass, field

    from pipeline.config_reference import keys

    @dataclass
    class Inner:
        """An inner section."""

        x: float = 0.5
        """Metres of x."""

    @dataclass
    class Outer:
        inner: Inner = field(default_factory=Inner)
        flag: bool = False
        undocumented: int = 3

    got = {k.path: k for k in keys(Outer)}
    assert got["inner"].section and got["inner"].doc == "An inner section."
    assert got["inner.x"].doc == "Metres of x." and got["inner.x"].default == "0.5" and got["inner.x"].type == "float"
    assert got["flag"].default == "false" and got["undocumented"].doc == ""


def test_no_page_tells_users_to_import_the_pipeline_project(project_root):
    """Users script against the library (navarena, navcore); pipeline/ and stages/ are the checkout's."""

    pages = [project_root / "README.md", *(project_root / "docs").rglob("*.md"), *(project_root / "examples").glob("*.py")]
    told = [f"{p.relative_to(project_root)}: {m.group(0)}" for p in pages
            for m in re.finditer(r"(from|import) (stages|pipeline)\b[^\n]*", p.read_text())]
    assert not told, told


def test_readme_is_short_and_names_the_data_root(project_root):
    text = (project_root / "README.md").read_text()
    assert len(text.splitlines()) <= 250
    assert "make dataset" in text and "make test" in text and "data_root" in text


def test_site_builds_strict(project_root, tmp_path):
    pytest.importorskip("mkdocs", reason="the docs extra (make setup installs it)")
    p = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
                       cwd=project_root, capture_output=True, text=True, timeout=600,
                       env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})
    assert p.returncode == 0, p.stderr[-3000:]
    site = tmp_path / "site"
    assert (site / "configuration" / "index.html").is_file() and (site / "design" / "costmap" / "index.html").is_file()
    api = (site / "reference" / "api" / "index.html").read_text()
    assert "is_state_valid" in api and "Renderer" in api  # mkdocstrings rendered the navcore API


def test_the_tour_benchmark_times_what_the_readme_prints():
    """make bench-tour runs the README's tour commands as printed, each against a stated time; a
    README edit that drops or changes one is caught here, not by a benchmark measuring something else."""
    from benchmarks.usage.tour import STEPS, in_readme, markdown

    assert [s.command for s in STEPS if not in_readme(s)] == []
    assert not in_readme(STEPS[0], "navarena run stages=[costmap]")  # a real check, not always true
    rows = [{"step": s.what, "command": s.command, "stated_s": s.stated_s, "measured_s": s.stated_s + k,
             "runs": [s.stated_s + k], "exit": 0, "within": k == 0} for k, s in enumerate(STEPS[:2])]
    md = markdown({"machine": "m", "steps": rows, "tour_s": 1.0, "tour_stated_s": 2.0})
    assert "| yes |" in md and "| **no** |" in md
