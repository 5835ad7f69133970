"""Fake model servers for tests and benchmarks: real HTTP on 127.0.0.1, each provider's wire protocol.

    from fakes import FakeOpenAI          # tests/ is on sys.path under pytest; elsewhere add it
    with FakeOpenAI(oracle=lambda request: {...decision...}, delay=1.5) as fake:
        pilot = make_pilot("openai", base_url=fake.base_url, api_key="sk-test")
        ...
        fake.requests        # every RecordedRequest (texts, images, schema, headers, ...)

See _server.py for the scripted actions (`fake.push("rate_limit", retry_after=0.05)`, ...).
"""

from ._server import ACTIONS, FakeServer, RecordedRequest, auto_decision
from .anthropic_fake import FakeAnthropic
from .gemini_fake import FakeGemini
from .inputs import SAMPLE_MAP, sample_image, sample_input
from .openai_fake import FakeOpenAI
from .scripted import DEFAULT_DECISION, ScriptedPilot
from .uvicorn_thread import ServerThread, free_port
from .warm import warm_up

__all__ = [
    "warm_up",
    "ACTIONS", "DEFAULT_DECISION", "SAMPLE_MAP", "FakeAnthropic", "FakeGemini", "FakeOpenAI", "FakeServer",
    "RecordedRequest", "ScriptedPilot", "ServerThread", "auto_decision", "free_port", "sample_image", "sample_input",
]
