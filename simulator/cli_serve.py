"""``python -m simulator serve``: the simulated analyser as a TCP or pseudo-terminal server (the
servers are :mod:`simulator.serve`). The first line printed is the device URL or the pty path."""
from __future__ import annotations

import argparse
import logging
import os
import signal
import sys
from collections.abc import Sequence

from analysis.command_line import with_examples

from .serve import Prebuilt, StopFlag, analyser_options, firmware_factory, open_pty, serve_pty, serve_tcp, tcp_listener, tcp_url

__all__ = ["main"]


def _parse_hostport(text: str) -> tuple[str, int]:
    host, sep, port = text.rpartition(":")
    host = host.strip("[]")
    if not sep or not host or not port.isdigit() or int(port) > 65535:
        raise argparse.ArgumentTypeError(f"expected HOST:PORT (port 0..65535, 0 = any free port), got {text!r}")
    return host, int(port)


def _build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m simulator serve",
        description="Run the simulated analyser as a TCP or pseudo-terminal server. The first line printed "
                    "is the device URL (socket://HOST:PORT) or the pty path to connect to. Each connection "
                    "gets a fresh analyser (same seed, power-on state).",
    )
    with_examples(p)
    door = p.add_mutually_exclusive_group(required=True)
    door.add_argument("--tcp", type=_parse_hostport, metavar="HOST:PORT",
                      help="listen on HOST:PORT (PORT 0 = any free port); use 127.0.0.1 for local use")
    door.add_argument("--pty", action="store_true", help="create a pseudo-terminal and print its path (POSIX)")
    p.add_argument("--seed", type=int, default=None, help="random seed of the simulated frame/operator")
    p.add_argument("--config", default=None, help="frame configuration TOML (defaults merged)")
    p.add_argument("--noise", choices=("on", "off"), default=None, help="sensor noise on/off")
    p.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                   help="any other create_analyser option, as in a sim:// URL query (repeatable)")
    p.add_argument("--precomputed", default=None, metavar="FILE.npz",
                   help="replay cached input volts (arrays volts[n_ch, n] and fs_hz) instead of simulating the "
                        "frame (throughput benchmarks)")
    p.add_argument("--max-clients", type=int, default=0, help="exit after serving this many clients (0 = never)")
    p.add_argument("--send-timeout", type=float, default=10.0,
                   help="drop a client that stops reading for this many seconds (default 10)")
    p.add_argument("--idle-timeout", type=float, default=0.0,
                   help="TCP: close a connection silent for this many seconds (0 = never, the default)")
    p.add_argument("--yield-after", type=float, default=5.0,
                   help="TCP: close a client silent for this many seconds while another client waits (default 5; "
                        "0 = never)")
    p.add_argument("-v", "--verbose", action="store_true", help="log every connection (stderr)")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m simulator serve``; returns the exit status."""
    args = _build_parser().parse_args(list(sys.argv[1:] if argv is None else argv))
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, stream=sys.stderr,
                        format="serve: %(levelname)s %(message)s")
    try:
        options = analyser_options(args.seed, args.config, args.noise, args.option)
        factory = Prebuilt(firmware_factory(options, args.precomputed))
        factory.ready()  # fail now, with a clear message, if the options are wrong
    except (ValueError, OSError, KeyError, TypeError) as exc:
        print(f"serve: cannot build the simulated analyser: {exc}", file=sys.stderr)
        return 2

    stop = StopFlag()
    previous = {sig: signal.signal(sig, stop.set) for sig in (signal.SIGTERM, signal.SIGINT)}
    try:
        if args.tcp is not None:
            host, port = args.tcp
            try:
                srv = tcp_listener(host, port)
            except OSError as exc:
                print(f"serve: cannot listen on {host}:{port}: {exc}", file=sys.stderr)
                return 2
            with srv:
                print(tcp_url(srv), flush=True)
                return serve_tcp(srv, factory, stop, max_clients=args.max_clients,
                                 send_timeout_s=args.send_timeout, idle_timeout_s=args.idle_timeout,
                                 yield_after_s=args.yield_after)
        master, path = open_pty()
        try:
            print(path, flush=True)
            return serve_pty(master, factory, stop, max_clients=args.max_clients,
                             send_timeout_s=args.send_timeout)
        finally:
            os.close(master)
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
