"""Load on ``stickslip serve``: 50 WebSocket clients while moves run, STOP latency, the dead man, memory.

The server (a :class:`~stickslip.server.room.ControlRoom` on ``sim://?realtime=1``, the
simulator stepping at 1 kHz on the wall clock, with its true calibration) runs under
uvicorn on a loopback port in this process; the 50 clients run in a child process (their
JSON decoding does not share this process's interpreter lock), each reading the 20 Hz
state stream and checking every message's ``seq``: none lost, none out of order.

While they read, joint 2 moves back and forth (60 deg, about 21 000 steps, 21 s a move)
and every few seconds a STOP is sent over HTTP in the middle of a move. STOP latency is
from the request's arrival at the endpoint to the last step the simulated controller
sent (both on this process's monotonic clock): p50, p99, max. Every 30 s a jog is held
with keep-alives every 50 ms and then let go silently (no release): the dead man's
latency is from the last keep-alive to the last step. Memory is this process's resident
set, sampled every 10 s: the first and the last minute and the growth between.

    python benchmarks/bench_serve.py                # the 10-minute run the issue asks for
    python benchmarks/bench_serve.py --minutes 1    # a quick look
"""

from __future__ import annotations

import argparse
import asyncio
import json
import multiprocessing as mp
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent / "tests" / "support")]

CLIENTS = 50


def rss_mib() -> float:
    """This process's resident set, MiB (Linux /proc; NaN elsewhere)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return float("nan")


def clients(url: str, n: int, seconds: float, out: Any) -> None:
    """The child process: ``n`` WebSocket readers for ``seconds``; puts one result per client in ``out``."""
    from websockets.asyncio.client import connect

    async def one(i: int) -> dict[str, Any]:
        seqs_ok = True
        count = 0
        last = None
        gaps = 0
        backwards = 0
        end = time.monotonic() + seconds
        async with connect(url.replace("http", "ws") + "/api/live", max_size=2**22) as ws:
            while time.monotonic() < end:
                try:
                    text = await asyncio.wait_for(ws.recv(), 5.0)
                except TimeoutError:
                    return {"client": i, "count": count, "gaps": gaps, "backwards": backwards, "ok": False,
                            "why": "no message for 5 s"}
                m = json.loads(text)
                if "seq" not in m:
                    continue
                if last is not None:
                    if m["seq"] <= last:
                        backwards += 1
                        seqs_ok = False
                    elif m["seq"] != last + 1:
                        gaps += m["seq"] - last - 1
                        seqs_ok = False
                last = m["seq"]
                count += 1
        return {"client": i, "count": count, "gaps": gaps, "backwards": backwards, "ok": seqs_ok, "why": ""}

    async def everyone() -> list[dict[str, Any]]:
        return await asyncio.gather(*(one(i) for i in range(n)), return_exceptions=False)

    for r in asyncio.run(everyone()):
        out.put(r)


def pct(values: list[float], q: float) -> float:
    """The ``q`` quantile (0..1) of ``values`` (nearest rank)."""
    s = sorted(values)
    return s[min(len(s) - 1, max(0, int(round(q * (len(s) - 1)))))]


def main(argv: list[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(prog="bench_serve.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, default=10.0, help="how long to run (default 10)")
    parser.add_argument("--clients", type=int, default=CLIENTS, help="WebSocket clients (default 50)")
    args = parser.parse_args(argv if argv is not None else [])
    import httpx
    from server_support import room_on, served, until

    from stickslip.server.app import create_app
    from stickslip.server.security import Access

    seconds = args.minutes * 60.0
    tmp = Path(tempfile.mkdtemp(prefix="bench-serve-"))
    room = room_on(tmp, "sim://?realtime=1")
    arm = room.owned.dev
    memory: list[tuple[float, float]] = []
    deadman: list[float] = []
    moves = 0
    with served(create_app(room, Access(None, True))) as url:
        queue: Any = mp.get_context("spawn").Queue()
        child = mp.get_context("spawn").Process(target=clients, args=(url, args.clients, seconds, queue))
        child.start()
        http = httpx.Client(base_url=url, timeout=40.0)
        t0 = time.monotonic()
        next_mem = t0
        next_jog = t0 + 15.0
        sign = -1
        while time.monotonic() - t0 < seconds:
            now = time.monotonic()
            if now >= next_mem:
                memory.append((now - t0, rss_mib()))
                next_mem += 10.0
            if now >= next_jog and now - t0 < seconds - 5:
                next_jog += 30.0
                deadman.append(_jog_and_let_go(http, room, arm))
                continue
            sign = -sign
            r = http.post("/api/move", json={"joint": 2, "by": f"{60 * sign}deg"})
            if r.status_code != 202:
                time.sleep(0.2)
                continue
            moves += 1
            ident = r.json()["id"]
            time.sleep(1.0 + (moves % 7) * 0.3)  # STOP lands somewhere in the first seconds of the move
            http.post("/api/stop")
            http.get(f"/api/motions/{ident}", params={"wait": 30})
            until(lambda: room.current() is None, 30, "the stopped move to end")
        child.join(120)
        results = [queue.get(timeout=30) for _ in range(args.clients)]
        http.close()
    memory.append((time.monotonic() - t0, rss_mib()))
    room.close()

    signed = [(last - got) * 1e3 for got, last in room.stops if last is not None]
    latencies = [max(0.0, v) for v in signed]  # a last step sent before the request came: no step after it
    ended = [(m.t_end - m.stop_requested) * 1e3 for m in room._motions.values()  # noqa: SLF001
             if m.stop_requested is not None and m.t_end is not None and m.kind == "move"]
    counts = [r["count"] for r in results]
    lost = sum(r["gaps"] for r in results)
    backwards = sum(r["backwards"] for r in results)
    first = [m for t, m in memory if t <= 70.0] or [memory[0][1]]
    last_min = [m for t, m in memory if t >= memory[-1][0] - 60.0]
    report = {
        "minutes": args.minutes, "clients": args.clients, "moves": moves, "stops": len(latencies),
        "messages_per_client_min": min(counts), "messages_per_client_max": max(counts),
        "lost": lost, "out_of_order": backwards, "clients_ok": sum(r["ok"] for r in results),
        "stop_ms_p50": pct(latencies, 0.5) if latencies else float("nan"),
        "stop_ms_p99": pct(latencies, 0.99) if latencies else float("nan"),
        "stop_ms_max": max(latencies) if latencies else float("nan"),
        "stops_with_a_step_after": sum(v > 0 for v in signed),
        "stop_to_end_ms_p99": pct(ended, 0.99) if ended else float("nan"),
        "deadman_ms": [round(d * 1e3, 1) for d in deadman],
        "rss_first_min_mib": statistics.mean(first), "rss_last_min_mib": statistics.mean(last_min),
        "rss_max_mib": max(m for _, m in memory),
    }
    print(f"stickslip serve on sim://?realtime=1, {args.minutes:g} min, {args.clients} WebSocket clients at 20 Hz")
    print(f"  moves of joint 2 (60 deg, 1 kHz): {moves}, each stopped part-way")
    print(f"  state messages per client: {min(counts)}..{max(counts)}; lost {lost}, out of order {backwards}; "
          f"clients with every message in order: {report['clients_ok']}/{args.clients}")
    print(f"  STOP latency (request received -> last step sent), {len(latencies)} stops: "
          f"p50 {report['stop_ms_p50']:.2f} ms, p99 {report['stop_ms_p99']:.2f} ms, max {report['stop_ms_max']:.2f} ms"
          " (target: p99 <= 100 ms)")
    print(f"    stops with a step sent after the request: {report['stops_with_a_step_after']} of {len(signed)} "
          "(the others came between two 5 ms chunks of steps: nothing was sent after them)")
    if ended:
        print(f"    request received -> the move ended, its position saved: p99 {report['stop_to_end_ms_p99']:.1f} ms "
              f"(the last {len(ended)} moves kept)")
    if deadman:
        print(f"  dead man (last keep-alive -> last step), {len(deadman)} jogs let go silently: "
              f"max {max(deadman) * 1e3:.0f} ms (target: 300 ms)")
    print(f"  resident memory: first minute {report['rss_first_min_mib']:.1f} MiB, last minute "
          f"{report['rss_last_min_mib']:.1f} MiB, max {report['rss_max_mib']:.1f} MiB")
    for r in results:
        if r["why"]:
            print(f"  client {r['client']}: {r['why']}")
    return report


def _jog_and_let_go(http: Any, room: Any, arm: Any) -> float:
    """Hold +z with keep-alives for 1.5 s, then send nothing: seconds from the last keep-alive to the last step."""
    from server_support import until

    body = {"direction": "+z", "speed": 6}
    end = time.monotonic() + 1.5
    last_alive = time.monotonic()
    while time.monotonic() < end:
        http.post("/api/jog", json=body)
        last_alive = time.monotonic()
        time.sleep(0.05)
    until(lambda: room.current() is None, 30, "the jog session to end")
    last = getattr(arm, "last_step_s", None)
    return float(last - last_alive) if isinstance(last, float) else float("nan")


if __name__ == "__main__":
    main(sys.argv[1:])
