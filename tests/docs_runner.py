"""The docs runner: every bash and Python block of the user-facing pages, run in page order.

A block runs as written, in a work folder that holds what the pages assume: `data` (the data root
the pages' first commands make), `navarena-v1.0.0` and `my_release` (a release built from it, as a
download would be), `examples` (the checkout's), and `.venv/bin/` read as the running venv's bin.
Bash blocks run with `bash -euo pipefail` (a server a block starts with `&` is stopped when the
block ends); a page's Python blocks share one namespace, as in a notebook. An HTML comment on the
line before a block tells the runner more:

    <!-- docs-run: skip: REASON -->     not run (the reason is required: a GPU, the network, ...)
    <!-- docs-run: file: PATH -->       the block is a file the page asks to save (written, not run)
    <!-- docs-run: expect: GLOB -->     after the block, GLOB (under $DATA) must exist

Blocks in other languages (yaml, text, bibtex) are data, not commands. `NAVARENA_QUICK=1` is set,
as docs/getting-started.md documents: evaluations and training runs shortened, the commands the
page's own.
"""
from __future__ import annotations

import glob
import os
import re
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

PAGES = ("docs/getting-started.md", "README.md", "docs/library.md", "docs/evaluation.md", "docs/own-capture.md")
"""In the order a new user reads them: getting-started makes the data root the others use."""
RUN_LANGS = {"bash": "bash", "sh": "bash", "shell": "bash", "python": "python", "py": "python"}
BLOCK = re.compile(r"(?:^<!-- docs-run: (?P<kind>skip|file|expect): (?P<arg>[^\n]*?) -->[ \t]*\n)?"
                   r"^(?P<indent>[ \t]*)```(?P<lang>[A-Za-z0-9_+-]*)[^\n]*\n(?P<code>.*?)^(?P=indent)```[ \t]*$", re.S | re.M)


@dataclass
class Block:
    page: str
    line: int
    lang: str
    code: str
    kind: str | None = None
    arg: str | None = None

    @property
    def where(self) -> str:
        return f"{self.page}:{self.line} ({self.lang})"


def blocks(project_root: Path, pages=PAGES) -> list[Block]:
    out = []
    for page in pages:
        text = (project_root / page).read_text(encoding="utf-8")
        for m in BLOCK.finditer(text):
            code = "\n".join(line[len(m["indent"]):] for line in m["code"].splitlines()) + "\n"
            out.append(Block(page, text.count("\n", 0, m.start("lang")) + 1, m["lang"].lower(), code, m["kind"], m["arg"]))
    return out


def runnable(b: Block) -> bool:
    return b.lang in RUN_LANGS and b.kind != "skip"


MARK = "\x00docs-runner-result "
SERVER = r"""
import contextlib, io, json, sys, traceback
ns = {"__name__": "__main__"}
out = sys.stdout
for line in sys.stdin:
    req = json.loads(line)
    buf = io.StringIO()
    try:
        with contextlib.redirect_stdout(buf):
            exec(compile(req["code"], req["where"], "exec"), ns)
        res = {"ok": True, "output": buf.getvalue()[-3000:]}
    except BaseException:
        res = {"ok": False, "output": buf.getvalue()[-2000:] + traceback.format_exc()[-4000:]}
    out.write("\x00docs-runner-result " + json.dumps(res) + "\n")
    out.flush()
"""


class PythonSession:
    """One Python process for a page's Python blocks (they share its namespace, as in a notebook),
    in the work folder with the runner's environment; its own process, so that the libraries a block
    loads (OpenMP through torch) never share a process with the runner's forks."""

    def __init__(self, work: Path, env: dict, python: str = sys.executable):
        import threading

        self.proc = subprocess.Popen([python, "-u", "-c", SERVER], cwd=work, env={**env, "PYTHONPATH": str(work)},
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.lines: list[str] = []
        self.lock = threading.Lock()

    def run(self, code: str, where: str, timeout: float) -> tuple[bool, str]:
        import json
        import queue
        import threading

        self.proc.stdin.write(json.dumps({"code": code, "where": where}) + "\n")
        self.proc.stdin.flush()
        got: queue.Queue = queue.Queue()

        def read():
            extra = []
            for line in self.proc.stdout:
                if line.startswith(MARK):
                    got.put((json.loads(line[len(MARK):]), extra))
                    return
                extra.append(line)
            got.put(({"ok": False, "output": f"the Python process ended (exit {self.proc.wait()})"}, extra))

        threading.Thread(target=read, daemon=True).start()
        try:
            res, extra = got.get(timeout=timeout)
        except queue.Empty:
            self.close()
            return False, f"timed out after {timeout} s"
        return res["ok"], "".join(extra)[-2000:] + res["output"]

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()


@dataclass
class Result:
    block: Block
    seconds: float
    ok: bool
    output: str


def run_block(b: Block, work: Path, env: dict, session: "PythonSession | None", venv_bin: str, timeout: float = 900) -> Result:
    t0 = time.perf_counter()
    if b.kind == "file":
        path = work / b.arg
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(b.code, encoding="utf-8")
        return Result(b, 0.0, True, f"wrote {b.arg}")
    if RUN_LANGS[b.lang] == "bash":
        code = b.code.replace(".venv/bin/", venv_bin)
        # a server started with `&` ends with the block
        script = "trap 'jobs -p | xargs -r kill 2>/dev/null || true' EXIT\n" + code
        env = {**env, "PATH": venv_bin + os.pathsep + env.get("PATH", "")}
        try:
            p = subprocess.run(["bash", "-euo", "pipefail", "-c", script], cwd=work, env=env, capture_output=True,
                               text=True, timeout=timeout)
            ok, output = p.returncode == 0, f"exit {p.returncode}\n{p.stdout[-3000:]}\n{p.stderr[-4000:]}"
        except subprocess.TimeoutExpired as e:
            ok, output = False, f"timed out after {timeout} s\n{(e.stdout or b'')[-2000:]!r}"
    else:
        ok, output = session.run(b.code, b.where, timeout)
    if ok and b.kind == "expect":
        ok = bool(glob.glob(str(Path(env["DATA"]) / b.arg.strip())))
        output += f"\nexpected {b.arg} under $DATA: {'found' if ok else 'missing'}"
    return Result(b, time.perf_counter() - t0, ok, output)
