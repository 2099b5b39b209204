"""The dataset card (README.md in the dataset-hub convention): YAML front matter that
`datasets.load_dataset(folder, "<task>", split=...)` reads (configs with data_files per task and
split, split sizes), and a body with the release's statistics, plots, evaluation set, embodiment,
evaluation protocol, scenes and their provenance, scenes left out and known limitations."""
from __future__ import annotations

from pathlib import Path

import pyarrow as pa
import yaml

from navcore.io.episode_schema import field_table
from navcore.io.licences import PROJECT_LICENSE
from navcore.io.release import KEY_COLUMNS

SCENES_SCHEMA = pa.schema([
    ("scene_id", pa.string()), ("name", pa.string()), ("group", pa.string()), ("format", pa.string()),
    ("license", pa.string()), ("redistributable", pa.bool_()), ("source_url", pa.string()), ("attribution", pa.string()),
    ("screening_verdict", pa.string()), ("screening_score", pa.float64()), ("episodes_kept", pa.bool_()),
    ("episodes", pa.string()),  # JSON {"task/split": count}
    ("goal_segmenter", pa.string()),  # the semantics segmenter whose instances are its ObjectNav goals (null: none ran)
    ("goal_instances", pa.int64()),  # how many instances it lifted
    ("content_sha256", pa.string()),  # sha256 over the scene's files (path and sha256): what versions compare
])
"""scenes.parquet: one row per released scene."""

HUB_LICENSES = {"ODbL-1.0": "odbl", "PDDL-1.0": "pddl", "ODC-By-1.0": "odc-by", "Unlicense": "unlicense"}
"""SPDX ids whose dataset-hub licence id is not simply the lower-case SPDX id."""
SIZES = ((1_000, "n<1K"), (10_000, "1K<n<10K"), (100_000, "10K<n<100K"), (1_000_000, "100K<n<1M"),
         (10_000_000, "1M<n<10M"), (100_000_000, "10M<n<100M"))


def hub_license(licenses: set[str]) -> dict:
    """The card's licence keys: one id when every scene (and the project) share it, else `other`."""
    if len(licenses) == 1:
        lic = next(iter(licenses))
        return {"license": HUB_LICENSES.get(lic, lic.lower())}
    return {"license": "other", "license_name": "per-scene",
            "license_link": "scenes.parquet"}


def citation(info: dict, rcfg) -> str:
    """The BibTeX users are asked to cite: release.citation, else an entry for this release itself
    (name, version, year, where it is published, the commit that made it)."""
    if rcfg.citation:
        return rcfg.citation.strip()
    key = f"{rcfg.name}_v{info['version']}".replace(".", "_").replace("-", "_")
    code = info.get("code") or {}
    fields = [("title", f"{{{rcfg.name} {info['version']}}}: goal-directed navigation episodes from 3D Gaussian "
                        "Splatting scenes"),
              ("author", "{NavArena contributors}"), ("year", str(info["created"])[:4]), ("version", info["version"]),
              ("note", "Dataset release made with NavArena"
                       + (f" at commit {code['commit'][:12]}" if code.get("commit") else ""))]
    if rcfg.homepage:
        fields.append(("howpublished", f"\\url{{{rcfg.homepage}}}"))
    return "@misc{" + key + ",\n" + ",\n".join(f"  {k} = {{{v}}}" for k, v in fields) + "\n}"


def size_category(n: int) -> str:
    for limit, name in SIZES:
        if n < limit:
            return name
    return "n>100M"


def front_matter(info: dict, rcfg) -> dict:
    counts = info["counts"]
    configs, dataset_info = [], []
    for task, splits in counts.items():
        for kind, folder in (("", "episodes"), ("_trajectories", "trajectories")):
            configs.append({"config_name": f"{task}{kind}",
                            "data_files": [{"split": sp, "path": f"{folder}/{task}/{sp}/*.parquet"}
                                           for sp in splits]})
        dataset_info.append({"config_name": task, "splits": [{"name": sp, "num_examples": n} for sp, n in splits.items()]})
    lic = {s["license"] or "unknown" for s in info["scene_rows"]} | {PROJECT_LICENSE}
    fm = {"pretty_name": f"{rcfg.name} {info['version']}", **hub_license(lic),
          "task_categories": ["robotics"],
          "tags": ["embodied-ai", "navigation", "pointnav", "imagenav", "objectnav", "3d-gaussian-splatting"],
          "size_categories": [size_category(sum(info["counts_total"].values()))],
          "configs": configs, "dataset_info": dataset_info}
    return fm


def _f(x, nd=2) -> str:
    return "-" if x is None else f"{x:,.{nd}f}"


def _table(rows: list[dict], by: str | None) -> list[str]:
    head = ["task"] + ([by] if by else []) + ["episodes", "mean geodesic path (m)", "mean expert steps",
                                               "total expert duration (h)", "mean oracle actions"]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        out.append("| " + " | ".join([r["task"]] + ([str(r[by])] if by else []) +
                                     [f"{r['episodes']:,}", _f(r["mean_geodesic_m"]), _f(r["mean_expert_steps"], 0),
                                      _f(r["expert_hours"]), _f(r["mean_oracle_actions"], 1)]) + " |")
    return out


def write_card(path: Path, info: dict, stats, scene_rows: list[dict], plots: list[str], rcfg) -> None:
    """The release card (README.md with the Hub's YAML front matter): a section a function, in order."""
    cfg = info["config"]
    info = {**info, "scene_rows": scene_rows,
            "counts_total": {t: sum(n for sp, n in s.items() if sp not in stats.extra_splits)
                             for t, s in info["counts"].items()}}
    fm = front_matter(info, rcfg)
    L = ["---", yaml.safe_dump(fm, sort_keys=False, width=120).rstrip(), "---", "",
         f"# {rcfg.name} {info['version']}", ""]
    if not info["public"]:
        L += ["> **Internal release (release.public=false): not for redistribution.** It keeps every scene "
              "whatever its licence; scenes whose licence does not allow redistribution are marked below.", ""]
    L += _introduction(info, stats, scene_rows) + _fields() + _statistics(stats, plots) + _eval_set(info["eval_set"])
    L += _embodiment(cfg) + _protocol(cfg) + _scenes(scene_rows, info["scenes"]["excluded"]) + _closing(info, rcfg)
    Path(path).write_text("\n".join(L))


def _introduction(info: dict, stats, scene_rows: list[dict]) -> list[str]:
    """What the release is, and how to load it."""
    L: list[str] = []
    total = stats.total_episodes()
    L += [f"Goal-directed navigation episodes (PointNav, ImageNav, ObjectNav) with expert trajectories, generated "
          f"by NavArena from frozen 3D Gaussian Splatting scenes: {total:,} episodes in {len(scene_rows)} scene(s), "
          f"created {info['created']}. Every file is listed with its sha256 in `MANIFEST.tsv` "
          "(whose own digest is `MANIFEST.tsv.sha256`); `navarena verify-release <folder>` checks a downloaded copy "
          "and names every damaged file.", "",
          "## Loading", "",
          "Every episode and trajectory file holds `task`, `split` and `scene_id` as columns, equal to its path "
          "`{episodes,trajectories}/<task>/<split>/<scene_id>.parquet`. An episode is unique by "
          "(`task`, `split`, `scene_id`, `episode_id`) across the release (`episode_id` alone repeats across "
          f"scenes; the evaluation set's split `{info['eval_set']['name']}` repeats test episodes under its own name); "
          "its expert steps join on those four columns.", "", "```python",
          "import datasets",
          "episodes = datasets.load_dataset(\"<this folder>\", \"pointnav\", split=\"train\")",
          "steps = datasets.load_dataset(\"<this folder>\", \"pointnav_trajectories\", split=\"train\")",
          "joined = steps.to_pandas().merge(episodes.to_pandas(), on=[\"task\", \"split\", \"scene_id\", \"episode_id\"])",
          "",
          "import pandas as pd  # every task, split and scene at once",
          "eps = pd.read_parquet(\"<this folder>/episodes\")",
          "steps = pd.read_parquet(\"<this folder>/trajectories/pointnav\")",
          "joined = steps.merge(eps, on=[\"task\", \"split\", \"scene_id\", \"episode_id\"])",
          "",
          "import pyarrow.dataset as ds",
          "table = ds.dataset(\"<this folder>/episodes\", format=\"parquet\").to_table(filter=ds.field(\"split\") == \"train\")",
          "",
          "import mlcroissant as mlc",
          "records = mlc.Dataset(jsonld=\"<this folder>/croissant.json\").records(\"pointnav\")",
          "```", "",
          "No rendered frames ship: the scenes' Gaussians do (`assets/`), and `navarena render-episodes` or the "
          "evaluation environment renders any view of an episode (ImageNav goal views ship in `goal_images/` only "
          "when the data root was made with `goal_images.enabled=true`).", "",
          "Schemas: `release.json` (`schemas`; `key_columns`: the columns every table file holds), from "
          "`navcore/io/episode_schema.py`. Frame: the scene's aligned "
          "frame (z up, metres, floor at z = 0); headings are yaw about +z.", ""]
    return L


def _fields() -> list[str]:
    """The episode and trajectory tables' fields, from their schemas."""
    L: list[str] = []
    L += ["## Fields", "", "Every episode and trajectory file starts with the key columns `task` (pointnav | imagenav | "
          "objectnav), `split` and `scene_id` (string; equal to the file's path), then:", "",
          "Episodes (`episodes/<task>/<split>/<scene_id>.parquet`, one row per episode):", "",
          *field_table("episodes", skip=KEY_COLUMNS), "",
          "Expert trajectories (`trajectories/<task>/<split>/<scene_id>.parquet`, one row per 20 Hz step):", "",
          *field_table("trajectories", skip=KEY_COLUMNS), ""]
    return L


def _statistics(stats, plots: list[str]) -> list[str]:
    """Episode counts and lengths per task, split, group and difficulty."""
    L: list[str] = []
    L += ["## Statistics", "", "Per task (the layout of the paper's Table 4; every split except the evaluation set, "
          "whose episodes repeat test episodes):", "", *_table(stats.rows(), None), ""]
    for by, title in (("split", "Per split"), ("group", "Per source group"), ("difficulty", "Per difficulty")):
        L += [f"{title}:", "", *_table(stats.rows(by), by), ""]
    if plots:
        L += ["Plots:", ""] + [f"![{Path(p).stem}]({p})" for p in plots] + [""]
    return L


def _eval_set(es: dict) -> list[str]:
    """The zero-shot evaluation set: what was drawn against what was asked."""
    L: list[str] = []
    L += [f"## Zero-shot evaluation set (`{es['name']}`)", "",
          f"A fixed, stratified sample of the `{', '.join(es['from_splits'])}` split (scenes held out of training by "
          f"`episodes.scene_splits`), {es['size']} episodes a task at {' / '.join(f'{k} {v:.0%}' for k, v in es['proportions'].items())} "
          "(the paper's 180 / 240 / 180), drawn round robin over source groups, scenes and goal categories "
          "(navcore/nav/eval_set.py). It ships as its own split (`split=" + es["name"] + "`) and as a listing "
          f"(`eval_sets/{es['name']}.parquet`); run it with `make eval ARGS=\"evaluate.split={es['name']}\"`.", "",
          "| task | selected | requested | easy / medium / hard | candidates easy / medium / hard | scenes | groups |",
          "|---|---|---|---|---|---|---|"]
    for task, r in es["per_task"].items():
        pd_, c = r["per_difficulty"], r["candidates"]
        L.append(f"| {task} | {r['selected']} | {r['requested']} | {' / '.join(str(v) for v in pd_.values())} | "
                 f"{' / '.join(str(v) for v in c.values())} | {r['scenes']} | {r['groups']} |")
    short = [t for t, r in es["per_task"].items() if r["selected"] < r["requested"]]
    if short:
        held = sorted({es["per_task"][t]["scenes"] for t in short})
        n_held = (f"{held[0]} scene{'s' if held[0] != 1 else ''}" if len(held) == 1 else
                  ", ".join(f"{t} {es['per_task'][t]['scenes']} scenes" for t in short))
        L += ["", f"Fewer than requested for {', '.join(short)}: the held-out scenes ({n_held}) hold fewer episodes at these "
              "proportions (the set is the largest one that keeps them). More held-out scenes (a larger `scenes.count`, "
              "or `episodes.scene_splits`) give a fuller set."]
    if not es["per_task"]:
        L += ["", "Empty: none of this release's scenes is in the held-out splits (episodes.scene_splits assigns "
              "scenes by a hash of their id; a small scene set may have none there)."]
    return L


def _embodiment(cfg: dict) -> list[str]:
    """The robot the episodes were made for."""
    L: list[str] = []
    emb = cfg["embodiment"]
    L += ["", "## Embodiment", "",
          f"`{emb['name']}`: footprint radius {emb['radius']} m, body {emb['h_min']}-{emb['h_max']} m above the floor, "
          f"camera at {emb['camera_height']} m (pitch {emb['camera_pitch_deg']} deg, {emb['hfov_deg']} deg horizontal field "
          f"of view, {emb['image_width']} x {emb['image_height']}), at most {emb['max_linear_velocity']} m/s and "
          f"{emb['max_angular_velocity']} rad/s. Expert trajectories at {1 / cfg['episodes']['dt']:.0f} Hz; "
          f"discrete actions: forward {cfg['episodes']['actions']['forward_step']} m, turns "
          f"{cfg['episodes']['actions']['turn_angle_deg']} deg.", ""]
    return L


def _protocol(cfg: dict) -> list[str]:
    """Success rules and step budgets."""
    L: list[str] = []
    diff = cfg["episodes"]["difficulty"]
    L += ["## Evaluation protocol", "",
          "| task | success radius (m) | rule |", "|---|---|---|"]
    for name, t in sorted(cfg["task"].items()):
        rule = {"objectnav": f"within the radius of the goal instance's {t['success_rule']}",
                "imagenav": f"within the radius and {t['heading_tolerance_deg']} deg of the goal heading (Pose SR)",
                }.get(t["type"], "within the radius of the goal point")
        L.append(f"| {name} | {t['success_radius']} | {rule} |")
    L += ["", "Step budgets by difficulty (geodesic distance): " + ", ".join(
        f"{n} < {u:g} m: {s}" if u < 1e8 else f"{n}: {s}" for n, u, s in zip(diff["names"], diff["upper"], diff["max_steps"]))
          + ". An episode ends when the agent stops (protocol `explicit_stop`) or reaches the goal region (`distance`), or "
          "when its step budget runs out; metrics (SR, SPL, DTW, collisions) are defined in the evaluation docs and "
          f"computed by `make eval` (dynamics: blocked moves `{cfg['evaluate']['dynamics']['blocked']}`).", "",
          "**Does a policy use its goal?** `navarena eval RELEASE --agent YOURS --decoy-goal` runs the same episodes with "
          "the agent shown another goal of the scene (ImageNav: another goal image; ObjectNav: another category present "
          "in the scene; PointNav: another goal point) and scores it on the true goal. The policy's goal gain is its SR "
          "with the true goal minus its SR with the decoy: a policy that ignores its goal has a gain of 0, and one that "
          "searches the scene can score well under the distance protocol with none. Report both.", ""]
    return L


def _scenes(scene_rows: list[dict], excluded: list[dict]) -> list[str]:
    """Every scene (and those a public release left out)."""
    L: list[str] = []
    L += ["## Scenes", "", "ObjectNav goals: the segmenter whose instances the scene's ObjectNav goals are (`oracle`: the "
          "scene's own per-Gaussian labels; `detector`, `sam3`, `open_vocab`: masks lifted from rendered views, "
          "see the semantics stage) and how many instances it found.", "",
          "| scene | id | group | licence | source | attribution | screening | ObjectNav goals | content sha256 |",
          "|---|---|---|---|---|---|---|---|---|"]
    for r in scene_rows:
        lic = (r["license"] or "unknown") + ("" if r["redistributable"] else " (**not redistributable**)")
        goals = f"`{r['goal_segmenter']}`, {r.get('goal_instances') or 0} instances" if r.get("goal_segmenter") else "none"
        L.append(f"| {r['name']} | {r['scene_id']} | {r['group']} | {lic} | "
                 f"{r['source_url'] or '-'} | {r['attribution'] or '-'} | {r['screening_verdict'] or '-'} | {goals} | "
                 f"`{(r['content_sha256'] or '')[:16]}` |")
    if excluded:
        L += ["", "### Scenes left out of this public release", "", "| scene | id | group | licence | reason |",
              "|---|---|---|---|---|"]
        L += [f"| {e['name']} | {e['scene_id']} | {e['group']} | {e['license'] or 'unknown'} | {e['reason']} |"
              for e in excluded]
    return L


def _closing(info: dict, rcfg) -> list[str]:
    """Limitations, how to reproduce, citation and licence."""
    L: list[str] = []
    code = info["code"]
    L += ["", "## Known limitations", "",
          "- Geometry is what the 3DGS shows: free space is derived from the Gaussians' opacity, so glass, mirrors "
          "and thin structures the capture missed are free, and floaters the screening did not catch are obstacles.",
          "- ObjectNav goals come from lifted open-vocabulary masks or a scene's shipped labels; a scene without "
          "either has no ObjectNav episodes.",
          "- The expert is a kinematic unicycle at the embodiment's limits, not a dynamic model of a robot.",
          "- Geodesic distances are exact to about 0.5 % (any-angle grid paths pulled taut).", "",
          "## Reproducing", "",
          f"Code {code.get('package')} at commit `{code.get('commit')}`" + (" (with uncommitted changes)" if code.get("dirty") else "")
          + f"; resolved config sha256 `{info['config_sha256'][:16]}` (in `release.json`, with each stage's hash, "
          "the catalog and the seeds).", ""]
    L += ["## Citation", "", "```bibtex", citation(info, rcfg), "```", ""]
    L += ["## Licence", "", f"The code that made it: {PROJECT_LICENSE} (`LICENSE`). Each scene and what is derived from "
          "it keeps the scene's licence (table above, `scenes.parquet`); credit the attribution it names.", ""]
    return L
