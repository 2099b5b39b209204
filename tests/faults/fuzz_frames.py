"""Property-based fuzzing (hypothesis) of the agent-server frames, both directions.

Evaluator side (a hostile server's frames): each case goes through exactly what RemoteAgent /
RemoteBatchAgent do with a received frame: unpack -> is_reply -> decode_value (reply image limit) ->
parse_action -> the environment's decode_action. Allowed outcomes: a reply, a stale frame, or a
ProtocolError / ValueError, which the evaluator records as the episode's failure.

Server side (a hostile client's frames): each case goes through serve_agent's Session.respond,
which must return a well-formed frame or nothing, never raise.

Frame types: action, batch_action, error, episode_start (unexpected type) and garbage for the
evaluator; observation, batch_observation, episode_start, batch_episode_start, episode_end,
batch_episode_end and garbage for the server. Each case starts from a valid frame of its type and
applies mutations: random msgpack values anywhere, wrong field types, giant / lying array and image
headers, forbidden dtypes, NaN / inf / huge numbers, wrong seq, truncation and bit flips of the
packed bytes, deep nesting, a decompression-bomb PNG. Per case: a time limit (a hang), the
process's memory bounded by RLIMIT_AS (a MemoryError counts as blown memory), the peak of
tracemalloc's traced allocations recorded on every TRACE_EVERY-th case, the process's peak RSS.

    PYTHONPATH=tests python -m faults.fuzz_frames --cases 10000 [--kinds client:action,server:observation] \
        [--out data/08_reports]   -> fuzz_frames.json (merged into bench_faults by faults.faults --merge)
"""
from __future__ import annotations

import argparse
import functools
import io
import math
import resource
import signal
import time
import tracemalloc

import msgpack
import numpy as np

from navcore.io import jsonio

TRACE_EVERY = 25
"""One case in this many runs under tracemalloc (its peak allocation is recorded)."""
CLIENT_KINDS = ("action", "batch_action", "error", "episode_start", "garbage")
SERVER_KINDS = ("observation", "batch_observation", "episode_start", "batch_episode_start", "episode_end",
                "batch_episode_end", "garbage")


class Hang(Exception):
    pass


def _alarm(signum, frame):
    raise Hang()


@functools.lru_cache(maxsize=4)
def png_bytes(w: int, h: int) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.new("RGB", (w, h)).save(buf, format="PNG")
    return buf.getvalue()


def png_image(w: int, h: int, declared=None) -> dict:
    return {"__image__": True, "data": png_bytes(w, h), "format": "png", "shape": list(declared or (h, w, 3))}


def strategies():
    from hypothesis import strategies as st

    num = st.one_of(st.integers(-2**63, 2**64 - 1), st.floats(allow_nan=True, allow_infinity=True),
                    st.sampled_from([0.0, -0.0, 1e308, -1e308, 5e-324, float("nan"), float("inf")]))
    leaf = st.one_of(st.none(), st.booleans(), num, st.text(max_size=20), st.binary(max_size=64))
    anyval = st.recursive(leaf, lambda c: st.one_of(st.lists(c, max_size=4),
                                                    st.dictionaries(st.text(max_size=8), c, max_size=4)),
                          max_leaves=12)
    array = st.fixed_dictionaries({
        "__ndarray__": st.just(True), "data": st.binary(max_size=64),
        "dtype": st.sampled_from(["<f4", "<f8", "|u1", "<i8", "|b1", "O", "V8", "<U5", "|S3", "<M8[s]", "<c16",
                                  "bogus", "", "<f2", "(2,)f4", "[('a', '<f4')]"]),
        "shape": st.one_of(st.lists(st.integers(-3, 2**40), max_size=9), anyval)})
    image = st.fixed_dictionaries({
        "__image__": st.just(True), "data": st.binary(max_size=64),
        "format": st.sampled_from(["png", "jpeg", "raw", "gif", None]),
        "shape": st.one_of(st.lists(st.integers(-3, 2**31), max_size=4), anyval),
        "dtype": st.sampled_from(["|u1", "<f4", "O"])})
    special = st.one_of(array, image, st.just("bomb"), st.just("deep"), st.just("lying_png"))
    return st, anyval, special


def base_frame(kind: str, seq: int) -> dict:
    """A valid frame of each type (the starting point of the mutations)."""
    obs = {"pose": {"__ndarray__": True, "data": np.zeros(3, np.float32).tobytes(), "dtype": "<f4", "shape": [3]},
           "pointgoal": {"__ndarray__": True, "data": np.array([2.0, 0.1], np.float32).tobytes(), "dtype": "<f4",
                         "shape": [2]},
           "depth": {"__ndarray__": True, "data": np.ones((6, 8), np.float32).tobytes(), "dtype": "<f4",
                     "shape": [6, 8]}}
    payload = {
        "action": {"waypoints": [{"x": 0.1, "y": 0.0, "yaw": 0.1}]},
        "batch_action": {"actions": {"0": {"v": 0.3, "w": 0.1, "dt": 0.1}, "1": {"action_id": 1}}},
        "error": {"error": "boom", "fatal": False},
        "episode_start": {"task": {"episode_id": "e", "task_type": "pointnav"}},
        "observation": obs,
        "batch_observation": {"observations": {"0": obs, "1": obs}},
        "batch_episode_start": {"episodes": {"0": {"task": {}}, "1": {"task": {}}}},
        "episode_end": {"success": True, "end_reason": "stop"},
        "batch_episode_end": {"episodes": {"0": {"success": False}}},
    }.get(kind, {})
    return {"type": kind, "payload": payload, "seq": seq, "timestamp": 0.0}


def mutate(draw, st, anyval, special, kind: str, seq: int) -> bytes:
    """A hostile frame's bytes: a valid one with random mutations."""
    if kind == "garbage":
        return draw(st.one_of(st.binary(max_size=256), st.builds(lambda v: msgpack.packb(v, use_bin_type=True),
                                                                   anyval)))
    f = base_frame(kind, seq)
    for _ in range(draw(st.integers(0, 4))):
        op = draw(st.sampled_from(["field", "payload_key", "special", "seq", "drop", "type", "nan_action"]))
        if op == "field":
            f[draw(st.sampled_from(["type", "payload", "seq", "timestamp"]))] = draw(anyval)
        elif op == "payload_key" and isinstance(f.get("payload"), dict):
            target = f["payload"]
            for _ in range(draw(st.integers(0, 2))):  # descend into nested maps
                subs = [k for k, v in target.items() if isinstance(v, dict)]
                if not subs:
                    break
                target = target[draw(st.sampled_from(sorted(subs)))]
            key = draw(st.one_of(st.sampled_from(sorted(target) or ["x"]), st.text(max_size=6)))
            target[key] = draw(anyval)
        elif op == "special" and isinstance(f.get("payload"), dict):
            sp = draw(special)
            if sp == "bomb":
                sp = png_image(4000, 4000)  # 48 MB once decoded from a few KB
            elif sp == "lying_png":
                sp = png_image(8, 8, declared=[2**20, 2**20, 3])
            elif sp == "deep":
                sp = []
                for _ in range(draw(st.integers(30, 200))):
                    sp = [sp]
            key = draw(st.sampled_from(["rgb", "depth", "pose", "waypoints", "actions", "observations", "x", "v"]))
            f["payload"][key] = sp
        elif op == "seq":
            f["seq"] = draw(st.sampled_from([seq - 1, seq + 1, -1, 0, 2**63, seq]))
        elif op == "drop":
            f.pop(draw(st.sampled_from(["type", "payload", "seq", "timestamp"])), None)
        elif op == "type":
            f["type"] = draw(st.sampled_from(["action", "batch_action", "error", "observation", "teleport", ""]))
        elif op == "nan_action" and isinstance(f.get("payload"), dict):
            f["payload"] = draw(st.sampled_from([
                {"waypoints": [{"x": float("nan")}]}, {"x": float("inf"), "y": 0}, {"v": 1e308, "w": 0, "dt": 1e308},
                {"waypoints": [{"x": 0.1}] * 5000}, {"action_id": 2**70}, {"action_id": True},
                {"waypoints": {"x": 1}}, {"actions": {"0": {"x": float("nan")}, "a": {}}}, {"stop": [1] * 100}]))
    try:
        data = msgpack.packb(f, use_bin_type=True)
    except (OverflowError, ValueError, TypeError):
        data = msgpack.packb(base_frame(kind, seq), use_bin_type=True)
    cut = draw(st.sampled_from(["none", "none", "none", "truncate", "flip"]))
    if cut == "truncate" and len(data) > 1:
        data = data[: draw(st.integers(0, len(data) - 1))]
    elif cut == "flip" and data:
        b = bytearray(data)
        for _ in range(draw(st.integers(1, 8))):
            i = draw(st.integers(0, len(b) - 1))
            b[i] ^= 1 << draw(st.integers(0, 7))
        data = bytes(b)
    return data


def client_case(data: bytes, kind: str) -> str:
    """What the evaluator does with one received frame; returns the outcome class."""
    from navcore.eval.env import decode_action
    from navcore.eval.protocol.client import REPLY_MAX_PIXELS, is_reply
    from navcore.eval.protocol.codec import ProtocolError, decode_value, parse_action, unpack
    from navcore.nav.actions import ActionSpace

    want = "batch_action" if kind == "batch_action" else "action"
    try:
        frame = unpack(data)
        if not is_reply(frame, 5, want, 3):
            return "stale"
        payload = decode_value(frame["payload"], max_pixels=REPLY_MAX_PIXELS)
        if want == "action":
            actions = [parse_action(payload)]
        else:
            acts = payload.get("actions", {}) if isinstance(payload, dict) else None
            if not isinstance(acts, dict):
                raise ProtocolError("no actions map")
            actions = []
            for k, v in acts.items():
                try:
                    int(k)
                except (TypeError, ValueError) as e:
                    raise ProtocolError("unknown slot") from e
                actions.append(parse_action(v))
        for a in actions:
            stop, moves = decode_action(a, ActionSpace())
            assert all(math.isfinite(c) for m in moves for c in m), "non-finite move accepted"
        return "accepted"
    except (ProtocolError, ValueError):
        return "rejected"


def server_case(data: bytes, session) -> str:
    from navcore.eval.protocol.codec import unpack

    out = session.respond(data)  # must never raise
    if out is None:
        return "no_reply"
    f = unpack(out)  # and whatever it sends is a well-formed frame
    return "error_frame" if f["type"] == "error" else "reply"


def run(kinds: list[str], cases: int, seed: int, time_limit: float) -> dict:
    from hypothesis import HealthCheck, given, settings

    from navcore.eval.agents import make_agent
    from navcore.eval.protocol.server import Session
    from navcore.nav.actions import ActionSpace

    st, anyval, special = strategies()
    signal.signal(signal.SIGALRM, _alarm)
    report = {}
    for spec in kinds:
        side, kind = spec.split(":")
        stats = {"cases": 0, "crashes": 0, "hangs": 0, "memory": 0, "outcomes": {}, "peak_traced_mb": 0.0,
                 "max_case_s": 0.0, "examples": []}
        session = Session(lambda: make_agent("depth_reactive"), "waypoint", ActionSpace())
        starts = [msgpack.packb(base_frame(k, n), use_bin_type=True)
                  for n, k in enumerate(("episode_start", "batch_episode_start"), 1)]

        @settings(max_examples=cases, deadline=None, database=None, derandomize=True,
                  suppress_health_check=list(HealthCheck))
        @given(st.data())
        def case(d):
            data = mutate(d.draw, st, anyval, special, kind, 5)
            if side == "server":  # episodes in progress (an agent that raised ended the last), so
                for f in starts:  # observations reach the agents
                    session.respond(f)
            traced = stats["cases"] % TRACE_EVERY == 0  # tracemalloc slows every allocation: a sample
            if traced:
                tracemalloc.start()
            t0 = time.perf_counter()
            signal.setitimer(signal.ITIMER_REAL, time_limit)
            try:
                out = client_case(data, kind) if side == "client" else server_case(data, session)
            except Hang:
                out = "hang"
                stats["hangs"] += 1
            except MemoryError:
                out = "memory"
                stats["memory"] += 1
            except Exception as e:  # noqa: BLE001 - a crash: recorded with the input
                out = "crash"
                stats["crashes"] += 1
                if len(stats["examples"]) < 5:
                    stats["examples"].append({"error": f"{type(e).__name__}: {str(e)[:200]}", "frame": data[:200].hex()})
            finally:
                signal.setitimer(signal.ITIMER_REAL, 0)
            stats["max_case_s"] = max(stats["max_case_s"], time.perf_counter() - t0)
            if traced:
                stats["peak_traced_mb"] = max(stats["peak_traced_mb"], tracemalloc.get_traced_memory()[1] / 2**20)
                tracemalloc.stop()
            stats["cases"] += 1
            stats["outcomes"][out] = stats["outcomes"].get(out, 0) + 1

        t0 = time.perf_counter()
        case()
        stats["seconds"] = round(time.perf_counter() - t0, 1)
        report[spec] = stats
        print(f"{spec}: {stats['cases']} cases, {stats['crashes']} crashes, {stats['hangs']} hangs, "
              f"{stats['memory']} memory, peak {stats['peak_traced_mb']:.1f} MB traced, outcomes {stats['outcomes']}, "
              f"{stats['seconds']} s", flush=True)
    return report


def main(argv=None) -> dict:
    import json
    import os
    import platform

    ap = argparse.ArgumentParser()
    ap.add_argument("--cases", type=int, default=10_000)
    ap.add_argument("--kinds", default=",".join([f"client:{k}" for k in CLIENT_KINDS] +
                                                [f"server:{k}" for k in SERVER_KINDS]))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--time-limit", type=float, default=5.0, help="seconds a case may take (else a hang)")
    ap.add_argument("--address-space-gb", type=float, default=8.0)
    ap.add_argument("--out", default="data/08_reports")
    args = ap.parse_args(argv)
    lim = int(args.address_space_gb * 2**30)
    resource.setrlimit(resource.RLIMIT_AS, (lim, lim))
    rep = run(args.kinds.split(","), args.cases, args.seed, args.time_limit)
    total = {"fuzz_frame_cases": sum(s["cases"] for s in rep.values()),
             "fuzz_frame_crashes": sum(s["crashes"] + s["memory"] for s in rep.values()),
             "fuzz_frame_hangs": sum(s["hangs"] for s in rep.values()),
             "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
             "machine": platform.node(), "cpu_cores": os.cpu_count(), "address_space_gb": args.address_space_gb,
             "kinds": rep}
    os.makedirs(args.out, exist_ok=True)
    path = os.path.join(args.out, "fuzz_frames.json")
    with open(path, "w") as f:
        f.write(jsonio.dumps(total, indent=1))
    print(json.dumps({k: v for k, v in total.items() if k != "kinds"}))
    return total


if __name__ == "__main__":
    main()
