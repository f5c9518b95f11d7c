"""``HOST:PORT`` option values (stdlib only: command lines import it for --help)."""

from __future__ import annotations

import argparse
import socket


def parse_host_port(
    text: str, default_port: int, default_host: str = "127.0.0.1"
) -> tuple[str, int]:
    """``HOST:PORT``, ``PORT`` (on ``default_host``) or ``HOST`` (on ``default_port``);
    ``[v6addr]:PORT`` for IPv6. A ValueError says what is wrong."""
    text = text.strip()
    if text.isdigit():
        host, port = default_host, text
    elif text.startswith("["):
        host, sep, port = text[1:].partition("]")
        port = port.removeprefix(":") if sep else ""
        port = port or str(default_port)
    elif text.count(":") == 1:
        host, _, port = text.partition(":")
    else:
        host, port = text, str(default_port)
    if not host:
        raise ValueError(f"{text!r}: no host")
    if not port.isdigit() or not 1 <= int(port) <= 65535:
        raise ValueError(f"{text!r}: the port must be a number in 1..65535")
    return host, int(port)


def add_host_port_option(
    parser: argparse.ArgumentParser, flag: str, default_port: int, help: str
) -> None:
    """An optional ``flag [HOST:]PORT`` (given alone: 127.0.0.1:``default_port``, loopback);
    a bad value is an argparse error that says what is wrong."""

    def parse(text: str) -> tuple[str, int]:
        try:
            return parse_host_port(text, default_port)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    parser.add_argument(
        flag,
        metavar="[HOST:]PORT",
        type=parse,
        nargs="?",
        const=("127.0.0.1", default_port),
        help=help,
    )


def bind_tcp_listener(host: str, port: int) -> socket.socket:
    """A TCP socket bound to ``host:port`` (IPv6 when the host has a colon; port 0: a free
    one), with SO_REUSEADDR as uvicorn sets it; not yet listening. OSError when it cannot be
    bound (the socket is closed)."""
    sock = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_STREAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind((host, port))
    except OSError:
        sock.close()
        raise
    return sock
