"""Pretrained models that ship with the project (navcore/models/, provenance beside each), read
with their published sha256 checked, and other models of the same kinds from a user's folder."""
from __future__ import annotations

from importlib import resources
from pathlib import Path

from navcore.io.release import sha256_file

MODEL_DIR = Path(str(resources.files("navcore") / "models" / "yolo_fastest_1.1_coco"))
"""The `detector` segmenter's default weights: Yolo-Fastest-1.1-XL, COCO (its README.md)."""
MODEL_FILES = {
    "yolo-fastest-1.1-xl.weights": "fac5fb41786c1f38f04972a658443b189f48720d7d117f9a044100e98a35b0c5",
    "yolo-fastest-1.1-xl.cfg": "c458427acc4fbeabceff4528ef7b65b066c0308ce599460f8ba299eba63abad3",
    "coco.names": "634a1132eb33f8091d60f2c346ababe8b905ae08387037aed883953b7329af84",
}
"""sha256 of the shipped files (as published by dog-qiuqiu/Yolo-Fastest)."""


def load_net(model: str | None):
    """(cv2.dnn net, class names) of a Darknet model folder (*.cfg, *.weights, *.names) or an ONNX
    file (with *.names beside it), or of the shipped model (None; its files checked by sha256)."""
    from navcore.optional import require

    cv2 = require("cv2", "the detector segmenter (OpenCV DNN)")

    if model is None:
        for name, digest in MODEL_FILES.items():
            p = MODEL_DIR / name
            if not p.is_file():
                raise FileNotFoundError(f"the shipped detector weights {p} are missing (reinstall the project)")
            if sha256_file(p) != digest:
                raise ValueError(f"{p}: sha256 differs from the shipped model's; the file is damaged")
        folder = MODEL_DIR
    else:
        folder = Path(model)
    if folder.suffix == ".onnx":
        names = folder.with_suffix(".names")
        if not folder.is_file():
            raise FileNotFoundError(f"detector model {folder} does not exist")
        net = cv2.dnn.readNetFromONNX(str(folder))
    else:
        cfgs, weights, namess = (sorted(folder.glob(p)) for p in ("*.cfg", "*.weights", "*.names"))
        if not (cfgs and weights and namess):
            raise FileNotFoundError(f"detector model {folder}: needs a Darknet *.cfg, *.weights and *.names (or an *.onnx)")
        names = namess[0]
        if not hasattr(cv2.dnn, "readNetFromDarknet"):  # OpenCV 5 removed it (a GPU image may bring one)
            raise RuntimeError(f"detector model {folder}: OpenCV {cv2.__version__} ({Path(cv2.__file__).parent}) "
                               "has no Darknet reader, which OpenCV 5 removed; install the one the project pins: "
                               "pip install 'opencv-python-headless>=4.8,<5' (offline: put its wheel in the "
                               "WHEELS folder of make setup-gpu), or give semantics.detector.model an ONNX model")
        net = cv2.dnn.readNetFromDarknet(str(cfgs[0]), str(weights[0]))
    if not names.is_file():
        raise FileNotFoundError(f"detector model {folder}: class names file {names} is missing")
    return net, [n.strip() for n in names.read_text().splitlines() if n.strip()]


def model_spec(model: str | None) -> dict:
    """How to run a detector model: {"family": "yolo" | "nanodet", "input_size": int | None}. A
    Darknet folder or the shipped model is a YOLO; an ONNX file says what it is in a JSON beside it
    (<name>.json, written by scripts/convert_detectors.py), else it is taken for a YOLO export."""
    import json

    if model is None or Path(model).suffix != ".onnx":
        return {"family": "yolo", "input_size": None}
    side = Path(model).with_suffix(".json")
    spec = json.loads(side.read_text()) if side.is_file() else {}
    family = spec.get("family", "yolo")
    if family not in ("yolo", "nanodet"):
        raise ValueError(f"detector model {model}: {side} names family {family!r}; known: yolo, nanodet")
    return {"family": family, "input_size": spec.get("input_size")}
