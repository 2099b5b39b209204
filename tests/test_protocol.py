"""The agent-server protocol: encodings, frame checks, a separate server process giving the same
metrics as in-process, and malformed / slow / crashing servers recorded as episode failures."""
import subprocess
import sys
import threading
import time

import msgpack
import numpy as np
import pytest
from sdk_like import AGENTS, SdkLikeClient, SdkLikeServer

from navcore.eval.agents import make_agent
from navcore.eval.env import EnvConfig
from navcore.eval.loop import run_episodes, run_episodes_batched
from navcore.eval.protocol.client import RemoteAgent, RemoteBatchAgent
from navcore.eval.protocol.codec import (
    ProtocolError,
    decode_value,
    encode_array,
    encode_image,
    error_message,
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
    with pytest.raises(ProtocolError, match=r"FormatError: a byte no msgpack type starts with; 3 bytes starting c1 00 01"):
        unpack(b"\xc1\x00\x01")  # msgpack's FormatError has no message of its own: ours says what came
    with pytest.raises(ProtocolError, match=r"ExtraData: .*as text 'hello'"):
        unpack(b"hello")
    assert error_message(unpack(pack("error", {"error": "boom", "fatal": True}, 1))) == "server error: boom (fatal)"
    with pytest.raises(ProtocolError):
        parse_action({"dance": 1})


def start_server_process(tmp_path, cwd, agent="depth_reactive"):
    port_file = tmp_path / "port"
    proc = subprocess.Popen([sys.executable, "-m", "navarena.serve_agent", "--agent", agent, "--port", "0",
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


# ---- against the navarena-server SDK's behaviour (tests/sdk_like.py, written from their protocol) ----


def _episodes(make_episode, n, **kw):
    eps = [make_episode(start=(1.0, 0.5, 0.3 * i), max_steps=kw.pop("max_steps", 12), **kw) for i in range(n)]
    for i, e in enumerate(eps):
        e.episode_id = f"e{i}"
    return eps


@pytest.mark.parametrize("agent", sorted(AGENTS))
def test_their_example_agents_drive_our_evaluator_in_both_flows(ctx, make_episode, agent):
    server = SdkLikeServer(agent)
    try:
        eps = _episodes(make_episode, 6)
        single = run_episodes(ctx, eps, RemoteAgent(server.url, timeout=5), EnvConfig(render=False))
        client = RemoteBatchAgent(server.url, timeout=5)
        batched = run_episodes_batched(ctx, eps, client, 4, EnvConfig(render=False))
        client.close()
        ends = server.wait_log("end:", 12)
    finally:
        server.stop()
    for rows in (single, batched):
        assert len(rows) == 6 and all(r["error"] == "" for r in rows), [r["error"] for r in rows]
        assert all(r["end_reason"] in ("budget", "entered") for r in rows)
        assert sum(r["steps"] for r in rows) > 6 and all(np.isfinite(r["trajectory"]).all() for r in rows)
    assert len(ends) == 12 and "end:?" not in ends  # episode_end carries end_reason in both flows


def test_an_error_on_episode_start_fails_that_episode_only(ctx, make_episode):
    """Their server answers a raising on_episode_start with an error frame and the next observation
    with a second one; the episodes after it must not read those frames one episode late."""
    server = SdkLikeServer("random_waypoint", quirk="raise_on_start")
    try:
        rows = run_episodes(ctx, _episodes(make_episode, 6), RemoteAgent(server.url, timeout=5), EnvConfig(render=False))
    finally:
        server.stop()
    errors = [r["error"] for r in rows]
    assert [bool(e) for e in errors] == [False, True, False, True, False, True], errors
    assert all("on_episode_start failed" in e for e in errors if e)


def test_duplicate_replies_are_skipped_not_read_late(ctx, make_episode):
    server = SdkLikeServer("random_velocity", quirk="duplicate")
    agent = RemoteAgent(server.url, timeout=5)
    try:
        rows = run_episodes(ctx, _episodes(make_episode, 3), agent, EnvConfig(render=False))
    finally:
        server.stop()
    assert all(r["error"] == "" for r in rows) and agent.stale_frames >= sum(r["steps"] for r in rows) - 3


def test_a_slow_server_is_not_cut_off_by_a_keepalive_ping(ctx, make_episode):
    """A policy that blocks its event loop (2 s here, 50 s in the field) answers no ping; our client
    sends none by default (their SDK neither), so only the reply time-out applies."""
    server = SdkLikeServer("random_waypoint", quirk="slow", delay=2.0)
    try:
        ok = run_episodes(ctx, _episodes(make_episode, 1, max_steps=2), RemoteAgent(server.url, timeout=10),
                          EnvConfig(render=False))
        pinged = run_episodes(ctx, _episodes(make_episode, 1, max_steps=2),
                              RemoteAgent(server.url, timeout=10, keepalive=0.3), EnvConfig(render=False))
    finally:
        server.stop()
    assert ok[0]["error"] == "" and ok[0]["steps"] == 2
    assert pinged[0]["end_reason"] == "agent_error"  # the mechanism the default avoids


def test_nan_waypoints_spend_their_steps_with_finite_pose_and_metrics(ctx, make_episode):
    server = SdkLikeServer("random_waypoint", quirk="nan")
    try:
        single = run_episodes(ctx, _episodes(make_episode, 2), RemoteAgent(server.url, timeout=5), EnvConfig(render=False))
        client = RemoteBatchAgent(server.url, timeout=5)
        batched = run_episodes_batched(ctx, _episodes(make_episode, 3), client, 2, EnvConfig(render=False))
        client.close()
    finally:
        server.stop()
    for r in single + batched:  # an invalid action is one step with a recorded error, not an agent failure
        assert r["end_reason"] != "agent_error" and not r["error"] and "finite" in r["action_error"], r
        assert r["invalid_actions"] >= 1
        assert np.isfinite(r["trajectory"]).all() and np.isfinite([r["spl"], r["ne"], r["soft_spl"]]).all()
    assert len(batched) == 3


@pytest.mark.parametrize("behaviour", ["crash", "malformed", "error"])
def test_batch_flow_records_every_queued_episode_when_the_client_fails(ctx, make_episode, behaviour):
    url, stop = bad_server(behaviour)
    eps = _episodes(make_episode, 7)
    try:
        rows = run_episodes_batched(ctx, eps, RemoteBatchAgent(url, timeout=0.5, retries=1), 2, EnvConfig(render=False))
    finally:
        stop()
    assert [r["episode_id"] for r in rows] == [e.episode_id for e in eps]
    assert all(r["end_reason"] == "agent_error" and r["error"] for r in rows)
    t0 = time.perf_counter()
    rows = run_episodes_batched(ctx, eps, RemoteBatchAgent("ws://127.0.0.1:9", timeout=0.5, retries=1), 2,
                                EnvConfig(render=False))
    assert len(rows) == 7 and all("unreachable" in r["error"] for r in rows) and time.perf_counter() - t0 < 10


def _our_server(action_space, agent="random"):
    from navcore.eval.protocol.server import serve_agent

    box = {}
    threading.Thread(target=serve_agent, daemon=True,
                     args=(lambda: make_agent(agent), "127.0.0.1", 0, lambda p: box.setdefault("port", p)),
                     kwargs={"action_space": action_space}).start()
    for _ in range(200):
        if "port" in box:
            return f"ws://127.0.0.1:{box['port']}"
        time.sleep(0.02)
    raise RuntimeError("serve_agent did not start")


@pytest.mark.parametrize("space", ["waypoint", "velocity"])
def test_their_client_drives_our_server_and_gets_their_action_forms(space):
    url = _our_server(space, "depth_reactive")
    c = SdkLikeClient(url)
    obs = {"rgb": np.zeros((32, 40, 3), np.uint8), "depth": np.full((32, 40), 3.0, np.float32),
           "pointgoal": np.array([2.0, 0.0], np.float32), "pose": np.zeros(3, np.float32)}
    # an observation before episode_start: an error frame, and the connection goes on
    with pytest.raises(RuntimeError, match="outside an episode"):
        c.request("observation", obs, "action")
    c.send("episode_start", {"task": {"episode_id": "x", "task_type": "pointnav"}})
    a = c.request("observation", obs, "action")
    if space == "waypoint":
        assert a["waypoints"][0]["x"] == pytest.approx(0.25) and "stop" not in a
    else:
        assert a["v"] * a["dt"] == pytest.approx(0.25) and a["w"] == 0
    stop = c.request("observation", {**obs, "pointgoal": np.array([0.1, 0.0], np.float32)}, "action")
    assert stop["stop"] is True  # a zero move their bench reads, with our stop flag
    c.send("episode_end", {"success": True, "end_reason": "stop"})
    # garbage and a raising agent: error frames, the server goes on
    c.ws.send(b"\xc1\xc1 not msgpack")
    assert unpack(c.ws.recv(timeout=5))["type"] == "error"
    c.send("episode_start", {"task": {}})
    with pytest.raises(RuntimeError, match="fatal"):
        c.request("observation", {"pointgoal": "xy"}, "action")  # a goal vector of letters: ValueError
    c.send("batch_episode_start", {"episodes": {"0": {"task": {}}, "1": {"task": {}}}})
    acts = c.request("batch_observation", {"observations": {"0": obs, "1": obs}}, "batch_action")["actions"]
    assert set(acts) == {"0", "1"}
    with pytest.raises(RuntimeError, match="never started"):
        c.request("batch_observation", {"observations": {"7": obs}}, "batch_action")
    c.close()
