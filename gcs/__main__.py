"""Operator command line: missions, commands and live status over MAVLink.

    python -m gcs mission upload CONN FILE [--type mission|fence|rally] [--verify]
    python -m gcs mission download CONN --out FILE [--type ...]
    python -m gcs mission clear CONN [--type ...]
    python -m gcs status CONN [CONN ...] [--period S] [--count N] [--stream-rate HZ]
    python -m gcs command CONN arm|disarm|start|mode NAME|speed M_S
    python -m gcs rehearse SCENARIO [--speedup S] [--wind SPEED_M_S,FROM_DEG] [--loss P]
        [--forecast-wind SPEED_M_S,FROM_DEG]
        [--seed N] [--connect CONN ...] [--json OUT] [--report DIR] [--arrival-s T]
        [--blackout VEHICLE,START_S,DURATION_S] [--threats-from FILE]
        [--speed-bias VEHICLE,FRACTION] [--utc-offset VEHICLE,SECONDS] [--db URL]
        [--abort VEHICLE|all,AT_S[,rtl|loiter]] [--hill LAT,LON,RADIUS_M,HEIGHT_M]
        [--on-vehicle-lost continue|retime|abort] [--stall-bound S] [--hard-deadline S]
        [--replan-delay S]

Common options: ``--vehicle SYSID`` (default: the first vehicle heard), ``--wait S`` (how long
to wait for it), ``--timeout S`` and ``--retries N`` per protocol exchange (default: a timeout
from the measured round trip, and failure only when the vehicle goes silent or the exchange
stops advancing, :mod:`gcs.mavlink.retry`), ``--signing-key HEX`` or ``--signing-passphrase
TEXT``. A mission transfer still running after a second prints its progress on stderr, once a
second. ``.plan`` files are QGroundControl JSON, ``.waypoints`` / ``.wpl`` / ``.txt`` are WPL
110. Exit 0 on success, 1 when the vehicle or link fails the operation (timeout, denied,
rejected item: the message says which and why), 2 for bad input."""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import math
import signal
import sys
import time
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import replace
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, Final, TextIO

from gcs.errors import GcsError
from gcs.mavlink import commands
from gcs.mavlink.link import Link
from gcs.mavlink.mission_protocol import Transfer
from gcs.mavlink.signing import SigningConfig, key_from_passphrase
from gcs.mavlink.status import status_line
from gcs.mavlink.vehicle import Vehicle
from gcs.service.stubs import DEFAULT_SPEEDUP
from planner.errors import PlannerError
from planner.mission import MissionItem
from planner.missionfile import read_mission_file, write_mission_file

if TYPE_CHECKING:
    from gcs.rehearsal.rehearse import Abort

MISSION_TYPES = {"mission": 0, "fence": 1, "rally": 2}


class UsageError(Exception):
    """Bad input from the command line (exit 2)."""


def _signing(args: argparse.Namespace) -> SigningConfig | None:
    if args.signing_key and args.signing_passphrase:
        raise UsageError("give --signing-key or --signing-passphrase, not both")
    if args.signing_passphrase:
        return SigningConfig(secret_key=key_from_passphrase(args.signing_passphrase))
    if args.signing_key:
        try:
            return SigningConfig.from_hex(args.signing_key)
        except ValueError as err:
            raise UsageError(f"--signing-key: {err}") from None
    return None


def _open(args: argparse.Namespace, conn: str) -> Link:
    """The link for ``conn`` (start it with ``async with``); bad options are a UsageError."""
    # Like MAVProxy, ask for telemetry: ArduPilot streams nothing on a port nobody asked.
    rate_hz = getattr(args, "stream_rate", None)
    try:
        return Link.open(
            conn, system_id=args.system_id, signing=_signing(args), stream_rate_hz=rate_hz
        )
    except ValueError as err:
        raise UsageError(str(err)) from None


async def _vehicle(link: Link, args: argparse.Namespace) -> Vehicle:
    peer = await link.wait_vehicle(args.vehicle, timeout_s=args.wait)
    return Vehicle(link, peer.system_id, peer.component_id)


def _transfer_options(args: argparse.Namespace) -> dict[str, float | int | None]:
    """``--timeout`` / ``--retries`` as the transfers take them (None: the adaptive policy)."""
    return {"timeout_s": args.timeout, "retries": args.retries}


class ProgressLines:
    """Progress of a slow mission transfer on ``out``: nothing during the first ``first_s``
    (a fast transfer says nothing), then a line at most every ``every_s`` (wall seconds)."""

    _VERBS: Final = MappingProxyType({"upload": "uploading", "download": "downloading"})

    def __init__(
        self,
        out: TextIO | None = None,
        *,
        clock: Callable[[], float] = time.monotonic,
        first_s: float = 1.0,
        every_s: float = 1.0,
    ) -> None:
        self.out = out
        self.clock = clock
        self.first_s = first_s
        self.every_s = every_s
        self.lines = 0
        self._transfer: Transfer | None = None
        self._started_s = clock()
        self._printed_s = -math.inf

    def watch(self, transfer: Transfer) -> None:
        """The transfer under way (the upload, then its verify download)."""
        self._transfer = transfer

    def poll(self) -> None:
        """Print a line if one is due."""
        t, now = self._transfer, self.clock()
        if t is None or t.done or now - self._started_s < self.first_s:
            return
        if now - self._printed_s < self.every_s:
            return
        done, total = t.progress
        verb = self._VERBS.get(t.operation, t.operation)
        resent = t.counters["resent"]
        print(
            f"{verb} {done}/{total} items, {resent} resend{'' if resent == 1 else 's'}",
            file=self.out or sys.stderr,
            flush=True,
        )
        self._printed_s = now
        self.lines += 1

    async def run(self) -> None:
        """Poll until cancelled."""
        while True:
            await asyncio.sleep(min(self.first_s, self.every_s) / 4)
            self.poll()


async def _with_progress(transfer: Callable[[ProgressLines], Awaitable[object]]) -> None:
    """Run the transfer coroutine ``transfer(lines)`` with its progress lines on stderr."""
    lines = ProgressLines()
    ticker = asyncio.create_task(lines.run())
    try:
        await transfer(lines)
    finally:
        ticker.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await ticker


async def mission_upload(args: argparse.Namespace) -> str:
    mission_type = MISSION_TYPES[args.type]
    items = [replace(it, mission_type=mission_type) for it in read_mission_file(args.file)]
    async with _open(args, args.conn) as link:
        vehicle = await _vehicle(link, args)
        t0 = time.monotonic()
        await _with_progress(
            lambda lines: vehicle.upload_mission(
                items,
                mission_type=mission_type,
                verify=args.verify,
                on_transfer=lines.watch,
                **_transfer_options(args),
            )
        )
        checked = ", verified by download" if args.verify else ""
        return (
            f"uploaded {len(items)} {args.type} items to vehicle {vehicle.system_id} "
            f"in {time.monotonic() - t0:.2f} s{checked}"
        )


async def mission_download(args: argparse.Namespace) -> str:
    mission_type = MISSION_TYPES[args.type]
    async with _open(args, args.conn) as link:
        vehicle = await _vehicle(link, args)
        got: list[list[MissionItem]] = []

        async def download(lines: ProgressLines) -> None:
            got.append(
                await vehicle.download_mission(
                    mission_type=mission_type, on_transfer=lines.watch, **_transfer_options(args)
                )
            )

        await _with_progress(download)
    (items,) = got
    write_mission_file(args.out, items)
    return (
        f"downloaded {len(items)} {args.type} items from vehicle {vehicle.system_id} to {args.out}"
    )


async def mission_clear(args: argparse.Namespace) -> str:
    async with _open(args, args.conn) as link:
        vehicle = await _vehicle(link, args)
        await vehicle.clear_mission(
            mission_type=MISSION_TYPES[args.type], **_transfer_options(args)
        )
    return f"cleared the {args.type} items of vehicle {vehicle.system_id}"


async def command(args: argparse.Namespace) -> str:
    action, rest = args.action, args.value
    needs = {"mode": "a mode name", "speed": "a speed in m/s"}
    if action in needs and rest is None:
        raise UsageError(f"command {action} needs {needs[action]}")
    if action not in needs and rest is not None:
        raise UsageError(f"command {action} takes no value (got {rest!r})")
    speed_m_s = 0.0
    if action == "speed":
        try:
            speed_m_s = float(rest)
        except ValueError:
            raise UsageError(f"command speed: {rest!r} is not a number") from None
    async with _open(args, args.conn) as link:
        v = await _vehicle(link, args)
        sysid, comp, t, r = v.system_id, v.component_id, args.timeout, args.retries
        if action in ("arm", "disarm"):
            send = commands.arm if action == "arm" else commands.disarm
            await send(link, sysid, force=args.force, target_component=comp, timeout_s=t, retries=r)
        elif action == "start":
            await commands.start_mission(link, sysid, target_component=comp, timeout_s=t, retries=r)
        elif action == "mode":
            await commands.set_mode(
                link, sysid, rest, autopilot=v.autopilot, target_component=comp, timeout_s=t,
                retries=r,
            )  # fmt: skip
        else:
            await commands.change_speed(
                link, sysid, speed_m_s, target_component=comp, timeout_s=t, retries=r
            )
    what = action if rest is None else f"{action} {rest}"
    return f"vehicle {v.system_id}: {what} accepted"


async def status(args: argparse.Namespace) -> str:
    """One line of live telemetry per vehicle, every ``--period`` s, until interrupted."""
    vehicles: dict[tuple[int, int], Vehicle] = {}
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    with contextlib.suppress(NotImplementedError):
        loop.add_signal_handler(signal.SIGINT, stop.set)
        loop.add_signal_handler(signal.SIGTERM, stop.set)
    async with contextlib.AsyncExitStack() as stack:
        links = [await stack.enter_async_context(_open(args, conn)) for conn in args.conn]
        deadline = time.monotonic() + args.wait
        printed = 0
        while not stop.is_set():
            for i, link in enumerate(links):
                for sysid, peer in link.vehicles.items():
                    if args.vehicle is None or sysid == args.vehicle:
                        key = (i, sysid)
                        if key not in vehicles:
                            vehicles[key] = Vehicle(link, sysid, peer.component_id)
            if not vehicles and time.monotonic() > deadline:
                who = "no vehicle" if args.vehicle is None else f"no vehicle {args.vehicle}"
                raise GcsError(f"{who} heard on {', '.join(args.conn)} within {args.wait:g} s")
            # Wait first: a vehicle just discovered has had no time to report anything.
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(args.period):
                    await stop.wait()
            if not vehicles:
                continue
            now = time.monotonic()
            for (i, _), v in sorted(vehicles.items()):
                counters, name = links[i].counters, str(links[i].endpoint)
                print(status_line(v.state, counters, now, link_name=name))
            sys.stdout.flush()
            printed += 1
            if args.count is not None and printed >= args.count:
                break
    return ""


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--vehicle", type=int, help="system id (default: the first vehicle heard)")
    p.add_argument("--wait", type=float, default=10.0, help="seconds to wait for the vehicle")
    p.add_argument(
        "--timeout",
        type=float,
        help="seconds before a resend (default: from the measured round trip, 10 ms to 1.5 s)",
    )
    p.add_argument(
        "--retries",
        type=int,
        help="resends per exchange (default: no count; fail after 10 s without hearing the "
        "vehicle or 20 s without progress)",
    )
    p.add_argument("--system-id", type=int, default=255, help="our MAVLink system id")
    p.add_argument("--signing-key", help="MAVLink 2 signing key, 64 hex digits")
    p.add_argument("--signing-passphrase", help="signing key as MAVProxy derives it")


def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m gcs", description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)

    mission = sub.add_parser("mission", help="upload, download or clear a mission")
    msub = mission.add_subparsers(dest="op", required=True)
    up = msub.add_parser("upload", help="upload a .plan or .waypoints file")
    up.add_argument("conn")
    up.add_argument("file")
    up.add_argument("--verify", action="store_true", help="download again and compare")
    down = msub.add_parser("download", help="download to a .plan or .waypoints file")
    down.add_argument("conn")
    down.add_argument("--out", required=True)
    clear = msub.add_parser("clear", help="delete the vehicle's items")
    clear.add_argument("conn")
    for p, fn in ((up, mission_upload), (down, mission_download), (clear, mission_clear)):
        p.add_argument("--type", choices=sorted(MISSION_TYPES), default="mission")
        _common(p)
        p.set_defaults(fn=fn)

    st = sub.add_parser("status", help="one line of live telemetry per vehicle")
    st.add_argument("conn", nargs="+")
    st.add_argument("--period", type=float, default=1.0, help="seconds between updates")
    st.add_argument("--count", type=int, help="stop after this many updates")
    st.add_argument("--stream-rate", type=float, default=4.0, help="telemetry rate to request (Hz)")
    _common(st)
    st.set_defaults(fn=status)

    cmd = sub.add_parser("command", help="arm, disarm, start, mode NAME, speed M_S")
    cmd.add_argument("conn")
    cmd.add_argument("action", choices=["arm", "disarm", "start", "mode", "speed"])
    cmd.add_argument("value", nargs="?")
    cmd.add_argument("--force", action="store_true", help="arm/disarm without checks")
    _common(cmd)
    cmd.set_defaults(fn=command)

    rh = sub.add_parser("rehearse", help="fly a scenario's mission to its arrival time")
    rh.add_argument("scenario", help="scenario file (.yaml or .json)")
    rh.add_argument("--speedup", type=float, default=DEFAULT_SPEEDUP, help="stub time / wall time")
    rh.add_argument("--wind", help="SPEED_M_S,FROM_DEG mean wind for the stub")
    rh.add_argument(
        "--free-run",
        action="store_true",
        help="the stub keeps its speed-up on the wall clock whatever the coordinator's delays "
        "(default: in lock step, it waits for the coordinator, so a busy machine slows the "
        "flight instead of answering late in it)",
    )
    rh.add_argument(
        "--forecast-wind",
        metavar="SPEED_M_S,FROM_DEG",
        help="forecast wind the schedule is timed in (instead of the scenario's wind; the "
        "vehicles' measured wind takes over in flight)",
    )
    rh.add_argument("--loss", type=float, default=0.0, help="stub packet loss probability")
    rh.add_argument("--seed", type=int, default=0, help="planner and stub seed")
    rh.add_argument("--connect", nargs="+", default=[], help="fly these vehicles instead")
    rh.add_argument(
        "--truth",
        help="with --connect: the simulator's truth log (sitl_stub --truth), for true arrivals; "
        "without: where the rehearsal's stub writes its truth log (kept)",
    )
    rh.add_argument(
        "--lockstep",
        metavar="FILE",
        help="with --connect: the lock-step file of the simulator flown (sitl_stub --lockstep "
        "FILE): the mission clock runs on its pace clock and the simulator waits for this "
        "coordinator",
    )
    rh.add_argument("--json", dest="json_out", help="write the flight record here")
    rh.add_argument("--report", help="write the report (figures, tables) into this directory")
    rh.add_argument("--arrival-s", type=float, help="required arrival (mission s) to request")
    rh.add_argument(
        "--blackout",
        action="append",
        default=[],
        help="VEHICLE,START_S,DURATION_S: that vehicle's link goes dark (mission time)",
    )
    rh.add_argument(
        "--speed-bias",
        action="append",
        default=[],
        help="VEHICLE,FRACTION: that stub vehicle flies (1 + FRACTION) x its true airspeed",
    )
    rh.add_argument(
        "--utc-offset",
        action="append",
        default=[],
        help="VEHICLE,SECONDS: that stub vehicle's UTC runs this far ahead of the true UTC",
    )
    rh.add_argument(
        "--hill",
        action="append",
        default=[],
        help="LAT,LON,RADIUS_M,HEIGHT_M: a hill in the stub's terrain that the scenario's lacks "
        "(a terrain database error: a vehicle may fly into it)",
    )
    rh.add_argument(
        "--on-vehicle-lost",
        choices=["continue", "retime", "abort"],
        default="continue",
        help="when a vehicle crashes or stalls: the others keep their slots (continue, the "
        "default), the team time moves to the earliest the others can make (retime), or the "
        "team is aborted (abort)",
    )
    rh.add_argument(
        "--stall-bound",
        type=float,
        default=300.0,
        metavar="S",
        help="a vehicle making no progress along its route this long (mission s) is lost "
        "(one that stops moving is lost after 10 s)",
    )
    rh.add_argument(
        "--hard-deadline",
        type=float,
        default=3600.0,
        metavar="S",
        help="the flight ends, failed, this long after the planned arrival (mission s)",
    )
    rh.add_argument("--threats-from", help="file to watch for pop-up threats (JSON lines)")
    rh.add_argument(
        "--abort",
        action="append",
        default=[],
        help="VEHICLE|all,AT_S[,rtl|loiter]: abort at that mission time (it leaves the team)",
    )
    rh.add_argument(
        "--db",
        help="keep the flight in this database as it happens (SQLAlchemy URL, e.g. "
        "sqlite:///out/tcgcs.db or postgresql+psycopg://user@host/db)",
    )
    rh.add_argument(
        "--resume",
        metavar="FLIGHT_ID",
        help="resume this flight of --db from its last checkpoint after its process died: "
        "reach its vehicles again (--connect, else the flight's own connections), compare "
        "their missions with the kept ones and go on; nothing launched or uploaded twice",
    )
    rh.add_argument(
        "--replan-delay",
        type=float,
        default=0.0,
        metavar="S",
        help="test hook: add S wall seconds to every pop-up re-plan (a re-plan that comes back "
        "too late: the vehicles whose routes enter the zone hold short of it)",
    )
    rh.add_argument(
        "--allow-conflicts",
        action="store_true",
        help="launch even where the plan leaves two vehicles under the separation (each pair "
        "said, an alarm): a rehearsal of the resolution in flight",
    )
    rh.add_argument("--tolerance", type=float, default=1.0, help="pass mark for arrivals (s)")
    rh.add_argument("--quiet", action="store_true", help="no progress lines")
    rh.set_defaults(fn=rehearse_cmd)

    db = sub.add_parser("db", help="the service's database")
    dbsub = db.add_subparsers(dest="op", required=True)
    upg = dbsub.add_parser("upgrade", help="bring the schema to the latest revision (Alembic)")
    upg.add_argument(
        "--url",
        help="SQLAlchemy URL (default TCGCS_DATABASE_URL, else the "
        "service's SQLite file in TCGCS_DATA_DIR)",
    )
    upg.set_defaults(fn=db_upgrade_cmd)

    sv = sub.add_parser("serve", help="run the coordinator service (REST API and stream)")
    sv.add_argument("--host", help="bind address (default TCGCS_HOST, else 127.0.0.1)")
    sv.add_argument("--port", type=int, help="port (default TCGCS_PORT, else 8600)")
    sv.set_defaults(fn=serve_cmd)

    dm = sub.add_parser(
        "demo", help="fly the paper scenario through the service's REST API and stream"
    )
    dm.add_argument("scenario", nargs="?", help="scenario file (default: the paper's)")
    dm.add_argument("--url", help="a running service (default: start one on loopback)")
    dm.add_argument("--token", help="its bearer token (with --url)")
    dm.add_argument("--report", default="out/demo-report", help="report directory")
    dm.add_argument("--speedup", type=float, default=DEFAULT_SPEEDUP)
    dm.add_argument("--quiet", action="store_true")
    dm.set_defaults(fn=demo_cmd)
    return ap


def _rehearsal_options(args: argparse.Namespace) -> object:
    from pathlib import Path

    from gcs.coordination.config import FlightConfig
    from gcs.rehearsal.rehearse import Blackout, Hill, RehearsalOptions
    from planner.errors import ScenarioError
    from planner.scenario import load_scenario, parse_wind

    path = Path(args.scenario)
    scenario = load_scenario(path)
    if args.forecast_wind is not None:
        try:
            forecast = parse_wind(args.forecast_wind, "--forecast-wind")
        except ScenarioError as err:
            raise UsageError(str(err)) from None
        scenario = scenario.with_forecast_wind(forecast)
    if not (args.speedup > 0 and args.speedup < 10_000):
        raise UsageError(f"--speedup must be in (0, 10000), got {args.speedup}")
    if not 0.0 <= args.loss < 1.0:
        raise UsageError(f"--loss must be in [0, 1), got {args.loss}")
    wind = None
    if args.wind:
        try:
            speed, from_deg = (float(x) for x in args.wind.split(","))
        except ValueError:
            raise UsageError(f"--wind: expected SPEED_M_S,FROM_DEG, got {args.wind!r}") from None
        if not 0.0 <= speed < 50.0:
            raise UsageError(f"--wind: speed {speed:g} m/s is outside [0, 50)")
        wind = (speed, from_deg % 360.0)
    ids = [v.id for v in scenario.vehicles]
    blackouts = []
    for text in args.blackout:
        parts = text.split(",")
        try:
            vid, start, dur = parts[0], float(parts[1]), float(parts[2])
        except (IndexError, ValueError):
            raise UsageError(
                f"--blackout: expected VEHICLE,START_S,DURATION_S, got {text!r}"
            ) from None
        if vid not in ids:
            raise UsageError(f"--blackout: no vehicle {vid!r} in the scenario ({', '.join(ids)})")
        if start < 0 or dur <= 0:
            raise UsageError(f"--blackout {text}: start must be >= 0 and duration > 0")
        blackouts.append(Blackout(vid, start, dur))
    aborts = [_abort(text, ids) for text in args.abort]
    hills = []
    for text in args.hill:
        try:
            lat, lon, radius, height = (float(x) for x in text.split(","))
        except ValueError:
            raise UsageError(f"--hill: expected LAT,LON,RADIUS_M,HEIGHT_M, got {text!r}") from None
        if not (abs(lat) < 90.0 and abs(lon) <= 180.0 and radius > 0.0 and height > 0.0):
            raise UsageError(f"--hill {text}: a latitude, a longitude, RADIUS_M > 0, HEIGHT_M > 0")
        hills.append(Hill(lat, lon, radius, height))
    for option, value in (
        ("--stall-bound", args.stall_bound),
        ("--hard-deadline", args.hard_deadline),
    ):
        if not (math.isfinite(value) and value > 0.0):
            raise UsageError(f"{option} must be a positive number of seconds, got {value:g}")
    if not (math.isfinite(args.replan_delay) and args.replan_delay >= 0.0):
        raise UsageError(f"--replan-delay must be >= 0 seconds, got {args.replan_delay:g}")
    speed_bias = _per_vehicle(args.speed_bias, "--speed-bias", "FRACTION", ids, (-0.5, 0.5))
    utc_offsets = _per_vehicle(args.utc_offset, "--utc-offset", "SECONDS", ids, (-1e6, 1e6))
    if args.connect and (blackouts or args.wind or args.loss or speed_bias or utc_offsets or hills):
        raise UsageError(
            "--blackout, --wind, --loss, --speed-bias, --utc-offset and --hill apply to the "
            "stub, not to --connect"
        )
    if args.lockstep and not args.connect:
        raise UsageError("--lockstep FILE joins a simulator flown with --connect")
    if args.lockstep and not Path(args.lockstep).is_file():
        raise UsageError(f"--lockstep {args.lockstep}: no such file (start sitl_stub first)")
    if args.truth and not Path(args.truth).resolve().parent.is_dir():
        raise UsageError(f"--truth {args.truth}: directory does not exist")
    return RehearsalOptions(
        scenario_path=path,
        scenario=scenario,
        speedup=args.speedup,
        wind=wind,
        loss=args.loss,
        seed=args.seed,
        connect=args.connect,
        truth=Path(args.truth) if args.truth else None,
        json_out=Path(args.json_out) if args.json_out else None,
        report_dir=Path(args.report) if args.report else None,
        required_arrival_s=args.arrival_s,
        blackouts=blackouts,
        aborts=aborts,
        speed_bias=speed_bias,
        utc_offsets_s=utc_offsets,
        hills=hills,
        threats_from=Path(args.threats_from) if args.threats_from else None,
        quiet=args.quiet,
        lockstep=not args.free_run,
        lockstep_file=Path(args.lockstep) if args.lockstep else None,
        config=FlightConfig(
            seed=args.seed,
            on_vehicle_lost=args.on_vehicle_lost,
            stall_bound_s=args.stall_bound,
            hard_deadline_s=args.hard_deadline,
            replan_delay_wall_s=args.replan_delay,
            allow_conflicts=args.allow_conflicts,
        ),
        db_url=args.db,
        resume=args.resume,
    )


def _abort(text: str, ids: list[str]) -> Abort:
    """``--abort VEHICLE|all,AT_S[,rtl|loiter]``."""
    from gcs.rehearsal.rehearse import Abort

    parts = text.split(",")
    try:
        vid, at_s = parts[0], float(parts[1])
    except (IndexError, ValueError):
        raise UsageError(f"--abort: expected VEHICLE|all,AT_S[,rtl|loiter], got {text!r}") from None
    mode = parts[2] if len(parts) > 2 else "rtl"
    if vid != "all" and vid not in ids:
        raise UsageError(f"--abort: no vehicle {vid!r} in the scenario ({', '.join(ids)})")
    if mode not in ("rtl", "loiter") or len(parts) > 3:
        raise UsageError(f"--abort {text}: the mode is rtl or loiter")
    if not (math.isfinite(at_s) and at_s >= 0.0):
        raise UsageError(f"--abort {text}: AT_S must be a mission time >= 0")
    return Abort(None if vid == "all" else vid, at_s, "rtl" if mode == "rtl" else "loiter")


def _per_vehicle(
    texts: list[str], option: str, what: str, ids: list[str], bounds: tuple[float, float]
) -> dict[str, float]:
    """``VEHICLE,VALUE`` options: one value per named scenario vehicle."""
    out: dict[str, float] = {}
    for text in texts:
        vid, _, value_text = text.partition(",")
        try:
            value = float(value_text)
        except ValueError:
            raise UsageError(f"{option}: expected VEHICLE,{what}, got {text!r}") from None
        if vid not in ids:
            raise UsageError(f"{option}: no vehicle {vid!r} in the scenario ({', '.join(ids)})")
        if not (math.isfinite(value) and bounds[0] <= value <= bounds[1]):
            raise UsageError(f"{option} {text}: {what} must be in [{bounds[0]:g}, {bounds[1]:g}]")
        out[vid] = value
    return out


async def rehearse_cmd(args: argparse.Namespace) -> str:
    from gcs.rehearsal.rehearse import RehearsalOptions, passed, rehearse
    from gcs.rehearsal.report import arrival_table, write_report

    opts = _rehearsal_options(args)
    assert isinstance(opts, RehearsalOptions)
    record = await rehearse(opts)
    print(arrival_table(record), flush=True)
    if opts.report_dir is not None:
        written = write_report(record, opts.report_dir)  # the record carries its world
        print(f"gcs: report in {opts.report_dir} ({', '.join(p.name for p in written)})")
    for alarm in record["alarms"]:
        print(f"gcs: alarm at {alarm['t_s']:.1f} s {alarm['vehicle'] or 'team'}: {alarm['reason']}")
    entered = record["zone_entries"]
    if entered:
        raise GcsError(
            "rehearsal failed: forbidden zone entered (flown track): "
            + "; ".join(
                f"{z['vehicle']} inside {z['zone']} for {z['inside_s']:g} s, "
                f"{-z['closest_m']:.0f} m deep"
                for z in entered
            )
        )
    if record["state"] == "failed":
        raise GcsError(f"rehearsal failed: {record['state_reason']}")
    if not passed(record, args.tolerance):
        raise GcsError(
            f"rehearsal missed: arrivals outside +/-{args.tolerance:g} s or separation below "
            f"{record['separation_m']:g} m (see the table)"
        )
    return f"rehearsal passed: every arrival within +/-{args.tolerance:g} s"


async def db_upgrade_cmd(args: argparse.Namespace) -> str:
    from gcs.api.settings import Settings
    from gcs.store.repository import Store

    url = args.url or Settings().db_url()
    if url.startswith("sqlite:///"):
        Path(url.removeprefix("sqlite:///")).parent.mkdir(parents=True, exist_ok=True)
    Store.open(url).close()  # opening migrates to head
    return f"database {url.split('@')[-1]} is at the latest revision"


async def serve_cmd(args: argparse.Namespace) -> str:
    import uvicorn

    from gcs.api.app import create_app
    from gcs.api.settings import Settings

    overrides: dict[str, object] = {}
    if args.host:
        overrides["host"] = args.host
    if args.port is not None:
        if not 1 <= args.port <= 65535:
            raise UsageError(f"--port must be in 1..65535, got {args.port}")
        overrides["port"] = args.port
    settings = Settings(**overrides)  # type: ignore[arg-type]
    app = create_app(settings)  # a bad tile file is an error before anything is served
    print(f"gcs: serving on http://{settings.host}:{settings.port}/v1 (docs at /v1/docs)")
    config = uvicorn.Config(app, host=settings.host, port=settings.port, log_level="warning")
    server = uvicorn.Server(config)
    stop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        # A stop asked for (Ctrl-C, or SIGTERM from a service manager) is a graceful one, and
        # a normal end: exit 0 (uvicorn would raise the signal again once stopped, and SIGTERM
        # would then kill the process, status 143). A second signal stops at once.
        stop.add_signal_handler(sig, _stop_server, server)
    server.capture_signals = contextlib.nullcontext  # type: ignore[method-assign,assignment]
    settled = asyncio.create_task(_settle(server, app))
    try:
        await server.serve()
    finally:
        settled.cancel()
        watch = getattr(app.state, "loop_watch", None)
        if watch is not None:
            watch.stop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            stop.remove_signal_handler(sig)
    return "service stopped"


async def _settle(server: Any, app: Any) -> None:
    """Once the service serves: what it started with kept out of the garbage collector's
    passes (a full pass over it held every request 140-160 ms under load), and a watch on
    its event loop (``tcgcs_api_loop_stall_max_seconds``; holds over 50 ms in its log)."""
    from gcs.service.loopwatch import LoopWatch, freeze_start_up

    while not server.started:
        await asyncio.sleep(0.05)
    freeze_start_up()
    watch = LoopWatch()
    watch.start()
    app.state.loop_watch = watch


def _stop_server(server: Any) -> None:
    if server.should_exit:
        server.force_exit = True
    server.should_exit = True


async def demo_cmd(args: argparse.Namespace) -> str:
    from pathlib import Path

    from gcs.api.demo import PAPER, DemoOptions, run_demo
    from gcs.rehearsal.rehearse import passed
    from gcs.rehearsal.report import arrival_table

    if args.url and not args.token:
        raise UsageError("--url needs --token (a token of that service with the admin scope)")
    opts = DemoOptions(
        scenario=Path(args.scenario) if args.scenario else PAPER,
        url=args.url,
        token=args.token,
        speedup=args.speedup,
        report_dir=Path(args.report),
        quiet=args.quiet,
    )
    record = await run_demo(opts)
    print(arrival_table(record), flush=True)
    print(f"gcs: report in {opts.report_dir}")
    if not passed(record, opts.tolerance_s):
        raise GcsError("demo missed: arrivals outside +/-1 s or separation lost (see the table)")
    return "demo passed: every arrival within +/-1 s, through the service"


async def _run(args: argparse.Namespace) -> str:
    result: str = await args.fn(args)
    return result


def main(argv: Sequence[str] | None = None) -> int:
    args = parser().parse_args(argv)
    try:
        out = asyncio.run(_run(args))
    except (UsageError, PlannerError, ValueError) as err:
        print(f"gcs: error: {err}", file=sys.stderr)
        return 2
    except GcsError as err:
        print(f"gcs: error: {err}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
    if out:
        print(f"gcs: {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
