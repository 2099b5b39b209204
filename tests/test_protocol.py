"""The agent-server protocol: encodings, frame checks, a separate server process giving the same
metrics as in-process, and malformed / slow / crashing servers recorded as episode failures."""
import subprocess
import sys
import threading
import time

import msgpack
import numpy as np
import pytest

from stages.evaluate.agents import make_agent
from stages.evaluate.env import EnvConfig
from stages.evaluate.loop import run_episodes, run_episodes_batched
from stages.evaluate.protocol.client import RemoteAgent, RemoteBatchAgent
from stages.evaluate.protocol.codec import (
    ProtocolError,
    decode_value,
    encode_array,
    encode_image,
    pack,
    parse_action,
    unpack,
)


def test_encodings_round_trip():
    a = np.arange(12, dtype=np.float32).reshape(3, 4)
    assert np.array_equal(decode_value(encode_array(a)), a)
    assert decode_value(encode_array(np.array([True, False])) ).dtype == bool
    img = (np.arange(48 * 64 * 3) % 251).astype(np.uint8).reshape(48, 64, 3)
    for fmt in ("png", "raw"):
        assert np.array_equal(decode_value(encode_image(img, fmt)), img)
    smooth = np.tile(np.linspace(0, 255, 64).astype(np.uint8)[None, :, None], (48, 1, 3))
    assert np.abs(decode_value(encode_image(smooth, "jpeg")).astype(int) - smooth).max() <= 8
    with pytest.raises(ProtocolError):
        encode_array(np.array(["x"]))
    with pytest.raises(ProtocolError):
        encode_image(np.zeros((4, 4), np.float32))


def test_frames_are_checked():
    f = unpack(pack("action", {"stop": True}, 7))
    assert f["type"] == "action" and f["seq"] == 7 and parse_action(f["payload"]) == {"stop": True}
    assert parse_action({"action_id": 1}) == 1
    assert parse_action({"waypoints": [{"x": 0.1, "y": 0, "yaw": 0}]})["waypoints"][0]["x"] == 0.1
    for bad in (b"\x00garbage", msgpack.packb({"type": "action", "payload": {}}),
                msgpack.packb({"type": "teleport", "payload": {}, "seq": 1, "timestamp": 0}),
                msgpack.packb({"type": "action", "payload": [], "seq": 1, "timestamp": 0})):
        with pytest.raises(ProtocolError):
            unpack(bad)
    with pytest.raises(ProtocolError, match="server error: boom"):
        unpack(pack("error", {"error": "boom", "fatal": True}, 1))
    with pytest.raises(ProtocolError):
        parse_action({"dance": 1})


def start_server_process(tmp_path, cwd, agent="depth_reactive"):
    port_file = tmp_path / "port"
    proc = subprocess.Popen([sys.executable, "-m", "stages.evaluate.protocol", "--agent", agent, "--port", "0",
                             "--port-file", str(port_file)], cwd=cwd)
    for _ in range(300):
        if port_file.exists() and port_file.read_text():
            return proc, int(port_file.read_text())
        time.sleep(0.05)
    proc.kill()
    raise RuntimeError("agent server did not start")


def test_remote_agent_gives_the_same_metrics_as_in_process(ctx, tmp_path, make_episode, project_root):
    eps = [make_episode(start=(1.0, 0.5, a), goal=(3.0, 0.5), geodesic=2.3, max_steps=120) for a in (0.0, 1.0, -2.0)]
    for i, e in enumerate(eps):
        e.episode_id = f"e{i}"
    local = run_episodes(ctx, eps, make_agent("depth_reactive"), EnvConfig(render=False))
    proc, port = start_server_process(tmp_path, project_root)
    try:
        remote_agent = RemoteAgent(f"ws://127.0.0.1:{port}", timeout=10)
        remote = run_episodes(ctx, eps, remote_agent, EnvConfig(render=False))
        remote_agent.close()
        batch_agent = RemoteBatchAgent(f"ws://127.0.0.1:{port}", timeout=10)
        batched = run_episodes_batched(ctx, eps, batch_agent, 2, EnvConfig(render=False))
        batch_agent.close()
    finally:
        proc.kill()
    keys = ["sr", "spl", "soft_spl", "ne", "steps", "collision_rate", "end_reason"]
    for other in (remote, batched):  # single flow and batch flow (2 slots for 3 episodes)
        assert [{k: r[k] for k in keys} for r in other] == [{k: r[k] for k in keys} for r in local]
        assert all(np.array_equal(a["trajectory"], b["trajectory"]) for a, b in zip(local, other))


def bad_server(behaviour: str):
    """A misbehaving server in a thread: returns (url, stop)."""
    from websockets.sync.server import serve

    def handler(ws):
        for data in ws:
            f = msgpack.unpackb(data)
            if f["type"] != "observation":
                continue
            if behaviour == "malformed":
                ws.send(b"\x93not a frame")
            elif behaviour == "slow":
                time.sleep(1.5)
                ws.send(pack("action", {"action_id": 1}, f["seq"]))
            elif behaviour == "crash":
                ws.close()
                return
            elif behaviour == "error":
                ws.send(pack("error", {"error": "policy exploded", "fatal": True}, f["seq"]))
            elif behaviour == "wrong_seq":
                ws.send(pack("action", {"action_id": 1}, f["seq"] + 5))

    server = serve(handler, "127.0.0.1", 0)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return f"ws://127.0.0.1:{server.socket.getsockname()[1]}", server.shutdown


@pytest.mark.parametrize("behaviour,reason", [("malformed", "ProtocolError"), ("slow", "TimeoutError"),
                                              ("crash", "Connection"), ("error", "policy exploded"),
                                              ("wrong_seq", "answers observation")])
def test_misbehaving_servers_fail_their_episodes_and_the_run_goes_on(ctx, behaviour, reason, make_episode):
    url, stop = bad_server(behaviour)
    eps = [make_episode(max_steps=20), make_episode(max_steps=20)]
    try:
        rows = run_episodes(ctx, eps, RemoteAgent(url, timeout=0.5, retries=2), EnvConfig(render=False))
    finally:
        stop()
    assert len(rows) == 2
    for r in rows:
        assert r["end_reason"] == "agent_error" and r["sr"] == 0 and reason in r["error"], r["error"]


def test_unreachable_server_is_an_episode_failure(ctx, make_episode):
    rows = run_episodes(ctx, [make_episode()], RemoteAgent("ws://127.0.0.1:9", timeout=0.5, retries=2),
                        EnvConfig(render=False))
    assert rows[0]["end_reason"] == "agent_error" and "unreachable" in rows[0]["error"]
