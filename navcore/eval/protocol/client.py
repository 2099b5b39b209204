"""The evaluator's side of the protocol: an agent served over WebSocket used like an in-process
agent (single-slot and batch flows).

Robustness (every case tested in tests/test_protocol.py): no keepalive ping by default (their SDK
sets ping_interval=None too, so a server busy 50 s inside a 90 s time-out is not cut off); frames
larger than `max_frame_bytes` close the connection; a reply is the frame whose seq answers ours:
stale frames of this connection (a duplicate reply, a late one) are skipped, at most `stale_limit`
of them within the time-out; an error frame of the current episode fails it. After any failure the
connection is dropped, so the next episode starts on a fresh one and never reads a stray frame of
the last (their server sends two error frames when on_episode_start raises).
"""
from __future__ import annotations

import time

from navcore.eval.protocol.codec import (
    ProtocolError,
    decode_value,
    encode_observation,
    error_message,
    pack,
    parse_action,
    unpack,
)

REPLY_MAX_PIXELS = 1 << 20
"""An image inside an action reply (which needs none) decodes only up to this size."""


def is_reply(frame: dict, seq: int, kind: str, episode_seq: int) -> bool:
    """Whether a checked frame is the reply (of type `kind`) to our request `seq` (True), a stale
    frame to skip (False: an earlier request's late or duplicate reply, an error frame of an
    earlier episode), or breaks the protocol (ProtocolError: an error frame of the running episode,
    a fatal one, a reply to a request not yet sent, a wrong type for our request)."""
    if frame["type"] == "error":
        if frame["seq"] >= episode_seq or frame["payload"].get("fatal"):
            raise ProtocolError(error_message(frame))
        return False
    if frame["seq"] == seq:
        if frame["type"] != kind:
            raise ProtocolError(f"expected a {kind} frame, got {frame['type']!r}")
        return True
    if frame["seq"] > seq:
        raise ProtocolError(f"{frame['type']} answers observation {frame['seq']}, not {seq}")
    return False


class RemoteAgent:
    """An agent served over WebSocket (single-slot flow), used like an in-process agent.

    Args:
        url: ws://host:port. timeout: seconds to wait for each reply. retries: connection attempts
            (back-off 2^n s). image_format: how rgb is sent (jpeg, png, raw). keepalive: seconds
            between WebSocket pings (None: none, as their SDK). max_frame_bytes: largest reply
            accepted. stale_limit: stale frames skipped before a reply counts as lost.
    """

    def __init__(self, url: str, timeout: float = 30.0, retries: int = 5, image_format: str = "jpeg",
                 keepalive: float | None = None, max_frame_bytes: int = 1 << 20, stale_limit: int = 16):
        self.url, self.timeout, self.retries, self.image_format = url, timeout, retries, image_format
        self.keepalive, self.max_frame_bytes, self.stale_limit = keepalive, max_frame_bytes, stale_limit
        self.ws = None
        self.seq = 0
        self.episode_seq = 0  # seq of the frame that started the running episode(s)
        self.stale_frames = 0

    def _connect(self):
        from websockets.sync.client import connect

        err = None
        for n in range(self.retries):
            try:
                ws = connect(self.url, open_timeout=self.timeout, max_size=self.max_frame_bytes, compression=None,
                             ping_interval=self.keepalive, ping_timeout=self.keepalive)
                # entered as its context (websockets >= 17.1 deprecates a bare connect); close() ends it
                return ws.__enter__()
            except OSError as e:  # refused, unreachable
                err = e
                time.sleep(min(2 ** n, 16) if n < self.retries - 1 else 0)
        raise ConnectionError(f"agent server {self.url} unreachable after {self.retries} attempts: {err}")

    def _send(self, kind: str, payload: dict) -> int:
        if self.ws is None:
            self.ws = self._connect()
        self.seq += 1
        try:
            self.ws.send(pack(kind, payload, self.seq))
        except Exception:
            self.close()
            raise
        return self.seq

    def _reply(self, seq: int, kind: str) -> dict:
        """The frame answering `seq` (of type `kind`), skipping stale frames; any failure drops the
        connection."""
        try:
            deadline = time.monotonic() + self.timeout
            for _ in range(self.stale_limit + 1):
                left = deadline - time.monotonic()
                if left <= 0:
                    break
                try:
                    frame = unpack(self.ws.recv(timeout=left))
                except TimeoutError:
                    break
                if is_reply(frame, seq, kind, self.episode_seq):
                    return frame
                self.stale_frames += 1  # a duplicate or late reply of an earlier request
            else:
                raise ProtocolError(f"more than {self.stale_limit} stale frames before the reply to {seq}")
            raise TimeoutError(f"agent server sent no reply within {self.timeout} s")
        except Exception:
            self.close()  # the next episode starts on a fresh connection
            raise

    def reset(self, task: dict) -> None:
        self.episode_seq = self._send("episode_start", {"task": task})

    def act(self, obs: dict):
        seq = self._send("observation", encode_observation(obs, self.image_format))
        return parse_action(decode_value(self._reply(seq, "action")["payload"], max_pixels=REPLY_MAX_PIXELS))

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
            except Exception:  # noqa: BLE001 - closing a broken connection
                pass
            finally:
                self.ws = None


class RemoteBatchAgent(RemoteAgent):
    """The batch flow of the protocol (slots keyed by string), for run_episodes_batched."""

    def start(self, tasks: dict) -> None:
        fresh = self.ws is None
        seq = self._send("batch_episode_start", {"episodes": {str(k): {"task": t} for k, t in tasks.items()}})
        if fresh:  # every error frame of this connection belongs to its running episodes
            self.episode_seq = seq

    def act(self, observations: dict) -> dict:
        seq = self._send("batch_observation", {"observations": {str(k): encode_observation(o, self.image_format)
                                                                for k, o in observations.items()}})
        payload = decode_value(self._reply(seq, "batch_action")["payload"], max_pixels=REPLY_MAX_PIXELS)
        acts = payload.get("actions", {}) if isinstance(payload, dict) else None
        if not isinstance(acts, dict):
            raise ProtocolError("batch_action payload has no actions map")
        out = {}
        for k, v in acts.items():
            try:
                out[int(k)] = parse_action(v)
            except (TypeError, ValueError) as e:
                raise ProtocolError(f"batch_action for unknown slot {str(k)[:20]!r}") from e
        return out

    def end(self, results: dict) -> None:
        self._send("batch_episode_end", {"episodes": {str(k): r for k, r in results.items()}})
