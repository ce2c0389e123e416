"""Load a page in headless Chromium (Debian's `chromium`) over the DevTools protocol: console errors,
uncaught exceptions, a JavaScript probe of the DOM and a PNG screenshot."""

from __future__ import annotations

import asyncio
import base64
import contextlib
import json
import os
import shutil
import signal
import subprocess
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


def find_chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser")


@dataclass
class PageLoad:
    errors: list[str] = field(default_factory=list)
    probe: Any = None
    screenshot: bytes = b""


async def _session(ws_url: str, url: str, probe: str, width: int, height: int) -> PageLoad:
    import websockets

    result = PageLoad()
    ids = iter(range(1, 1_000_000))
    async with websockets.connect(ws_url, max_size=64 * 1024 * 1024) as ws:

        async def call(method: str, **params: Any) -> dict[str, Any]:
            my_id = next(ids)
            await ws.send(json.dumps({"id": my_id, "method": method, "params": params}))
            while True:
                message = json.loads(await ws.recv())
                if message.get("id") == my_id:
                    if "error" in message:
                        raise RuntimeError(f"{method}: {message['error']}")
                    return dict(message.get("result", {}))
                _collect(message, result)

        for domain in ("Page", "Runtime", "Log"):
            await call(f"{domain}.enable")
        await call(
            "Emulation.setDeviceMetricsOverride",
            width=width,
            height=height,
            deviceScaleFactor=1,
            mobile=False,
        )
        await call("Page.navigate", url=url)
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:  # wait for the load event
            message = json.loads(await asyncio.wait_for(ws.recv(), timeout=30))
            _collect(message, result)
            if message.get("method") == "Page.loadEventFired":
                break
        evaluated = await call("Runtime.evaluate", expression=probe, returnByValue=True)
        result.probe = evaluated.get("result", {}).get("value")
        shot = await call("Page.captureScreenshot", format="png", captureBeyondViewport=True)
        result.screenshot = base64.b64decode(shot["data"])
    return result


def _collect(message: dict[str, Any], result: PageLoad) -> None:
    method = message.get("method")
    params = message.get("params", {})
    if method == "Runtime.exceptionThrown":
        result.errors.append(json.dumps(params.get("exceptionDetails", {}))[:500])
    elif method == "Runtime.consoleAPICalled" and params.get("type") in ("error", "assert"):
        result.errors.append(json.dumps(params.get("args", []))[:500])
    elif method == "Log.entryAdded" and params.get("entry", {}).get("level") == "error":
        result.errors.append(str(params["entry"].get("text"))[:500])


def load_page(path: Path | str, probe: str, *, width: int = 1200, height: int = 900) -> PageLoad:
    """Open `path` (a file, as file://; or a URL string) in a fresh headless Chromium and return what
    `_session` gathered."""
    import urllib.request

    binary = find_chromium()
    assert binary is not None
    profile = tempfile.mkdtemp(prefix="carlos-chromium-")
    try:
        proc = subprocess.Popen(
            [
                binary,
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--no-first-run",
                "--remote-debugging-port=0",
                "--remote-debugging-address=127.0.0.1",
                f"--user-data-dir={profile}",
                "about:blank",
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,  # its helper processes too are ended below, before the profile goes
        )
        try:
            port_file = Path(profile) / "DevToolsActivePort"
            deadline = time.monotonic() + 30
            while not (port_file.is_file() and port_file.read_text().strip()) and time.monotonic() < deadline:
                time.sleep(0.1)
            port = int(port_file.read_text().split()[0])
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=10) as response:
                pages = [t for t in json.load(response) if t.get("type") == "page"]
            return asyncio.run(
                _session(
                    pages[0]["webSocketDebuggerUrl"],
                    path.as_uri() if isinstance(path, Path) else path,
                    probe,
                    width,
                    height,
                )
            )
        finally:
            proc.terminate()
            with contextlib.suppress(subprocess.TimeoutExpired):
                proc.wait(timeout=10)
            if proc.poll() is None:
                proc.kill()
                proc.wait()
            # Chromium's renderer and utility processes outlive it for a moment, writing into the profile
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGKILL)
    finally:
        for attempt in range(20):  # a helper killed just now may still finish a write
            try:
                shutil.rmtree(profile)
                break
            except FileNotFoundError:
                break
            except OSError:
                if attempt == 19:
                    raise
                time.sleep(0.1)
