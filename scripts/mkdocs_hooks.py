"""MkDocs hook: the design notes stay beside their code (stages/<name>/design.md,
navcore/<name>/design.md) and are published as design/<name>.md; links between them and to code
files are rewritten for the site."""
from __future__ import annotations

import re
from pathlib import Path

from mkdocs.structure.files import File

ROOT = Path(__file__).resolve().parents[1]
NOTES = {f"design/{p.parent.name}.md": p for p in sorted([*ROOT.glob("stages/*/design.md"),
                                                          *ROOT.glob("navcore/*/design.md")])}
LINK = re.compile(r"\]\((?:\.\./)*(?:stages|navcore)/(\w+)/design\.md(#[^)]*)?\)")


def on_files(files, config):
    for dest, src in NOTES.items():
        files.append(File.generated(config, dest, abs_src_path=str(src)))
    return files


def on_page_markdown(markdown, page, config, files):
    if page.file.src_uri.startswith("design/"):
        return LINK.sub(lambda m: f"]({m.group(1)}.md{m.group(2) or ''})", markdown)
    up = "../" * page.file.src_uri.count("/")
    return LINK.sub(lambda m: f"]({up}design/{m.group(1)}.md{m.group(2) or ''})", markdown)
