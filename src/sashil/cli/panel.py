"""``sashil panel``: the bench in a browser, served on this machine only, behind a per-launch token."""

from __future__ import annotations

import argparse
import sys

from sashil.errors import ConfigError

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
        "--host",
        default="127.0.0.1",
        metavar="ADDR",
        help="address to listen on (default 127.0.0.1: this machine only); another needs --allow-remote, --tls-cert and --tls-key",
    )
    parser.add_argument(
        "--allow-remote",
        action="store_true",
        help="allow a --host other machines reach (HTTPS only: with --tls-cert and --tls-key)",
    )
    parser.add_argument("--tls-cert", metavar="FILE", help="TLS certificate (PEM) to serve HTTPS with")
    parser.add_argument("--tls-key", metavar="FILE", help="TLS private key (PEM) of --tls-cert")
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


def check_listen(host: str, allow_remote: bool, cert: str | None, key: str | None) -> str:
    """The scheme to serve with ("http" on loopback, "https" with a certificate); ConfigError (one
    line) for a non-loopback host without --allow-remote and TLS, or TLS files missing."""
    from pathlib import Path

    from sashil.panel.guard import is_loopback, is_wildcard

    if (cert is None) != (key is None):
        raise ConfigError("--tls-cert and --tls-key: give both or neither")
    for option, path in (("--tls-cert", cert), ("--tls-key", key)):
        if path is not None and not Path(path).is_file():
            raise ConfigError(f"{option} {path}: no such file")
    if not is_loopback(host):
        if is_wildcard(host):
            raise ConfigError(
                f"--host {host}: a wildcard address cannot be checked against a request's Host header: "
                "give the address other machines reach this one by"
            )
        if not allow_remote:
            raise ConfigError(
                f"--host {host}: not a loopback address: the panel can energise the coil; add --allow-remote (HTTPS only)"
            )
        if cert is None:
            raise ConfigError(
                f"--host {host} --allow-remote: plain HTTP off this machine is refused: add --tls-cert FILE and --tls-key FILE"
            )
    return "https" if cert is not None else "http"


def run(args: argparse.Namespace) -> int:
    import socket

    import uvicorn

    from sashil.panel.app import WS_IMPL, Panel, make_app
    from sashil.panel.bench import Bench
    from sashil.panel.guard import host_names, is_loopback, new_token

    if not 0 <= args.port <= 65535:
        raise ConfigError(f"--port: expected 0..65535, got {args.port}")
    scheme = check_listen(args.host, args.allow_remote, args.tls_cert, args.tls_key)
    bench = Bench(args.config, args.runs, args.laws)
    if args.config is not None:
        bench.resolve({"law": next(iter(bench.laws))})  # a bad --config is one line now, not at Start
    address = args.host.strip("[]")
    family = socket.AF_INET6 if ":" in address else socket.AF_INET
    listener = socket.socket(family, socket.SOCK_STREAM)
    listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        listener.bind((address, args.port))
    except OSError as err:
        listener.close()
        raise ConfigError(f"--host {args.host} --port {args.port}: cannot listen ({err.strerror})") from None
    listener.listen(128)  # a page opened as soon as the URL is printed waits in the backlog
    port = listener.getsockname()[1]
    token = new_token()
    panel = Panel(bench, token, port, args.on_disconnect, host_names(args.host), scheme)
    config = uvicorn.Config(
        make_app(panel),
        log_level="warning",
        ws=WS_IMPL,
        lifespan="on",
        ssl_certfile=args.tls_cert,
        ssl_keyfile=args.tls_key,
    )
    server = uvicorn.Server(config)
    shown = "127.0.0.1" if is_loopback(args.host) else host_names(args.host)[-1]
    print(f"sashil panel: open {scheme}://{shown}:{port}/?token={token}", flush=True)
    where = "this machine only" if scheme == "http" else f"HTTPS on {args.host}"
    print(f"  ({where}; Ctrl-C stops the server and any run at 0 A)", file=sys.stderr, flush=True)
    server.run(sockets=[listener])
    return 0
