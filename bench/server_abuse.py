"""The pilot server under the abuse of issue 16: N requests that each name a distinct model.

Before the allow-list every distinct `openai:<name>` built and kept a new SDK client (the report: 198 -> 1,327 MB
and 13 -> 1,413 open files after 1,400 requests). Now only allowed SPECs are built. This prints, per repetition,
the growth of the resident memory and of the open file handles over N refused requests, and the median time of
one refusal; then the medians. Runs in-process (FastAPI's TestClient), no network.

    .venv/bin/python bench/server_abuse.py [--requests 2000] [--reps 3]
"""

from __future__ import annotations

import argparse
import base64
import io
import os
import statistics
import time

from fastapi.testclient import TestClient
from machine import describe
from PIL import Image

from vlnpilot.server import create_app


def rss_mb() -> float:
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def open_files() -> int:
    return len(os.listdir("/proc/self/fd"))


def body(pilot: str) -> dict:
    buf = io.BytesIO()
    Image.new("RGB", (64, 48), (120, 140, 160)).save(buf, format="JPEG")
    return {"image": base64.b64encode(buf.getvalue()).decode(), "query": "Go to the kitchen",
            "topological_map": {}, "state": "Recognize Room", "pilot": pilot}


def one_rep(n: int, rep: int) -> tuple[float, int, float, set[int]]:
    app = create_app(pilot_spec="openai:gpt-4.1")
    with TestClient(app) as client:
        for i in range(50):  # warm up
            client.post("/v1/decide", json=body(f"openai:warm-{rep}-{i}"))
        rss0, fds0 = rss_mb(), open_files()
        times, statuses = [], set()
        for i in range(n):
            t0 = time.perf_counter()
            statuses.add(client.post("/v1/decide", json=body(f"openai:model-{rep}-{i}")).status_code)
            times.append(time.perf_counter() - t0)
        return rss_mb() - rss0, open_files() - fds0, statistics.median(times), statuses


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--requests", type=int, default=2000)
    parser.add_argument("--reps", type=int, default=3)
    args = parser.parse_args()
    os.environ.setdefault("OPENAI_API_KEY", "sk-not-a-real-key-bench")  # lets a leaky server build clients
    print(describe())
    rows = []
    for rep in range(args.reps):
        d_rss, d_fds, t_med, statuses = one_rep(args.requests, rep)
        rows.append((d_rss, d_fds, t_med))
        print(f"rep {rep}: {args.requests} distinct pilot names -> statuses {sorted(statuses)}, "
              f"RSS {d_rss:+.1f} MB, open files {d_fds:+d}, median refusal {1000 * t_med:.2f} ms")
    rss, fds, refusal = (statistics.median(r[i] for r in rows) for i in range(3))
    print(f"median over {args.reps}: RSS {rss:+.1f} MB, open files {fds:+.0f}, refusal {1000 * refusal:.2f} ms")


if __name__ == "__main__":
    main()
