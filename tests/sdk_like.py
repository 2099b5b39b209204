"""A stand-in for the navarena-server SDK, written here from its documented protocol (their code is
not copied): an asyncio WebSocket server with their connection rules and their example agents'
action forms, and their client's side (keepalive off, msgpack default hooks for arrays, PNG images).

Behaviours of their serve(): one session per connection; episode_start -> on_episode_start (on an
exception: one error frame with the episode_start's seq, and the episode is not started, so the next
observation gets a second error frame); observation outside an episode -> error frame; predict
raising -> a fatal error frame and the episode ends; batch frames per slot; an undecodable frame
ends the connection; ping_interval None; compression None; max_size None.
"""
from __future__ import annotations

import asyncio
import io
import random
import threading
import time

import msgpack
import numpy as np

# ---- their wire encodings ----------------------------------------------------------------------


def _default(obj):
    if isinstance(obj, np.ndarray):
        if obj.ndim == 3 and obj.shape[2] in (1, 3, 4) and obj.dtype == np.uint8:
            from PIL import Image

            buf = io.BytesIO()
            Image.fromarray(obj[..., 0] if obj.shape[2] == 1 else obj).save(buf, format="PNG")
            return {"__image__": True, "data": buf.getvalue(), "format": "png", "shape": list(obj.shape)}
        return {"__ndarray__": True, "data": obj.tobytes(), "dtype": obj.dtype.str, "shape": list(obj.shape)}
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def _hook(obj):
    if isinstance(obj, dict) and obj.get("__ndarray__"):
        return np.frombuffer(obj["data"], np.dtype(obj["dtype"])).reshape(obj["shape"]).copy()
    if isinstance(obj, dict) and obj.get("__image__"):
        from PIL import Image

        a = np.array(Image.open(io.BytesIO(obj["data"])), np.uint8)
        return a[:, :, None] if a.ndim == 2 else a
    return obj


def pack(kind: str, payload: dict, seq: int) -> bytes:
    return msgpack.packb({"type": kind, "payload": payload, "seq": seq, "timestamp": time.time()},
                         default=_default, use_bin_type=True)


def unpack(data: bytes) -> dict:
    raw = msgpack.unpackb(data, object_hook=_hook, raw=False)
    if not isinstance(raw, dict) or not {"type", "payload", "seq", "timestamp"} <= set(raw):
        raise ValueError("not a frame")
    return raw


# ---- their example agents' action forms --------------------------------------------------------
AGENTS = {
    # examples/random_agent.py: a flat waypoint, no list
    "random": lambda obs, step: {"x": random.uniform(-0.3, 0.5), "y": random.uniform(-0.1, 0.1),
                                 "yaw": random.uniform(-0.2, 0.2)},
    "random_waypoint": lambda obs, step: {"waypoints": [{"x": random.uniform(-0.3, 0.5), "y": random.uniform(-0.1, 0.1),
                                                         "yaw": random.uniform(-0.2, 0.2)}]},
    "random_velocity": lambda obs, step: {"v": random.uniform(-0.5, 1.0), "w": random.uniform(-1.0, 1.0), "dt": 0.1},
    "objectnav_waypoint": lambda obs, step: {"waypoints": [{"x": random.uniform(-0.3, 0.5), "y": random.uniform(-0.1, 0.1),
                                                            "yaw": random.uniform(-0.2, 0.2)}]},
    "imagenav_velocity": lambda obs, step: {"v": random.uniform(0.0, 1.0), "w": random.uniform(-1.0, 1.0), "dt": 0.1},
}


class SdkLikeServer:
    """Their serve() in a thread. agent: a key of AGENTS. quirk: None, "raise_on_start" (every
    second episode's on_episode_start raises), "duplicate" (every reply sent twice), "slow" (predict
    blocks the event loop `delay` s, like a model busy on the GPU), "nan" (a NaN waypoint)."""

    def __init__(self, agent: str = "random", quirk: str | None = None, delay: float = 0.0, seed: int = 0):
        self.agent, self.quirk, self.delay = AGENTS[agent], quirk, delay
        self.rng = random.Random(seed)
        self.episodes_started = 0
        self.log: list[str] = []
        self.loop = asyncio.new_event_loop()
        ready = threading.Event()
        threading.Thread(target=self._run, args=(ready,), daemon=True).start()
        ready.wait(10)
        self.url = f"ws://127.0.0.1:{self.port}"

    def _run(self, ready):
        import websockets

        asyncio.set_event_loop(self.loop)

        async def main():
            self.server = await websockets.serve(self._handle, "127.0.0.1", 0, compression=None, max_size=None,
                                                 ping_interval=None)
            self.port = self.server.sockets[0].getsockname()[1]
            ready.set()
            await self.server.serve_forever()

        try:
            self.loop.run_until_complete(main())
        except BaseException:  # noqa: BLE001 - stopped
            pass

    def _predict(self, obs, step):
        random.seed(self.rng.random())
        a = self.agent(obs, step)
        if self.quirk == "nan":
            a = {"waypoints": [{"x": float("nan"), "y": 0.0, "yaw": 0.0}]}
        if self.quirk == "slow":
            time.sleep(self.delay)  # blocks the loop: no pong either
        return a

    async def _handle(self, ws):
        in_episode, batch, step = False, {}, 0
        try:
            async for data in ws:
                msg = unpack(data)  # undecodable: the handler ends (their serve logs and drops)
                kind, p, seq = msg["type"], msg["payload"], msg["seq"]
                self.log.append(kind)
                if kind == "episode_start":
                    self.episodes_started += 1
                    if self.quirk == "raise_on_start" and self.episodes_started % 2 == 0:
                        await ws.send(pack("error", {"error": "on_episode_start failed"}, seq))
                        continue
                    in_episode, step = True, 0
                elif kind == "observation":
                    if not in_episode:
                        await ws.send(pack("error", {"error": "Received OBSERVATION outside of an active episode."}, seq))
                        continue
                    reply = pack("action", self._predict(p, step), seq)
                    await ws.send(reply)
                    if self.quirk == "duplicate":
                        await ws.send(reply)
                    step += 1
                elif kind == "episode_end":
                    self.log.append(f"end:{p.get('end_reason', '?')}")
                    in_episode = False
                elif kind == "batch_episode_start":
                    for slot in p.get("episodes", {}):
                        batch[slot] = 0
                elif kind == "batch_observation":
                    if not batch:
                        await ws.send(pack("error", {"error": "no active batch"}, seq))
                        continue
                    acts = {slot: self._predict(o, batch.get(slot, 0)) for slot, o in p.get("observations", {}).items()}
                    await ws.send(pack("batch_action", {"actions": acts}, seq))
                elif kind == "batch_episode_end":
                    for slot, r in p.get("episodes", {}).items():
                        self.log.append(f"end:{r.get('end_reason', '?')}")
                        batch.pop(slot, None)
        except Exception:  # noqa: BLE001 - their serve logs and closes the session
            pass

    def stop(self):
        async def shutdown():
            self.server.close()
            await self.server.wait_closed()

        asyncio.run_coroutine_threadsafe(shutdown(), self.loop).result(10)

    def wait_log(self, prefix: str, n: int, timeout: float = 5.0) -> list[str]:
        """The log entries starting with `prefix`, once there are n of them (or the time-out)."""
        t0 = time.monotonic()
        while sum(x.startswith(prefix) for x in self.log) < n and time.monotonic() - t0 < timeout:
            time.sleep(0.02)
        return [x for x in self.log if x.startswith(prefix)]


class SdkLikeClient:
    """Their Connection's rules, synchronously: keepalive off, max_size None, strict seq, error
    frames raise. Sends their episode_start {task}, observations, episode_end."""

    def __init__(self, url: str, timeout: float = 10.0):
        from websockets.sync.client import connect

        self.ws = connect(url, compression=None, max_size=None, ping_interval=None, open_timeout=timeout).__enter__()
        self.timeout, self.seq = timeout, 0

    def send(self, kind: str, payload) -> int:
        self.seq += 1
        self.ws.send(pack(kind, payload, self.seq))
        return self.seq

    def request(self, kind: str, payload, reply: str) -> dict:
        seq = self.send(kind, payload)
        msg = unpack(self.ws.recv(timeout=self.timeout))
        if msg["type"] == "error":
            raise RuntimeError(f"Server error: {msg['payload']}")
        if msg["type"] != reply or msg["seq"] != seq:
            raise RuntimeError(f"Expected {reply} for {seq}, got {msg['type']} {msg['seq']}")
        return msg["payload"]

    def close(self):
        self.ws.close()
