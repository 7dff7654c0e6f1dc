"""Vehicle side of the MAVLink mission protocol, as a sans-IO state machine.

The server is driven by ``handle(msg, link, now_s)`` and ``tick(now_s)`` and returns a
:class:`Reaction` (messages to send, each addressed to a link, and events for the vehicle). It
never touches a socket or a clock, so tests drive it with a fake clock.

``now_s`` is WALL time. The protocol timeouts (re-request an item after ``timeout_s``) are
transport timeouts: the GCS answers in wall time whatever the simulation speed-up, so a 1.5 s
re-request must not become 15 ms at 100x. (ArduPilot SITL uses simulated time here; with a
large speed-up it re-requests far too eagerly.)

Behaviour follows ArduPilot's ``MissionItemProtocol``:

- Upload: MISSION_COUNT -> MISSION_REQUEST_INT(seq) ... -> MISSION_ACK (with
  ``legacy_requests=True`` the requests are MISSION_REQUEST, as older ArduPilot sends them;
  either way MISSION_ITEM_INT and MISSION_ITEM are accepted). A missing item is
  re-requested after ``timeout_s``; after ``max_retries`` re-requests without progress the
  upload is cancelled (MISSION_ACK MAV_MISSION_OPERATION_CANCELLED). Legacy MISSION_ITEM is
  accepted in place of MISSION_ITEM_INT. Duplicate or out-of-order items are ignored. An
  invalid item ends the upload with the precise MAV_MISSION_RESULT.
- Unlike ArduPilot, items are staged and committed only when the upload completes, so a failed
  upload never loses the stored mission (the mission protocol spec's recommendation).
- Download is stateless: MISSION_REQUEST_LIST -> MISSION_COUNT, and any MISSION_REQUEST_INT /
  MISSION_REQUEST for a valid seq is answered with MISSION_ITEM_INT / MISSION_ITEM. Only the
  ``downloads`` counter follows it: a download counts once every item of the list announced
  to that GCS has been served (a repeated MISSION_REQUEST_LIST for the same count goes on
  with the same download; a new upload of that type ends it uncounted; an empty list does
  not count).
- Mission item 0 of the flown mission (type 0) is home: it is always read back as the current
  home, and the count is at least 1.
- Fence and rally items are stored separately and never flown.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from sitl_stub.items import (
    MAV_MISSION_TYPE_FENCE,
    MAV_MISSION_TYPE_MISSION,
    MAV_MISSION_TYPE_RALLY,
    MissionItem,
)
from sitl_stub.storage import legacy_x_from_int, legacy_x_to_int, stored_item

LinkId = int

# Commands the stub's autopilot accepts in a flown mission (ArduPlane accepts many more).
NAV_COMMANDS_WITH_LOCATION = frozenset(
    {
        mavlink2.MAV_CMD_NAV_WAYPOINT,
        mavlink2.MAV_CMD_NAV_LOITER_UNLIM,
        mavlink2.MAV_CMD_NAV_LOITER_TURNS,
        mavlink2.MAV_CMD_NAV_LOITER_TIME,
        mavlink2.MAV_CMD_NAV_LAND,
        mavlink2.MAV_CMD_NAV_TAKEOFF,
    }
)
# DO_LAND_START marks where a landing sequence begins; flown as a no-op. ArduPilot keeps its
# location (AP_Mission.cpp stored_in_location) and accepts MAV_FRAME_MISSION for it.
DO_COMMANDS_WITH_LOCATION = frozenset({mavlink2.MAV_CMD_DO_LAND_START})
MISSION_COMMANDS = (
    NAV_COMMANDS_WITH_LOCATION
    | DO_COMMANDS_WITH_LOCATION
    | {
        mavlink2.MAV_CMD_NAV_RETURN_TO_LAUNCH,
        mavlink2.MAV_CMD_DO_CHANGE_SPEED,
    }
)
FENCE_COMMANDS = frozenset(
    {
        mavlink2.MAV_CMD_NAV_FENCE_RETURN_POINT,
        mavlink2.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
        mavlink2.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION,
        mavlink2.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION,
        mavlink2.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION,
    }
)
RALLY_COMMANDS = frozenset({mavlink2.MAV_CMD_NAV_RALLY_POINT})

GLOBAL_FRAMES = frozenset(
    {
        mavlink2.MAV_FRAME_GLOBAL,
        mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT,
        mavlink2.MAV_FRAME_GLOBAL_TERRAIN_ALT,
        mavlink2.MAV_FRAME_GLOBAL_INT,
        mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
        mavlink2.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT,
    }
)
# ArduPilot's LOCATION_ALT_MAX_M.
ALT_MAX_M = 83000.0

DEFAULT_CAPACITY = {
    MAV_MISSION_TYPE_MISSION: 700,
    MAV_MISSION_TYPE_FENCE: 84,
    MAV_MISSION_TYPE_RALLY: 100,
}


class Step(enum.Enum):
    """Where the (single) upload transfer is."""

    IDLE = enum.auto()
    RECEIVING = enum.auto()


class Result(enum.Enum):
    """How the last upload ended."""

    NONE = enum.auto()
    SUCCESS = enum.auto()
    TIMEOUT = enum.auto()
    INVALID_ITEM = enum.auto()
    CANCELLED = enum.auto()
    DENIED = enum.auto()


@dataclass(frozen=True, slots=True)
class Send:
    """A message to send on one link (``link=None``: every link)."""

    link: LinkId | None
    msg: Any


@dataclass(frozen=True, slots=True)
class MissionStored:
    """A complete upload (or a clear) replaced the stored items of one mission type."""

    mission_type: int
    items: tuple[MissionItem, ...]


@dataclass(slots=True)
class Reaction:
    """What the server wants done after a message or a tick."""

    sends: list[Send] = field(default_factory=list)
    events: list[MissionStored] = field(default_factory=list)


@dataclass(slots=True)
class _Upload:
    link: LinkId
    gcs_system: int
    gcs_component: int
    mission_type: int
    start: int
    end: int  # exclusive
    partial: bool
    next_seq: int
    staged: list[MissionItem]
    last_progress_s: float
    last_request_s: float
    retries: int = 0


@dataclass(slots=True)
class _Download:
    """The items of a list announced to a GCS that it has not been sent yet (a counter's)."""

    count: int
    unsent: set[int]


# A download is followed per link, GCS system, GCS component and mission type.
_DownloadKey = tuple[LinkId, int, int, int]


@dataclass(frozen=True, slots=True)
class _Finished:
    link: LinkId
    gcs_system: int
    gcs_component: int
    mission_type: int
    last_seq: int


def _finite(*values: float) -> bool:
    return all(math.isfinite(v) for v in values)


def validate_item(item: MissionItem) -> int:
    """Return the MAV_MISSION_RESULT for one item (MAV_MISSION_ACCEPTED if it is valid)."""
    mt = item.mission_type
    cmd = item.command
    if mt == MAV_MISSION_TYPE_MISSION:
        allowed = MISSION_COMMANDS
    elif mt == MAV_MISSION_TYPE_FENCE:
        allowed = FENCE_COMMANDS
    elif mt == MAV_MISSION_TYPE_RALLY:
        allowed = RALLY_COMMANDS
    else:
        return int(mavlink2.MAV_MISSION_INVALID)
    if mt == MAV_MISSION_TYPE_MISSION and item.seq == 0:
        # Item 0 is home: ArduPilot overwrites it, so any content is accepted.
        return int(mavlink2.MAV_MISSION_ACCEPTED)
    if cmd not in allowed:
        return int(mavlink2.MAV_MISSION_UNSUPPORTED)
    if not _finite(item.param1):
        return int(mavlink2.MAV_MISSION_INVALID_PARAM1)
    if not _finite(item.param2):
        return int(mavlink2.MAV_MISSION_INVALID_PARAM2)
    has_location = (
        cmd in NAV_COMMANDS_WITH_LOCATION
        or cmd in DO_COMMANDS_WITH_LOCATION
        or mt != MAV_MISSION_TYPE_MISSION
    )
    if has_location:
        if not -900_000_000 <= item.x <= 900_000_000:
            return int(mavlink2.MAV_MISSION_INVALID_PARAM5_X)
        if not -1_800_000_000 <= item.y <= 1_800_000_000:
            return int(mavlink2.MAV_MISSION_INVALID_PARAM6_Y)
        if not _finite(item.z) or abs(item.z) >= ALT_MAX_M:
            return int(mavlink2.MAV_MISSION_INVALID_PARAM7)
        frames = GLOBAL_FRAMES
        if cmd in DO_COMMANDS_WITH_LOCATION and mt == MAV_MISSION_TYPE_MISSION:
            frames = GLOBAL_FRAMES | {mavlink2.MAV_FRAME_MISSION}
        if item.frame not in frames:
            return int(mavlink2.MAV_MISSION_UNSUPPORTED_FRAME)
    if cmd == mavlink2.MAV_CMD_NAV_LOITER_TURNS and not 0 <= item.param1 <= 255:
        return int(mavlink2.MAV_MISSION_INVALID_PARAM1)
    if cmd == mavlink2.MAV_CMD_NAV_LOITER_TIME and not 0 <= item.param1 <= 65535:
        return int(mavlink2.MAV_MISSION_INVALID_PARAM1)
    if cmd == mavlink2.MAV_CMD_DO_CHANGE_SPEED and not (
        0 <= item.param1 <= 3 and -2 <= item.param2 <= 1000
    ):
        return int(
            mavlink2.MAV_MISSION_INVALID_PARAM1
            if not 0 <= item.param1 <= 3
            else mavlink2.MAV_MISSION_INVALID_PARAM2
        )
    return int(mavlink2.MAV_MISSION_ACCEPTED)


def item_from_msg(msg: Any, *, ardupilot: bool = False) -> tuple[MissionItem | None, int]:
    """Convert MISSION_ITEM_INT or legacy MISSION_ITEM to a MissionItem, or a result code.

    With ``ardupilot`` a MISSION_ITEM's degrees become int 1e7 as AP_Mission's
    convert_MISSION_ITEM_to_MISSION_ITEM_INT does (``x * 1.0e7f``, truncated), else rounded.
    """
    if msg.get_type() == "MISSION_ITEM":
        x, y = float(msg.x), float(msg.y)
        if not math.isfinite(x) or abs(x) > 90.0:
            return None, int(mavlink2.MAV_MISSION_INVALID_PARAM5_X)
        if not math.isfinite(y) or abs(y) > 180.0:
            return None, int(mavlink2.MAV_MISSION_INVALID_PARAM6_Y)
        if ardupilot:
            xi, yi = legacy_x_to_int(x), legacy_x_to_int(y)
        else:
            xi, yi = round(x * 1e7), round(y * 1e7)
    else:
        xi, yi = int(msg.x), int(msg.y)
    item = MissionItem(
        seq=int(msg.seq),
        frame=int(msg.frame),
        command=int(msg.command),
        current=int(msg.current),
        autocontinue=int(msg.autocontinue),
        param1=float(msg.param1),
        param2=float(msg.param2),
        param3=float(msg.param3),
        param4=float(msg.param4),
        x=xi,
        y=yi,
        z=float(msg.z),
        mission_type=int(getattr(msg, "mission_type", 0)),
    )
    return item, int(mavlink2.MAV_MISSION_ACCEPTED)


def addressed_to(msg: Any, system_id: int, component_id: int) -> bool:
    """True if a message's target ids (0 = broadcast) include this system and component."""
    ts = getattr(msg, "target_system", 0)
    tc = getattr(msg, "target_component", 0)
    return ts in (0, system_id) and tc in (0, component_id)


class MissionServer:
    """The mission service of one vehicle (all three mission types).

    With ``ardupilot_storage`` (the default) flown-mission items are kept in the form ArduPilot
    stores them (:func:`sitl_stub.storage.stored_item`: frames, centimetre altitudes,
    per-command parameters) and read back that way, and a download marks ``current = 1`` as
    ``MissionItemProtocol_Waypoints::get_item`` does: on every item whose COMMAND ID equals
    the index of the NAV command being flown (``current_nav_index()``, None before a mission
    has started). With ``ardupilot_storage=False`` items are echoed exactly as sent.
    """

    def __init__(
        self,
        *,
        system_id: int,
        component_id: int = 1,
        home: MissionItem | None = None,
        timeout_s: float = 1.5,
        max_retries: int = 10,
        capacity: dict[int, int] | None = None,
        legacy_requests: bool = False,
        ardupilot_storage: bool = True,
        current_nav_index: Callable[[], int | None] | None = None,
    ) -> None:
        self.system_id = system_id
        self.ardupilot_storage = ardupilot_storage
        self.current_nav_index: Callable[[], int | None] = current_nav_index or (lambda: None)
        self.legacy_requests = legacy_requests
        self.component_id = component_id
        self.timeout_s = timeout_s
        self.max_retries = max_retries
        self.capacity = dict(DEFAULT_CAPACITY if capacity is None else capacity)
        self.home = home or MissionItem(seq=0, frame=0, command=mavlink2.MAV_CMD_NAV_WAYPOINT)
        self._stored: dict[int, tuple[MissionItem, ...]] = {
            MAV_MISSION_TYPE_MISSION: (),
            MAV_MISSION_TYPE_FENCE: (),
            MAV_MISSION_TYPE_RALLY: (),
        }
        self._upload: _Upload | None = None
        self._finished: _Finished | None = None
        self.last_result = Result.NONE
        self._downloads: dict[_DownloadKey, _Download] = {}
        # "uploads": every replacement of stored items (clears too); "accepted_uploads":
        # uploads the protocol completed (MISSION_ACK accepted); "downloads": see the module
        # docstring. Every mission type counts.
        self.counters: dict[str, int] = {
            "ignored": 0,
            "uploads": 0,
            "failed_uploads": 0,
            "accepted_uploads": 0,
            "downloads": 0,
        }
        self._handlers: dict[str, Callable[[Any, LinkId, float, Reaction], None]] = {
            "MISSION_COUNT": self._on_count,
            "MISSION_WRITE_PARTIAL_LIST": self._on_partial,
            "MISSION_ITEM_INT": self._on_item,
            "MISSION_ITEM": self._on_item,
            "MISSION_REQUEST_LIST": self._on_request_list,
            "MISSION_REQUEST_INT": self._on_request,
            "MISSION_REQUEST": self._on_request,
            "MISSION_CLEAR_ALL": self._on_clear_all,
            "MISSION_ACK": self._on_ack,
        }

    # -- queries -------------------------------------------------------------------------

    @property
    def step(self) -> Step:
        return Step.IDLE if self._upload is None else Step.RECEIVING

    def handles(self, msg_type: str) -> bool:
        return msg_type in self._handlers

    def items(self, mission_type: int = MAV_MISSION_TYPE_MISSION) -> tuple[MissionItem, ...]:
        """The stored items as a GCS would download them (item 0 of type 0 is home)."""
        stored = self._stored.get(mission_type, ())
        if mission_type != MAV_MISSION_TYPE_MISSION:
            return stored
        home = replace(self.home, seq=0, current=0, mission_type=0)
        if self.ardupilot_storage:
            home = stored_item(home)
        return (home, *stored[1:])

    def count(self, mission_type: int = MAV_MISSION_TYPE_MISSION) -> int:
        """``len(self.items(mission_type))`` without building the items."""
        n = len(self._stored.get(mission_type, ()))
        return max(n, 1) if mission_type == MAV_MISSION_TYPE_MISSION else n

    def next_deadline(self) -> float | None:
        """Wall time at which ``tick`` has something to do, if any."""
        if self._upload is None:
            return None
        return self._upload.last_request_s + self.timeout_s

    # -- direct manipulation (API, tests) ------------------------------------------------

    def store(self, items: tuple[MissionItem, ...], mission_type: int = 0) -> None:
        """Replace the stored items without the protocol (no validation)."""
        self._stored[mission_type] = tuple(
            replace(it, seq=i, mission_type=mission_type) for i, it in enumerate(items)
        )

    # -- inputs --------------------------------------------------------------------------

    def handle(self, msg: Any, link: LinkId, now_s: float) -> Reaction:
        """Process one received message; messages not for the mission service are ignored."""
        reaction = Reaction()
        handler = self._handlers.get(msg.get_type())
        if handler is None or not addressed_to(msg, self.system_id, self.component_id):
            return reaction
        handler(msg, link, now_s, reaction)
        return reaction

    def tick(self, now_s: float) -> Reaction:
        """Re-request a missing item, or give up, when the timeout has passed."""
        reaction = Reaction()
        up = self._upload
        if up is None or now_s - up.last_request_s < self.timeout_s:
            return reaction
        if up.retries >= self.max_retries:
            self._upload = None
            self.last_result = Result.TIMEOUT
            self.counters["failed_uploads"] += 1
            self._ack(
                reaction,
                up.link,
                up.gcs_system,
                up.gcs_component,
                int(mavlink2.MAV_MISSION_OPERATION_CANCELLED),
                up.mission_type,
            )
            return reaction
        up.retries += 1
        up.last_request_s = now_s
        self._request(reaction, up)
        return reaction

    # -- upload --------------------------------------------------------------------------

    def _busy_with_other(self, msg: Any, link: LinkId) -> bool:
        up = self._upload
        return up is not None and (
            up.link != link
            or up.gcs_system != msg.get_srcSystem()
            or up.gcs_component != msg.get_srcComponent()
        )

    def _admit_write(self, msg: Any, link: LinkId, r: Reaction) -> int | None:
        """The mission type of a write request, or None after refusing it with an ACK."""
        mt = int(msg.mission_type)
        src, comp = msg.get_srcSystem(), msg.get_srcComponent()
        if mt not in self._stored:
            self._ack(r, link, src, comp, int(mavlink2.MAV_MISSION_UNSUPPORTED), mt)
            return None
        if self._busy_with_other(msg, link):
            self._ack(r, link, src, comp, int(mavlink2.MAV_MISSION_DENIED), mt)
            return None
        return mt

    def _on_count(self, msg: Any, link: LinkId, now_s: float, r: Reaction) -> None:
        mt = self._admit_write(msg, link, r)
        if mt is None:
            return
        src, comp = msg.get_srcSystem(), msg.get_srcComponent()
        count = int(msg.count)
        up = self._upload
        if (
            up is not None
            and not up.partial
            and up.mission_type == mt
            and up.end == count
            and up.next_seq == 0
        ):
            # Retransmitted MISSION_COUNT (our first request was lost): just ask again.
            up.last_request_s = now_s
            self._request(r, up)
            return
        if count > self.capacity[mt]:
            self._upload = None
            self._ack(r, link, src, comp, int(mavlink2.MAV_MISSION_NO_SPACE), mt)
            return
        self._finished = None
        if count == 0:
            self._upload = None
            self._commit(r, mt, ())
            self.counters["accepted_uploads"] += 1
            self._ack(r, link, src, comp, int(mavlink2.MAV_MISSION_ACCEPTED), mt)
            return
        self._upload = _Upload(
            link=link,
            gcs_system=src,
            gcs_component=comp,
            mission_type=mt,
            start=0,
            end=count,
            partial=False,
            next_seq=0,
            staged=[],
            last_progress_s=now_s,
            last_request_s=now_s,
        )
        self._request(r, self._upload)

    def _on_partial(self, msg: Any, link: LinkId, now_s: float, r: Reaction) -> None:
        mt = self._admit_write(msg, link, r)
        if mt is None:
            return
        src, comp = msg.get_srcSystem(), msg.get_srcComponent()
        start, end = int(msg.start_index), int(msg.end_index)
        n = self.count(mt)
        if end == -1:
            end = n - 1
        if not 0 <= start <= end < n:
            self._upload = None
            self._ack(r, link, src, comp, int(mavlink2.MAV_MISSION_INVALID_SEQUENCE), mt)
            return
        self._finished = None
        self._upload = _Upload(
            link=link,
            gcs_system=src,
            gcs_component=comp,
            mission_type=mt,
            start=start,
            end=end + 1,
            partial=True,
            next_seq=start,
            staged=[],
            last_progress_s=now_s,
            last_request_s=now_s,
        )
        self._request(r, self._upload)

    def _on_item(self, msg: Any, link: LinkId, now_s: float, r: Reaction) -> None:
        mt = int(msg.mission_type)
        up = self._upload
        seq = int(msg.seq)
        if up is None or up.link != link or up.mission_type != mt:
            fin = self._finished
            if (
                up is None
                and fin is not None
                and fin.link == link
                and fin.mission_type == mt
                and fin.last_seq == seq
            ):
                # Our final ACK was lost and the GCS resent the last item: ack again.
                self._ack(
                    r,
                    link,
                    fin.gcs_system,
                    fin.gcs_component,
                    int(mavlink2.MAV_MISSION_ACCEPTED),
                    mt,
                )
                return
            self.counters["ignored"] += 1
            return
        if seq != up.next_seq:
            # Duplicate or out of order: ignored, as ArduPilot does; the timer re-requests.
            self.counters["ignored"] += 1
            return
        item, result = item_from_msg(msg, ardupilot=self.ardupilot_storage)
        if item is not None:
            result = validate_item(item)
            if self.ardupilot_storage and mt == MAV_MISSION_TYPE_MISSION:
                item = stored_item(item)
        if item is None or result != mavlink2.MAV_MISSION_ACCEPTED:
            self._upload = None
            self.last_result = Result.INVALID_ITEM
            self.counters["failed_uploads"] += 1
            self._ack(r, link, up.gcs_system, up.gcs_component, result, mt)
            return
        up.staged.append(item)
        up.next_seq += 1
        up.retries = 0
        up.last_progress_s = now_s
        up.last_request_s = now_s
        if up.next_seq < up.end:
            self._request(r, up)
            return
        # Complete.
        if up.partial:
            merged = list(self._stored[mt])
            while len(merged) < up.end:
                merged.append(self.home)
            for it in up.staged:
                merged[it.seq] = it
            new_items: tuple[MissionItem, ...] = tuple(merged)
        else:
            new_items = tuple(up.staged)
        self._upload = None
        self._finished = _Finished(link, up.gcs_system, up.gcs_component, mt, seq)
        self._commit(r, mt, new_items)
        self.counters["accepted_uploads"] += 1
        self._ack(r, link, up.gcs_system, up.gcs_component, int(mavlink2.MAV_MISSION_ACCEPTED), mt)

    def _commit(self, r: Reaction, mission_type: int, items: tuple[MissionItem, ...]) -> None:
        self.store(items, mission_type)
        self.last_result = Result.SUCCESS
        self.counters["uploads"] += 1
        self._downloads = {k: d for k, d in self._downloads.items() if k[3] != mission_type}
        r.events.append(MissionStored(mission_type, self.items(mission_type)))

    def _request(self, r: Reaction, up: _Upload) -> None:
        make = (
            mavlink2.MAVLink_mission_request_message
            if self.legacy_requests
            else mavlink2.MAVLink_mission_request_int_message
        )
        r.sends.append(
            Send(up.link, make(up.gcs_system, up.gcs_component, up.next_seq, up.mission_type))
        )

    # -- download, clear, ack ------------------------------------------------------------

    def _on_request_list(self, msg: Any, link: LinkId, now_s: float, r: Reaction) -> None:
        mt = int(msg.mission_type)
        src, comp = msg.get_srcSystem(), msg.get_srcComponent()
        if mt not in self._stored:
            self._ack(r, link, src, comp, int(mavlink2.MAV_MISSION_UNSUPPORTED), mt)
            return
        n = self.count(mt)
        key = (link, src, comp, mt)
        known = self._downloads.get(key)
        if n > 0 and (known is None or known.count != n):
            self._downloads[key] = _Download(n, set(range(n)))
        r.sends.append(Send(link, mavlink2.MAVLink_mission_count_message(src, comp, n, mt)))

    def _note_served(self, key: _DownloadKey, seq: int) -> None:
        """Item ``seq`` went out; the last unsent item of a download counts the download."""
        d = self._downloads.get(key)
        if d is None:
            return
        d.unsent.discard(seq)
        if not d.unsent:
            del self._downloads[key]
            self.counters["downloads"] += 1

    def _on_request(self, msg: Any, link: LinkId, now_s: float, r: Reaction) -> None:
        mt = int(msg.mission_type)
        src, comp = msg.get_srcSystem(), msg.get_srcComponent()
        up = self._upload
        if up is not None and up.link == link and up.mission_type == mt:
            # A request while we are receiving is a confused peer; not an error for us.
            self.counters["ignored"] += 1
            return
        items = self.items(mt) if mt in self._stored else ()
        seq = int(msg.seq)
        if not 0 <= seq < len(items):
            self._ack(r, link, src, comp, int(mavlink2.MAV_MISSION_INVALID_SEQUENCE), mt)
            return
        it = items[seq]
        if self.ardupilot_storage and mt == MAV_MISSION_TYPE_MISSION:
            current = 1 if it.command == self.current_nav_index() else 0
            it = replace(it, current=current)
        if msg.get_type() == "MISSION_REQUEST":
            if self.ardupilot_storage:
                lat, lon = legacy_x_from_int(it.x), legacy_x_from_int(it.y)
            else:
                lat, lon = it.x * 1e-7, it.y * 1e-7
            out: Any = mavlink2.MAVLink_mission_item_message(
                src, comp, it.seq, it.frame, it.command, it.current, it.autocontinue,
                it.param1, it.param2, it.param3, it.param4, lat, lon, it.z, mt,
            )  # fmt: skip
        else:
            out = mavlink2.MAVLink_mission_item_int_message(
                src, comp, it.seq, it.frame, it.command, it.current, it.autocontinue,
                it.param1, it.param2, it.param3, it.param4, it.x, it.y, it.z, mt,
            )  # fmt: skip
        r.sends.append(Send(link, out))
        self._note_served((link, src, comp, mt), seq)

    def _on_clear_all(self, msg: Any, link: LinkId, now_s: float, r: Reaction) -> None:
        mt = int(msg.mission_type)
        src, comp = msg.get_srcSystem(), msg.get_srcComponent()
        if mt == mavlink2.MAV_MISSION_TYPE_ALL:
            types = list(self._stored)
        elif mt in self._stored:
            types = [mt]
        else:
            self._ack(r, link, src, comp, int(mavlink2.MAV_MISSION_UNSUPPORTED), mt)
            return
        if self._busy_with_other(msg, link):
            self._ack(r, link, src, comp, int(mavlink2.MAV_MISSION_DENIED), mt)
            return
        self._upload = None
        for t in types:
            self._commit(r, t, ())
        self._ack(r, link, src, comp, int(mavlink2.MAV_MISSION_ACCEPTED), mt)

    def _on_ack(self, msg: Any, link: LinkId, now_s: float, r: Reaction) -> None:
        # A GCS ack ends a download (stateless here) or cancels an upload it started.
        up = self._upload
        if (
            up is not None
            and up.link == link
            and up.gcs_system == msg.get_srcSystem()
            and int(msg.type) == mavlink2.MAV_MISSION_OPERATION_CANCELLED
        ):
            self._upload = None
            self.last_result = Result.CANCELLED

    def _ack(
        self, r: Reaction, link: LinkId, system: int, component: int, result: int, mt: int
    ) -> None:
        r.sends.append(
            Send(link, mavlink2.MAVLink_mission_ack_message(system, component, result, mt))
        )
