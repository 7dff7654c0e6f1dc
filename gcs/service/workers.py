"""The service's side of its flight workers (:mod:`gcs.service.worker`): each flight flies in a
worker process the service starts, follows and restarts, and the service answers for it from
what the worker tells it.

A :class:`WorkerFlight` starts its worker (:meth:`WorkerFlight.start`), or finds one a killed
service process left flying (:meth:`WorkerFlight.adopt`), and follows its feed: the events go
on a bus of the service's own (numbered as the worker numbered them), the snapshot, vehicles
and figures are kept as last told. Reads are answered from those, never by waiting on the
worker; commands go to it on its socket. A worker that dies before its flight is over is
started again on the flight's checkpoint (``--resume``), at most :data:`RESTARTS` times in
:data:`RESTART_WINDOW_S`.

The channel is the worker's Unix socket in the flight's folder: local to the machine, the same
for SQLite and PostgreSQL, and nothing to run beside the service. What must survive the
service, the flight's events and checkpoints, the worker writes to the store itself.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import os
import signal
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from gcs.coordination.bus import EventBus
from gcs.coordination.events import EventKind, FlightEvent
from gcs.coordination.runner import ENDED, FlightState
from gcs.service.ended import FINAL_FILE
from gcs.service.scenariotext import Conflict, NotFound, ServiceError
from gcs.service.worker import LINE_LIMIT, LOG_FILE, READS, error_of, socket_path

__all__ = ["RESTARTS", "WORKERS_AHEAD", "Spawner", "WorkerFlight", "WorkerGone", "ahead_of_service"]

log = logging.getLogger(__name__)

WORKERS_AHEAD = 5
"""How far ahead of the service its flight workers run unless told (``nice`` this much lower),
where the service may raise a priority: a flight's control loop before the API, its planning
jobs and anything else on the machine at the default priority."""


def ahead_of_service() -> int | None:
    """The flight workers' priority unless told (``TCGCS_WORKER_NICE``): :data:`WORKERS_AHEAD`
    ahead of this process where it may raise a priority (CAP_SYS_NICE, or a ``RLIMIT_NICE``
    that allows it: tried on this process, then put back), else None (this process's)."""
    now = os.getpriority(os.PRIO_PROCESS, 0)
    ahead = max(-20, now - WORKERS_AHEAD)
    try:
        os.setpriority(os.PRIO_PROCESS, 0, ahead)
    except OSError:
        return None
    os.setpriority(os.PRIO_PROCESS, 0, now)  # a lower priority needs no privilege
    return ahead


READY_WALL_S = 60.0
"""How long (wall s) a new worker may take to say it is ready (its simulator started, its
vehicles heard)."""
RESTARTS = 5
RESTART_WINDOW_S = 60.0
"""A worker that died is started again at most :data:`RESTARTS` times in this many wall s."""
FEED_SILENCE_S = 15.0
"""A worker's feed says the flight's state every 0.25 s of wall time: silent this long (wall
s), it is taken as broken (the worker is asked, and killed if it does not answer). The
default of :attr:`Spawner.feed_silence_s` (setting ``TCGCS_WORKER_SILENCE_S``)."""
RECONNECT_WALL_S = 10.0
"""How long (wall s) a worker that still runs may take to answer again after its feed broke
before it is killed and replaced. The default of :attr:`Spawner.answer_wall_s` (setting
``TCGCS_WORKER_ANSWER_S``)."""
MAP_WALL_S = 1.0
"""The map is asked of a flight's worker at most this often (wall s)."""
REQUEST_WALL_S = 30.0
"""How long (wall s) a command may take in the worker (an abort waits for its vehicles)."""


class WorkerGone(ServiceError):
    """The flight's worker could not be reached (it is being started again)."""

    status = 503


class WorkerFlight:
    """A flight flown by a worker process, as the service sees it."""

    def __init__(self, folder: Path, ready: Mapping[str, Any], spawner: Spawner) -> None:
        self.folder = folder
        self.spawner = spawner
        self.id: str = ready["flight_id"]
        self.schedule_id: str = ready["schedule_id"]
        self.scenario_id: str = ready["scenario_id"]
        self.connections: dict[str, str] = dict(ready["connections"])
        self.simulated: bool = bool(ready["simulated"])
        self.pid: int = int(ready["pid"])
        self.bus = EventBus(first_seq=int(ready["last_seq"]) + 1)
        """The flight's events as the worker numbered them (from those it still keeps)."""
        self.proc: asyncio.subprocess.Process | None = None
        self.on_over: Callable[[WorkerFlight], None] | None = None
        self.final: tuple[dict[str, Any], dict[str, Any] | None] | None = None
        """Once it is over: its last snapshot and map, as the worker kept them."""
        self.restarts: list[float] = []
        self.not_flown_on = "no reason given"
        """Why no worker flew the flight on after its own died (said with the failure)."""
        self.keep_told: Callable[[Sequence[FlightEvent]], object] | None = None
        """Keeps events in the store (as the worker's own writer does): those the worker told
        and may not have kept when it died are kept before another takes the flight on."""
        self.lost = False
        """No worker flies it on: it has failed (said by two events on its bus)."""
        self._state: dict[str, Any] = {}
        self._told = 0
        self._take_state(ready)
        self._feed: asyncio.Task[None] | None = None
        self._closing = False
        self._map: tuple[float, dict[str, Any]] | None = None
        self._map_asked: asyncio.Task[Any] | None = None

    # -- starting -------------------------------------------------------------------------------

    @classmethod
    async def start(cls, folder: Path, spawner: Spawner, *, resume: bool = False) -> WorkerFlight:
        """Start a worker on the flight of ``folder`` (its spec, or with ``resume`` its
        checkpoint) and follow it once it is ready.

        Raises
        ------
        ServiceError
            The worker could not make the flight (its error, made again).
        """
        proc, ready = await spawner.spawn(folder, resume)
        flight = cls(folder, ready, spawner)
        flight.proc = proc
        flight.follow()
        return flight

    @classmethod
    async def adopt(cls, folder: Path, spawner: Spawner) -> WorkerFlight | None:
        """The worker a killed service process left flying in ``folder``, if it answers."""
        try:
            ready = (await _request(folder, "ready", {}, timeout_s=2.0))["result"]
        except (OSError, TimeoutError, ValueError, ServiceError):
            return None
        flight = cls(folder, {**ready, "last_seq": 0}, spawner)
        flight.follow()
        return flight

    def follow(self) -> None:
        """Follow the worker's feed (restarting it when it dies) until the flight is over."""
        self._feed = asyncio.get_running_loop().create_task(self._follow())

    # -- what the worker told -------------------------------------------------------------------

    def _take_state(self, doc: Mapping[str, Any]) -> None:
        """The worker's state, unless a newer one was taken (a command's answer overtakes
        the feed); a new worker numbers from 1 again."""
        n = int(doc.get("n", 0))
        if self._state and n <= self._told:
            return
        self._told = n
        self._state = {
            "snapshot": doc["snapshot"],
            "vehicles": doc.get("vehicles", {}),
            "figures": doc.get("figures", {}),
        }

    @property
    def state(self) -> FlightState:
        return FlightState(self._state["snapshot"]["state"])

    @property
    def over(self) -> bool:
        """It has ended and what it leaves is kept (its record, report and last snapshot)."""
        return self.final is not None

    def snapshot(self) -> dict[str, Any]:
        """The flight's snapshot as the worker last told it (at most
        :data:`~gcs.service.worker.STATE_WALL_S` of wall time old)."""
        if self.final is not None:
            return self.final[0]
        snap: dict[str, Any] = self._state["snapshot"]
        return snap

    def vehicle_views(self) -> dict[str, dict[str, Any]]:
        """Per connection, its vehicle as the worker last told it."""
        views: dict[str, dict[str, Any]] = self._state["vehicles"]
        return views

    def figures(self) -> dict[str, Any]:
        figures: dict[str, Any] = self._state["figures"]
        return figures

    @property
    def record_path(self) -> Path:
        return self.folder / "flight.json"

    @property
    def report_dir(self) -> Path | None:
        folder = self.folder / "report"
        return folder if self.over and folder.is_dir() else None

    # -- commands -------------------------------------------------------------------------------

    async def request(self, op: str, **args: Any) -> Any:
        """Ask the worker (a :class:`~gcs.service.scenariotext.ServiceError` it answered is
        raised again here).

        Raises
        ------
        WorkerGone
            It could not be reached.
        """
        if self.over:
            raise _ended(self)
        try:
            doc = await _request(self.folder, op, args, timeout_s=REQUEST_WALL_S)
        except (OSError, TimeoutError, ValueError) as err:
            if self.over:
                raise _ended(self) from None
            raise WorkerGone(f"flight {self.id}: its worker did not answer ({err})") from None
        if "state" in doc and self.final is None:
            self._take_state(doc["state"])
        if op not in READS:
            self._map = None  # a command may have changed it
        return doc.get("result")

    async def flight_map(self) -> dict[str, Any]:
        """What the map draws: asked of the worker at most once per :data:`MAP_WALL_S` of
        wall time however many clients ask (they share one request and its answer), so that
        readers cannot keep the flight's loop busy; asked again after any event or command
        (a re-plan, a threat, an upload may have changed it)."""
        if self.final is not None:
            if self.final[1] is None:
                raise NotFound(f"flight {self.id} left no map")
            return self.final[1]
        now = time.monotonic()
        if self._map is not None and now - self._map[0] <= MAP_WALL_S:
            return self._map[1]
        if self._map_asked is None or self._map_asked.done():
            self._map_asked = asyncio.get_running_loop().create_task(self.request("map"))
        doc: dict[str, Any] = await asyncio.shield(self._map_asked)
        self._map = (now, doc)
        return doc

    # -- the feed -------------------------------------------------------------------------------

    async def _follow(self) -> None:
        try:
            while not self._closing:
                ended = await self._read_feed()
                if ended or self._closing:
                    break
                if self._ended_meanwhile():
                    break
                if self._worker_alive():
                    # Its feed broke but it runs: follow it again if it answers; one that
                    # does not is killed before another is started (never two workers on
                    # one flight's vehicles).
                    if await self._answers_within(self.spawner.answer_wall_s):
                        continue
                    log.error("flight %s: its worker (pid %d) stopped answering: killed",
                              self.id, self.pid)  # fmt: skip
                    self.kill()
                if not await self._restart():
                    self._lose()
                    break
        finally:
            self._end()

    def _worker_alive(self) -> bool:
        if self.proc is not None and self.proc.pid == self.pid:
            return self.proc.returncode is None
        return _alive(self.pid)

    async def _answers_within(self, wall_s: float) -> bool:
        deadline = time.monotonic() + wall_s
        while time.monotonic() < deadline and self._worker_alive():
            try:
                await _request(self.folder, "state", {}, timeout_s=1.0)
                return True
            except (OSError, TimeoutError, ValueError, ServiceError):
                await asyncio.sleep(0.1)
        return False

    async def _read_feed(self) -> bool:
        """Read the feed until it ends (True) or breaks (False: the worker died)."""
        try:
            reader, writer = await asyncio.open_unix_connection(
                str(socket_path(self.folder)), limit=LINE_LIMIT
            )
        except OSError:
            return False
        try:
            req = {"op": "follow", "args": {"after_seq": self.bus.last_seq}}
            writer.write(json.dumps(req).encode() + b"\n")
            await writer.drain()
            silence_s = self.spawner.feed_silence_s
            while line := await asyncio.wait_for(reader.readline(), silence_s):
                msg = json.loads(line)
                kind = msg.get("type")
                if kind == "event":
                    self.bus.take(FlightEvent.from_wire(msg["data"]))
                    self._map = None  # a re-plan, a threat, an upload: the map may differ
                elif kind == "state":
                    self._take_state(msg["data"])
                elif kind == "end":
                    return True
            return False
        except (OSError, ValueError, TimeoutError, asyncio.IncompleteReadError):
            return False  # broken, or silent (a hung worker)
        finally:
            writer.close()

    def _kept_final(self) -> dict[str, Any] | None:
        """What the flight left when it ended (its last snapshot and map), if it did."""
        try:
            doc: dict[str, Any] = json.loads((self.folder / FINAL_FILE).read_text())
        except (OSError, ValueError):
            return None
        return doc if "snapshot" in doc else None

    def _ended_meanwhile(self) -> bool:
        """The worker went: did its flight end first (its last snapshot kept, ended)?"""
        doc = self._kept_final()
        return doc is not None and doc["snapshot"].get("state") in {s.value for s in ENDED}

    async def _restart(self) -> bool:
        """Start the flight's worker again on its checkpoint; False once it has died too
        often (the flight is then left as the store has it, and said in the log)."""
        now = time.monotonic()
        self.restarts = [t for t in self.restarts if now - t < RESTART_WINDOW_S]
        if len(self.restarts) >= RESTARTS:
            self.not_flown_on = f"its worker died {RESTARTS} times in a minute"
            log.error("flight %s: %s", self.id, self.not_flown_on)
            return False
        self.restarts.append(now)
        await self._wait_gone(5.0)
        if self._worker_alive():
            self.kill()
            await self._wait_gone(5.0)
        log.warning("flight %s: its worker (pid %d) died; flying on from its checkpoint",
                    self.id, self.pid)  # fmt: skip
        await self.keep_told_events()
        try:
            self.proc, ready = await self.spawner.spawn(self.folder, True)
        except ServiceError as err:
            self.not_flown_on = str(err)
            log.error("flight %s: not flown on: %s", self.id, err)
            return False
        self.pid = int(ready["pid"])
        self._told = 0
        self._take_state(ready)
        kept = int(ready["last_seq"])
        if kept < self.bus.last_seq:  # said, but not kept before the worker died
            log.warning("flight %s: events %d-%d were lost with its worker",
                        self.id, kept + 1, self.bus.last_seq)  # fmt: skip
            self.bus.rebase(kept)
        return True

    async def keep_told_events(self) -> None:
        """Keep every event the worker told (the store skips those it kept itself): a worker
        that takes the flight on numbers its events on from them."""
        if self.keep_told is None:
            return
        try:
            await asyncio.to_thread(self.keep_told, self.bus.since(0))
        except Exception:  # the store unreachable: the events not kept are lost, as said
            log.exception("flight %s: the events its worker told were not kept", self.id)

    def _lose(self) -> None:
        """No worker flies the flight on (no checkpoint to fly on from, or it died too
        often): the flight has failed, and says so (events for its streams, and :attr:`lost`
        for the service to keep them)."""
        snap = dict(self._state["snapshot"])
        was = snap.get("state")
        why = (
            f"its worker (pid {self.pid}) died and no other could fly it on "
            f"(it was {was}; {self.not_flown_on}): the flight has failed; its vehicles fly "
            "what they hold"
        )
        log.error("flight %s: %s", self.id, why)
        snap["state"] = FlightState.FAILED.value
        self._state = {**self._state, "snapshot": snap}
        t_s = float(snap.get("t_s") or 0.0)
        for kind, payload in (
            (EventKind.FLIGHT, {"state": FlightState.FAILED.value, "was": was}),
            (EventKind.ALARM, {"why": "flight worker lost"}),
        ):
            self.bus.publish(FlightEvent(time.time(), t_s, None, kind, why, payload=payload))
        self.lost = True

    def _end(self) -> None:
        doc = self._kept_final()
        self.final = None if doc is None else (doc["snapshot"], doc.get("map"))
        if self.final is None and self._closing:
            return
        if self.final is None:
            self.final = self._state["snapshot"], None
        if self.on_over is not None:
            self.on_over(self)

    # -- stopping -------------------------------------------------------------------------------

    async def close(self, *, stop: bool) -> None:
        """Stop following; with ``stop`` tell the worker to stop first (a flight on bundled
        simulator vehicles then ends; one on live vehicles flies on, for the next service
        process) and wait for it to exit."""
        if stop and not self.over:
            with contextlib.suppress(ServiceError):
                await self.request("stop")
            await self._wait_gone(30.0)
        self._closing = True
        if self._feed is not None:
            self._feed.cancel()
            with contextlib.suppress(BaseException):
                await self._feed

    async def _wait_gone(self, timeout_s: float) -> None:
        """Until its worker has exited (at most ``timeout_s`` of wall time)."""
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(timeout_s):
                if self.proc is not None and self.proc.pid == self.pid:
                    await self.proc.wait()  # ours: reaped by the event loop
                    return
                while _alive(self.pid):
                    await asyncio.sleep(0.01)

    def kill(self) -> None:
        """Kill the worker at once (its flight is flown on from its checkpoint)."""
        with contextlib.suppress(ProcessLookupError):
            os.kill(self.pid, signal.SIGKILL)


def _ended(flight: WorkerFlight) -> ServiceError:
    return Conflict(f"flight {flight.id} is {flight.state.value}")


class Spawner:
    """Starts flight workers for one service process, keeping one more started ahead and
    loaded (``--standby``): a flight created, or a worker that died replaced, then waits for
    no Python start-up (over a second here). Close it with the service (:meth:`close`)."""

    def __init__(
        self,
        db_url: str,
        *,
        feed_silence_s: float = FEED_SILENCE_S,
        answer_wall_s: float = RECONNECT_WALL_S,
        spare: bool = True,
        nice: int | None = None,
    ) -> None:
        self.db_url = db_url
        self.spare = spare
        """Keep one worker started ahead (else each starts when it is needed)."""
        self.nice = nice
        """The workers' scheduling priority (None: this process's)."""
        self.feed_silence_s = feed_silence_s
        """A worker's feed silent this long (wall s) is taken as broken."""
        self.answer_wall_s = answer_wall_s
        """A worker whose feed broke but which still runs is killed and replaced when it
        has not answered within this long (wall s): a hung worker."""
        self._spare: asyncio.subprocess.Process | None = None
        self._warming: asyncio.Task[None] | None = None

    async def spawn(
        self, folder: Path, resume: bool
    ) -> tuple[asyncio.subprocess.Process, dict[str, Any]]:
        """Start a worker on the flight of ``folder`` and read its first line: ready, or
        why not."""
        folder.mkdir(parents=True, exist_ok=True)
        proc = await self._take_spare()
        if proc is not None:
            assert proc.stdin is not None
            order = {"folder": str(folder), "db": self.db_url, "resume": resume}
            proc.stdin.write(json.dumps(order).encode() + b"\n")
            try:
                await proc.stdin.drain()
                proc.stdin.close()
            except ConnectionError:
                proc = None  # it died waiting: start one the slow way
        if proc is None:
            args = [sys.executable, "-m", WORKER, str(folder), "--db", self.db_url]
            args += self._nice_args()
            if resume:
                args.append("--resume")
            with (folder / LOG_FILE).open("ab") as errors:
                proc = await asyncio.create_subprocess_exec(
                    *args,
                    stdin=asyncio.subprocess.DEVNULL,
                    stdout=asyncio.subprocess.PIPE,
                    stderr=errors,
                    start_new_session=True,  # a signal to the service's group is not its
                )
        try:
            ready = await _ready(proc, folder)
        finally:
            self._warm()
        nice = ready.get("snapshot", {}).get("worker", {}).get("nice")
        if self.nice is not None and nice != self.nice:
            log.warning(
                "flight %s: its worker runs at priority %s, not %s (CAP_SYS_NICE?)",
                folder.name, nice, self.nice,
            )  # fmt: skip
        return proc, ready

    async def _take_spare(self) -> asyncio.subprocess.Process | None:
        if self._warming is not None:
            with contextlib.suppress(Exception):
                await self._warming
        spare, self._spare = self._spare, None
        if spare is None or spare.returncode is not None:
            return None
        return spare

    def _warm(self) -> None:
        """Start the next spare (in the background)."""
        if not self.spare:
            return
        if self._spare is None and (self._warming is None or self._warming.done()):
            self._warming = asyncio.get_running_loop().create_task(self._start_spare())

    async def _start_spare(self) -> None:
        self._spare = await asyncio.create_subprocess_exec(
            sys.executable, "-m", WORKER, "--standby", *self._nice_args(),
            stdin=asyncio.subprocess.PIPE, stdout=asyncio.subprocess.PIPE,
            stderr=asyncio.subprocess.DEVNULL, start_new_session=True,
        )  # fmt: skip

    def _nice_args(self) -> list[str]:
        return [] if self.nice is None else ["--nice", str(self.nice)]

    async def close(self) -> None:
        """The spare ends (its stdin closed): one being started is waited for first (a start
        cancelled midway would leave its process's pipes to be closed after the event loop)."""
        if self._warming is not None:
            with contextlib.suppress(Exception):
                await asyncio.wait_for(asyncio.shield(self._warming), 30.0)
        spare, self._spare = self._spare, None
        if spare is not None and spare.returncode is None:
            assert spare.stdin is not None
            spare.stdin.close()
            try:
                await asyncio.wait_for(spare.wait(), 5.0)
            except TimeoutError:
                spare.kill()
                await spare.wait()


WORKER = "gcs.service.worker"


async def _ready(proc: asyncio.subprocess.Process, folder: Path) -> dict[str, Any]:
    """A worker's first line: its ready document, or its error raised here."""
    assert proc.stdout is not None
    try:
        line = await asyncio.wait_for(proc.stdout.readline(), READY_WALL_S)
    except TimeoutError:
        proc.kill()
        raise ServiceError(f"flight {folder.name}: its worker did not start") from None
    try:
        doc = json.loads(line)
    except ValueError:
        doc = {}
    if "ready" in doc:
        ready: dict[str, Any] = doc["ready"]
        return ready
    await proc.wait()
    error = doc.get("error") or {"message": f"its worker exited ({proc.returncode})"}
    raise error_of(error)


async def _request(
    folder: Path, op: str, args: Mapping[str, Any], *, timeout_s: float
) -> dict[str, Any]:
    """One request on the worker's socket: its whole answer (an error raised again)."""
    async with asyncio.timeout(timeout_s):
        reader, writer = await asyncio.open_unix_connection(
            str(socket_path(folder)), limit=LINE_LIMIT
        )
        try:
            writer.write(json.dumps({"op": op, "args": args}).encode() + b"\n")
            await writer.drain()
            line = await reader.readline()
        finally:
            writer.close()
    if not line:
        raise ConnectionResetError("no answer")
    doc: dict[str, Any] = json.loads(line)
    if not doc.get("ok"):
        raise error_of(doc.get("error") or {})
    return doc


def _alive(pid: int) -> bool:
    """A process another service process started (not this one's child) still runs."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True
