"""Outputs a run would recompute because the config changed since they were made.

A (stage, scene) whose marker holds another config hash is recomputed. When the user named that
stage (or it is in the default list they ran) that is what they asked for; when it only runs as
an upstream of a stage they named (`stages=[evaluate]` with other episode overrides than the run
that made the episodes), it silently overwrites their data. `config_changes` finds these pairs
and which keys differ (markers record their stage's config: graph.stage_config); the executor
prints them at the start and in the run summary, and refuses to overwrite outputs of stages the
run does not name unless `force=true` (then it recomputes them) or the run names them. A change
of a storage key only (what a stage keeps, e.g. voxelize.store_opacity) changes nothing any
stage computes and is never refused.
"""
from __future__ import annotations

from pipeline.graph import BY_NAME, STAGES, stage_config, stage_storage
from pipeline.markers import read_marker


def flatten(d, prefix: str = "") -> dict:
    """{"a": {"b": 1}} -> {"a.b": 1} (lists and scalars are leaves)."""
    if not isinstance(d, dict):
        return {prefix.rstrip("."): d}
    out = {}
    for k, v in d.items():
        out.update(flatten(v, f"{prefix}{k}."))
    return out


def diff(old: dict | None, new: dict) -> list[tuple[str, object, object]]:
    """(key, old, new) of the keys that differ; None when the old config was not recorded."""
    if old is None:
        return None
    a, b = flatten(old), flatten(new)
    missing = object()
    return [(k.replace("_inputs.", "(inputs) "), a.get(k, missing), b.get(k, missing)) for k in sorted(set(a) | set(b))
            if a.get(k, missing) != b.get(k, missing)]


def config_changes(cfg, catalog, scenes, stages, hashes) -> dict[str, dict]:
    """Per stage whose existing outputs were made with another config: {"scenes": [scene ids],
    "keys": [(key, old, new)] of its own settings, "cause": why when its own settings are equal}."""
    out: dict[str, dict] = {}
    parts = {st.name: stage_config(cfg, st.name) for st in stages}
    for st in stages:
        for scene in scenes:
            if BY_NAME[st.name].only_synthetic and not scene.synthetic:
                continue
            m = read_marker(catalog.path("markers", scene, stage=st.name))
            if m is None or m.get("config_hash") == hashes.of(st.name, scene):
                continue
            row = out.setdefault(st.name, {"scenes": [], "keys": [], "cause": "", "storage_only": True})
            row["scenes"].append(scene.scene_id)
            d = diff(m.get("config"), parts[st.name])
            stored = diff(m.get("storage"), stage_storage(cfg, st.name)) if "storage" in m else None
            if not (d == [] and stored):  # a change of what is stored only (no content downstream changes)
                row["storage_only"] = False
            if d == [] and stored:
                row["keys"] = sorted(set(row["keys"]) | {(k, _show(a), _show(b)) for k, a, b in stored})
                continue
            if d is None:
                row["cause"] = row["cause"] or "made before markers recorded their settings"
            elif d:
                row["keys"] = sorted(set(row["keys"]) | {(k, _show(a), _show(b)) for k, a, b in d})
            else:
                ups = [n for n in BY_NAME[st.name].needs if n in out]
                newer = [] if ups else recomputed_since(m, st.name, scene, catalog)
                before_keying = not scene.synthetic and m.get("keyed") != "captured"
                row["cause"] = row["cause"] or (
                    f"its upstream {', '.join(ups)} changed" if ups else
                    "made before scenes read from files were keyed apart from the generator's settings: recompute "
                    "once, after which a synthetic.* setting no longer touches them" if before_keying else
                    f"it was made from an older {', '.join(newer)}: {'they were' if len(newer) > 1 else 'that stage was'}"
                    f" recomputed since, with the settings of this run, and {st.name} was not" if newer else
                    "the stage's code version or the scene's catalog options changed")
                if newer:
                    row["stale_after"] = sorted(set(row.get("stale_after", [])) | set(newer))
    return out


def recomputed_since(marker: dict, stage: str, scene, catalog) -> list[str]:
    """The stages upstream of `stage` whose outputs for the scene were made by a later run than
    its own (a one-stage run with an override leaves the later stages made from the old output)."""
    when = (marker.get("run") or {}).get("started_ns")
    if when is None:
        return []
    out, todo, seen = [], list(BY_NAME[stage].needs), set()
    while todo:
        n = todo.pop()
        if n in seen:
            continue
        seen.add(n)
        todo += BY_NAME[n].needs
        up = read_marker(catalog.path("markers", scene, stage=n))
        if up and (up.get("run") or {}).get("started_ns", 0) > when:
            out.append(n)
    return sorted(out, key=lambda n: [s.name for s in STAGES].index(n))


def _show(v) -> str:
    return "(unset)" if type(v) is object else str(v)


def describe(changes: dict[str, dict]) -> list[str]:
    """Lines of text, one per stage."""
    lines = []
    for stage, c in changes.items():
        what = "; ".join(f"{k}: {a} -> {b}" for k, a, b in c["keys"][:8]) + (" ..." if len(c["keys"]) > 8 else "")
        lines.append(f"{stage} ({len(c['scenes'])} scene(s)): {what or c['cause']}")
    return lines


def refusal(changes: dict[str, dict], blocked: list[str], overrides: list[str] | None = None) -> str:
    """The message of a run that would overwrite outputs of stages it does not name; `overrides`
    (this run's command-line settings) complete the exact commands it suggests."""
    keep = sorted({f"{k}={a}" for s in blocked for k, a, _ in changes[s]["keys"] if a != "(unset)" and "(inputs)" not in k})
    named = ",".join(blocked)
    stale = sorted({u for s in blocked for u in changes[s].get("stale_after", [])})
    given = " ".join(o for o in (overrides or []) if not o.startswith("stages="))
    msg = ["this run would recompute outputs made with other settings, of stages it does not name:",
           *(f"  {line}" for line in describe({s: changes[s] for s in blocked}))]
    if stale and not keep:  # made before an upstream was recomputed: no setting of this run brings them back
        msg += [f"Nothing was changed. {', '.join(blocked)} still hold(s) what the older {', '.join(stale)} gave. To make "
                "the data root consistent with the settings of this run, recompute them once:",
                f"  navarena run stages=[{named}] {given}".rstrip(),
                "or add force=true to this command."]
    else:
        msg += ["Nothing was changed. To keep those outputs, repeat the settings they were made with"
                + (f": {' '.join(keep)}" if keep else "") + ".",
                f"To recompute them, name the stages (stages=[{named},...]) or add force=true."]
    return "\n".join(msg)
