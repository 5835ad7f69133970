"""Offline o200k token counts (pilots/tokens.py, issue 27): the ranks ship in the bpe-openai wheel, and the prefix
two requests share is counted segment by segment, then token by token inside the first segment that differs."""

from __future__ import annotations

from vlnpilot.pilots.tokens import Segment, encode, openai_segments, shared_prefix, text_segment


def test_o200k_counts_offline_as_openai_does() -> None:
    assert encode("Hello world") == [13225, 2375]  # o200k_base, as tiktoken gives it


def _request(step_text: str, image: str, state_prompt: str = "Search the object.") -> dict:
    return {"response_format": {"type": "json_schema", "json_schema": {"name": "s", "schema": {}}},
            "messages": [{"role": "system", "content": "You pilot a drone. " * 50},
                         {"role": "user", "content": [
                             {"type": "text", "text": "Find the cup."}, {"type": "text", "text": state_prompt},
                             {"type": "text", "text": step_text},
                             {"type": "image_url", "image_url": {"url": image, "detail": "low"}}]}]}


def test_the_shared_prefix_ends_inside_the_first_text_that_differs() -> None:
    before = openai_segments(_request("## Step\n3\n", "data:a"))
    now = openai_segments(_request("## Step\n4\n", "data:b"))
    split = shared_prefix(now, before)
    step_tokens = len(encode("## Step\n4\n"))
    assert split.text_outside < step_tokens  # "## Step\n" is shared as well
    assert split.input_tokens == split.text_tokens + 85  # the image at detail low
    assert split.shared_tokens == split.shared_text_tokens  # the new image is outside
    assert shared_prefix(now, None).shared_tokens == 0


def test_a_new_state_prompt_ends_the_prefix_there() -> None:
    before = openai_segments(_request("## Step\n3\n", "data:a"), schema=False)
    now = openai_segments(_request("## Step\n4\n", "data:b", state_prompt="Reach the object."), schema=False)
    split = shared_prefix(now, before)
    assert split.text_outside >= len(encode("Reach the object.")) - 1 + len(encode("## Step\n4\n")) - 3
    assert shared_prefix([text_segment("a b")], [Segment(image="x", image_tokens=85)]).shared_tokens == 0
