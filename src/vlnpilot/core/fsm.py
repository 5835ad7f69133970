"""The finite-state machine of the paper's Tables 1 and 3: one table, read by prompts, schemas and validation.

Where the paper is incomplete we decide, and mark each decision with `added_next` (never mixed into
`paper_next`, so a test can check the paper's Table 3 verbatim):

* Start has no row: the controller handles it (take-off) and enters Recognize Room without asking the
  pilot, so it costs no step.
* Recognize Room, Oriented Towards Door and Go Through Door may stay in themselves: one 10 cm move
  rarely finishes recognising, aligning or crossing.
* Position in Center of Room is named by Table 3 but has no row. After a crossing the drone moves
  into the new room and then recognises it again: moves A1, A2 and rotations; next states itself or
  Recognize Room.
* Stay on Room and Describe Object are final: entering one ends the episode and the monitor judges it.
* Declaring a final state means stopping, so `E` (hover) is accepted together with a final next state even
  where the state's own row does not list it (Recognize Room -> Stay on Room). Real pilots answered so, and
  forcing a rotation on a pilot that has finished is a rule no image can justify.
* The movement of an answer is flown in the *current* state; the next state's moves apply from the next step
  (a rejection says so when a pilot uses a move of the state it is moving to).

Additions for events in the scene (issue 24), marked `added_moves` / `added_next` beside the paper's:

* Goal Unreachable is a final state: the pilot reports that no open door leads on to the goal (a door on the
  only route has closed). Search Open Door may move on to it; the judge counts it as an outcome of its own kind,
  `unreachable`, only when the goal is truly unreachable by the true map at that moment.
* Every asked state may hover (`E`, `HOVER_ADDED`): to wait for a person to pass, to look again from the same
  place, or to change state without moving (a state change otherwise forces a move under the old state's rules,
  e.g. a rotation in Recognize Room that loses the door already in view). It costs a step. Where the paper's row
  lists `E` already (Search Open Door, Reach Object, the final states) nothing is added, so `paper_moves` stays
  Table 3 verbatim. The oscillation guard does not count hovers (`safety/guard.py`).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

from vlnpilot.core.commands import COMMANDS
from vlnpilot.core.errors import UnknownNameError


class State(StrEnum):
    START = "Start"
    RECOGNIZE_ROOM = "Recognize Room"
    SEARCH_OPEN_DOOR = "Search Open Door"
    ORIENTED_TOWARDS_DOOR = "Oriented Towards Door"
    GO_THROUGH_DOOR = "Go Through Door"
    POSITION_IN_CENTER = "Position in Center of Room"
    STAY_ON_ROOM = "Stay on Room"
    SEARCH_OBJECT = "Search Object"
    REACH_OBJECT = "Reach Object"
    DESCRIBE_OBJECT = "Describe Object"
    GOAL_UNREACHABLE = "Goal Unreachable"  # an addition (issue 24): no route to the goal is left
    FINAL = "Final"


def parse_state(name: str) -> State:
    """A state from its name, ignoring case, spaces, '_' and '-' (models write 'Search open Door')."""
    key = "".join(ch for ch in str(name).lower() if ch.isalnum())
    for s in State:
        if "".join(ch for ch in s.value.lower() if ch.isalnum()) == key or s.name.lower().replace("_", "") == key:
            return s
    raise UnknownNameError("state", name, [s.value for s in State])


def _moves(*codes: str) -> tuple[str, ...]:
    out: list[str] = []
    for code in codes:
        if "-" in code:  # "B1-B3"
            first, last = code.split("-")
            out += [f"{first[0]}{i}" for i in range(int(first[1:]), int(last[1:]) + 1)]
        else:
            out.append(code)
    assert all(c in COMMANDS for c in out), out
    return tuple(out)


@dataclass(frozen=True)
class StateSpec:
    state: State
    goal: str
    paper_moves: tuple[str, ...]  # the paper's (or the profile's) moves; `moves` adds `added_moves`
    paper_next: tuple[State, ...]
    added_next: tuple[State, ...] = ()
    final: bool = False
    description: str = ""  # Table 1's description
    added_moves: tuple[str, ...] = ()  # moves beyond the paper's (issue 24: hover in every asked state)

    @property
    def moves(self) -> tuple[str, ...]:
        """The moves an answer may fly in this state: the paper's and the added ones, in the command table's order."""
        if not self.added_moves:
            return self.paper_moves
        return tuple(c for c in COMMANDS if c in self.paper_moves or c in self.added_moves)

    @property
    def next_states(self) -> tuple[State, ...]:
        return self.paper_next + self.added_next

    @property
    def answer_moves(self) -> tuple[str, ...]:
        """Moves an answer may carry: the row's moves, plus `E` when a next state is final (see the module doc)."""
        if FINAL_MOVE in self.moves or not any(s in FINAL_STATES for s in self.next_states):
            return self.moves
        return (*self.moves, FINAL_MOVE)

    def allows(self, move: str, next_state: State) -> bool:
        """Whether an answer may fly `move` in this state while moving on to `next_state`."""
        return move in self.moves or (move == FINAL_MOVE and next_state in FINAL_STATES)


S = State
FINAL_MOVE = "E"  # hovering: the move that goes with declaring a final state
HOVER_ADDED = _moves("E")  # an addition (issue 24, EVFIX item 3): hover in every asked state (module doc)
_PAPER_TABLE: tuple[StateSpec, ...] = (
    StateSpec(S.START, "Activate the system and take off.", _moves("E"), (S.RECOGNIZE_ROOM,),
              description="The initial state where the system is activated."),
    StateSpec(S.RECOGNIZE_ROOM, "Identify the current room.", _moves("A1", "B1-B3", "C1-C3"),
              (S.STAY_ON_ROOM, S.SEARCH_OBJECT, S.SEARCH_OPEN_DOOR), (S.RECOGNIZE_ROOM,),
              description="The agent tries to determine the room in which it is currently located.",
              added_moves=HOVER_ADDED),
    StateSpec(S.STAY_ON_ROOM, "Remain stationary in the target room.", _moves("E"), (S.FINAL,), final=True,
              description="When the target room is reached and no object is to be found."),
    StateSpec(S.SEARCH_OBJECT, "Locate and center the target object.", _moves("A1", "A2", "B1-B3", "C1-C3"),
              (S.SEARCH_OBJECT, S.REACH_OBJECT),
              description="Once inside the target room, the system searches for the specific object of interest.",
              added_moves=HOVER_ADDED),
    StateSpec(S.REACH_OBJECT, "Approach and align with the object.", _moves("A1", "B1", "C1", "D1", "D2", "E"),
              (S.DESCRIBE_OBJECT, S.SEARCH_OBJECT, S.REACH_OBJECT),
              description="Guides the drone closer to the object."),
    StateSpec(S.DESCRIBE_OBJECT, "Stop and describe the object.", _moves("E"), (S.FINAL,), final=True,
              description="When close to the object, the system describes its position and orientation "
                          "with respect to the target."),
    StateSpec(S.SEARCH_OPEN_DOOR, "Look for an open door to the goal.", _moves("A1", "B1-B3", "C1-C3", "E"),
              (S.SEARCH_OPEN_DOOR, S.ORIENTED_TOWARDS_DOOR), (S.GOAL_UNREACHABLE,),
              description="If the target room is different from the current one, the system searches for "
                          "an open door to navigate through."),
    StateSpec(S.ORIENTED_TOWARDS_DOOR, "Align with the open door.", _moves("A1", "B1", "C1", "D1", "D2"),
              (S.GO_THROUGH_DOOR, S.SEARCH_OPEN_DOOR), (S.ORIENTED_TOWARDS_DOOR,),
              description="Aligns the drone to face the detected open door before crossing it.",
              added_moves=HOVER_ADDED),
    StateSpec(S.GO_THROUGH_DOOR, "Enter the next room through the door.", _moves("A1"),
              (S.POSITION_IN_CENTER, S.ORIENTED_TOWARDS_DOOR), (S.GO_THROUGH_DOOR,),
              description="Commands the drone to move through the recognized and oriented door.",
              added_moves=HOVER_ADDED),
    StateSpec(S.POSITION_IN_CENTER, "Move away from the door towards the middle of the new room.",
              _moves("A1", "A2", "B1-B3", "C1-C3"), (), (S.POSITION_IN_CENTER, S.RECOGNIZE_ROOM),
              description="After crossing a door, the drone moves into the new room before recognising it.",
              added_moves=HOVER_ADDED),
    StateSpec(S.GOAL_UNREACHABLE, "Report that the goal cannot be reached.", _moves("E"), (), (S.FINAL,),
              final=True, description="An addition (issue 24): every route to the goal room is closed (a door "
                                      "on the only route has shut); the drone hovers and reports it."),
    StateSpec(S.FINAL, "The episode is over.", _moves("E"), (), final=True,
              description="Terminal marker used by the final states."),
)

# Profiles change allowed moves only, never the transitions. `paper` is Table 3 verbatim.
# `fast` lets the navigation states fly longer forward moves (use it with a safety shield).
FINAL_STATES = frozenset(s.state for s in _PAPER_TABLE if s.final)
# The states in which the pilot is asked: the controller handles Start (take-off) itself and never asks in Final.
ASKED_STATES: tuple[State, ...] = tuple(s for s in State if s not in (State.START, State.FINAL))
_FAST_EXTRA: dict[State, tuple[str, ...]] = {
    S.RECOGNIZE_ROOM: ("A2",),
    S.SEARCH_OPEN_DOOR: ("A2", "A3"),
    S.ORIENTED_TOWARDS_DOOR: ("A2",),
    S.POSITION_IN_CENTER: ("A3",),
    S.SEARCH_OBJECT: ("A3",),
}
# `ranged` (issue 23, bench/longer_moves.py): `fast`, and `A2` in Reach Object, for a drone whose forward range
# tells the pilot when there is room for it (a 25 cm move while a RoboMaster TT's ToF reads beyond 1.2 m halves the
# approach's steps); the shield still keeps every move clear.
_RANGED_EXTRA: dict[State, tuple[str, ...]] = {**_FAST_EXTRA, S.REACH_OBJECT: ("A2",)}
PROFILES = ("paper", "fast", "ranged")


def default_profile(has_forward_range: bool) -> str:
    """`vln-pilot run`'s profile when none is given: `ranged` for a drone with a forward range (the objects20
    trials: 20/20 with it against 19/20 without, in fewer steps on 17 of 20 rows), else the paper's."""
    return "ranged" if has_forward_range else "paper"


def fsm_table(profile: str = "paper") -> dict[State, StateSpec]:
    """The state table for a profile ('paper' is the default and follows the paper's Table 3)."""
    if profile not in PROFILES:
        raise UnknownNameError("FSM profile", profile, PROFILES)
    table = {spec.state: spec for spec in _PAPER_TABLE}
    if profile != "paper":
        for state, extra in (_FAST_EXTRA if profile == "fast" else _RANGED_EXTRA).items():
            spec = table[state]
            moves = tuple(c for c in COMMANDS if c in spec.paper_moves or c in extra)
            table[state] = StateSpec(spec.state, spec.goal, moves, spec.paper_next, spec.added_next,
                                     spec.final, spec.description, spec.added_moves)
    return table


def state_spec(state: State | str, profile: str = "paper") -> StateSpec:
    return fsm_table(profile)[state if isinstance(state, State) else parse_state(state)]
