"""`topdress gnss decode FILE`: one JSON object per NMEA line, to inspect a receiver's output."""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
from collections.abc import Iterator
from typing import Any, BinaryIO, TextIO

from topdress.errors import DeviceError
from topdress.terminal.nmea import NmeaDecoder


def register(sub: Any) -> None:
    gnss = sub.add_parser("gnss", help="GNSS receiver tools")
    gsub = gnss.add_subparsers(dest="gnss_command", required=True, metavar="ACTION")
    dec = gsub.add_parser(
        "decode",
        help="decode an NMEA capture, one JSON object per line",
        description="Decode NMEA 0183 lines (any talker) and print one JSON object per line "
        "with keys line, talker, type, ok, error, fix_valid, speed_kmh, course_deg, lat, lon, "
        "utc. Empty lines and '#' comment lines are skipped; a summary of the counters goes "
        "to stderr.",
    )
    dec.add_argument("file", help="NMEA capture file, '-' for stdin")
    dec.set_defaults(func=_decode_command)


def _decode_command(args: argparse.Namespace) -> int:
    if args.file == "-":
        return _decode_to_stdout(sys.stdin.buffer)
    try:
        stream = open(args.file, "rb")  # noqa: SIM115 - closed below
    except OSError as exc:
        raise DeviceError(f"cannot read {args.file}: {exc}") from exc
    with stream:
        return _decode_to_stdout(stream)


def _decode_to_stdout(stream: BinaryIO) -> int:
    try:
        return decode_stream(stream, sys.stdout, sys.stderr)
    except BrokenPipeError:  # `| head`: the reader has all it wanted
        sys.stdout = open(os.devnull, "w")  # noqa: SIM115 - quiets the flush at exit
        return 0


def decode_stream(stream: BinaryIO, out: TextIO, err: TextIO) -> int:
    decoder = NmeaDecoder()
    for number, line in _numbered_lines(stream):
        fix = decoder.decode(line)
        out.write(json.dumps({"line": number, **dataclasses.asdict(fix)}) + "\n")
    counts = ", ".join(f"{k}={v}" for k, v in sorted(decoder.counters.items()))
    err.write(f"gnss decode: {counts or 'no lines'}\n")
    return 0


def _numbered_lines(stream: BinaryIO) -> Iterator[tuple[int, bytes]]:
    # splitlines() takes CR, LF and CRLF as terminators, as receivers use all three.
    for number, line in enumerate(stream.read().splitlines(), start=1):
        if line.strip() and not line.startswith(b"#"):
            yield number, line
