"""The evaluator's side of the protocol: an agent served over WebSocket used like an in-process
agent (single-slot and batch flows)."""
from __future__ import annotations

import time

from stages.evaluate.protocol.codec import ProtocolError, decode_value, encode_observation, pack, parse_action, unpack


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
