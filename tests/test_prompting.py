"""Prompts and the model-answer contract: the prompt, the schema and the validation all follow the tables."""

from __future__ import annotations

import io
import json
import re

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from PIL import Image

from vlnpilot.core.commands import COMMANDS
from vlnpilot.core.decision import (
    DOOR_POSITIONS,
    FIELDS,
    Decision,
    DecisionError,
    PilotInput,
    normalize_decision,
    parse_decision,
    validate_decision,
)
from vlnpilot.core.errors import ConfigError
from vlnpilot.core.fsm import ASKED_STATES, PROFILES, State, fsm_table, state_spec
from vlnpilot.prompting.render import (
    Prompt,
    PromptTemplateError,
    build_prompt,
    decision_schema,
    encode_jpeg,
    map_rooms,
    prompt_hash,
    render_state_prompt,
    render_state_template,
    system_prompt,
)

CASES = [(profile, state) for profile in PROFILES for state in ASKED_STATES]
CASE_IDS = [f"{p}-{s.name}" for p, s in CASES]

# The paper's Appendix D, verbatim.
APPENDIX_D = (
    "{'room': 'bedroom', 'movement': 'E', 'state': 'Final', 'description': 'A large mirror is visible on the right "
    "side of the image, reflecting light. It is positioned near a window and next to a wardrobe. The mirror is "
    "mostly in frame and upright.', 'door_position': 'not_visible'}"
)

MAP = {
    "nodes": [{"id": "bedroom", "name": "Bedroom"}, {"id": "living_room", "name": "Living room"},
              {"id": "kitchen", "name": "Kitchen"}],
    "edges": [{"from": "bedroom", "to": "living_room", "door": "d1"}, {"from": "living_room", "to": "kitchen"}],
}


def section(text: str, title: str) -> str:
    """The body of a '## TITLE' section, up to the next '---' rule or '## ' heading."""
    m = re.search(rf"^## {re.escape(title)}[ \t]*\n(.*?)(?=^---[ \t]*$|^## |\Z)", text, re.M | re.S)
    assert m, f"no section {title!r}"
    return m.group(1)


def listed_codes(text: str) -> list[str]:
    return re.findall(r"^- `([A-Z][0-9]?)`: ", section(text, "MOVEMENT COMMANDS"), re.M)


def rule_states(text: str) -> list[str]:
    return re.findall(r"^- `([^`]+)`: ", section(text, "OUTPUT STATE RULES"), re.M)


def valid_values(text: str, field: str) -> list[str]:
    body = section(text, "VALID ANSWER VALUES IN THIS STATE")
    m = re.search(rf"^- `{field}`: [^`\n]*(.*)$", body, re.M)
    assert m, field
    return re.findall(r"`([^`]+)`", m.group(1))


def make_input(**overrides) -> PilotInput:
    values = dict(image=np.zeros((48, 64, 3), np.uint8), query="Go to the kitchen", topological_map=MAP,
                  state=State.SEARCH_OPEN_DOOR, previous_movement="B2", step=3)
    values.update(overrides)
    return PilotInput(**values)


# ---------------------------------------------------------------------------------------------- state prompts


@pytest.mark.parametrize(("profile", "state"), CASES, ids=CASE_IDS)
def test_state_prompt_names_exactly_the_table(profile: str, state: State) -> None:
    spec = state_spec(state, profile)
    text = render_state_prompt(state, profile)
    assert text.startswith(f"## State: **{state.value}**")
    assert listed_codes(text) == list(spec.answer_moves)  # table order, nothing more, nothing less
    assert valid_values(text, "movement") == list(spec.answer_moves)
    assert sorted(rule_states(text)) == sorted(s.value for s in spec.next_states)  # each once, no others
    assert valid_values(text, "state") == [s.value for s in spec.next_states]
    # no command outside the state's moves is named anywhere in the prompt
    named = set(re.findall(r"`([A-E][1-3]?)`", text))
    assert named <= set(spec.answer_moves), named - set(spec.answer_moves)
    for code in spec.moves:  # each listed with the table's description
        assert f"- `{code}`: {COMMANDS[code].description}" in text
    assert "$" not in text  # every placeholder rendered


def test_rotation_direction_follows_table_2() -> None:
    text = render_state_prompt(State.SEARCH_OBJECT)
    assert "### B. Right rotation" in text and "- `B1`: rotate right 15°" in text
    assert "### C. Left rotation" in text and "- `C3`: rotate left 90°" in text


def test_fast_profile_extra_moves_appear() -> None:
    paper, fast = fsm_table("paper"), fsm_table("fast")
    changed = [s for s in ASKED_STATES if paper[s].moves != fast[s].moves]
    assert changed, "the fast profile must add moves somewhere"
    for s in changed:
        extra = set(fast[s].moves) - set(paper[s].moves)
        assert extra <= set(listed_codes(render_state_prompt(s, "fast")))
        assert not extra & set(listed_codes(render_state_prompt(s, "paper")))
    assert "- `A3`: move forward 50 cm" in render_state_prompt(State.SEARCH_OPEN_DOOR, "fast")
    assert "`A3`" not in render_state_prompt(State.SEARCH_OPEN_DOOR, "paper")


def test_start_and_final_have_no_prompt() -> None:
    for state in (State.START, State.FINAL):
        with pytest.raises(ConfigError):
            render_state_prompt(state)
        with pytest.raises(ConfigError):
            decision_schema(state)


GOOD = """## State: **$state**

## GOAL
$goal

## POLICY RULES
- Use `A1`.

## MOVEMENT COMMANDS

$movement_commands

---

## OUTPUT STATE RULES

- `Position in Center of Room`: if through.
- `Go Through Door`: if crossing.
- `Oriented Towards Door`: if off-center.
"""


def test_render_state_template_accepts_a_matching_template() -> None:
    text = render_state_template(GOOD, state_spec(State.GO_THROUGH_DOOR))
    assert listed_codes(text) == ["A1", "E"]  # E: the hover to wait for a person (issue 24)


@pytest.mark.parametrize(
    ("template", "match"),
    [
        (GOOD.replace("- `Go Through Door`: if crossing.\n", ""), "missing"),  # misses an allowed state
        (GOOD + "- `Recognize Room`: never.\n", "not allowed"),  # names a state not allowed
        (GOOD.replace("`Go Through Door`", "`Fly Away`"), "unknown state"),  # names no state at all
        (GOOD + "- `Go Through Door`: again.\n", "duplicated"),
        (GOOD.replace("Use `A1`", "Use `B1`"), "not allowed in"),  # prose names a disallowed command
        (GOOD.replace("$movement_commands", "none"), "movement_commands"),
        (GOOD.replace("$goal", "$slide_left"), "placeholder"),  # no lateral moves in this state
        (GOOD.replace("## OUTPUT STATE RULES", "## RULES"), "OUTPUT STATE RULES"),
    ],
)
def test_render_state_template_fails_loudly(template: str, match: str) -> None:
    with pytest.raises(PromptTemplateError, match=match):
        render_state_template(template, state_spec(State.GO_THROUGH_DOOR))


def test_system_prompt_is_appendix_a_plus_c() -> None:
    text = system_prompt()
    assert "drone" in text and "## Output Format" in text and "### Field Definitions" in text
    for field in FIELDS:
        assert f'"{field}"' in text
    # the system prompt is shared by every state: it must not list one state's moves
    assert "VALID ANSWER VALUES" not in text and "## State:" not in text


# ---------------------------------------------------------------------------------------------------- schema

# Keywords that OpenAI strict structured outputs accept (plus "description").
ALLOWED_KEYWORDS = {"type", "properties", "required", "additionalProperties", "enum", "description"}


def walk_keys(schema: dict) -> set[str]:
    keys = set(schema)
    for sub in schema.get("properties", {}).values():
        keys |= walk_keys(sub)
    return keys


@pytest.mark.parametrize(("profile", "state"), CASES, ids=CASE_IDS)
def test_schema_enums_equal_the_table(profile: str, state: State) -> None:
    spec = state_spec(state, profile)
    schema = decision_schema(state, profile)
    assert schema["type"] == "object" and schema["additionalProperties"] is False
    assert schema["required"] == list(FIELDS) == list(schema["properties"])
    props = schema["properties"]
    assert props["movement"]["enum"] == list(spec.answer_moves)
    assert props["state"]["enum"] == [s.value for s in spec.next_states]
    assert props["door_position"]["enum"] == list(DOOR_POSITIONS)
    assert all(p["type"] == "string" for p in props.values())
    assert "enum" not in props["room"]
    assert walk_keys(schema) - {"room", "movement", "state", "description", "door_position"} <= ALLOWED_KEYWORDS
    json.dumps(schema)


def test_schema_rooms_enum() -> None:
    schema = decision_schema(State.RECOGNIZE_ROOM, rooms=["bedroom", "kitchen"])
    assert schema["properties"]["room"]["enum"] == ["bedroom", "kitchen", "unknown"]
    assert decision_schema(State.RECOGNIZE_ROOM, rooms=["unknown"])["properties"]["room"]["enum"] == ["unknown"]


# ----------------------------------------------------------------------------------------------- build_prompt


def test_build_prompt_parts() -> None:
    p = build_prompt(make_input(feedback=("movement 'A3' is not allowed", "shield: wall ahead")))
    assert isinstance(p, Prompt)
    assert p.system == system_prompt()
    assert "Go to the kitchen" in p.context
    assert json.dumps(MAP, indent=2, sort_keys=True) in p.context
    assert p.state_prompt == render_state_prompt(State.SEARCH_OPEN_DOOR)
    assert "## Current FSM state\nSearch Open Door" in p.step_text
    assert "`B2` (rotate right 45°)" in p.step_text and "## Step\n3" in p.step_text
    fb = section(p.step_text, "Controller feedback")
    assert "- movement 'A3' is not allowed" in fb and "- shield: wall ahead" in fb
    user = p.user_text()
    assert user.index(p.context.strip()) < user.index(p.state_prompt.strip()) < user.index(p.step_text.strip())
    assert p.schema == decision_schema(State.SEARCH_OPEN_DOOR, rooms=["bedroom", "living_room", "kitchen"])
    assert Image.open(io.BytesIO(p.image_jpeg)).format == "JPEG"


def test_build_prompt_stable_parts_do_not_change() -> None:
    a = build_prompt(make_input())
    b = build_prompt(make_input(state=State.REACH_OBJECT, previous_movement=None, step=0, query="Find the cup",
                                profile="fast"))
    assert a.system == b.system
    assert "Controller feedback" not in a.step_text
    assert "none (this is the first step" in b.step_text
    assert a.state_prompt != b.state_prompt
    c = build_prompt(make_input(step=9, previous_movement="a1", feedback=("x",)))
    assert c.context == a.context and c.state_prompt == a.state_prompt


def test_map_rooms_shapes() -> None:
    assert map_rooms(MAP) == ["bedroom", "living_room", "kitchen"]
    assert map_rooms({"nodes": ["a", "b"]}) == ["a", "b"]
    assert map_rooms({"nodes": {"a": {}, "b": {}}}) == ["a", "b"]
    assert map_rooms({}) == []


def test_encode_jpeg() -> None:
    rng = np.random.default_rng(0)
    img = rng.integers(0, 255, (480, 640, 3), dtype=np.uint8)
    full = Image.open(io.BytesIO(encode_jpeg(img)))
    assert full.size == (640, 480)
    small = Image.open(io.BytesIO(encode_jpeg(img, quality=50, max_side=320)))
    assert small.size == (320, 240)
    assert len(encode_jpeg(img, quality=30)) < len(encode_jpeg(img, quality=95))
    assert Image.open(io.BytesIO(encode_jpeg(np.zeros((4, 4, 4), np.uint8)))).size == (4, 4)
    for bad in (np.zeros((4, 4, 3), np.float32), np.zeros((4, 4, 2), np.uint8), np.zeros((0, 4, 3), np.uint8)):
        with pytest.raises(ConfigError):
            encode_jpeg(bad)
    with pytest.raises(ConfigError):
        encode_jpeg(img, quality=0)


def test_prompt_hash() -> None:
    h = prompt_hash()
    assert re.fullmatch(r"[0-9a-f]{12}", h) and h == prompt_hash("paper")
    assert prompt_hash("fast") != h
    with pytest.raises(KeyError):
        prompt_hash("nope")


# ---------------------------------------------------------------------------------------------- parse_decision


def test_parse_appendix_d_verbatim() -> None:
    d = parse_decision(APPENDIX_D)
    assert d.core() == {"room": "bedroom", "movement": "E", "state": "Final",
                        "description": "A large mirror is visible on the right side of the image, reflecting light. "
                        "It is positioned near a window and next to a wardrobe. The mirror is mostly in frame and "
                        "upright.", "door_position": "not_visible"}
    assert d.raw_text == APPENDIX_D
    assert validate_decision(d, State.DESCRIBE_OBJECT) is None


ANSWER = {"room": "kitchen", "movement": "A1", "state": "Go Through Door", "description": "A door {ahead}.",
          "door_position": "center"}


@pytest.mark.parametrize(
    "reply",
    [
        json.dumps(ANSWER),
        "```json\n" + json.dumps(ANSWER, indent=2) + "\n```",
        "Sure! Here is my decision:\n```\n" + json.dumps(ANSWER) + "\n```\nGood luck.",
        "I see a door ahead, so: " + json.dumps(ANSWER) + " -- that's it {not json}.",
        "{draft} then " + json.dumps({"decision": ANSWER}),
        repr(ANSWER),
    ],
    ids=["plain", "fenced", "fenced-prose", "prose", "wrapped", "python-dict"],
)
def test_parse_tolerates_wrappings(reply: str) -> None:
    d = parse_decision(reply)
    assert d.core() == ANSWER
    assert d.raw_text == reply


def test_parse_normalises_door_position_and_defaults() -> None:
    d = parse_decision('{"room": null, "movement": "a1", "state": "go through door", "door_position": "Not Visible"}')
    assert (d.room, d.door_position, d.description) == ("unknown", "not_visible", "")
    assert parse_decision(json.dumps({**ANSWER, "door_position": " Centre"})).door_position == "center"


@pytest.mark.parametrize(
    ("reply", "match"),
    [
        ("", "no JSON object"),
        ("I will move forward.", "no JSON object"),
        ("{not: json at all", "no JSON object"),
        ("[1, 2, 3]", "no JSON object"),
        (json.dumps({k: v for k, v in ANSWER.items() if k != "movement"}), "movement"),
        (json.dumps({k: v for k, v in ANSWER.items() if k != "room"}), "room"),
        (json.dumps({**ANSWER, "movement": ["A1", "B1"]}), "'movement' must be a string"),
        (json.dumps({**ANSWER, "state": 3}), "'state' must be a string"),
        (json.dumps({**ANSWER, "door_position": "left | center | right | not_visible"}), "door_position"),
        (json.dumps({**ANSWER, "door_position": "up"}), "door_position"),
    ],
)
def test_parse_rejects_with_a_reason(reply: str, match: str) -> None:
    with pytest.raises(DecisionError, match=match) as info:
        parse_decision(reply)
    assert info.value.reason and info.value.raw_text in (reply, None)


json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(max_size=20),
    lambda children: st.lists(children, max_size=4) | st.dictionaries(st.text(max_size=10), children, max_size=4),
    max_leaves=15,
)


@settings(max_examples=300, suppress_health_check=[HealthCheck.too_slow])
@given(st.text(max_size=400) | st.text(alphabet="{}[]'\":,`\\ aAE1\n", max_size=400))
def test_parse_never_crashes_on_text(text: str) -> None:
    try:
        d = parse_decision(text)
    except DecisionError as exc:
        assert exc.reason
    else:
        assert isinstance(d, Decision) and d.door_position in DOOR_POSITIONS


@settings(max_examples=200)
@given(
    st.dictionaries(st.sampled_from([*FIELDS, "other"]), json_values, max_size=6), st.booleans(), st.text(max_size=30)
)
def test_parse_never_crashes_on_dicts(obj: dict, as_python: bool, prose: str) -> None:
    text = prose + (repr(obj) if as_python else json.dumps(obj))
    try:
        parse_decision(text)
    except DecisionError as exc:
        assert exc.reason


@settings(max_examples=200)
@given(
    st.fixed_dictionaries({
        "room": st.text(max_size=30), "movement": st.sampled_from(sorted(COMMANDS)),
        "state": st.sampled_from([s.value for s in State]), "description": st.text(max_size=80),
        "door_position": st.sampled_from(DOOR_POSITIONS),
    }),
    st.sampled_from(["json", "python", "fenced"]),
    st.text(alphabet=st.characters(blacklist_characters="{}`"), max_size=40),
)
def test_parse_roundtrips_valid_answers(answer: dict, style: str, prose: str) -> None:
    body = {"json": json.dumps(answer), "python": repr(answer), "fenced": f"```json\n{json.dumps(answer)}\n```"}[style]
    d = parse_decision(prose + body + prose)
    expected = {**answer, "room": answer["room"].strip() or "unknown", "description": answer["description"].strip()}
    assert d.core() == expected


# ------------------------------------------------------------------------------------ validate / normalize


def decision(movement: str, state: str) -> Decision:
    return Decision(room="kitchen", movement=movement, state=state)


def test_validate_accepts_allowed_case_insensitively() -> None:
    assert validate_decision(decision("a1", "oriented towards DOOR"), State.SEARCH_OPEN_DOOR) is None
    assert validate_decision(decision(" B3 ", "search_open_door"), State.SEARCH_OPEN_DOOR) is None


def test_validate_rejects_disallowed_move_listing_allowed() -> None:
    reason = validate_decision(decision("D1", "Search Open Door"), State.SEARCH_OPEN_DOOR)
    assert reason and "'D1'" in reason and "not allowed" in reason and "\n" not in reason
    assert "A1, B1, B2, B3, C1, C2, C3, E" in reason
    # A3 is allowed only in the fast profile
    assert validate_decision(decision("A3", "Search Open Door"), State.SEARCH_OPEN_DOOR, "paper")
    assert validate_decision(decision("A3", "Search Open Door"), State.SEARCH_OPEN_DOOR, "fast") is None


def test_validate_rejects_disallowed_transition_listing_allowed() -> None:
    reason = validate_decision(decision("A1", "Stay on Room"), State.GO_THROUGH_DOOR)
    assert reason and "'Stay on Room'" in reason and "not allowed" in reason
    for s in state_spec(State.GO_THROUGH_DOOR).next_states:
        assert f"'{s.value}'" in reason
    assert "movement" not in reason  # the move was fine


def test_validate_rejects_unknown_names() -> None:
    reason = validate_decision(decision("forward", "fly"), State.RECOGNIZE_ROOM)
    assert reason and "'forward'" in reason and "'fly'" in reason and "\n" not in reason
    assert "A1, B1, B2, B3, C1, C2, C3" in reason and "'Stay on Room'" in reason


@pytest.mark.parametrize(("profile", "state"), CASES, ids=CASE_IDS)
def test_validate_agrees_with_schema(profile: str, state: State) -> None:
    props = decision_schema(state, profile)["properties"]
    for code in COMMANDS:
        for nxt in State:
            ok = validate_decision(decision(code.lower(), nxt.value.upper()), state, profile) is None
            # the schema cannot say "E only with a final state": validation adds that one condition
            assert ok == (code in props["movement"]["enum"] and nxt.value in props["state"]["enum"]
                          and state_spec(state, profile).allows(code, nxt))


def test_normalize_decision() -> None:
    d = normalize_decision(decision(" b2", "search OPEN door"))
    assert (d.movement, d.state) == ("B2", "Search Open Door")
    odd = normalize_decision(decision("fly", "nowhere"))
    assert (odd.movement, odd.state) == ("fly", "nowhere")


def test_parse_prefers_the_fenced_answer_over_an_echoed_example() -> None:
    echoed = '{"room": "x", "movement": "valid_single_movement_command", "state": "next_FSM_state"}'
    reply = f"The format is {echoed}. My answer:\n```json\n{json.dumps(ANSWER)}\n```"
    assert parse_decision(reply).core() == ANSWER


def test_the_decision_fields_have_one_definition() -> None:
    from vlnpilot.core.decision import DecisionFields
    from vlnpilot.server.app import DecideResponse

    assert FIELDS == tuple(DecisionFields.model_fields) == ("room", "movement", "state", "description",
                                                          "door_position")
    assert tuple(Decision(room="r", movement="A1", state="Search Object").core()) == FIELDS
    assert decision_schema(State.SEARCH_OBJECT)["required"] == list(FIELDS)
    assert tuple(decision_schema(State.SEARCH_OBJECT)["properties"]) == FIELDS
    assert tuple(DecideResponse.model_fields)[: len(FIELDS)] == FIELDS
