"""glsynth view under load from a scripted page: a real server (child process) and a websocket
client that moves the camera as a mouse drag does (an input every 33 ms, 30 Hz).

- frames per second while moving, at the interactive size the server picks;
- latency from an input to the first frame that reflects it or a later input (median, p95);
- time from the camera stopping (the still message) to the full-size still frame, at the
  viewer's size; and, in this process, a 1920x1080 still (render and PNG) at `fast`'s knobs;
- time to switch environment (scene message to scene summary, and to the first full-size
  frame after it) at the demo and paper presets;
- a move sent 40 ms into a full-size still: time from the move to its frame, and whether the
  stale still ever arrives (the still is interrupted);
- the server's RSS before and after 500 camera moves and 10 environment switches (llvmpipe
  draws on the CPU, so its "GPU memory" is in the RSS).

    .venv/bin/python bench/bench_view.py [--moves 500] [--switches 10] [--paper-switches 2]
        [--only switch]   (the demo switches and the interrupted stills alone, for
                           before/after comparisons: bench/results/view_switch.json)
"""

import argparse
import contextlib
import dataclasses
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from common import write_results  # noqa: E402
from viewhelpers import ViewServer, receive  # noqa: E402
from websockets.sync.client import connect  # noqa: E402

INPUT_S = 1 / 30


def rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise RuntimeError("no VmRSS")


def settled_rss_mb(pid: int, wait_s: float = 3.0) -> float:
    """The server's RSS once its idle work (packing the cracks no view has shown, then
    verdict renders) has had ``wait_s``: the lowest of 5 readings 0.25 s apart, since a
    verdict render in flight holds transient arrays."""
    time.sleep(wait_s)
    readings = []
    for _ in range(5):
        readings.append(rss_mb(pid))
        time.sleep(0.25)
    return min(readings)


def orbit(pose: list, step: int) -> list:
    """``pose`` turned by ``step`` x 0.2 degrees about the world z axis through its position
    (the page sends such poses while dragging)."""
    a = np.radians(0.2 * step)
    turn = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    out = np.array(pose)
    out[:3, :3] = turn @ out[:3, :3]
    return out.tolist()


def drag(ws, camera: dict, moves: int) -> dict:
    """``moves`` inputs at 30 Hz; each is told apart by a focal length that differs in the
    ninth digit, which every frame header repeats."""
    sent, frames = [], []
    base = camera["focal_mm"]
    t_start = time.perf_counter()
    for i in range(moves):
        due = t_start + i * INPUT_S
        while (now := time.perf_counter()) < due:
            try:
                header, _ = receive(ws, "frame", timeout=due - now)
                frames.append((time.perf_counter(), header))
            except TimeoutError:
                break
        ws.send(json.dumps({"type": "camera", "pose": orbit(camera["pose"], i),
                            "focal_mm": base + i * 1e-6, "moving": True}))
        sent.append(time.perf_counter())
    end = time.perf_counter()
    while True:  # the frames still on the way
        try:
            header, _ = receive(ws, "frame", timeout=1.0)
            frames.append((time.perf_counter(), header))
        except TimeoutError:
            break
    return _drag_numbers(sent, frames, base, end - t_start)


def _drag_numbers(sent: list[float], frames: list, base: float, seconds: float) -> dict:
    reflected = [round((h["focal_mm"] - base) / 1e-6) for _, h in frames]
    latency = []
    for i, t in enumerate(sent):
        first = next((at for at, (_, h) in zip(reflected, frames) if at >= i), None)
        if first is not None:
            latency.append(frames[reflected.index(first)][0] - t)
    latency_ms = np.array(latency) * 1e3
    in_drag = [f for f in frames if f[0] <= sent[-1]]
    return {"inputs": len(sent), "frames": len(frames), "fps_moving": len(in_drag) / seconds,
            "sizes": sorted({f"{h['width']}x{h['height']}" for _, h in frames}),
            "render_ms_median": statistics.median(h["render_ms"] for _, h in frames),
            "latency_ms_median": float(np.median(latency_ms)),
            "latency_ms_p95": float(np.percentile(latency_ms, 95))}


def still_seconds(ws, camera: dict, repeats: int = 5) -> dict:
    times = []
    for i in range(repeats):
        ws.send(json.dumps({"type": "camera", "pose": orbit(camera["pose"], 40 * i),
                            "focal_mm": camera["focal_mm"], "moving": False}))
        t0 = time.perf_counter()
        header, _ = receive(ws, "frame")
        assert header["still"]
        times.append(time.perf_counter() - t0)
    return {"size": f"{header['width']}x{header['height']}",
            "seconds_median": statistics.median(times), "seconds_max": max(times)}


def switch_seconds(ws, envs: list[int], quality: str, pid: int) -> dict:
    """Seconds from each scene message to its summary and to the first frame after it (the
    page's camera, at full size), and the server's RSS after each (once the idle work, the
    cracks no view has shown yet, is done)."""
    times, to_frame, rss = [], [], []
    for env in envs:
        t0 = time.perf_counter()
        ws.send(json.dumps({"type": "scene", "seed": 0, "env": env, "quality": quality,
                            "config_toml": None}))
        receive(ws, "scene", timeout=600)
        times.append(time.perf_counter() - t0)
        header, _ = receive(ws, "frame", timeout=600)
        assert header["still"]
        to_frame.append(time.perf_counter() - t0)
        rss.append(settled_rss_mb(pid))
    return {"summary_s": times, "frame_s": to_frame, "rss_mb": rss}


def interrupt_seconds(ws, camera: dict, repeats: int = 5) -> dict:
    """A still, then a move 40 ms later: seconds from the move to its (small) frame, and the
    stills that arrive after that frame (stale: never, if the move interrupts the still)."""
    times, stale = [], 0
    for i in range(repeats):
        pose = orbit(camera["pose"], 40 * i + 7)
        ws.send(json.dumps({"type": "camera", "pose": pose, "focal_mm": camera["focal_mm"],
                            "moving": False}))
        time.sleep(0.04)
        ws.send(json.dumps({"type": "camera", "pose": orbit(pose, 1),
                            "focal_mm": camera["focal_mm"], "moving": True}))
        t0 = time.perf_counter()
        while receive(ws, "frame")[0]["still"]:
            pass  # the still finished before the move came
        times.append(time.perf_counter() - t0)
        with contextlib.suppress(TimeoutError):
            while True:
                stale += receive(ws, "frame", timeout=1.0)[0]["still"]
    return {"move_to_frame_s_median": statistics.median(times),
            "move_to_frame_s_max": max(times), "stale_stills_after_the_move": stale}


def full_hd_still() -> dict:
    """A 1920x1080 still at `fast`'s knobs, rendered and PNG-encoded as the server does."""
    from glsynth.core.config import load_config
    from glsynth.data.quality import apply_quality
    from glsynth.render.view import EnvironmentView
    from glsynth.view.frames import encode
    from glsynth.view.worker import STILL_BANDS

    config = apply_quality(load_config("demo"), "fast")
    config = dataclasses.replace(config, render=dataclasses.replace(config.render, width=1920,
                                                                    height=1080))
    view = EnvironmentView.open(config, 0, 0, cull=False, anywhere=True)
    times = {1: [], STILL_BANDS: []}
    for index in range(1, 6):
        view.renderer.prepare_cracks()  # packed once: both ways then draw the same work
        for bands in times:
            camera = view.camera(index).camera
            t0 = time.perf_counter()
            output = view.renderer.render(camera, interrupt=(lambda: False) if bands > 1
                                          else None, bands=bands)
            encode(output.color, still=True)
            times[bands].append(time.perf_counter() - t0)
    view.renderer.release()
    return {"size": "1920x1080", "seconds_median": statistics.median(times[1]),
            "seconds_max": max(times[1]),
            "interruptible_seconds_median": statistics.median(times[STILL_BANDS]),
            "interruptible_bands": STILL_BANDS}


def bench_demo(args: argparse.Namespace, out: Path) -> dict:
    server = ViewServer(out / "demo")
    try:
        with connect(server.ws_url, max_size=None, open_timeout=30) as ws:
            scene = receive(ws, "scene", timeout=300)
            camera = {"pose": scene["cameras"][1]["pose"],
                      "focal_mm": scene["cameras"][1]["focal_mm"]}
            drag(ws, camera, 30)  # warm up: the pacer settles on a size
            rss = {"start_mb": settled_rss_mb(server.proc.pid)}
            moving = drag(ws, camera, args.moves)
            rss["after_moves_mb"] = settled_rss_mb(server.proc.pid)
            still = still_seconds(ws, camera)
            interrupt = interrupt_seconds(ws, camera)
            switch = switch_seconds(ws, [(i + 1) % 3 for i in range(args.switches)], "fast",
                                    server.proc.pid)
    finally:
        server.stop()
    after = switch["rss_mb"]
    # The demo preset has 3 environments: from the third switch on each has been open once.
    rss.update(after_each_switch_mb=after, growth_mb=after[-1] - rss["start_mb"],
               growth_max_mb=max(after) - rss["start_mb"],
               growth_after_third_switch_mb=after[-1] - after[2] if len(after) > 3 else None)
    return {"moving": moving, "still": still, "interrupt": interrupt, "rss": rss,
            "switch_s": spread(switch["summary_s"]),
            "switch_to_first_frame_s": spread(switch["frame_s"])}


def spread(values: list[float]) -> dict:
    return {"median": statistics.median(values), "max": max(values), "n": len(values),
            "each": values}


def look(ws, scene: dict) -> None:
    """The page looks through the scene's camera 1 and gets its still (a switch then renders
    the page's camera)."""
    ws.send(json.dumps({"type": "camera", "pose": scene["cameras"][1]["pose"],
                        "focal_mm": scene["cameras"][1]["focal_mm"], "moving": False}))
    receive(ws, "frame")


def bench_switch(args: argparse.Namespace, out: Path) -> dict:
    """The demo's interrupted stills (10) and switches alone, the page at camera 1."""
    server = ViewServer(out / "switch")
    try:
        with connect(server.ws_url, max_size=None, open_timeout=30) as ws:
            scene = receive(ws, "scene", timeout=300)
            look(ws, scene)
            interrupt = interrupt_seconds(ws, {"pose": scene["cameras"][1]["pose"],
                                               "focal_mm": scene["cameras"][1]["focal_mm"]}, 10)
            look(ws, scene)
            start = settled_rss_mb(server.proc.pid)
            switch = switch_seconds(ws, [(i + 1) % 3 for i in range(args.switches)], "fast",
                                    server.proc.pid)
    finally:
        server.stop()
    return {"interrupt": interrupt, "switch_s": spread(switch["summary_s"]),
            "switch_to_first_frame_s": spread(switch["frame_s"]),
            "rss_start_mb": start, "rss_after_each_switch_mb": switch["rss_mb"]}


def bench_paper_switch(args: argparse.Namespace, out: Path) -> dict:
    server = ViewServer(out / "paper", "--preset", "paper")
    try:
        with connect(server.ws_url, max_size=None, open_timeout=30) as ws:
            scene = receive(ws, "scene", timeout=600)
            look(ws, scene)
            switch = switch_seconds(ws, list(range(1, args.paper_switches + 1)), "fast",
                                    server.proc.pid)
    finally:
        server.stop()
    return spread(switch["summary_s"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--moves", type=int, default=500)
    parser.add_argument("--switches", type=int, default=10)
    parser.add_argument("--paper-switches", type=int, default=2)
    parser.add_argument("--only", choices=["switch"])
    args = parser.parse_args()
    if args.only == "switch":
        with tempfile.TemporaryDirectory() as tmp:
            write_results("view_switch", bench_switch(args, Path(tmp)))
        return
    with tempfile.TemporaryDirectory() as tmp:
        results = {"demo_fast": bench_demo(args, Path(tmp)),
                   "paper_fast_switch_s": bench_paper_switch(args, Path(tmp)),
                   "still_1920x1080_fast": full_hd_still(),
                   "loadavg_1_5_15_min_at_end": Path("/proc/loadavg").read_text().split()[:3]}
    write_results("view", results)


if __name__ == "__main__":
    main()
