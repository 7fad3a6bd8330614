"""`dear view` in a real headless browser: Debian's Chromium, driven through chromedriver's
WebDriver protocol (plain HTTP + JSON, Python's standard library).

Starts `deard` replaying samples/demo in a loop and `dear view --bind 127.0.0.1:0` on it, loads
the page once, waits until the depth and blend pictures show a frame and the page reports a
frame rate, then takes screenshots until the pixels of the depth and blend pictures differ from
the first screenshot's: the page follows the stream. Polls each condition up to a generous
timeout (no fixed sleeps); prints what it saw and exits non-zero on a failure.

Usage: view_browser.py [--bin-dir target/debug] [--timeout 60]
Run by scripts/test.sh's tier "browser view"; needs chromium and chromium-driver
(scripts/setup.sh installs them) and the workspace's debug binaries (cargo test --workspace).
"""

from __future__ import annotations

import argparse
import base64
import contextlib
import io
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
from pathlib import Path
from typing import Any

from PIL import Image, ImageChops

ROOT = Path(__file__).resolve().parents[2]
CHROMIUM_FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--window-size=1280,900",
]
# The page's bounding boxes and the state its script shows, read in the browser.
PAGE_STATE = """
const box = (id) => {
  const r = document.getElementById(id).getBoundingClientRect();
  return [r.left, r.top, r.right, r.bottom].map((v) => v * devicePixelRatio);
};
const img = (id) => document.getElementById(id);
return {
  depth: box("depth"), blend: box("blend"),
  depth_frame: img("depth").dataset.frame || null,
  blend_frame: img("blend").dataset.frame || null,
  depth_width: img("depth").naturalWidth, blend_width: img("blend").naturalWidth,
  fps: parseFloat(document.getElementById("fps").textContent),
};
"""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def http(method: str, url: str, body: Any = None, timeout: float = 30) -> Any:
    data = None if body is None else json.dumps(body).encode()
    req = urllib.request.Request(
        url, data=data, method=method, headers={"Content-Type": "application/json"}
    )
    with urllib.request.urlopen(req, timeout=timeout) as response:
        return json.loads(response.read() or b"null")


def poll(what: str, timeout: float, check: Any) -> Any:
    """Calls `check` until it returns something truthy; fails after `timeout` seconds."""
    deadline = time.monotonic() + timeout
    last = None
    while time.monotonic() < deadline:
        last = check()
        if last:
            return last
        time.sleep(0.1)
    raise AssertionError(f"timed out after {timeout} s waiting for {what} (last: {last!r})")


class Driver:
    """One chromedriver process and one browser session."""

    def __init__(self, profile: Path, log: Path, timeout: float) -> None:
        port = free_port()
        self.base = f"http://127.0.0.1:{port}"
        self.process = subprocess.Popen(
            ["chromedriver", f"--port={port}", f"--log-path={log}"],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        try:
            poll("chromedriver", timeout, self._ready)
            capabilities = {
                "browserName": "chrome",
                "goog:chromeOptions": {
                    "binary": shutil.which("chromium") or "/usr/bin/chromium",
                    "args": [*CHROMIUM_FLAGS, f"--user-data-dir={profile}"],
                },
            }
            session = http(
                "POST",
                f"{self.base}/session",
                {"capabilities": {"alwaysMatch": capabilities}},
                timeout=timeout,
            )
        except BaseException:
            self.process.kill()
            self.process.wait()
            raise
        self.session = f"{self.base}/session/{session['value']['sessionId']}"

    def _ready(self) -> bool:
        try:
            return bool(http("GET", f"{self.base}/status", timeout=2)["value"]["ready"])
        except (OSError, urllib.error.URLError, KeyError, ValueError):
            return False

    def open(self, url: str) -> None:
        http("POST", f"{self.session}/url", {"url": url})

    def script(self, source: str) -> Any:
        return http("POST", f"{self.session}/execute/sync", {"script": source, "args": []})["value"]

    def screenshot(self) -> Image.Image:
        png = base64.b64decode(http("GET", f"{self.session}/screenshot")["value"])
        return Image.open(io.BytesIO(png)).convert("RGB")

    def close(self) -> None:
        with contextlib.suppress(OSError, urllib.error.URLError):
            http("DELETE", self.session, timeout=10)
        self.process.terminate()
        try:
            self.process.wait(10)
        except subprocess.TimeoutExpired:
            self.process.kill()


def crop(shot: Image.Image, box: list[float]) -> Image.Image:
    return shot.crop(tuple(round(v) for v in box))


def colours(image: Image.Image) -> int:
    return len(image.getcolors(maxcolors=1 << 20) or [])


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--bin-dir", type=Path, default=ROOT / "target" / "debug")
    parser.add_argument("--timeout", type=float, default=60.0)
    args = parser.parse_args()
    for tool in ("chromium", "chromedriver"):
        if not shutil.which(tool):
            sys.exit(
                f"{tool} not found: run scripts/setup.sh (Debian's chromium and chromium-driver)"
            )
    for binary in ("deard", "dear"):
        if not (args.bin_dir / binary).is_file():
            sys.exit(
                f"{args.bin_dir / binary} not found: build the workspace (cargo test --workspace)"
            )

    started = time.monotonic()
    service = f"dear-test/{os.getpid()}/view-browser/frames"
    processes: list[subprocess.Popen[bytes]] = []
    driver: Driver | None = None
    with tempfile.TemporaryDirectory() as tmp_dir:
        tmp = Path(tmp_dir)
        try:
            with open(tmp / "deard.log", "wb") as deard_log:
                processes.append(
                    subprocess.Popen(
                        [
                            args.bin_dir / "deard",
                            "--service",
                            service,
                            "--refine",
                            "classical",
                            "--loop",
                            "--replay",
                            ROOT / "samples" / "demo",
                        ],
                        stdout=subprocess.DEVNULL,
                        stderr=deard_log,
                    )
                )
            view = subprocess.Popen(
                [args.bin_dir / "dear", "view", "--bind", "127.0.0.1:0", "--service", service],
                stdout=subprocess.PIPE,
            )
            processes.append(view)
            assert view.stdout is not None
            line = view.stdout.readline().decode()
            print(f"view_browser: {line.strip()}")
            url = next((w for w in line.split() if w.startswith("http://")), None)
            assert url, f"dear view printed no address: {line!r}"

            driver = Driver(tmp / "profile", tmp / "chromedriver.log", args.timeout)
            driver.open(url)

            def showing() -> dict[str, Any] | None:
                state = driver.script(PAGE_STATE)
                shown = state["depth_width"] > 0 and state["blend_width"] > 0 and state["fps"] > 0
                return state if shown else None

            state = poll("the page to show frames and a frame rate", args.timeout, showing)
            first = driver.screenshot()
            for name in ("depth", "blend"):
                n = colours(crop(first, state[name]))
                # A picture of the scene, not an empty box: the turbo depth and the blend have
                # thousands of colours, a blank or broken image a handful.
                assert n > 500, f"the {name} picture has {n} colours: not a frame"
            print(
                f"view_browser: frames shown after {time.monotonic() - started:.1f} s "
                f"(depth frame {state['depth_frame']}, blend frame {state['blend_frame']}, "
                f"{state['fps']} fps)"
            )

            def moved() -> tuple[dict[str, Any], dict[str, float]] | None:
                now = driver.script(PAGE_STATE)
                shot = driver.screenshot()
                diffs = {}
                for name in ("depth", "blend"):
                    a, b = crop(first, state[name]), crop(shot, now[name])
                    if a.size != b.size:
                        return None
                    histogram = ImageChops.difference(a, b).convert("L").histogram()
                    changed = sum(histogram[16:])  # pixels that differ by more than JPEG noise
                    diffs[name] = changed / (a.size[0] * a.size[1])
                return (now, diffs) if all(d > 0.01 for d in diffs.values()) else None

            now, diffs = poll("the pictures to change with the stream", args.timeout, moved)
            print(
                f"view_browser: the pictures changed (depth frame {state['depth_frame']} -> "
                f"{now['depth_frame']}, {diffs['depth']:.0%} of its pixels; blend "
                f"{diffs['blend']:.0%}); the page shows {now['fps']} fps"
            )
            driver.close()
            driver = None
            view.send_signal(signal.SIGINT)
            assert view.wait(10) == 0, "dear view did not stop cleanly on Ctrl-C"
            print(f"view_browser: ok ({time.monotonic() - started:.1f} s)")
        except BaseException:
            log = tmp / "deard.log"
            if log.exists():
                print(
                    "deard log (tail):\n" + "\n".join(log.read_text().splitlines()[-20:]),
                    file=sys.stderr,
                )
            raise
        finally:
            if driver is not None:
                driver.close()
            for p in processes:
                if p.poll() is None:
                    p.kill()
                p.wait()


if __name__ == "__main__":
    main()
