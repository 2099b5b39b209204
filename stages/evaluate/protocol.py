"""The NavArena agent-server protocol: policies served over WebSocket, the evaluator a client.

Frames: one msgpack map each, {type, payload, seq, timestamp}, all four required (payload a map,
seq an int). Types: episode_start, observation, action, episode_end, error, and their batch_
variants. Single slot: episode_start {task} -> (observation -> action carrying the observation's
seq)* -> episode_end {success, ...}. Batch: batch_episode_start {episodes: {slot: {task}}},
batch_observation {observations: {slot: obs}} -> batch_action {actions: {slot: action}},
batch_episode_end {episodes: {slot: result}}. Server errors: type error, payload {error, fatal?}.

Encodings: arrays {"__ndarray__": true, data: bytes, dtype: numpy dtype string (kinds b, i, u, f),
shape}; HxWx{1,3,4} uint8 images {"__image__": true, data, format: jpeg | png | raw, shape
(, dtype for raw)}.

Actions a server may send: {"waypoints": [{"x", "y", "yaw"}, ...]} (ROS robot frame: x forward,
y left, yaw counter-clockwise), {"v", "w", "dt"}, {"action_id": 0..3} (0 stop, 1 forward,
2 left, 3 right), and STOP as {"stop": true} (our choice; their docs leave it open).

Client behaviour (as theirs): 30 s timeout per reply, 5 connection attempts with 2^n s back-off,
no compression, no reconnection inside an episode: a time-out, a closed connection, an error frame
or a malformed frame fails the episode (the evaluator records why and goes on).
"""
from __future__ import annotations

import io
import time

import msgpack
import numpy as np

FRAME_TYPES = {"observation", "action", "episode_start", "episode_end", "error", "batch_observation",
               "batch_action", "batch_episode_start", "batch_episode_end"}


class ProtocolError(RuntimeError):
    """A frame that breaks the protocol, or a server error frame."""


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


def decode_value(v):
    """Undo encode_array / encode_image anywhere in a nested payload."""
    if isinstance(v, dict):
        if v.get("__ndarray__"):
            return np.frombuffer(v["data"], dtype=np.dtype(v["dtype"])).reshape(v["shape"]).copy()
        if v.get("__image__"):
            shape = tuple(v["shape"])
            if v["format"] == "raw":
                return np.frombuffer(v["data"], dtype=np.dtype(v.get("dtype", "|u1"))).reshape(shape).copy()
            from PIL import Image

            img = np.asarray(Image.open(io.BytesIO(v["data"])))
            return img.reshape(shape)
        return {k: decode_value(x) for k, x in v.items()}
    if isinstance(v, list):
        return [decode_value(x) for x in v]
    return v


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


def unpack(data) -> dict:
    """A frame, checked: msgpack map with type, payload (map), seq (int) and timestamp."""
    try:
        frame = msgpack.unpackb(data, raw=False)
    except Exception as e:  # noqa: BLE001
        raise ProtocolError(f"not a msgpack frame: {type(e).__name__}: {e}") from e
    if not isinstance(frame, dict) or not {"type", "payload", "seq", "timestamp"} <= set(frame):
        raise ProtocolError(f"a frame must be a map with type, payload, seq and timestamp, got {str(frame)[:120]}")
    if frame["type"] not in FRAME_TYPES or not isinstance(frame["payload"], dict) or \
            not isinstance(frame["seq"], int):
        raise ProtocolError(f"malformed frame: type {frame.get('type')!r}, seq {frame.get('seq')!r}")
    if frame["type"] == "error":
        raise ProtocolError(f"server error: {frame['payload'].get('error')}"
                            + (" (fatal)" if frame["payload"].get("fatal") else ""))
    return frame


def parse_action(payload: dict):
    """An action frame's payload -> an environment action."""
    if payload.get("stop"):
        return {"stop": True}
    if "waypoints" in payload:
        return {"waypoints": list(payload["waypoints"])}
    if "v" in payload:
        return {"v": payload["v"], "w": payload.get("w", 0.0), "dt": payload.get("dt", 0.05)}
    if "action_id" in payload:
        return int(payload["action_id"])
    raise ProtocolError(f"action payload has none of stop, waypoints, v/w/dt, action_id: {str(payload)[:120]}")


def action_payload(action) -> dict:
    """An environment action -> an action frame's payload (server side)."""
    if isinstance(action, dict):
        return action
    a = int(action)
    return {"stop": True} if a == 0 else {"action_id": a}


# ---- evaluator side -----------------------------------------------------------------------------
class RemoteAgent:
    """An agent served over WebSocket (single-slot flow), used like an in-process agent.

    Args:
        url: ws://host:port. timeout: seconds to wait for each reply. retries: connection attempts
            (back-off 2^n s). image_format: how rgb is sent (jpeg, png, raw).
    """

    def __init__(self, url: str, timeout: float = 30.0, retries: int = 5, image_format: str = "jpeg"):
        self.url, self.timeout, self.retries, self.image_format = url, timeout, retries, image_format
        self.ws = None
        self.seq = 0

    def _connect(self):
        from websockets.sync.client import connect

        err = None
        for n in range(self.retries):
            try:
                return connect(self.url, open_timeout=self.timeout, max_size=None, compression=None)
            except OSError as e:  # refused, unreachable
                err = e
                time.sleep(min(2 ** n, 16) if n < self.retries - 1 else 0)
        raise ConnectionError(f"agent server {self.url} unreachable after {self.retries} attempts: {err}")

    def _send(self, kind: str, payload: dict) -> int:
        if self.ws is None:
            self.ws = self._connect()
        self.seq += 1
        self.ws.send(pack(kind, payload, self.seq))
        return self.seq

    def _recv(self) -> dict:
        try:
            data = self.ws.recv(timeout=self.timeout)
        except TimeoutError as e:
            self.close()  # a late reply must not be read as the next episode's
            raise TimeoutError(f"agent server sent nothing within {self.timeout} s") from e
        except Exception:
            self.close()
            raise
        return unpack(data)

    def reset(self, task: dict) -> None:
        self._send("episode_start", {"task": task})

    def act(self, obs: dict):
        seq = self._send("observation", encode_observation(obs, self.image_format))
        frame = self._recv()
        if frame["type"] != "action":
            raise ProtocolError(f"expected an action frame, got {frame['type']!r}")
        if frame["seq"] != seq:
            raise ProtocolError(f"action answers observation {frame['seq']}, not {seq}")
        return parse_action(decode_value(frame["payload"]))

    def end(self, result: dict) -> None:
        if self.ws is not None:
            try:
                self._send("episode_end", result)
            except Exception:  # noqa: BLE001 - the episode is over either way
                self.close()

    def close(self) -> None:
        if self.ws is not None:
            try:
                self.ws.close()
            finally:
                self.ws = None


class RemoteBatchAgent(RemoteAgent):
    """The batch flow of the protocol (slots keyed by string), for run_episodes_batched."""

    def start(self, tasks: dict) -> None:
        self._send("batch_episode_start", {"episodes": {str(k): {"task": t} for k, t in tasks.items()}})

    def act(self, observations: dict) -> dict:
        seq = self._send("batch_observation", {"observations": {str(k): encode_observation(o, self.image_format)
                                                                for k, o in observations.items()}})
        frame = self._recv()
        if frame["type"] != "batch_action":
            raise ProtocolError(f"expected a batch_action frame, got {frame['type']!r}")
        if frame["seq"] != seq:
            raise ProtocolError(f"batch_action answers observation {frame['seq']}, not {seq}")
        acts = decode_value(frame["payload"]).get("actions", {})
        return {int(k): parse_action(v) for k, v in acts.items()}

    def end(self, results: dict) -> None:
        self._send("batch_episode_end", {"episodes": {str(k): r for k, r in results.items()}})


# ---- server side --------------------------------------------------------------------------------
def serve_agent(agent_factory, host: str = "127.0.0.1", port: int = 8000, ready=None) -> None:
    """Serve in-process agents over the protocol (one agent per connection), single and batch flows.
    `ready` (optional callable) is called with the bound port once listening."""
    from websockets.sync.server import serve

    def handler(ws):
        agents: dict = {}
        for data in ws:
            try:
                frame = unpack(data)
            except ProtocolError as e:
                ws.send(pack("error", {"error": str(e), "fatal": False}, -1))
                continue
            kind, p, seq = frame["type"], decode_value(frame["payload"]), frame["seq"]
            if kind == "episode_start":
                agents[0] = agent_factory()
                agents[0].reset(p.get("task", {}))
            elif kind == "observation":
                ws.send(pack("action", action_payload(agents[0].act(p)), seq))
            elif kind == "batch_episode_start":
                for slot, ep in p.get("episodes", {}).items():
                    agents[slot] = agent_factory()
                    agents[slot].reset(ep.get("task", {}))
            elif kind == "batch_observation":
                acts = {slot: action_payload(agents[slot].act(o)) for slot, o in p.get("observations", {}).items()}
                ws.send(pack("batch_action", {"actions": acts}, seq))

    with serve(handler, host, port, max_size=None, compression=None) as server:
        if ready:
            ready(server.socket.getsockname()[1])
        server.serve_forever()


def main(argv=None) -> None:
    """python -m stages.evaluate.protocol --agent depth_reactive --port 8000: serve a registered agent."""
    import argparse

    from stages.evaluate.agents import make_agent

    ap = argparse.ArgumentParser(description=main.__doc__)
    ap.add_argument("--agent", default="depth_reactive")
    ap.add_argument("--host", default="127.0.0.1")
    ap.add_argument("--port", type=int, default=8000)
    ap.add_argument("--port-file", default=None, help="write the bound port here once listening (port 0 = any)")
    args = ap.parse_args(argv)

    def ready(port):
        if args.port_file:
            with open(args.port_file, "w") as f:
                f.write(str(port))
        print(f"serving agent {args.agent!r} on ws://{args.host}:{port}", flush=True)

    serve_agent(lambda: make_agent(args.agent), args.host, args.port, ready)


if __name__ == "__main__":
    main()
