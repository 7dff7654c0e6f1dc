"""Ordered slots moved in flight (:mod:`planner.slots`): only from the slot a vehicle cannot
make, each after it only as far as its spacing needs; the figures worked out here by hand."""

from __future__ import annotations

import pytest

from planner.errors import InfeasibleError
from planner.slots import ordered_targets, pushed, slot_groups
from planner.timing import ArrivalWindow


def _window(vid: str, lo: float, hi: float) -> ArrivalWindow:
    return ArrivalWindow(vid, lo, hi, f"{vid} at its top speed", f"{vid} at its slowest")


def test_a_late_vehicle_moves_its_slot_and_the_ones_after_it_only_as_far_as_needed() -> None:
    """Slots 90 s apart, 10 s of slack before D's: B cannot arrive before 130 s. B's slot
    moves to 130, C's to 220 (90 after B's), D's to 310; A's stays. Late by 5 s, B moves C's
    by as much and D's not at all."""
    slots = {"A": 0.0, "B": 90.0, "C": 180.0, "D": 280.0}
    moved = pushed(slots, {"B": 130.0}, 90.0)
    assert moved["A"] == 0.0 and moved["B"] == 130.0 and moved["C"] == 220.0
    assert moved["D"] == 310.0  # 220 + 90 > 280
    assert pushed(slots, {"B": 95.0}, 90.0) == {"A": 0.0, "B": 95.0, "C": 185.0, "D": 280.0}
    assert pushed(slots, {}, 90.0) == slots


def test_a_wave_moves_as_one() -> None:
    """Waves 120 s apart: one vehicle of the second wave cannot arrive before 150 s: its
    whole wave moves to 150, the third to 270; the first stays."""
    slots = {"A": 0.0, "B": 0.0, "C": 120.0, "D": 120.0, "E": 240.0}
    assert slot_groups(slots) == [["A", "B"], ["C", "D"], ["E"]]
    assert pushed(slots, {"D": 150.0}, 120.0) == {
        "A": 0.0,
        "B": 0.0,
        "C": 150.0,
        "D": 150.0,
        "E": 270.0,
    }


def test_a_re_plan_moves_only_the_slots_from_the_one_it_makes_late() -> None:
    """A has arrived (no window); B's new route cannot make 90 s before 140; C can wait
    until 300. B's and C's slots move (140, 230), A's stays, and the reason names B."""
    slots = {"A": 0.0, "B": 90.0, "C": 180.0}
    windows = [_window("B", 140.0, 400.0), _window("C", 100.0, 300.0)]
    targets, first_s, reason = ordered_targets(windows, slots, 90.0)
    assert targets == {"B": 140.0, "C": 230.0} and first_s == 0.0
    assert "from B's on" in reason and "B cannot arrive before 140.0 s" in reason
    kept, _, why = ordered_targets([_window("B", 50.0, 400.0), _window("C", 100.0, 300.0)],
                                   slots, 90.0)  # fmt: skip
    assert kept == {"B": 90.0, "C": 180.0} and why == "every vehicle keeps its slot"


@pytest.mark.parametrize(
    ("windows", "named"),
    [
        ([_window("B", 140.0, 400.0), _window("C", 100.0, 200.0)], "C"),
        ([_window("A", -10.0, 10.0), _window("B", -100.0, 400.0)], None),
    ],
    ids=["after-it-cannot-wait", "nothing-moves"],
)
def test_a_slot_that_cannot_wait_is_named(windows: list[ArrivalWindow], named: str | None) -> None:
    """C can arrive no later than 200 s: B's late route would need it at 230 s: refused,
    naming C and why. Where nothing moves, nothing is refused."""
    slots = {"A": 0.0, "B": 90.0, "C": 180.0}
    if named is None:
        ordered_targets(windows, slots, 90.0)
        return
    with pytest.raises(InfeasibleError, match=r"vehicle C cannot arrive as late as 230\.0 s") as e:
        ordered_targets(windows, slots, 90.0)
    assert e.value.vehicle == "C" and "C at its slowest" in str(e.value)


def test_an_arrived_vehicle_slot_cannot_move() -> None:
    """B has arrived at 90 s (no window) and A, ahead of it, cannot make 0 s: A's slot
    would push B's: refused, naming B."""
    with pytest.raises(InfeasibleError, match=r"vehicle B cannot arrive as late as 110\.0 s"):
        ordered_targets([_window("A", 20.0, 100.0)], {"A": 0.0, "B": 90.0}, 90.0)


def test_a_vehicle_early_for_its_own_slot_does_not_stop_the_ones_after_it_moving() -> None:
    """A will be early for its slot (it can arrive no later than -20 s) whatever happens;
    B's new route cannot make 90 s before 120: B's slot moves, A's stays, and nothing is
    refused for A."""
    windows = [_window("A", -50.0, -20.0), _window("B", 120.0, 400.0)]
    targets, _, _ = ordered_targets(windows, {"A": 0.0, "B": 90.0}, 90.0)
    assert targets == {"A": 0.0, "B": 120.0}
