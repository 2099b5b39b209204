"""Scene licences: which ones allow a public release to redistribute a scene and what is derived from it.

A catalog entry names its licence (`license:` an SPDX id, or free text), where it came from
(`source_url:`) and whom to credit (`attribution:`). A public release (`release.public=true`)
ships a scene only when its licence is an SPDX id of ``REDISTRIBUTABLE``: the release carries the
scene's aligned model, renders (ImageNav goal images) and maps, all derivatives of the capture, so a
licence must allow redistribution of derivatives. Free text, an unknown id, a non-commercial or
no-derivatives licence is never assumed to allow it: a team that has read such terms and may ship
under them adds the id to ``release.extra_licenses`` (and the card lists it beside the scene).
"""
from __future__ import annotations

PROJECT_LICENSE = "Apache-2.0"
"""The project's licence (LICENSE, pyproject.toml), carried by the procedural scenes it generates
and by what the pipeline derives from scenes whose own licence allows it."""

REDISTRIBUTABLE = {
    "CC0-1.0": "public domain dedication",
    "PDDL-1.0": "public domain dedication (data)",
    "Unlicense": "public domain dedication (software)",
    "CC-BY-4.0": "attribution",
    "CC-BY-3.0": "attribution",
    "CC-BY-SA-4.0": "attribution, share-alike (derived files keep the licence)",
    "CC-BY-SA-3.0": "attribution, share-alike (derived files keep the licence)",
    "ODC-By-1.0": "attribution (data)",
    "ODbL-1.0": "attribution, share-alike (data)",
    "CDLA-Permissive-2.0": "permissive (data)",
    "CDLA-Permissive-1.0": "permissive (data)",
    "CDLA-Sharing-1.0": "share-alike (data)",
    "Apache-2.0": "permissive, keep the notice",
    "MIT": "permissive, keep the notice",
    "BSD-2-Clause": "permissive, keep the notice",
    "BSD-3-Clause": "permissive, keep the notice",
}
"""SPDX ids whose terms allow redistributing a scene and its derivatives, with the condition the
card repeats. Left out on purpose: every -NC- (non-commercial) and -ND- (no derivatives) variant,
dataset terms of use (ScanNet's, Matterport's: no redistribution) and anything unstated."""


def redistributable(license: str | None, extra: tuple[str, ...] | list[str] = ()) -> tuple[bool, str]:
    """(allowed, why) for a scene's licence in a public release; `extra`: ids a team allows after
    reading their terms (release.extra_licenses)."""
    if license is None or not str(license).strip():
        return False, "no licence stated (catalog entry `license:`)"
    lic = str(license).strip()
    if lic in REDISTRIBUTABLE:
        return True, REDISTRIBUTABLE[lic]
    if lic in extra:
        return True, "allowed by release.extra_licenses"
    return False, (f"licence {lic!r} is not one that allows redistributing derivatives (navcore/io/licences.py "
                   f"REDISTRIBUTABLE); add it to release.extra_licenses once its terms are read")
