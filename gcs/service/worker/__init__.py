"""A flight worker: one flight (:class:`~gcs.service.flight.Flight`) in an OS process of its
own, with its own event loop, vehicle links and store connection, so that nothing the service
process does (requests, uploads, planning) reaches its control loop.

``python -m gcs.service.worker FOLDER --db URL [--resume]``: the flight of ``FOLDER/spec.json``
(:class:`FlightSpec`), or with ``--resume`` the flight of that folder the store says is running,
from its checkpoint. With ``--standby`` it starts and loads everything first, then waits for
its flight as a line on stdin (``{"folder", "db", "resume"}``): the service keeps one waiting,
so that a worker that died is replaced in a fraction of a second, not a Python start-up.

Its first line on stdout says it is ready (``{"ready": {...}}``) or why it could not start
(``{"error": {...}}``, exit 1); after that it writes nothing there (the service that started
it may be gone). It logs to ``FOLDER/worker.log`` and exits 0 once the flight has ended and
what it leaves is kept (or when told to ``stop``).

It answers on the Unix socket ``FOLDER/worker.sock``, one JSON object per line. A request
``{"op": ..., "args": {...}}`` gets ``{"ok": true, "result": ...}`` or ``{"ok": false,
"error": {"type", "message", ...}}`` (a :class:`~gcs.service.scenariotext.ServiceError`, made
again by :func:`error_of`). ``follow`` (``after_seq``) turns the connection into the flight's
feed: every event after ``after_seq`` (``{"type": "event"}``), its state at least every
:data:`STATE_WALL_S` of wall time and after each command (``{"type": "state"}``: snapshot,
vehicles, figures), and ``{"type": "end"}`` once it is over.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import logging
import os
import signal
import sys
import tempfile
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from pydantic import TypeAdapter

from gcs.coordination.runner import ENDED
from gcs.errors import GcsError
from gcs.mavlink.signing import SigningConfig
from gcs.service.fleet import Fleet
from gcs.service.flight import Flight, Rehearsal
from gcs.service.flightjobs import start_server
from gcs.service.loopwatch import LoopWatch, freeze_start_up
from gcs.service.planning import kept_planned
from gcs.service.scenariotext import (
    Conflict,
    Infeasible,
    InvalidInput,
    NotFound,
    PreconditionFailed,
    ServiceError,
)
from gcs.store.repository import Store
from planner.scenario import Threat

__all__ = [
    "LOG_FILE",
    "PID_FILE",
    "READS",
    "SOCKET_FILE",
    "SPEC_FILE",
    "STATE_WALL_S",
    "FlightSpec",
    "error_doc",
    "error_of",
    "main",
    "socket_path",
]

log = logging.getLogger(__name__)

SPEC_FILE = "spec.json"
SOCKET_FILE = "worker.sock"
SOCKET_PATH_MAX = 100
"""The longest Unix socket path bound (the system's limit is 107 bytes)."""
PID_FILE = "worker.pid"
LOG_FILE = "worker.log"
STATE_WALL_S = 0.25
"""The feed sends the flight's state at least this often (wall s)."""
END_WAIT_S = 10.0
"""Once the flight is over, how long (wall s) the worker waits for its followers to read the
end before it exits."""
_THREAT: TypeAdapter[Threat] = TypeAdapter(Threat)
READS = frozenset({"state", "ready", "map", "team_time"})
"""The operations that change nothing: answered without the flight's state."""
LINE_LIMIT = 1 << 20
"""The longest request line read (bytes)."""


@dataclass(frozen=True)
class VehicleSpec:
    """A live vehicle of the flight: its connection, system id and signing key (hex)."""

    connection: str
    system_id: int | None = None
    signing_key: str | None = None


@dataclass(frozen=True)
class FlightSpec:
    """What a worker needs to make a new flight (kept in ``FOLDER/spec.json``)."""

    flight_id: str
    schedule_id: str
    vehicles: tuple[VehicleSpec, ...] | None = None
    """Per scenario vehicle in its order; None: bundled simulator vehicles (:attr:`rehearsal`)."""
    rehearsal: Rehearsal | None = None
    lockstep: str | None = None
    """With :attr:`vehicles`: the lock-step file of the simulator they are on, joined."""

    def write(self, folder: Path) -> None:
        """Into ``folder`` (readable by its owner only: it may hold signing keys)."""
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / SPEC_FILE
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            json.dump(asdict(self), f)

    @classmethod
    def read(cls, folder: Path) -> FlightSpec:
        doc = json.loads((folder / SPEC_FILE).read_text(encoding="utf-8"))
        vehicles = doc.get("vehicles")
        rehearsal = doc.get("rehearsal")
        return cls(
            doc["flight_id"],
            doc["schedule_id"],
            None if vehicles is None else tuple(VehicleSpec(**v) for v in vehicles),
            None if rehearsal is None else Rehearsal(**rehearsal),
            doc.get("lockstep"),
        )


def socket_path(folder: Path) -> Path:
    """Where the worker of the flight in ``folder`` answers: ``FOLDER/worker.sock``, or when
    that path is too long for a Unix socket, ``<fid>.sock`` in a folder of this user's in the
    temporary directory (only its owner may enter it)."""
    path = folder / SOCKET_FILE
    if len(str(path).encode()) <= SOCKET_PATH_MAX:
        return path
    short = Path(tempfile.gettempdir()) / f"tcgcs-{os.getuid()}"
    short.mkdir(mode=0o700, exist_ok=True)
    if short.stat().st_uid != os.getuid() or short.stat().st_mode & 0o077:
        raise OSError(f"{short} is not this user's own folder")
    return short / f"{folder.name}.sock"


# -- errors on the wire ---------------------------------------------------------------------------

_ERRORS: dict[str, type[ServiceError]] = {
    c.__name__: c for c in (ServiceError, NotFound, Conflict, PreconditionFailed, InvalidInput)
}


def error_doc(err: ServiceError) -> dict[str, Any]:
    """A service error for the wire (:func:`error_of` makes it again)."""
    doc: dict[str, Any] = {"type": type(err).__name__, "message": str(err)}
    if isinstance(err, Infeasible):
        doc |= {"earliest_s": err.earliest_s, "vehicle": err.vehicle, "latest_s": err.latest_s}
    return doc


def error_of(doc: Mapping[str, Any]) -> ServiceError:
    """The service error :func:`error_doc` wrote."""
    message = str(doc.get("message", "the flight worker failed"))
    if doc.get("type") == "Infeasible":
        return Infeasible(message, doc.get("earliest_s"), doc.get("vehicle"), doc.get("latest_s"))
    return _ERRORS.get(str(doc.get("type")), ServiceError)(message)


# -- the worker -----------------------------------------------------------------------------------


class Worker:
    """Serves one flight on its socket until it is over."""

    def __init__(self, flight: Flight) -> None:
        self.flight = flight
        self.watch = LoopWatch(counting=lambda: flight.runner.state not in ENDED)
        self.ended = asyncio.Event()
        self.stopping = False
        self._changed = asyncio.Event()
        self._followers = 0
        self._told = 0
        """States told so far: each numbered, so that an older one read late is not taken."""
        self._figures: tuple[int, dict[str, Any]] | None = None
        """The flight's figures and the last event they count (they change with events only)."""
        self.nice = os.getpriority(os.PRIO_PROCESS, 0)
        """Its scheduling priority (set, if asked, before the flight was given it)."""
        flight.on_over = lambda _: self.ended.set()
        flight.about_worker = self.about

    def about(self) -> dict[str, Any]:
        """This process, its scheduling priority (``nice``), and the longest its event loop
        was held (ms of wall time)."""
        return {
            "pid": os.getpid(),
            "nice": self.nice,
            "loop_stall_max_ms": round(self.watch.stall_max_s * 1e3, 3),
        }

    def state(self) -> dict[str, Any]:
        """The flight's snapshot (with this worker's pid and longest loop stall), its
        vehicles and its figures, numbered (``n``)."""
        self._told += 1
        return {
            "n": self._told,
            "snapshot": self.flight.snapshot(),
            "vehicles": self.flight.vehicle_views(),
            "figures": self._figures_now(),
        }

    def _figures_now(self) -> dict[str, Any]:
        last_seq = self.flight.bus.last_seq
        if self._figures is None or self._figures[0] != last_seq:
            self._figures = last_seq, self.flight.figures()
        return self._figures[1]

    def ready(self) -> dict[str, Any]:
        f = self.flight
        return {
            "flight_id": f.id,
            "pid": os.getpid(),
            "schedule_id": f.schedule.id,
            "scenario_id": f.schedule.scenario_id,
            "connections": f.connections,
            "simulated": f.simulated,
            "last_seq": f.bus.last_seq,
            **self.state(),
        }

    async def serve(self, client: asyncio.StreamReader, out: asyncio.StreamWriter) -> None:
        try:
            while line := await client.readline():
                try:
                    req = json.loads(line)
                    op, args = str(req["op"]), dict(req.get("args") or {})
                except (ValueError, KeyError, TypeError):
                    await _send(out, {"ok": False, "error": {"message": "a malformed request"}})
                    continue
                if op == "follow":
                    await self._follow(out, int(args.get("after_seq", 0)))
                    return
                await _send(out, await self._answer(op, args))
        except (ConnectionError, asyncio.IncompleteReadError, ValueError):
            pass
        finally:
            out.close()

    async def _answer(self, op: str, args: dict[str, Any]) -> dict[str, Any]:
        f = self.flight
        commands: dict[str, Callable[[], Any]] = {
            "state": self.state,
            "ready": self.ready,
            "map": f.flight_map,
            "team_time": f.team_time,
            "upload": f.upload,
            "launch": lambda: f.launch(args.get("start_utc_s"), args.get("delay_s")),
            "add_threat": lambda: f.add_threat(
                _THREAT.validate_python(args["threat"]), args.get("at_s")
            ),
            "remove_threat": lambda: f.remove_threat(str(args["threat_id"])),
            "move_team_time": lambda: f.move_team_time(
                float(args["arrival_s"]), args.get("version")
            ),
            "abort": lambda: f.abort(args.get("vehicle"), str(args.get("mode", "rtl"))),
            "pause": lambda: f.pause(args.get("at_s")),
            "resume": f.resume,
            "stop": self.stop,
        }
        command = commands.get(op)
        if command is None:
            return {"ok": False, "error": {"message": f"no operation {op!r}"}}
        try:
            result = command()
            if asyncio.iscoroutine(result):
                result = await result
        except ServiceError as err:
            return {"ok": False, "error": error_doc(err)}
        except Exception as err:
            log.exception("%s failed", op)
            return {"ok": False, "error": {"message": f"{op}: {type(err).__name__}: {err}"}}
        if op in READS:
            return {"ok": True, "result": result}
        self._changed.set()
        # The state after it, with the answer: what the service answers next shows it.
        return {"ok": True, "result": result, "state": self.state()}

    async def _follow(self, out: asyncio.StreamWriter, after_seq: int) -> None:
        """The feed: events after ``after_seq``, the state, the end."""
        self._followers += 1
        sub = self.flight.bus.subscribe(maxsize=1_000_000, after_seq=after_seq)
        loop = asyncio.get_running_loop()
        try:
            await _send(out, {"type": "state", "data": self.state()})
            next_state = loop.time() + STATE_WALL_S
            while True:
                got = await sub.get_within(max(0.0, next_state - loop.time()))
                while got is not None:
                    await _send(out, {"type": "event", "data": got.to_wire()})
                    got = sub.get_nowait()
                if self.ended.is_set():
                    await _send(out, {"type": "state", "data": self.state()})
                    await _send(out, {"type": "end"})
                    return
                if loop.time() >= next_state or self._changed.is_set():
                    self._changed.clear()
                    await _send(out, {"type": "state", "data": self.state()})
                    next_state = loop.time() + STATE_WALL_S
        except (ConnectionError, OSError):
            return
        finally:
            sub.close()
            self._followers -= 1

    async def stop(self) -> dict[str, Any]:
        """Told to stop by the service: a flight on bundled simulator vehicles ends (failed:
        its simulator stops); one on live vehicles goes on (the next worker flies it on)."""
        self.stopping = True
        asyncio.get_running_loop().call_soon(self.ended.set)
        return {"flight_id": self.flight.id, "stopping": True}

    async def run(self, folder: Path) -> None:
        """Serve until the flight is over and its followers have read the end (or until
        told to stop)."""
        self.watch.start()
        sock = socket_path(folder)
        with contextlib.suppress(FileNotFoundError):
            sock.unlink()
        server = await asyncio.start_unix_server(self.serve, path=str(sock), limit=LINE_LIMIT)
        (folder / PID_FILE).write_text(f"{os.getpid()}\n", encoding="utf-8")
        _say({"ready": self.ready()})
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, lambda: asyncio.ensure_future(self.stop()))
        try:
            await self.ended.wait()
            if self.stopping:
                await self.flight.close()
            deadline = loop.time() + END_WAIT_S
            while self._followers and loop.time() < deadline:
                await asyncio.sleep(0.02)
        finally:
            server.close()
            with contextlib.suppress(FileNotFoundError):
                sock.unlink()
            self.watch.stop()


async def _send(out: asyncio.StreamWriter, doc: Mapping[str, Any]) -> None:
    out.write(json.dumps(doc).encode() + b"\n")
    await out.drain()


def _say(doc: Mapping[str, Any]) -> None:
    """The one line on stdout; stdout is then let go (the reader may be gone)."""
    sys.stdout.write(json.dumps(doc, default=str) + "\n")
    sys.stdout.flush()
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    os.close(devnull)


# -- the process ----------------------------------------------------------------------------------


async def _flight(folder: Path, store: Store, fleet: Fleet, resume: bool) -> Flight:
    if resume:
        fid = folder.name
        flight = Flight.resumed(fid, store=store, fleet=fleet, folder=folder)
        if flight is None:
            raise ServiceError(f"flight {fid}: no checkpoint to fly on from")
        return flight
    spec = FlightSpec.read(folder)
    entry = kept_planned(store, spec.schedule_id)
    vehicles = None
    if spec.vehicles is not None:
        for v in spec.vehicles:
            if v.signing_key is not None:
                fleet.signing[v.connection] = SigningConfig.from_hex(v.signing_key)
        vehicles = [(v.connection, v.system_id) for v in spec.vehicles]
    return await Flight.create(
        spec.flight_id, entry, vehicles, spec.rehearsal, store=store, fleet=fleet, folder=folder,
        lockstep=None if spec.lockstep is None else Path(spec.lockstep),
    )  # fmt: skip


async def _main(folder: Path, db_url: str, resume: bool) -> int:
    store = Store.open(db_url, migrate=False)
    try:
        async with Fleet() as fleet:
            try:
                flight = await _flight(folder, store, fleet, resume)
            except ServiceError as err:
                _say({"error": error_doc(err)})
                return 1
            except (GcsError, OSError, TimeoutError, ValueError) as err:
                _say({"error": {"type": "ServiceError", "message": str(err)}})
                return 1
            # What the flight starts with (the modules, its world and schedule, its links)
            # lives as long as it does: kept out of the collector's passes, a full pass over
            # the objects it makes in flight is short (one over all of them held the loop
            # up to 100 ms on a busy machine).
            freeze_start_up()
            await Worker(flight).run(folder)
            if flight.task is not None and not flight.task.done() and not flight.over:
                # Stopped with live vehicles in the air: the next worker flies them on.
                flight.task.cancel()
                with contextlib.suppress(BaseException):
                    await flight.task
            return 0
    finally:
        store.close()


def prioritize(niceness: int) -> str | None:
    """Run at scheduling priority ``niceness`` (``nice``: below 0 is ahead of the service and
    everything else at the default, and needs the privilege to raise a priority,
    CAP_SYS_NICE); None, or why it could not (the process then runs at the one it has)."""
    if niceness == os.getpriority(os.PRIO_PROCESS, 0):
        return None
    try:
        os.setpriority(os.PRIO_PROCESS, 0, niceness)
    except OSError as err:
        now = os.getpriority(os.PRIO_PROCESS, 0)
        return f"priority {niceness} refused ({err.strerror}): it runs at {now}"
    return None


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m gcs.service.worker", description=__doc__)
    ap.add_argument("folder", type=Path, nargs="?", help="the flight's folder (its spec.json)")
    ap.add_argument("--db", help="the service's database URL")
    ap.add_argument("--resume", action="store_true", help="fly on from its checkpoint")
    ap.add_argument(
        "--standby",
        action="store_true",
        help="start, load everything, and wait for one flight: a line on stdin, "
        '{"folder", "db", "resume"} (exit 0 at the end of stdin)',
    )
    ap.add_argument(
        "--nice",
        type=int,
        default=None,
        help="the scheduling priority to run at (and its planning jobs; below 0 needs "
        "CAP_SYS_NICE)",
    )
    args = ap.parse_args(argv)
    refused = None if args.nice is None else prioritize(args.nice)
    start_server()  # the flight's planning jobs' (loaded while nothing waits for it)
    if args.standby:
        line = sys.stdin.readline()
        if not line.strip():
            return 0
        doc = json.loads(line)
        folder, db_url, resume = Path(doc["folder"]), str(doc["db"]), bool(doc["resume"])
    elif args.folder is None or args.db is None:
        ap.error("a flight's folder and --db are needed (or --standby)")
    else:
        folder, db_url, resume = args.folder, args.db, args.resume
    folder.mkdir(parents=True, exist_ok=True)
    if args.standby:  # what the interpreter says on stderr goes to the flight's log too
        fd = os.open(folder / LOG_FILE, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
        os.dup2(fd, 2)
        os.close(fd)
    logging.basicConfig(
        filename=folder / LOG_FILE,
        level=logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    if refused is not None:
        log.warning("flight worker %s", refused)
    return asyncio.run(_main(folder, db_url, resume))
