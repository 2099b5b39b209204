"""Docs whose code runs: every bash and Python block of README.md, docs/getting-started.md,
docs/library.md, docs/evaluation.md and docs/own-capture.md, in page order, on the default dataset
and its release (tests/docs_runner.py says how). A page whose example fails fails make test."""
import os
import subprocess
import sys
from pathlib import Path

from docs_runner import PAGES, PythonSession, blocks, run_block, runnable

SKIP_REASONS = ("the runner", "a GPU", "the network", "your own", "a SLURM", "make bench")
"""What a skipped block may wait on: the runner itself (make dataset, make test), a GPU, the
network (PyPI), the user's own files, a cluster, a benchmark (minutes to hours)."""


def test_every_block_has_a_kind_and_a_skip_says_why(project_root):
    found = blocks(project_root)
    assert {b.page for b in found} == set(PAGES)
    run = [b for b in found if runnable(b)]
    assert len(run) >= 25, len(run)
    for b in found:
        if b.kind == "skip":
            assert b.arg.startswith(SKIP_REASONS), (b.where, b.arg)
    skipped = [b for b in found if b.kind == "skip"]
    assert len(skipped) <= len(run) // 2, [b.where for b in skipped]


def test_parser_reads_directives_and_indented_blocks(tmp_path):
    page = tmp_path / "p.md"
    page.write_text("x\n<!-- docs-run: skip: a GPU -->\n```bash\nmake gpu\n```\n\n- item:\n\n  ```python\n  print(1)\n  ```\n"
                    "<!-- docs-run: file: my_pkg/policy.py -->\n```python\nclass A: pass\n```\n```yaml\na: 1\n```\n")
    got = blocks(tmp_path, ("p.md",))
    assert [(b.lang, b.kind, b.arg, b.code) for b in got] == [
        ("bash", "skip", "a GPU", "make gpu\n"), ("python", None, None, "print(1)\n"),
        ("python", "file", "my_pkg/policy.py", "class A: pass\n"), ("yaml", None, None, "a: 1\n")]
    assert [runnable(b) for b in got] == [False, True, True, False]


def test_the_pages_run_in_order(project_root, tmp_path):
    work = tmp_path / "work"
    work.mkdir()
    (work / "examples").symlink_to(project_root / "examples")
    venv_bin = str(Path(sys.executable).parent) + "/"
    env = {**os.environ, "DATA": str(work / "first_run"), "NAVARENA_QUICK": "1", "PYTHONUNBUFFERED": "1"}
    # what the pages assume exists: make dataset's data root and its release, downloaded as navarena-v1.0.0
    for cmd in ([venv_bin + "navarena", "run", f"data_root={work / 'data'}"],
                [venv_bin + "navarena", "release", "--root", str(work / "data"), "--out", str(work / "navarena-v1.0.0")]):
        p = subprocess.run(cmd, cwd=project_root, env=env, capture_output=True, text=True, timeout=900)
        assert p.returncode == 0, (cmd, p.stdout[-2000:], p.stderr[-3000:])
    (work / "my_release").symlink_to(work / "navarena-v1.0.0")
    sessions: dict[str, PythonSession] = {}
    failed, timing = [], []
    try:
        for b in blocks(project_root):
            if not runnable(b) and b.kind != "file":
                continue
            if b.lang in ("python", "py") and b.kind != "file" and b.page not in sessions:
                sessions[b.page] = PythonSession(work, env)
            r = run_block(b, work, env, sessions.get(b.page), venv_bin)
            timing.append(f"{b.where}: {r.seconds:.1f} s{'' if r.ok else ' FAILED'}")
            if not r.ok:
                failed.append(f"{b.where}\n{b.code}\n{r.output}")
    finally:
        for s in sessions.values():
            s.close()
    print("\n".join(timing))
    assert not failed, "\n\n".join(failed)
