"""Dataset label sets and the goal vocabulary they map onto.

Real datasets ship labels as class ids per Gaussian or per mesh vertex; what an id means is the
dataset's class table. `LabelSet` is one such table (names in id order, the id of the first name,
the ignore values); the built-in tables (tables/*.txt, each naming its source) are those of the
label sets SceneSplat / SceneSplat++ and the scan datasets use: nyu40, scannet20, scannet200,
scannetpp100, s3dis, mpcat40. A catalog entry picks one (`labels.classes: scannet200`) or names a
file; a SceneSplat folder may ship its own (classes.txt).

`GoalVocabulary` maps a label set's class names onto the ObjectNav goal categories (default: the
HM3D six plus table and cabinet) through a written table (`GOAL_ALIASES`, one for every label
set; a label set may add its own lines). A class that maps to no goal keeps its dataset name in
the instance table (usable as a goal by naming it in `task.categories`); structure (`STRUCTURE`)
is never a goal.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

TABLE_DIR = Path(__file__).resolve().parent / "tables"
BUILTIN = ("nyu40", "scannet20", "scannet200", "scannetpp100", "s3dis", "mpcat40")


def normalise(name: str) -> str:
    """A class name as the vocabulary compares it: lower case, single spaces, '_' and '-' as spaces."""
    return " ".join(str(name).strip().lower().replace("-", " ").replace("_", " ").split())


def as_category(name: str) -> str:
    """A class name as an instance-table category: normalised, spaces as '_' (tv monitor -> tv_monitor)."""
    return normalise(name).replace(" ", "_")


@dataclass(frozen=True)
class LabelSet:
    """A class table: id -> name.

    Attributes:
        name: the table's name (a built-in key or the file it was read from).
        names: class names in id order.
        id_offset: the id of names[0] (0 for index tables such as SceneSplat's segment.npy; 1 for
            raw NYU40 / ScanNet ids, whose 0 is "unannotated").
        ignore: ids that mean "no label" (besides every negative id and ids past the table).
        source: where the table comes from (the file's comment header).
    """

    name: str
    names: tuple[str, ...]
    id_offset: int = 0
    ignore: tuple[int, ...] = ()
    source: str = ""

    def lookup(self, class_id: int) -> str | None:
        """The class name of an id, or None for an ignored or unknown id."""
        k = int(class_id) - self.id_offset
        if class_id < 0 or class_id in self.ignore or not 0 <= k < len(self.names):
            return None
        return self.names[k]

    def with_ids(self, id_offset: int | None = None, ignore=None) -> "LabelSet":
        """The same names with the id of the first and the ignore values overridden (None: kept)."""
        if id_offset is None and ignore is None:
            return self
        return LabelSet(self.name, self.names, self.id_offset if id_offset is None else int(id_offset),
                        tuple(self.ignore if ignore is None else (int(i) for i in ignore)), self.source)


def read_table(path: str | Path, name: str | None = None) -> LabelSet:
    """A class table file: one name per line in id order ('#' lines are comments, joined into
    `source`), or 'id<TAB or space>name' lines (ids need not be contiguous; the gaps are unknown ids)."""
    path = Path(path)
    try:
        lines = path.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as e:
        raise ValueError(f"{path}: unreadable class table ({e})") from None
    comments = [ln.lstrip("#").strip() for ln in lines if ln.startswith("#")]
    rows = [ln.strip() for ln in lines if ln.strip() and not ln.startswith("#")]
    if not rows:
        raise ValueError(f"{path}: class table has no names")
    pairs = [r.split(None, 1) for r in rows]
    if all(len(p) == 2 and p[0].lstrip("-").isdigit() for p in pairs):  # "id name" lines
        ids = [int(p[0]) for p in pairs]
        lo, hi = min(ids), max(ids)
        names = [""] * (hi - lo + 1)
        for i, p in zip(ids, pairs):
            names[i - lo] = p[1].strip()
        return LabelSet(name or str(path), tuple(names), lo, tuple(i for i in range(lo, hi + 1) if not names[i - lo]),
                        " ".join(comments))
    return LabelSet(name or str(path), tuple(rows), 0, (), " ".join(comments))


def builtin(name: str) -> LabelSet:
    """A built-in class table by key (BUILTIN)."""
    if name not in BUILTIN:
        raise KeyError(f"no built-in class table {name!r}; built-in: {', '.join(BUILTIN)} (or give a path to a names file)")
    return read_table(TABLE_DIR / f"{name}.txt", name)


def resolve(spec: str, base: Path | None = None, id_offset: int | None = None, ignore=None) -> LabelSet:
    """The class table a catalog entry names: a built-in key or a path (relative to `base`), with
    optional id offset and ignore values overriding the table's."""
    p = Path(spec)
    if spec in BUILTIN:
        table = builtin(spec)
    else:
        p = p if p.is_absolute() or base is None else base / p
        if not p.is_file():
            raise FileNotFoundError(f"labels.classes={spec!r}: neither a built-in table ({', '.join(BUILTIN)}) nor a file "
                                    f"({p} does not exist)")
        table = read_table(p)
    return table.with_ids(id_offset, ignore)


# ---- the goal vocabulary ------------------------------------------------------------------------

GOAL_CATEGORIES = ("chair", "bed", "sofa", "toilet", "tv_monitor", "plant", "table", "cabinet")
"""The default ObjectNav goal categories: HM3D's six (chair, bed, plant, toilet, tv_monitor, sofa)
plus table and cabinet."""

GOAL_ALIASES = {
    # dataset class (normalised) -> goal category. Sources: HM3D / MP3D ObjectNav's mpcat40 goals
    # (chair, bed, plant, toilet, tv_monitor, sofa), ScanNet200's and ScanNet++'s fine classes,
    # NYU40's names; a name equal to a goal category maps to itself.
    "chair": "chair", "office chair": "chair", "armchair": "chair", "sofa chair": "chair", "folded chair": "chair",
    "dining chair": "chair", "swivel chair": "chair", "desk chair": "chair",
    "bed": "bed", "bunk bed": "bed", "loft bed": "bed",
    "sofa": "sofa", "couch": "sofa", "sectional": "sofa", "loveseat": "sofa",
    "toilet": "toilet",
    "tv monitor": "tv_monitor", "tv": "tv_monitor", "television": "tv_monitor", "monitor": "tv_monitor",
    "computer monitor": "tv_monitor",
    "plant": "plant", "potted plant": "plant", "flowerpot": "plant", "flower pot": "plant", "houseplant": "plant",
    "table": "table", "dining table": "table", "coffee table": "table", "end table": "table", "side table": "table",
    "desk": "table", "kitchen table": "table", "round table": "table",
    "cabinet": "cabinet", "kitchen cabinet": "cabinet", "file cabinet": "cabinet", "bathroom cabinet": "cabinet",
    "storage cabinet": "cabinet", "cupboard": "cabinet", "wardrobe": "cabinet", "chest of drawers": "cabinet",
    "toilet seat": "toilet",
}

STRUCTURE = frozenset({
    # never goals: the building itself (normalised names across the built-in tables)
    "wall", "floor", "ceiling", "door", "doorframe", "door frame", "window", "window frame", "windowsill", "beam",
    "column", "pillar", "stairs", "staircase", "railing", "stair rail", "rail", "shower wall", "closet wall",
    "shower floor", "bathroom stall", "bathroom stall door", "closet door", "shower door", "ledge", "otherstructure",
    "structure", "board panel", "void", "unlabeled",
})


def is_structure(name: str) -> bool:
    return normalise(name) in STRUCTURE


@dataclass
class GoalVocabulary:
    """Class names -> goal categories.

    Attributes:
        categories: the goal categories (instance-table names).
        aliases: extra lines of the mapping table (dataset class -> goal category), e.g. from a
            catalog entry's `labels.goal_map`; they win over GOAL_ALIASES.
    """

    categories: tuple[str, ...] = GOAL_CATEGORIES
    aliases: dict[str, str] = field(default_factory=dict)

    def __post_init__(self):
        self._extra = {normalise(k): v for k, v in self.aliases.items()}

    def goal_of(self, name: str) -> str | None:
        """The goal category of a dataset class name, or None (structure, or no mapping line)."""
        n = normalise(name)
        if n in STRUCTURE:
            return None
        goal = self._extra.get(n) or GOAL_ALIASES.get(n) or (as_category(n) if as_category(n) in self.categories else None)
        return goal if goal in self.categories else None

    def category_of(self, name: str) -> str:
        """The instance-table category of a dataset class: its goal category, else its own name."""
        return self.goal_of(name) or as_category(name)
