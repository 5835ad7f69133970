"""The pilot server under abuse: N requests naming distinct models (issue 16), and a decode bomb (issue 26).

Before the allow-list every distinct `openai:<name>` built and kept a new SDK client (the report: 198 -> 1,327 MB
and 13 -> 1,413 open files after 1,400 requests). Now only allowed SPECs are built. This prints, per repetition,
the growth of the resident memory and of the open file handles over N refused requests, and the median time of
one refusal; then the medians. Runs in-process (FastAPI's TestClient), no network.

The decode bomb (issue 26): a 78 KB PNG of 4096x4096 pixels, sent by `--bomb-clients` concurrent clients, each
`--bomb-rounds` times, naming a pilot the server does not serve, then naming the one it serves. The server runs
in its own process (uvicorn on 127.0.0.1) and its peak resident memory (VmHWM) is reported. `--before REF` first
measures the server of a git commit (exported with `git archive`), so that before and after come from one run.

    .venv/bin/python bench/server_abuse.py [--requests 2000] [--reps 3] [--bomb-clients 64] [--before REF] [--smoke]
"""

from __future__ import annotations

import argparse
import base64
import io
import os
import socket
import statistics
import subprocess
import sys
import tarfile
import tempfile
import threading
import time
from pathlib import Path

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


# ------------------------------------------------------------------------------------------ the decode bomb

SERVER = """
import sys, uvicorn
from vlnpilot.server import create_app
uvicorn.run(create_app(pilot_spec="openai:gpt-4.1"), host="127.0.0.1", port=int(sys.argv[1]), log_level="error")
"""


def bomb_png(width: int = 4096, height: int = 4096) -> str:
    """A PNG of black pixels: 4096x4096 is about 50 KB compressed, 48 MB once decoded to RGB."""
    buf = io.BytesIO()
    Image.new("RGB", (width, height)).save(buf, format="PNG", optimize=True)
    return base64.b64encode(buf.getvalue()).decode()


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def peak_rss_mb(pid: int) -> tuple[float, float]:
    """(current, peak) resident memory of a process, from /proc/PID/status."""
    fields = dict(line.split(":", 1) for line in Path(f"/proc/{pid}/status").read_text().splitlines() if ":" in line)
    return int(fields["VmRSS"].split()[0]) / 1024, int(fields["VmHWM"].split()[0]) / 1024


def export_source(ref: str, into: Path) -> Path:
    """The src/ directory of a git commit, written under `into` (no worktree, no checkout)."""
    archive = subprocess.run(["git", "archive", "--format=tar", ref, "src"], check=True, capture_output=True,
                             cwd=Path(__file__).resolve().parent.parent).stdout
    with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
        tar.extractall(into, filter="data")
    return into / "src"


def bomb(src: Path, clients: int, rounds: int, image: str, largest: str) -> dict:
    """Start the server of `src`, fire the bomb, return its statuses and memory."""
    import httpx

    port = free_port()
    env = {**os.environ, "PYTHONPATH": str(src), "OPENAI_API_KEY": "sk-not-a-real-key-bench",
           "OPENAI_BASE_URL": "http://127.0.0.1:9/v1"}  # a pilot call that gets through fails here, not on the net
    server = subprocess.Popen([sys.executable, "-c", SERVER, str(port)], env=env)
    url = f"http://127.0.0.1:{port}"
    try:
        for _ in range(300):
            try:
                if httpx.get(url + "/healthz", timeout=1).status_code == 200:
                    break
            except httpx.TransportError:
                time.sleep(0.1)
        idle, _ = peak_rss_mb(server.pid)
        results = {}
        cases = (("not allowed", "openai:not-allowed", image), ("allowed", "openai:gpt-4.1", image),
                 ("largest allowed image", "openai:gpt-4.1", largest))
        for label, pilot, picture in cases:
            statuses: list[int] = []
            start = threading.Barrier(clients)
            payload = {"image": picture, "query": "Go to the kitchen", "topological_map": {},
                       "state": "Recognize Room", "pilot": pilot}

            def client(payload: dict = payload, start: threading.Barrier = start, statuses: list = statuses) -> None:
                with httpx.Client(timeout=120) as http:
                    start.wait()
                    for _ in range(rounds):
                        statuses.append(http.post(url + "/v1/decide", json=payload).status_code)

            threads = [threading.Thread(target=client) for _ in range(clients)]
            for t in threads:
                t.start()
            for t in threads:
                t.join()
            results[label] = (sorted(set(statuses)), peak_rss_mb(server.pid)[1])
        return {"idle": idle, **results}
    finally:
        server.terminate()
        server.wait(10)


def bomb_report(args: argparse.Namespace) -> None:
    image, largest = bomb_png(), bomb_png(4096, 2160)  # the bomb, and the largest image the server decodes
    print(f"decode bomb: {len(image) * 3 // 4 // 1024} KB PNG of 4096x4096, {args.bomb_clients} clients x "
          f"{args.bomb_rounds} requests, first naming a pilot not served, then the served one, then the served one "
          "with a 4096x2160 PNG (the largest "
          "the server decodes); peaks are cumulative")
    here = Path(__file__).resolve().parent.parent / "src"
    with tempfile.TemporaryDirectory() as tmp:
        trees = ([(f"before ({args.before})", export_source(args.before, Path(tmp)))] if args.before else [])
        for label, src in [*trees, ("after (this tree)", here)]:
            r = bomb(src, args.bomb_clients, args.bomb_rounds, image, largest)
            print(f"{label}: idle {r.pop('idle'):.0f} MB; "
                  + "; ".join(f"{case} -> statuses {st}, peak {peak:.0f} MB" for case, (st, peak) in r.items()))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--requests", type=int, default=2000)
    parser.add_argument("--reps", type=int, default=3)
    parser.add_argument("--bomb-clients", type=int, default=64)
    parser.add_argument("--bomb-rounds", type=int, default=2)
    parser.add_argument("--before", metavar="REF", help="also measure the decode bomb on this git commit")
    parser.add_argument("--only", choices=("names", "bomb"), help="run only one of the two")
    parser.add_argument("--smoke", action="store_true", help="20 requests, 1 rep, 2 bomb clients (for the tests)")
    args = parser.parse_args()
    if args.smoke:
        args.requests, args.reps, args.bomb_clients, args.bomb_rounds = 20, 1, 2, 1
    os.environ.setdefault("OPENAI_API_KEY", "sk-not-a-real-key-bench")  # lets a leaky server build clients
    print(describe())
    if args.only != "names":
        bomb_report(args)
    if args.only == "bomb":
        return
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
