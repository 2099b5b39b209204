"""The server side: our in-process agents behind the protocol, single and batch flows."""
from __future__ import annotations

from stages.evaluate.protocol.codec import ProtocolError, action_payload, decode_value, pack, unpack


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
