"""Configuration of a release (`navarena release`, section `release`)."""
from __future__ import annotations

from dataclasses import dataclass, field

from navcore.nav.eval_set import EvalSetConfig


@dataclass
class ReleaseConfig:
    """A versioned release folder assembled from a finished data root (pipeline/release)."""

    version: str = "0.1.0"
    """MAJOR.MINOR.PATCH; a release built with `previous` must have a higher one."""
    name: str = "navarena"
    """Dataset name (the card's title, Croissant's name, the default folder's prefix)."""
    out: str | None = None
    """Release folder; null = {data_root}/11_releases/{name}-v{version} (on the data root's
    filesystem, so that every file is a hard link: a release costs no second copy)."""
    copy_files: bool = False
    """Copy every file instead of hard-linking it: an independent release. A hard-linked release
    (the default: no second copy of the bytes) shares its files with the data root and with the
    previous release; a file changed or damaged in one is changed in the others, so edit neither
    in place. A copied release reuses nothing of the previous one either."""
    previous: str | None = None
    """Folder of the previous release: release notes (scenes added, removed, changed; counts before
    and after), and files whose bytes did not change are hard links to the previous release's."""
    public: bool = True
    """Leave out every scene whose licence does not allow redistribution (navcore/io/licences.py;
    the card lists each with the reason); false keeps every scene, for internal use only, and the
    card says so at its top."""
    extra_licenses: list[str] = field(default_factory=list)
    """Licence ids a team allows in a public release beyond the written table, after reading their
    terms (e.g. CC-BY-NC-4.0 for a non-commercial release)."""
    homepage: str | None = None
    """Where the release is published (card and Croissant `url`)."""
    citation: str | None = None
    """BibTeX the card and Croissant ask users to cite."""
    eval_set: EvalSetConfig = field(default_factory=EvalSetConfig)
    """The zero-shot evaluation set shipped as its own split."""
    workers: int = 0
    """Threads hashing files (0 = the machine's cores)."""
