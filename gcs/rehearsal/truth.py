"""Read a simulator truth file (``tcgcs-truth/1`` JSON lines) into sampled tracks
(:mod:`gcs.coordination.tracks` measures a flight against them).

The file is what ``python -m sitl_stub --truth FILE`` writes (the format is in
docs/sitl_stub.md); this module only parses the lines, it does not import the simulator. A
header line ``{"format": "tcgcs-truth/1", ...}`` is followed by one line per vehicle and sample
time with ``utc_s``, ``sysid``, ``lat_deg``, ``lon_deg``, ``alt_m`` (AMSL), ``airspeed_m_s``,
``groundspeed_m_s``, ``armed`` and (optionally) ``on_ground``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from gcs.coordination.tracks import TruthSample, closest_approach, min_separation
from gcs.errors import GcsError

TRUTH_FORMAT = "tcgcs-truth/1"


_NUMBER_FIELDS = ("utc_s", "lat_deg", "lon_deg", "alt_m", "airspeed_m_s", "groundspeed_m_s")


class TruthFileError(GcsError, ValueError):
    """A truth file that cannot be read (names the file and line)."""


# -- reading ---------------------------------------------------------------------------------


def read_truth(path: Path | str) -> dict[int, list[TruthSample]]:
    """The samples of each vehicle by system id, in time order.

    A last line without its newline that does not parse is ignored (the simulator may be
    writing it); an empty file, or one holding only part of the header, gives ``{}``.

    Raises
    ------
    TruthFileError
        (a :class:`~gcs.errors.GcsError`) naming the file and line, for a file that cannot be
        read, a header of another format, or a line that is not a sample.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise TruthFileError(f"truth file {path}: cannot read it ({err})") from None
    lines = text.split("\n")
    # The text after the last newline is an unfinished line (or "" when the file ends cleanly).
    complete, partial = lines[:-1], lines[-1]
    out: dict[int, list[TruthSample]] = {}
    for lineno, line in enumerate(complete, start=1):
        _take(out, path, lineno, line, tolerate=False)
    if partial.strip():
        _take(out, path, len(complete) + 1, partial, tolerate=True)
    for samples in out.values():
        samples.sort(key=lambda s: s.utc_s)  # stable, linear when already in order
    return out


def _take(
    out: dict[int, list[TruthSample]], path: Path, lineno: int, line: str, *, tolerate: bool
) -> None:
    where = f"truth file {path} line {lineno}"
    if not line.strip():
        if lineno == 1:
            raise TruthFileError(f"{where}: empty; expected the {TRUTH_FORMAT} header")
        return
    try:
        rec = json.loads(line)
    except ValueError:
        if tolerate:
            return
        raise TruthFileError(f"{where}: not JSON: {_clip(line)}") from None
    if not isinstance(rec, dict):
        raise TruthFileError(f"{where}: expected a JSON object, got {_clip(line)}")
    if lineno == 1:
        fmt = rec.get("format")
        if fmt != TRUTH_FORMAT:
            raise TruthFileError(f"{where}: format is {fmt!r}, expected {TRUTH_FORMAT!r}")
        return
    if "format" in rec:
        raise TruthFileError(f"{where}: a second header")
    sample, sysid = _sample(rec, where)
    out.setdefault(sysid, []).append(sample)


def _sample(rec: dict[str, Any], where: str) -> tuple[TruthSample, int]:
    values: list[float] = []
    for name in _NUMBER_FIELDS:
        v = rec.get(name)
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise TruthFileError(f"{where}: {name} is {v!r}, expected a number")
        if not math.isfinite(v):
            raise TruthFileError(f"{where}: {name} is {v!r}, expected a finite number")
        values.append(float(v))
    sysid = rec.get("sysid")
    if isinstance(sysid, bool) or not isinstance(sysid, int) or not 1 <= sysid <= 255:
        raise TruthFileError(f"{where}: sysid is {sysid!r}, expected a system id 1..255")
    armed = rec.get("armed")
    if not isinstance(armed, bool):
        raise TruthFileError(f"{where}: armed is {armed!r}, expected true or false")
    on_ground = rec.get("on_ground")
    if on_ground is not None and not isinstance(on_ground, bool):
        raise TruthFileError(f"{where}: on_ground is {on_ground!r}, expected true or false")
    if not -90.0 <= values[1] <= 90.0:
        raise TruthFileError(f"{where}: lat_deg {values[1]!r} is outside [-90, 90]")
    utc, lat, lon, alt, tas, gs = values
    return TruthSample(utc, lat, lon, alt, tas, gs, armed, on_ground), sysid


def _clip(line: str, n: int = 60) -> str:
    return repr(line if len(line) <= n else line[:n] + "...")


__all__ = [
    "TRUTH_FORMAT",
    "TruthFileError",
    "TruthSample",
    "closest_approach",
    "min_separation",
    "read_truth",
]
