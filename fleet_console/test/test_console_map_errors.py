"""A bad map in Debian's headless Chromium: the console started on a broken map file (no ROS, no fleet) serves the
page, the page names the fault above the map, and the page goes on (its login form works and says when the broker
cannot be reached)."""
import os
import re
import signal
import socket
import subprocess
import sys

import pytest

from fleet_console.browser import ConsolePage, missing

pytestmark = pytest.mark.skipif(bool(missing()), reason="not installed (scripts/setup.sh): %s" % missing())


def closed_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def console(tmp_path):
    (tmp_path / "map.yaml").write_text("image: map.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n")
    (tmp_path / "map.pgm").write_bytes(b"P5 this is not a picture")
    proc = subprocess.Popen([sys.executable, "-c", "from fleet_console.node import main; raise SystemExit(main())",
                             "--no-ros", "--port", "0", "--broker-url", "mqtt://127.0.0.1:%d" % closed_port(),
                             "--map-file", str(tmp_path / "map.yaml")], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    lines = []
    for line in proc.stdout:
        lines.append(line)
        found = re.search(r"point a browser at (http://127\.0\.0\.1:\d+/)", line)
        if found:
            break
    try:
        assert found, "".join(lines)
        yield found.group(1)
        assert proc.poll() is None, "the console stopped: " + "".join(lines)
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGTERM)
            try:
                proc.wait(20)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def test_a_broken_map_image_is_named_on_the_page_and_the_page_goes_on(console):
    page = ConsolePage(console)
    try:
        text = page.wait(lambda: page.js("return document.getElementById('map-error').textContent"),
                         "the map's error on the page", timeout=20)
        assert text.startswith("Map: map file ") and "image map.pgm cannot be read" in text, text
        page.login("anna", "whatever")
        page.wait(lambda: "The fleet's broker cannot be reached" in page.status(), "the page saying the broker is "
                  "unreachable", timeout=30)
        assert not page.js("return window.fleetConsole.connected")
        assert text == page.js("return document.getElementById('map-error').textContent")
    finally:
        page.close()
