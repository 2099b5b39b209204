"""``navarena serve-agent --agent depth_reactive --port 8000`` (``python -m navarena.serve_agent``): an
agent behind the NavArena agent-server protocol (navcore.eval.protocol), for any evaluator that speaks it."""
from __future__ import annotations

from navcore.eval.protocol.server import serve_agent


def main(argv=None) -> None:
    """Serve an agent over the NavArena agent-server protocol (msgpack over WebSocket)."""
    import argparse

    from navarena.evaluate import agent_arg
    from navcore.eval.agents import make_agent

    ap = argparse.ArgumentParser(prog="navarena serve-agent", description=main.__doc__)
    ap.add_argument("--agent", default="depth_reactive",
                    help="a registered agent (oracle, depth_reactive, random, ...) or package.module:Class")
    ap.add_argument("--agent-arg", action="append", default=[], metavar="KEY=VALUE", type=agent_arg,
                    help="an argument of the agent's constructor, repeatable (a YAML value)")
    ap.add_argument("--host", default="127.0.0.1")
    ap.add_argument("--port", type=int, default=8000)
    ap.add_argument("--port-file", default=None, help="write the bound port here once listening (port 0 = any)")
    ap.add_argument("--action-space", default="native", choices=["native", "waypoint", "velocity"],
                    help="native: action_id / stop; waypoint, velocity: navarena-server's forms (their bench)")
    args = ap.parse_args(argv)

    def ready(port):
        if args.port_file:
            with open(args.port_file, "w") as f:
                f.write(str(port))
        print(f"serving agent {args.agent!r} on ws://{args.host}:{port}", flush=True)

    kwargs = dict(args.agent_arg)
    serve_agent(lambda: make_agent(args.agent, **kwargs), args.host, args.port, ready, action_space=args.action_space)



if __name__ == "__main__":
    main()
