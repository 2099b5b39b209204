"""The robot: footprint, body height band, camera and kinematic limits.

The schema's defaults are LoCoBot's (navcore/conf/embodiment/locobot.yaml names it and nothing else);
the other files of navcore/conf/embodiment/ override what differs.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from importlib import resources

EMBODIMENT_DIR = resources.files("navcore.conf") / "embodiment"
"""The embodiment files: package data of navcore, and the pipeline's Hydra config group `embodiment`
(conf/config.yaml searches pkg://navcore.conf)."""


@dataclass
class Embodiment:
    """A robot body: footprint and body band (costmap), camera (rendering), kinematic limits."""

    name: str = "locobot"
    """Name used in output paths."""
    radius: float = 0.18
    """Footprint radius, metres."""
    h_min: float = 0.05
    """Lowest point of the body above the floor that collides, metres (lower things are stepped over)."""
    h_max: float = 0.9
    """Highest point of the body, metres."""
    camera_height: float = 0.88
    """Camera height above the floor, metres."""
    camera_pitch_deg: float = 0.0
    """Camera pitch, degrees (negative looks down)."""
    hfov_deg: float = 90.0
    """Horizontal field of view, degrees."""
    image_width: int = 640
    """Camera image width, pixels."""
    image_height: int = 480
    """Camera image height, pixels."""
    max_linear_velocity: float = 0.45
    """m/s."""
    max_angular_velocity: float = 0.8
    """rad/s."""
    max_linear_acceleration: float = 0.25
    """m/s^2."""
    max_angular_acceleration: float = 0.6
    """rad/s^2."""



@dataclass
class Limits:
    """Kinematic limits of an embodiment (m/s, rad/s, m/s^2, rad/s^2)."""

    v_max: float
    w_max: float
    a_max: float
    alpha_max: float

    @classmethod
    def of(cls, emb) -> "Limits":
        return cls(emb.max_linear_velocity, emb.max_angular_velocity, emb.max_linear_acceleration,
                   emb.max_angular_acceleration)


def embodiment_names() -> list[str]:
    """The names of the embodiments navcore ships (navcore/conf/embodiment/*.yaml)."""
    return sorted(p.name[:-5] for p in EMBODIMENT_DIR.iterdir() if p.name.endswith(".yaml"))


def load_embodiment(name: str) -> Embodiment:
    """An embodiment from navcore/conf/embodiment/{name}.yaml (for costmap.embodiments): the schema's
    defaults with the file's keys over them, each of the field's type."""
    import yaml

    path = EMBODIMENT_DIR / f"{name}.yaml"
    if name not in embodiment_names():
        raise ValueError(f"unknown embodiment {name!r}; known: {', '.join(embodiment_names())}")
    spec = yaml.safe_load(path.read_text()) or {}
    types = {f.name: type(f.default) for f in fields(Embodiment)}
    unknown = sorted(set(spec) - set(types))
    if unknown:
        raise ValueError(f"embodiment file {path}: unknown key(s) {', '.join(unknown)}; known: {', '.join(types)}")
    try:
        return Embodiment(**{k: types[k](v) for k, v in spec.items()})
    except (TypeError, ValueError) as e:
        raise ValueError(f"embodiment file {path}: {e}") from None
