"""The viewer as a web page: `pointplan view` loaded in headless Chromium.

Skipped where Chromium or viser is missing (`.ci/run` installs Chromium on CI when it can).
Chromium is driven over its DevTools protocol: the page is read until the scene has come
over the websocket; the DOM then holds the control panel and the scene's canvas, and a
screenshot shows both.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("viser")
CHROMIUM = next((shutil.which(n) for n in ("chromium", "chromium-browser", "google-chrome") if shutil.which(n)), None)
pytestmark = [pytest.mark.slow, pytest.mark.skipif(CHROMIUM is None, reason="no Chromium (apt-get install chromium)")]
SRC = Path(__file__).resolve().parents[1] / "src"


@pytest.fixture(scope="module")
def viewer_url(free_port: Callable[[], int]):  # type: ignore[no-untyped-def]
    port = free_port()
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(SRC), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen(
        [sys.executable, "-m", "pointplan", "view", "--env", "boxes3d", "--robot", "sshape", "--port", str(port)],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=env,
    )
    lines: list[str] = []
    threading.Thread(target=lambda: lines.extend(iter(proc.stdout.readline, "")), daemon=True).start()  # type: ignore[union-attr]
    deadline = time.monotonic() + 180
    while not any("open http" in x for x in lines):
        if proc.poll() is not None or time.monotonic() > deadline:
            proc.kill()
            pytest.fail("pointplan view did not start:\n" + "".join(lines))
        time.sleep(0.2)
    yield f"http://127.0.0.1:{port}"
    proc.send_signal(signal.SIGINT)  # the viewer stops its server on Ctrl-C
    try:
        proc.wait(timeout=20)
    except subprocess.TimeoutExpired:
        proc.kill()


class _Browser:
    """Headless Chromium driven over its DevTools protocol.

    The page is polled in real time until what a test looks for is there. Chromium's
    ``--virtual-time-budget`` does not wait for websocket traffic, so on a loaded CI
    machine a one-shot ``--dump-dom`` could come back before the viewer had sent the
    scene's title (seen on CI three times, through four tries with growing budgets).
    """

    def __init__(self, tmp: Path) -> None:
        import json
        import urllib.request

        from websockets.sync.client import connect  # viser's own dependency

        cmd = [
            CHROMIUM,
            "--headless",
            "--no-sandbox",
            "--enable-unsafe-swiftshader",
            "--window-size=1000,700",
            "--remote-debugging-port=0",
            f"--user-data-dir={tmp}",
            "about:blank",
        ]
        self.proc = subprocess.Popen(
            cmd,  # type: ignore[arg-type]
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,
        )
        port_file, deadline = tmp / "DevToolsActivePort", time.monotonic() + 60
        while not (port_file.exists() and port_file.read_text().strip()):
            if self.proc.poll() is not None or time.monotonic() > deadline:
                self.close()
                pytest.fail("headless Chromium did not start")
            time.sleep(0.2)
        port = int(port_file.read_text().split()[0])
        for _ in range(100):  # the page target appears shortly after the port file
            targets = json.loads(urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=10).read())
            pages = [t for t in targets if t.get("type") == "page"]
            if pages:
                break
            time.sleep(0.2)
        self.ws = connect(pages[0]["webSocketDebuggerUrl"], max_size=None, open_timeout=30)
        self.next_id = 0

    def call(self, method: str, **params: object) -> dict:  # type: ignore[type-arg]
        import json

        self.next_id += 1
        self.ws.send(json.dumps({"id": self.next_id, "method": method, "params": params}))
        while True:  # events may come in between; the answer carries the id
            msg = json.loads(self.ws.recv(timeout=60))
            if msg.get("id") == self.next_id:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg.get("result", {})  # type: ignore[no-any-return]

    def html(self) -> str:
        res = self.call("Runtime.evaluate", expression="document.documentElement.outerHTML", returnByValue=True)
        return str(res.get("result", {}).get("value", ""))

    def screenshot(self, path: Path) -> None:
        import base64

        path.write_bytes(base64.b64decode(self.call("Page.captureScreenshot", format="png")["data"]))

    def close(self) -> None:
        if getattr(self, "ws", None) is not None:
            self.ws.close()
        with contextlib.suppress(ProcessLookupError):
            os.killpg(self.proc.pid, signal.SIGKILL)
        self.proc.wait(timeout=20)


@pytest.fixture
def browser(tmp_path: Path):  # type: ignore[no-untyped-def]
    b = _Browser(tmp_path / "chromium")
    yield b
    b.close()


def test_the_page_shows_the_scene_and_the_time_step_controls(
    viewer_url: str, browser: _Browser, tmp_path: Path
) -> None:
    browser.call("Page.navigate", url=viewer_url)
    wanted = ("<canvas", "boxes3d/test/0/seed0", "sshape", "time step", "play")
    deadline, dom = time.monotonic() + 120, ""
    while time.monotonic() < deadline:  # real time: the scene comes over the websocket
        dom = browser.html()
        if all(w in dom for w in wanted):
            break
        time.sleep(0.5)
    assert "<canvas" in dom  # the 3D scene
    assert "boxes3d/test/0/seed0" in dom and "sshape" in dom  # the title in the control panel
    assert "time step" in dom and "play" in dom  # the slider and the play box
    from matplotlib.image import imread

    # The panel's text and the rendered scene may take a few frames to paint: screenshots
    # until both show, for up to a minute; a blank panel has no dark pixels at all.
    text, spread, shot = 0.0, 0.0, tmp_path / "view.png"
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        browser.screenshot(shot)
        img = imread(str(shot))[..., :3]
        h, w = img.shape[:2]
        panel = img[: h // 4, int(w * 0.62) :]  # the control panel sits top right
        scene = img[h // 4 : 3 * h // 4, w // 4 : 3 * w // 4]
        text = max(text, float((panel.mean(-1) < 0.4).mean()))
        spread = max(spread, float(np.ptp(scene.reshape(-1, 3), axis=0).max()))
        if text > 0.005 and spread > 0.3:
            break
        time.sleep(1.0)
    assert text > 0.002, f"the control panel shows no text ({text:.4f} of its pixels are dark)"
    assert spread > 0.3, "the scene is blank"
