"""ROS 1/2 bags and MCAP files read with rosbags within size caps: one-line errors, warnings for damage.

:class:`GuardedBag` opens rosbags' AnyReader on ``paths`` after walking every MCAP file (runtime.mcap_walk),
with decompression bounded (runtime.bag_caps) while it is open, and refuses a file whose chunks overlapping in
time would be decompressed together past ``MAX_LIVE_BYTES``. What it promises its callers (`vtr eval --run`,
`vtr collect --bag`, `vtr teach --bag`):

- every failure is a :class:`~vtr.runtime.bag_caps.BagFileError` whose one line names the file, and for a
  message its topic and its index on that topic (0-based, in time order), never a traceback;
- a file that is damaged but partly readable (cut off, a summary that does not read, a chunk that stops
  reading part way, fewer messages than its index declares) is read as far as it goes, with a line in
  ``warnings`` saying so.

Needs the optional extra ``[ros]`` (rosbags), imported when a bag is opened.
"""

from __future__ import annotations

import os
import tempfile
from collections import Counter
from collections.abc import Iterator, Sequence
from contextlib import ExitStack
from pathlib import Path
from typing import Any

from vtr.runtime import mcap_walk
from vtr.runtime.bag_caps import (
    MAX_LIVE_BYTES,
    MAX_MESSAGE_BYTES,
    BagFileError,
    CapError,
    bounded_decompression,
    mib,
)


def shown(text: str) -> str:
    """``text`` as it is when printable, else quoted (a crafted topic name must not break the line)."""
    return text if text.isprintable() else repr(text)


def _why(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if len(text) <= 160 else text[:157] + "..."


class GuardedBag:
    """``with GuardedBag(paths) as bag:`` then ``bag.connections``, ``bag.messages(conns)`` and
    ``bag.deserialize(conn, index, raw)``; ``bag.warnings`` lists what was damaged."""

    def __init__(
        self, paths: Sequence[str | os.PathLike[str]], typestore: Any = None, mcap: bool = False
    ) -> None:
        self.paths = [Path(p) for p in paths]
        self.typestore = typestore
        self.mcap = mcap  # every file is an MCAP whatever its name (a run), and is refused when it is not
        self.warnings: list[str] = []
        self._names: dict[str, str] = {}  # the path rosbags reads (maybe a repaired copy) -> the user's
        self._stack = ExitStack()
        self._reader: Any = None

    # ------------------------------------------------------------------ opening
    def __enter__(self) -> GuardedBag:
        try:
            from rosbags.highlevel import AnyReader
        except ModuleNotFoundError:
            raise ModuleNotFoundError(
                "reading bags needs rosbags: pip install 'vtr-mpc[ros]'", name="rosbags"
            ) from None
        missing = [str(p) for p in self.paths if not p.exists()]
        if missing:
            raise BagFileError(f"no bag at {', '.join(missing)}")
        self._stack.enter_context(bounded_decompression())
        try:
            walks = {p: self._walks(p) for p in self.paths}
            damaged = {p: w for p, w in walks.items() if any(x.damage for x in w.values())}
            try:
                self._open(AnyReader, damaged)
            except BagFileError:
                raise
            except Exception as exc:  # a summary or index that does not read: try the data section alone
                again = {p: w for p, w in walks.items() if w and p not in damaged}
                if not again:
                    raise BagFileError(f"{self.name()}: cannot read it as a bag ({_why(exc)})") from None
                for walked in again.values():
                    for key, w in walked.items():
                        walked[key] = mcap_walk.Walk(
                            w.path, w.size, w.good_end, f"its index does not read ({_why(exc)})"
                        )
                try:
                    self._open(AnyReader, {**damaged, **again})
                except BagFileError:
                    raise
                except Exception:
                    raise BagFileError(f"{self.name()}: cannot read it as a bag ({_why(exc)})") from None
            self._check_live_chunks()
        except BaseException:
            self._stack.close()
            raise
        return self

    def _walks(self, path: Path) -> dict[Path, mcap_walk.Walk]:
        """The walk of each MCAP file of ``path`` (a file or a bag folder)."""
        if path.is_dir():
            files = sorted(path.glob("*.mcap"))
        else:
            files = [path] if path.suffix == ".mcap" or self.mcap else []
        try:
            return {f: mcap_walk.walk(f) for f in files}
        except OSError as exc:
            raise BagFileError(f"{path}: cannot read it ({_why(exc)})") from None

    def _open(self, any_reader: type, damaged: dict[Path, dict[Path, mcap_walk.Walk]]) -> None:
        """Open the reader on the paths, damaged MCAP files replaced by repaired copies (with a warning)."""
        paths = []
        for path in self.paths:
            walks = damaged.get(path)
            named = path.is_file() and path.suffix != ".mcap" and self.mcap  # rosbags goes by the suffix
            if not walks and not named:
                paths.append(path)
                continue
            folder = Path(self._stack.enter_context(tempfile.TemporaryDirectory(prefix="vtr-bag-")))
            bad = {f: w for f, w in (walks or {}).items() if w.damage}
            for f, w in bad.items():
                self._warn(f"{f} is damaged: {w.damage}; reading the records before byte {w.good_end}")
            if path.is_dir():
                copy = mcap_walk.copy_folder(path, bad, folder)
            elif bad:
                copy = mcap_walk.repaired(bad[path], folder / f"{path.stem}.mcap")
            else:
                copy = folder / f"{path.stem}.mcap"
                os.symlink(path.resolve(), copy)
            self._names[str(copy)] = str(path)
            paths.append(copy)
        reader = any_reader(paths, default_typestore=self.typestore)
        try:
            reader.open()
        except CapError as exc:
            raise BagFileError(f"{self.name()}: {exc}") from None
        self._reader = reader
        self._stack.callback(reader.close)

    def _check_live_chunks(self) -> None:
        """Refuse chunks that rosbags would decompress together (times overlapping) past MAX_LIVE_BYTES."""
        for reader in self._reader.readers:
            storage = getattr(reader, "storage", None)
            for store in getattr(storage, "storages", [storage]):
                events = []
                for c in getattr(store, "chunks", None) or []:
                    if isinstance(c, tuple) and hasattr(c, "uncompressed_size"):
                        events += [(c.message_start_time, 1, c.uncompressed_size)]
                        events += [(c.message_end_time + 1, 0, -c.uncompressed_size)]
                live = peak = 0
                for _, _, size in sorted(events):
                    live += size
                    peak = max(peak, live)
                if peak > MAX_LIVE_BYTES:
                    raise BagFileError(
                        f"{self.name(reader)}: chunks overlapping in time would take {mib(peak)} at once, more "
                        f"than the {mib(MAX_LIVE_BYTES)} cap"
                    )

    def __exit__(self, *exc: object) -> None:
        self._stack.close()

    # ------------------------------------------------------------------ reading
    @property
    def connections(self) -> list[Any]:
        return list(self._reader.connections)

    def name(self, owner: Any = None) -> str:
        """The user's name of ``owner``'s file (a connection's reader), or of all the paths."""
        path = getattr(owner, "path", None)
        if path is None:
            return ", ".join(str(p) for p in self.paths)
        return self._names.get(str(path), str(path))

    def where(self, conn: Any, index: int) -> str:
        """ "FILE: TOPIC message INDEX" (a topic that is not printable text shown quoted, so it stays one line)."""
        return f"{self.name(conn.owner)}: {shown(conn.topic)} message {index}"

    def _warn(self, text: str) -> None:
        if text not in self.warnings:
            self.warnings.append(text)

    def messages(self, connections: Sequence[Any]) -> Iterator[tuple[Any, int, int, bytes]]:
        """(connection, index on its topic, receive time ns, raw bytes) in time order. A message over
        MAX_MESSAGE_BYTES is an error; a file that stops reading part way ends the messages with a warning,
        and one yielding fewer messages than it declares gets a warning when they have all been read."""
        if not connections:
            return
        index: Counter = Counter()
        read: Counter = Counter()
        source = self._reader.messages(connections=list(connections))
        while True:
            try:
                conn, ns, raw = next(source)
            except StopIteration:
                break
            except CapError as exc:
                raise BagFileError(f"{self.name()}: {exc}") from None
            except Exception as exc:  # rosbags' errors for a damaged chunk or record: keep what was read
                self._warn(
                    f"{self.name()} is damaged: reading stopped after {sum(read.values())} messages "
                    f"({_why(exc)}); using the messages before it"
                )
                return
            i = index[conn.topic]
            index[conn.topic] += 1
            read[id(conn)] += 1
            if len(raw) > MAX_MESSAGE_BYTES:
                raise BagFileError(
                    f"{self.where(conn, i)} takes {mib(len(raw))}, more than the {mib(MAX_MESSAGE_BYTES)} cap"
                )
            yield conn, i, ns, raw
        for conn in connections:
            declared = getattr(conn, "msgcount", 0) or 0
            if read[id(conn)] < declared:
                self._warn(
                    f"{self.name(conn.owner)} is damaged: {read[id(conn)]} of the {declared} {conn.topic} "
                    "messages it declares were read"
                )

    def deserialize(self, conn: Any, index: int, raw: bytes) -> Any:
        """The message, or BagFileError naming the file, topic and index when its bytes are not its type."""
        try:
            return self._reader.deserialize(raw, conn.msgtype)
        except Exception as exc:
            raise BagFileError(
                f"{self.where(conn, index)} does not decode as {conn.msgtype} ({_why(exc)})"
            ) from None
