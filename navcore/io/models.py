"""Pretrained detectors that ship with the project (navcore/models/, provenance beside each), read
with their published sha256 checked, and other models of the same kinds from a user's folder.

A detector is named three ways (semantics.detector.model): null (the default shipped model,
DEFAULT_MODEL), the name of a shipped folder (SHIPPED), or a path: a Darknet folder (*.cfg,
*.weights, *.names), an ONNX file (class names in <name>.names or classes.txt beside it), or a folder
holding one. How to feed and decode a model is its `ModelSpec`: a shipped model's is written here,
a user's ONNX file is recognised by its sha256 when it is one of the known releases (KNOWN_ONNX), and a
<name>.json beside it (family, input_size, ...) says it for any other.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, replace
from importlib import resources
from pathlib import Path

from navcore.io.release import sha256_file

MODELS_ROOT = Path(str(resources.files("navcore") / "models"))


@dataclass(frozen=True)
class ModelSpec:
    """How a detector is fed and decoded.

    family: yolo (rows of cx, cy, w, h normalised, objectness, class scores: a Darknet net or a YOLO
    export with its decode inside) | gfl (per-stride class scores after the sigmoid and box side
    distributions, generalized focal loss: NanoDet, PP-PicoDet) | yolox (YOLOX exported with
    decode_in_inference=False: grid offsets and log sizes per stride, objectness and class scores
    after the sigmoid)."""

    family: str = "yolo"
    input_size: int | None = None
    """Network input side, pixels (None: semantics.detector.input_size)."""
    channels: str = "rgb"
    """rgb | bgr: the channel order the network was trained on."""
    scale: float = 1 / 255
    """Pixel values are multiplied by this, then normalised by mean and std (per channel)."""
    mean: tuple[float, float, float] = (0.0, 0.0, 0.0)
    std: tuple[float, float, float] = (1.0, 1.0, 1.0)
    resize: str = "stretch"
    """stretch: resized to the square input, aspect ratio lost | letterbox: aspect kept, pasted at the
    top-left of a canvas filled with `pad`."""
    interpolation: str = "linear"
    """linear | cubic (OpenCV's resize)."""
    pad: float = 114.0
    strides: tuple[int, ...] | None = None
    """The output levels' strides, finest first (None: inferred from each level's cell count)."""

    def check(self, where: str) -> "ModelSpec":
        problems = [f"family {self.family!r} (known: yolo, gfl, yolox)"] * (self.family not in ("yolo", "gfl", "yolox"))
        problems += [f"channels {self.channels!r} (rgb | bgr)"] * (self.channels not in ("rgb", "bgr"))
        problems += [f"resize {self.resize!r} (stretch | letterbox)"] * (self.resize not in ("stretch", "letterbox"))
        problems += [f"interpolation {self.interpolation!r} (linear | cubic)"] * (self.interpolation not in ("linear", "cubic"))
        if problems:
            raise ValueError(f"detector model {where}: {'; '.join(problems)}")
        return self


PICODET = ModelSpec(family="gfl", channels="rgb", scale=1 / 255, mean=(0.485, 0.456, 0.406), std=(0.229, 0.224, 0.225),
                    resize="stretch", interpolation="cubic", strides=(8, 16, 32, 64))
"""PP-PicoDet (PaddleDetection 2021.10 legacy export): RGB, ImageNet mean and std, plain cubic resize;
4 levels, strides 8-64 (the shared model README's decode)."""
YOLOX = ModelSpec(family="yolox", channels="bgr", scale=1.0, resize="letterbox", pad=114.0, strides=(8, 16, 32))
"""YOLOX >= 0.1.1: BGR 0..255, no normalisation, top-left letterbox padded with 114."""
NANODET = ModelSpec(family="gfl")
"""NanoDet as scripts/convert_detectors.py converted it: RGB / 255 like the YOLO default."""
FAMILY_PRESETS = {"yolo": ModelSpec(), "nanodet": NANODET, "gfl": NANODET, "picodet": PICODET, "yolox": YOLOX}
"""The `family` a <name>.json beside an ONNX file may name, and the preprocessing each implies (its
other keys override)."""


@dataclass(frozen=True)
class Shipped:
    """A model folder of navcore/models: its files' published sha256 (checked on every load)."""

    folder: str
    files: dict[str, str]
    network: str
    """The file the network is read from (the Darknet cfg for a Darknet model)."""
    names: str
    spec: ModelSpec
    title: str


SHIPPED = {
    "yolo_fastest_1.1_coco": Shipped(
        "yolo_fastest_1.1_coco",
        {"yolo-fastest-1.1-xl.weights": "fac5fb41786c1f38f04972a658443b189f48720d7d117f9a044100e98a35b0c5",
         "yolo-fastest-1.1-xl.cfg": "c458427acc4fbeabceff4528ef7b65b066c0308ce599460f8ba299eba63abad3",
         "coco.names": "634a1132eb33f8091d60f2c346ababe8b905ae08387037aed883953b7329af84"},
        "yolo-fastest-1.1-xl.cfg", "coco.names", ModelSpec(), "Yolo-Fastest-1.1-XL"),
    "picodet_s_320_coco": Shipped(
        "picodet_s_320_coco",
        {"picodet_s_320_coco.onnx": "d7852a1508b36bfc2739770ad52ff28bf81e219dc5c15dd7868d5ebdf007b6c8",
         "classes.txt": "634a1132eb33f8091d60f2c346ababe8b905ae08387037aed883953b7329af84",
         "LICENSE": "c71d239df91726fc519c6eb72d318ec65820627232b2f796219e87dcf35d0ab4"},
        "picodet_s_320_coco.onnx", "classes.txt", replace(PICODET, input_size=320), "PP-PicoDet-S 320"),
    "yolox_nano_416_coco": Shipped(
        "yolox_nano_416_coco",
        {"yolox_nano.onnx": "d39bee73564e338080378b0ad567fbb40e818b55bbfaf971de82a0267ed16b8a",
         "classes.txt": "634a1132eb33f8091d60f2c346ababe8b905ae08387037aed883953b7329af84",
         "LICENSE": "0ec3668d3274bcf29e8a29e9576d5a2cd96fc78d3c5bec4387355a796e5d9088"},
        "yolox_nano.onnx", "classes.txt", replace(YOLOX, input_size=416), "YOLOX-Nano 416"),
}
"""The detectors in navcore/models (each folder's README.md: provenance, licence, figures)."""
DEFAULT_MODEL = "yolox_nano_416_coco"
"""The default detector's main model (semantics.detector.model: null): the default detector is the
per-category mix of shipped models that navcore/models/detector.json names (chosen by the figures of
docs/benchmarks/bench_semantics_detector.md); a null model with no per-category models is this one."""
DEFAULT_DETECTOR = MODELS_ROOT / "detector.json"
"""The default detector (semantics.detector.model and models null / empty): its models per category,
thresholds and allow-list, written by `python -m benchmarks.goals.semantics_detector --choose`."""

def default_detector() -> dict | None:
    """navcore/models/detector.json: the default detector's main model, its models per category, thresholds
    and allow-list, as the benchmark chose them (None where the file is missing)."""
    if not DEFAULT_DETECTOR.is_file():
        return None
    doc = json.loads(DEFAULT_DETECTOR.read_text())
    if not isinstance(doc.get("models"), dict) or not isinstance(doc.get("confidence"), dict) or "model" not in doc:
        raise ValueError(f"{DEFAULT_DETECTOR}: the default detector needs 'model', 'models' (category -> model), "
                         "'confidence' and 'categories'")
    return doc


def model_thresholds(model: str | None) -> dict | None:
    """The thresholds.json beside a shipped model or a user's model file (None where there is none):
    {"confidence": {category: score}, "categories": [...], ...} as the benchmark wrote it."""
    network, _, _ = resolve(model)
    path = Path(network).parent / "thresholds.json"
    if not path.is_file():
        return None
    doc = json.loads(path.read_text())
    if not isinstance(doc.get("confidence"), dict) or not isinstance(doc.get("categories"), list):
        raise ValueError(f"{path}: a detector thresholds file needs 'confidence' (category -> score) and 'categories'")
    return doc


KNOWN_ONNX = {
    "cdab77bdde16e4f76bec734c4e5791801d1739e4c7ec1995e0e110e04300d0c2": replace(PICODET, input_size=416),
    "d7852a1508b36bfc2739770ad52ff28bf81e219dc5c15dd7868d5ebdf007b6c8": replace(PICODET, input_size=320),
    "d39bee73564e338080378b0ad567fbb40e818b55bbfaf971de82a0267ed16b8a": replace(YOLOX, input_size=416),
}
"""sha256 -> spec of published ONNX releases (PicoDet-S 416 and 320, YOLOX-Nano 416), so that a
user's copy of one needs no JSON beside it."""


_DIGESTS: dict[tuple, str] = {}
"""(path, size, mtime) -> sha256: a model file is hashed once a process (the pipeline resolves the
detector for every config hash)."""


def file_digest(path: Path) -> str:
    """sha256_file, remembered while the file's size and modification time stay."""
    st = path.stat()
    key = (str(path.resolve()), st.st_size, st.st_mtime_ns)
    if key not in _DIGESTS:
        _DIGESTS[key] = sha256_file(path)
    return _DIGESTS[key]


def _shipped_files(entry: Shipped) -> Path:
    folder = MODELS_ROOT / entry.folder
    for name, digest in entry.files.items():
        p = folder / name
        if not p.is_file():
            raise FileNotFoundError(f"the shipped detector file {p} is missing (reinstall the project)")
        if file_digest(p) != digest:
            raise ValueError(f"{p}: sha256 differs from the shipped model's; the file is damaged")
    return folder


def resolve(model: str | None) -> tuple[Path, Path, ModelSpec]:
    """(network file, class names file, spec) of a model named as semantics.detector.model is."""
    name = DEFAULT_MODEL if model is None else str(model)
    if name in SHIPPED:
        entry = SHIPPED[name]
        folder = _shipped_files(entry)
        return folder / entry.network, folder / entry.names, entry.spec
    path = Path(name)
    if path.is_dir():
        onnx = sorted(path.glob("*.onnx"))
        if onnx and not sorted(path.glob("*.cfg")):
            path = onnx[0]
    if path.suffix == ".onnx":
        if not path.is_file():
            raise FileNotFoundError(f"detector model {path} does not exist")
        names = path.with_suffix(".names")
        names = names if names.is_file() else path.parent / "classes.txt"
        return path, names, onnx_spec(path)
    if not path.is_dir():
        raise FileNotFoundError(f"detector model {path} does not exist (a shipped name: {', '.join(SHIPPED)}; "
                                "a Darknet folder; or an ONNX file)")
    cfgs, namess = sorted(path.glob("*.cfg")), sorted(path.glob("*.names"))
    if not (cfgs and sorted(path.glob("*.weights")) and namess):
        raise FileNotFoundError(f"detector model {path}: needs a Darknet *.cfg, *.weights and *.names (or an *.onnx)")
    return cfgs[0], namess[0], ModelSpec()


def onnx_spec(path: Path) -> ModelSpec:
    """The spec of an ONNX detector: the <name>.json beside it, else a known release's by sha256, else
    a YOLO export's."""
    side = path.with_suffix(".json")
    if side.is_file():
        raw = json.loads(side.read_text())
        family = raw.pop("family", "yolo")
        if family not in FAMILY_PRESETS:
            raise ValueError(f"detector model {path}: {side} names family {family!r}; known: {', '.join(FAMILY_PRESETS)}")
        known = {k for k in ModelSpec.__dataclass_fields__ if k != "family"}
        extra = sorted(set(raw) - known)
        if extra:
            raise ValueError(f"detector model {path}: {side} has unknown keys {extra}; known: family, {', '.join(sorted(known))}")
        raw = {k: tuple(v) if isinstance(v, list) else v for k, v in raw.items()}
        return replace(FAMILY_PRESETS[family], **raw).check(str(side))
    if path.is_file():
        digest = file_digest(path)
        if digest in KNOWN_ONNX:
            return KNOWN_ONNX[digest]
    return ModelSpec()


def load_net(model: str | None):
    """(cv2.dnn net, class names, spec) of a model named as semantics.detector.model is (module doc);
    a shipped model's files are checked by sha256."""
    from navcore.optional import require

    cv2 = require("cv2", "the detector segmenter (OpenCV DNN)")

    network, names, spec = resolve(model)
    if network.suffix == ".onnx":
        net = cv2.dnn.readNetFromONNX(str(network))
    else:
        if not hasattr(cv2.dnn, "readNetFromDarknet"):  # OpenCV 5 removed it
            raise RuntimeError(f"detector model {network.parent}: OpenCV {cv2.__version__} ({Path(cv2.__file__).parent}) "
                               "has no Darknet reader, which OpenCV 5 removed; install OpenCV 4: "
                               "pip install 'opencv-python-headless>=4.8,<5' (offline: put its wheel in the "
                               "WHEELS folder of make setup-gpu), or use an ONNX model (the default, "
                               f"semantics.detector.model=null, is {SHIPPED[DEFAULT_MODEL].title})")
        net = cv2.dnn.readNetFromDarknet(str(network), str(sorted(network.parent.glob("*.weights"))[0]))
    if not names.is_file():
        raise FileNotFoundError(f"detector model {network}: class names file {names} is missing "
                                f"(<name>.names or classes.txt beside it)")
    return net, [n.strip() for n in names.read_text().splitlines() if n.strip()], spec
