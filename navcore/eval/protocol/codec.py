"""Protocol codec: frames (msgpack maps {type, payload, seq, timestamp}), arrays and images inside
payloads, and the action forms (see the package docstring)."""
from __future__ import annotations

import io
import time

import msgpack
import numpy as np

from navcore.eval.env import brief

FRAME_TYPES = {"observation", "action", "episode_start", "episode_end", "error", "batch_observation",
               "batch_action", "batch_episode_start", "batch_episode_end"}


class ProtocolError(RuntimeError):
    """A frame that breaks the protocol, or a server error frame."""


MAX_DEPTH = 32
"""Deepest nesting of maps / lists inside a payload."""
MAX_IMAGE_PIXELS = 1 << 24
"""Largest decoded image (H x W), against decompression bombs."""
MAX_NDIM = 8


# ---- values -------------------------------------------------------------------------------------
def encode_array(a: np.ndarray) -> dict:
    a = np.ascontiguousarray(a)
    if a.dtype.kind not in "biuf":
        raise ProtocolError(f"arrays of dtype kind {a.dtype.kind!r} cannot be sent (b, i, u, f only)")
    return {"__ndarray__": True, "data": a.tobytes(), "dtype": a.dtype.str, "shape": list(a.shape)}


def encode_image(img: np.ndarray, fmt: str = "jpeg", quality: int = 90) -> dict:
    """HxWx{1,3,4} uint8 -> image map (jpeg, png or raw)."""
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] not in (1, 3, 4):
        raise ProtocolError(f"images must be HxWx{{1,3,4}} uint8, got {img.dtype} {img.shape}")
    if fmt == "raw":
        return {"__image__": True, "data": img.tobytes(), "format": "raw", "shape": list(img.shape), "dtype": "|u1"}
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(img[..., 0] if img.shape[2] == 1 else img).save(
        buf, format="JPEG" if fmt == "jpeg" else "PNG", **({"quality": quality} if fmt == "jpeg" else {}))
    return {"__image__": True, "data": buf.getvalue(), "format": fmt, "shape": list(img.shape)}


def decode_value(v, _depth: int = 0, max_pixels: int = MAX_IMAGE_PIXELS):
    """Undo encode_array / encode_image anywhere in a nested payload. Hostile values (a shape that
    does not match the bytes, a dtype outside b/i/u/f, an image larger than MAX_IMAGE_PIXELS or
    unlike its declared shape, nesting deeper than MAX_DEPTH) raise ProtocolError: nothing is
    allocated beyond what the frame itself holds (a decoded image: at most its declared shape)."""
    if _depth > MAX_DEPTH:
        raise ProtocolError(f"payload nested deeper than {MAX_DEPTH}")
    if isinstance(v, dict):
        try:
            if v.get("__ndarray__"):
                return _decode_array(v)
            if v.get("__image__"):
                return _decode_image(v, max_pixels)
        except ProtocolError:
            raise
        except Exception as e:  # noqa: BLE001 - any decoder failure is the frame's fault
            raise ProtocolError(f"undecodable array / image: {type(e).__name__}: {str(e)[:200]}") from e
        return {k: decode_value(x, _depth + 1, max_pixels) for k, x in v.items()}
    if isinstance(v, list):
        return [decode_value(x, _depth + 1, max_pixels) for x in v]
    return v


def _shape(v) -> tuple[int, ...]:
    shape = v.get("shape")
    if not isinstance(shape, (list, tuple)) or len(shape) > MAX_NDIM or \
            not all(isinstance(n, int) and not isinstance(n, bool) and n >= 0 for n in shape):
        raise ProtocolError(f"bad array shape {brief(shape)}")
    return tuple(shape)


def _dtype(name) -> np.dtype:
    try:
        dt = np.dtype(name)
    except TypeError as e:
        raise ProtocolError(f"bad dtype {brief(name)}") from e
    if dt.kind not in "biuf" or dt.itemsize > 16 or dt.fields is not None or dt.subdtype is not None:
        raise ProtocolError(f"arrays of dtype {dt} are not accepted (b, i, u, f only)")
    return dt


def _from_bytes(v, dt: np.dtype, shape: tuple[int, ...]) -> np.ndarray:
    data = v.get("data")
    if not isinstance(data, (bytes, bytearray)):
        raise ProtocolError("array data must be bytes")
    if int(np.prod(shape, dtype=object)) * dt.itemsize != len(data):
        raise ProtocolError(f"array of shape {list(shape)} and dtype {dt} needs "
                            f"{int(np.prod(shape, dtype=object)) * dt.itemsize} bytes, the frame has {len(data)}")
    return np.frombuffer(data, dtype=dt).reshape(shape).copy()


def _decode_array(v) -> np.ndarray:
    return _from_bytes(v, _dtype(v.get("dtype")), _shape(v))


def _decode_image(v, max_pixels: int = MAX_IMAGE_PIXELS) -> np.ndarray:
    shape = _shape(v)
    if len(shape) != 3 or shape[2] not in (1, 3, 4) or shape[0] * shape[1] > max_pixels:
        raise ProtocolError(f"images are HxWx{{1,3,4}} of at most {max_pixels} pixels, got {list(shape)}")
    fmt = v.get("format")
    if fmt == "raw":
        return _from_bytes(v, _dtype(v.get("dtype", "|u1")), shape)
    if fmt not in ("jpeg", "png"):
        raise ProtocolError(f"unknown image format {brief(fmt)!r}")
    from PIL import Image

    img = Image.open(io.BytesIO(v["data"]))
    if (img.height, img.width) != shape[:2]:  # checked before the pixels are decoded
        raise ProtocolError(f"image of {img.width}x{img.height} declared as {list(shape)}")
    arr = np.asarray(img)
    return arr.reshape(shape)


def encode_observation(obs: dict, image_format: str = "jpeg") -> dict:
    """An environment observation as a payload: rgb as an image, other arrays as ndarrays."""
    out = {}
    for k, v in obs.items():
        if k in ("rgb", "goal_image") and isinstance(v, np.ndarray):
            out[k] = encode_image(v, image_format)
        elif isinstance(v, np.ndarray):
            out[k] = encode_array(v)
        else:
            out[k] = v
    return out


# ---- frames -------------------------------------------------------------------------------------
def pack(kind: str, payload: dict, seq: int) -> bytes:
    return msgpack.packb({"type": kind, "payload": payload, "seq": int(seq), "timestamp": time.time()},
                         use_bin_type=True)


def frame_detail(data, e: Exception) -> str:
    """What was wrong with bytes that are not msgpack: the error (msgpack's FormatError has no
    message of its own), the frame's size, its first bytes and whether it reads as text."""
    reason = str(e) or {"FormatError": "a byte no msgpack type starts with",
                        "StackError": "nested too deep"}.get(type(e).__name__, "invalid")
    if isinstance(data, str):
        return f"{type(e).__name__}: {reason}; a text frame of {len(data)} characters: {data[:40]!r}"
    raw = bytes(data) if isinstance(data, (bytes, bytearray, memoryview)) else b""
    head = raw[:16].hex(" ")
    text = ""
    try:
        t = raw[:40].decode("utf-8")
        if t.isprintable():
            text = f", as text {t!r}"
    except UnicodeDecodeError:
        pass
    return f"{type(e).__name__}: {reason}; {len(raw)} bytes starting {head or '(empty)'}{text}"


def unpack(data) -> dict:
    """A frame, checked: msgpack map with type, payload (map), seq (int) and timestamp."""
    try:
        frame = msgpack.unpackb(data, raw=False)
    except Exception as e:  # noqa: BLE001
        raise ProtocolError(f"not a msgpack frame ({frame_detail(data, e)})") from e
    if not isinstance(frame, dict) or not {"type", "payload", "seq", "timestamp"} <= set(frame):
        raise ProtocolError(f"a frame must be a map with type, payload, seq and timestamp, got {brief(frame)}")
    kind, seq = frame["type"], frame["seq"]
    if not isinstance(kind, str) or kind not in FRAME_TYPES or not isinstance(frame["payload"], dict) or \
            not isinstance(seq, int) or isinstance(seq, bool):
        raise ProtocolError(f"malformed frame: type {brief(kind)}, seq {brief(seq)}")
    return frame


def error_message(frame: dict) -> str:
    """The text of an error frame (their servers send {error}, fatal optional)."""
    p = frame["payload"]
    err = p.get("error")
    text = err[:400] if isinstance(err, str) else brief(err)
    return f"server error: {text}" + (" (fatal)" if p.get("fatal") else "")


def parse_action(payload: dict):
    """An action frame's payload -> an environment action (the environment checks the numbers).

    Forms: {"stop": true}; {"waypoints": [{x, y, yaw}, ...]}; a flat {x, y, yaw} (navarena-server's
    random agent); {"v", "w", "dt"}; {"action_id": 0..3}."""
    if not isinstance(payload, dict):
        raise ProtocolError(f"an action payload is a map, got {type(payload).__name__}")
    if payload.get("stop"):
        return {"stop": True}
    if "waypoints" in payload:
        if not isinstance(payload["waypoints"], list):
            raise ProtocolError("waypoints must be a list of {x, y, yaw} maps")
        return {"waypoints": list(payload["waypoints"])}
    if "v" in payload:
        return {"v": payload["v"], "w": payload.get("w", 0.0), "dt": payload.get("dt", 0.05)}
    if {"x", "y", "yaw"} & set(payload):
        return {"waypoints": [{k: payload[k] for k in ("x", "y", "yaw") if k in payload}]}
    if "action_id" in payload:
        a = payload["action_id"]
        if isinstance(a, bool) or not isinstance(a, int):
            raise ProtocolError(f"action_id must be an integer, got {brief(a)}")
        return a
    raise ProtocolError(f"action payload has none of stop, waypoints, x/y/yaw, v/w/dt, action_id: {brief(payload)}")


ACTION_SPACES = ("native", "waypoint", "velocity")


def action_payload(action, space: str = "native", forward_step: float = 0.25, turn: float = 0.2617993877991494,
                   dt: float = 1.0) -> dict:
    """An environment action -> an action frame's payload (server side). `space`: native (action_id,
    {"stop": true}), or navarena-server's waypoint / velocity action spaces, which their bench reads
    (discrete moves become one relative pose, or a command of `dt` seconds; STOP becomes a zero move
    flagged "stop": true, which their bench ignores and ours honours)."""
    if space not in ACTION_SPACES:
        raise ValueError(f"unknown action space {space!r}; choose one of {ACTION_SPACES}")
    if isinstance(action, dict):
        if space == "native" or action.get("stop") or ("waypoints" in action and space == "waypoint") or \
                ("v" in action and space == "velocity"):
            return _stop_form(space, dt) if action.get("stop") else action
        raise ValueError(f"cannot express {brief(action)} in the {space} action space")
    a = int(action)
    if space == "native":
        return {"stop": True} if a == 0 else {"action_id": a}
    if a == 0:
        return _stop_form(space, dt)
    x, yaw = (forward_step, 0.0) if a == 1 else (0.0, turn if a == 2 else -turn)
    if space == "waypoint":
        return {"waypoints": [{"x": x, "y": 0.0, "yaw": yaw}]}
    return {"v": x / dt, "w": yaw / dt, "dt": dt}


def _stop_form(space: str, dt: float) -> dict:
    if space == "waypoint":
        return {"waypoints": [{"x": 0.0, "y": 0.0, "yaw": 0.0}], "stop": True}
    if space == "velocity":
        return {"v": 0.0, "w": 0.0, "dt": dt, "stop": True}
    return {"stop": True}
