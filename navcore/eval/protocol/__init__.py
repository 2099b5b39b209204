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
y left, yaw counter-clockwise), one flat {"x", "y", "yaw"} (their random agent), {"v", "w", "dt"},
{"action_id": 0..3} (0 stop, 1 forward, 2 left, 3 right), and STOP as {"stop": true} (our choice;
their docs leave it open; serve_agent --action-space waypoint|velocity sends a zero move flagged
stop, which their bench reads as a move). Numbers must be finite (NaN fails the episode).

Client behaviour (as theirs): 30 s timeout per reply, 5 connection attempts with 2^n s back-off,
no compression, no keepalive ping, no reconnection inside an episode: a time-out, a closed
connection, an error frame of the episode or a malformed frame fails the episode (the evaluator
records why and goes on). Beyond theirs: stale frames (duplicate or late replies) are skipped by
seq; after a failure the next episode starts on a fresh connection; replies over 1 MiB, arrays
whose shape does not match their bytes, images over 16 M pixels or unlike their declared shape,
and payloads nested deeper than 32 are refused. The batch flow records every queued episode: a
failure fails the slots in flight and the queue goes on (on a new connection).

Modules: codec (values, frames, actions), client (the evaluator's RemoteAgent / RemoteBatchAgent),
server (serve_agent: our agents behind the protocol); the command is ``navarena serve-agent``
(navarena/serve_agent.py).
"""
