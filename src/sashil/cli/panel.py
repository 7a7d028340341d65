"""``sashil panel``: the bench in a browser, served on this machine only, behind a per-launch token."""

from __future__ import annotations

import argparse
import sys

EXAMPLE = "sashil panel --config configs/sim.yaml --port 8765"

#: the default port (any free port may be given; 0 picks one)
DEFAULT_PORT = 8765


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--config", metavar="FILE", help="YAML config of the rig (default: simulated rig, seed parameters)"
    )
    parser.add_argument(
        "--port",
        type=int,
        default=DEFAULT_PORT,
        metavar="N",
        help=f"TCP port on 127.0.0.1 (default {DEFAULT_PORT}; 0: a free one)",
    )
    parser.add_argument(
        "--laws", metavar="DIR", help="also offer the laws of DIR/*.py (file laws; the page never names code itself)"
    )
    parser.add_argument("--runs", metavar="DIR", default="runs", help="folder the run folders go in (default runs/)")
    parser.add_argument(
        "--on-disconnect",
        choices=("stop", "keep"),
        default="stop",
        help="when the controlling page's connection drops during a run: stop it at 0 A (default, a dead-man) "
        "or keep it running (any page, or Ctrl-C here, still stops it)",
    )


def run(args: argparse.Namespace) -> int:
    import socket

    import uvicorn

    from sashil.errors import ConfigError
    from sashil.panel.app import WS_IMPL, Panel, make_app
    from sashil.panel.bench import Bench
    from sashil.panel.guard import new_token

    if not 0 <= args.port <= 65535:
        raise ConfigError(f"--port: expected 0..65535, got {args.port}")
    bench = Bench(args.config, args.runs, args.laws)
    if args.config is not None:
        bench.resolve({"law": next(iter(bench.laws))})  # a bad --config is one line now, not at Start
    listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        listener.bind(("127.0.0.1", args.port))
    except OSError as err:
        listener.close()
        raise ConfigError(f"--port {args.port}: cannot listen on 127.0.0.1 ({err.strerror})") from None
    port = listener.getsockname()[1]
    token = new_token()
    panel = Panel(bench, token, port, args.on_disconnect)
    server = uvicorn.Server(uvicorn.Config(make_app(panel), log_level="warning", ws=WS_IMPL, lifespan="on"))
    print(f"sashil panel: open http://127.0.0.1:{port}/?token={token}", flush=True)
    print("  (this machine only; Ctrl-C stops the server and any run at 0 A)", file=sys.stderr, flush=True)
    server.run(sockets=[listener])
    return 0
