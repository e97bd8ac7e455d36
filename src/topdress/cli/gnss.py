"""`topdress gnss decode FILE`: one JSON object per NMEA line, to inspect a receiver's output."""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
from collections.abc import Callable, Iterator
from typing import Any, BinaryIO, TextIO

from topdress.errors import DeviceError
from topdress.gnss.nmea import NmeaDecoder


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
    for lines in _numbered_chunks(stream):
        for number, line in lines:
            fix = decoder.decode(line)
            record = {"line": number, **dataclasses.asdict(fix)}
            out.write(json.dumps(record, allow_nan=False) + "\n")  # strict JSON, no Infinity
        out.flush()  # a live receiver piped in shows each line as it comes
    counts = ", ".join(f"{k}={v}" for k, v in sorted(decoder.counters.items()))
    err.write(f"gnss decode: {counts or 'no lines'}\n")
    return 0


def _numbered_chunks(stream: BinaryIO) -> Iterator[list[tuple[int, bytes]]]:
    """The lines of each chunk read, numbered; a chunk is what the stream has at hand, so a
    receiver piped in live is decoded as it talks. CR, LF and CRLF each end a line (receivers
    use all three), also when a chunk ends between the CR and the LF."""
    read: Callable[[int], bytes] = getattr(stream, "read1", stream.read)
    number, pending = 0, bytearray()
    while chunk := read(65536):
        pending += chunk
        if b"\n" not in chunk and b"\r" not in chunk:
            continue  # no line end yet: a long stretch without one is read in linear time
        parts = bytes(pending).splitlines(keepends=True)
        # Held back: a line without its end yet, or one ending in CR that an LF may follow.
        pending = bytearray(parts.pop() if not parts[-1].endswith(b"\n") else b"")
        numbered = []
        for part in parts:
            number += 1
            numbered.append((number, part))
        yield _kept(numbered)
    if pending:
        yield _kept([(number + 1, bytes(pending))])


def _kept(numbered: list[tuple[int, bytes]]) -> list[tuple[int, bytes]]:
    lines = [(n, line.rstrip(b"\r\n")) for n, line in numbered]
    return [(n, line) for n, line in lines if line.strip() and not line.startswith(b"#")]
