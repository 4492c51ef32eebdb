"""Append-only JSON-lines record files that prove what they are before anything is dropped or appended.

A record file (e.g. the diagnosis's DEM cache) starts with a header line written when the tool
creates it::

    {"warpdem_records": "dem-cache", "created": "2026-11-28T10:00:00", "fingerprint": "<sha256 of the two>"}

then one JSON object per line. Before a tool appends to an existing file or repairs it, the file
must prove it is one: its first line is a header of the expected kind whose fingerprint matches,
or (a file written before headers existed) every line that is JSON is a record of that kind
(``is_record``) and there is at least one. Any other file (a measurement file or a config named
by mistake) is refused with :class:`NotARecordFile`, naming the file and the key that named it,
and is never modified. Torn lines of a proven file (a write cut by a kill) are cut from it and
kept in ``<file>.torn``, so nothing is lost.
"""
from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

from .config_io import write_atomic
from .errors import ConfigError
from .provenance import json_digest

__all__ = ["HEADER_KEY", "NotARecordFile", "RecordFile", "header_line", "is_header"]

HEADER_KEY = "warpdem_records"


class NotARecordFile(ConfigError):
    """An existing file named as a record file is not one; it was left untouched."""


def _header_fingerprint(kind: str, created: str) -> str:
    return json_digest({HEADER_KEY: kind, "created": created})


def header_line(kind: str) -> str:
    """The header line (without newline) of a new record file of ``kind``."""
    created = time.strftime("%Y-%m-%dT%H:%M:%S")
    return json.dumps({HEADER_KEY: kind, "created": created, "fingerprint": _header_fingerprint(kind, created)})


def is_header(obj: Any, kind: str) -> bool:
    """True when ``obj`` (a parsed first line) is a header of ``kind`` with a matching fingerprint."""
    return (isinstance(obj, Mapping) and obj.get(HEADER_KEY) == kind and isinstance(obj.get("created"), str)
            and obj.get("fingerprint") == _header_fingerprint(kind, obj["created"]))


@dataclass
class Contents:
    """What :meth:`RecordFile.read` found: records ``(line number, record)``, the numbers of torn
    lines (not a JSON object, or not a record), whether it has a header, and its raw lines."""

    records: list[tuple[int, dict]] = field(default_factory=list)
    torn: list[int] = field(default_factory=list)
    header: bool = False
    lines: list[str] = field(default_factory=list)
    final_newline: bool = True


@dataclass
class RecordFile:
    """One append-only record file.

    ``kind``: the format name in the header (e.g. ``"dem-cache"``); ``is_record``: whether a
    parsed line is a record of this kind (used to recognise files written before headers);
    ``key``: the config key or option that names the file, for messages (e.g. ``"cache"``);
    ``what``: the file in words (``"DEM cache"``)."""

    path: Path
    kind: str
    is_record: Callable[[Mapping[str, Any]], bool]
    key: str
    what: str

    def __post_init__(self) -> None:
        self.path = Path(self.path)

    def refuse(self, why: str) -> NotARecordFile:
        return NotARecordFile(f"{self.key}: {self.path} is not a {self.what} ({why}); it was left untouched: "
                              f"name a new file for '{self.key}' (or the {self.what} a warpdem tool wrote)")

    def check_path(self) -> None:
        """Refuse a path that can never be this record file (a folder, a folder that is a file)."""
        if self.path.exists() and not self.path.is_file():
            raise self.refuse("it is a folder" if self.path.is_dir() else "it is not a regular file")
        for part in self.path.parents:
            if part.exists() and not part.is_dir():
                raise self.refuse(f"{part} is a file, not a folder")

    def read(self) -> Contents:
        """The file's records, checked to be this kind of file (see the module docstring); a missing
        or empty file has none. Refuses (:class:`NotARecordFile`) any other file, unmodified."""
        self.check_path()
        if not self.path.exists():
            return Contents()
        data = self.path.read_bytes()
        if not data.strip():
            return Contents(lines=[], final_newline=True)
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError:
            raise self.refuse("it is not UTF-8 text") from None
        lines = text.splitlines()
        out = Contents(lines=lines, final_newline=text.endswith("\n"))
        parsed: list[tuple[int, Any]] = []
        for k, line in enumerate(lines):
            if not line.strip():
                continue
            try:
                parsed.append((k, json.loads(line)))
            except ValueError:  # json.JSONDecodeError is a ValueError
                parsed.append((k, None))
        first_k, first = parsed[0]
        out.header = first_k == 0 and is_header(first, self.kind)
        body = parsed[1:] if out.header else parsed
        for k, obj in body:
            if isinstance(obj, dict) and self.is_record(obj):
                out.records.append((k + 1, obj))
            elif obj is None or out.header:
                out.torn.append(k + 1)
            else:  # complete JSON that is not a record: not this kind of file
                raise self.refuse(f"line {k + 1} is not a {self.what} record")
        if not out.header and not out.records:
            first_is = "not JSON" if first is None else f"not a {self.what} header"
            raise self.refuse(f"its first line is {first_is} and it holds no {self.what} record")
        return out

    def repair(self, contents: Contents, drop: Iterable[int], log: Callable[[str], None] | None = None) -> None:
        """Cut the lines numbered ``drop`` (1-based) from a file :meth:`read` proved, keeping them in
        ``<file>.torn``; also ends a complete last line that lost its newline. Atomic."""
        drop = set(drop)
        if drop:
            kept_aside = self.path.with_name(self.path.name + ".torn")
            with open(kept_aside, "a", encoding="utf-8") as fh:
                fh.write("".join(contents.lines[k - 1] + "\n" for k in sorted(drop)))
            if log is not None:
                log(f"{self.path}: {len(drop)} torn line(s) (a write cut by an interruption) moved to {kept_aside.name}")
        kept = [ln for k, ln in enumerate(contents.lines, start=1) if k not in drop]
        write_atomic(self.path, "".join(ln + "\n" for ln in kept))

    def append(self, records: Iterable[Mapping[str, Any]], encode: Callable[[Any], str] = json.dumps) -> None:
        """Append whole lines in one write, then flush and fsync; a new (or empty) file gets its
        header first. Call :meth:`read` before the first append of a session: it refuses a file
        that is not this kind."""
        text = "".join(encode(r) + "\n" for r in records)
        if not text:
            return
        self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            fh = open(self.path, "x", encoding="utf-8")  # new: the header first (one process creates it)
            text = header_line(self.kind) + "\n" + text
        except FileExistsError:
            fh = open(self.path, "a", encoding="utf-8")
            if fh.tell() == 0:  # an empty file (e.g. touched): nothing to lose, start it as a new one
                text = header_line(self.kind) + "\n" + text
        with fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
