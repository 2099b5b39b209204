"""The server side: our in-process agents behind the protocol, single and batch flows.

Every problem becomes an error frame {error, fatal} carrying the seq of the frame that caused it,
and the connection goes on (as navarena-server's serve): an undecodable frame (seq -1), an
observation before episode_start or for a slot that was never started, an agent that raises
(fatal: that episode is over). Frames above `max_frame_bytes` close the connection (1009).
"""
from __future__ import annotations

from navcore.eval.env import brief
from navcore.eval.protocol.codec import ProtocolError, action_payload, decode_value, pack, unpack
from navcore.nav.actions import ActionSpace


class Session:
    """One connection's agents (slot 0 in the single flow, one per slot in the batch flow)."""

    def __init__(self, agent_factory, space: str, actions: ActionSpace):
        self.factory, self.space, self.actions = agent_factory, space, actions
        self.agents: dict = {}

    def payload(self, action) -> dict:
        return action_payload(action, self.space, self.actions.forward_step, self.actions.turn)

    def respond(self, data) -> bytes | None:
        """One received frame (bytes) -> the packed reply, or None. Never raises: every problem
        becomes an error frame with the seq of the frame that caused it (-1: unreadable)."""
        kind, seq = "", -1
        try:
            frame = unpack(data)
            kind, seq = frame["type"], frame["seq"]
            reply = self.handle(kind, decode_value(frame["payload"]), seq)
        except Exception as e:  # noqa: BLE001 - the connection and the server go on
            reply = "error", {"error": f"{type(e).__name__}: {str(e)[:400]}",
                              "fatal": kind in ("observation", "batch_observation")}
        if reply is None:
            return None
        try:
            return pack(reply[0], reply[1], seq)
        except Exception as e:  # noqa: BLE001 - an agent's reply that msgpack cannot carry
            return pack("error", {"error": f"unsendable reply: {type(e).__name__}: {str(e)[:200]}", "fatal": True}, seq)

    def handle(self, kind: str, p: dict, seq: int) -> tuple[str, dict] | None:
        """One decoded frame -> the reply (type, payload), or None."""
        if kind == "episode_start":
            self.agents = {"0": self.factory()}
            self.agents["0"].reset(_task(p))
        elif kind == "observation":
            if "0" not in self.agents:
                return "error", {"error": "observation outside an episode: send episode_start first", "fatal": False}
            try:
                return "action", self.payload(self.agents["0"].act(p))
            except Exception:
                self.agents.pop("0", None)  # the episode is over (their server does the same)
                raise
        elif kind == "episode_end":
            self.agents.pop("0", None)
        elif kind == "batch_episode_start":
            for slot, ep in _map(p, "episodes").items():
                self.agents[str(slot)] = self.factory()
                self.agents[str(slot)].reset(_task(ep))
        elif kind == "batch_observation":
            obs = _map(p, "observations")
            missing = [s for s in obs if str(s) not in self.agents]
            if missing:
                return "error", {"error": f"batch_observation for slots never started: {brief(missing)}", "fatal": False}
            return "batch_action", {"actions": {s: self.payload(self.agents[str(s)].act(o)) for s, o in obs.items()}}
        elif kind == "batch_episode_end":
            for slot in _map(p, "episodes"):
                self.agents.pop(str(slot), None)
        else:
            return "error", {"error": f"a server does not accept {kind} frames", "fatal": False}
        return None


def _map(p: dict, key: str) -> dict:
    v = p.get(key, {})
    if not isinstance(v, dict):
        raise ProtocolError(f"{key} must be a map")
    return v


def _task(p) -> dict:
    t = p.get("task", p) if isinstance(p, dict) else {}
    return t if isinstance(t, dict) else {}


def serve_agent(agent_factory, host: str = "127.0.0.1", port: int = 8000, ready=None, action_space: str = "native",
                actions: ActionSpace | None = None, max_frame_bytes: int = 256 << 20) -> None:
    """Serve in-process agents over the protocol (one session per connection), single and batch
    flows. `ready` (optional callable) is called with the bound port once listening.
    `action_space`: native (action_id / stop), waypoint or velocity (navarena-server's forms, which
    their bench reads; discrete moves of `actions` become one relative pose or a 1 s command)."""
    from websockets.sync.server import serve

    action_payload(0, action_space)  # reject an unknown space before listening
    actions = actions or ActionSpace()

    def handler(ws):
        session = Session(agent_factory, action_space, actions)
        for data in ws:
            reply = session.respond(data)
            if reply is not None:
                ws.send(reply)

    with serve(handler, host, port, max_size=max_frame_bytes, compression=None, ping_interval=None) as server:
        if ready:
            ready(server.socket.getsockname()[1])
        server.serve_forever()
