"""fleet_launch's RViz config (config/fleet.rviz, fleet.launch rviz:=true) loads in Debian's rviz 1.14
without config problems, headless: each test starts its own roscore on a free port and rviz under
a virtual X server (Xvfb on a display it picks), and stops both after. The screenshot is kept in
test_results/rviz/fleet_rviz.png. A config with known mistakes proves the check sees them."""
import os
import shutil
import signal
import socket
import subprocess
import time

import pytest
import rospkg
import yaml
from PIL import Image

from fleet_tests.rviz_shot import RvizSession, tools_missing

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CONFIG = os.path.join(rospkg.RosPack().get_path("fleet_launch"), "config", "fleet.rviz")

pytestmark = pytest.mark.skipif(bool(tools_missing()), reason="not installed: %s (make setup)" % tools_missing())


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def master(tmp_path, monkeypatch):
    port = free_port()
    uri = "http://127.0.0.1:%d" % port
    for key, value in (("ROS_MASTER_URI", uri), ("ROS_IP", "127.0.0.1"), ("ROS_HOSTNAME", "127.0.0.1"),
                       ("ROS_HOME", str(tmp_path / "ros"))):
        monkeypatch.setenv(key, value)
    core = subprocess.Popen(["roscore", "-p", str(port)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    import rosgraph
    end = time.time() + 60
    while not rosgraph.is_master_online(uri) and time.time() < end:
        time.sleep(0.2)
    assert rosgraph.is_master_online(uri), "roscore did not come up"
    yield uri
    core.send_signal(signal.SIGINT)
    try:
        core.wait(20)
    except subprocess.TimeoutExpired:
        os.killpg(core.pid, signal.SIGKILL)
        core.wait()


def test_fleet_rviz_loads_without_config_problems(master, tmp_path):
    with RvizSession(CONFIG, str(tmp_path / "rviz")) as rviz:
        rviz.wait_ready(90)
        shot = rviz.screenshot(str(tmp_path / "fleet_rviz.png"))
        problems = rviz.config_problems()
        xvfb_display = rviz.display
    assert problems == [], "\n".join(problems)
    img = Image.open(shot).convert("RGB")
    with open(CONFIG) as f:
        geometry = yaml.safe_load(f)["Window Geometry"]
    assert img.size == (geometry["Width"], geometry["Height"])
    # the window is drawn: the grey render view, the light panels, the displays' names in colour
    colours = img.resize((120, 80)).getcolors(120 * 80)
    assert colours is not None and len(colours) > 20, "the screenshot is (almost) one colour"
    keep = os.path.join(ROOT, "test_results", "rviz")
    os.makedirs(keep, exist_ok=True)
    shutil.copy(shot, os.path.join(keep, "fleet_rviz.png"))
    # the X server is gone after the session: its lock file was removed
    assert not os.path.exists("/tmp/.X%s-lock" % xvfb_display.lstrip(":"))


def test_config_mistakes_are_reported(master, tmp_path):
    """An unknown display class, a misspelt property, a value rviz does not accept, an unknown tool
    and a duplicated display name: each is named by the check."""
    with open(CONFIG) as f:
        doc = yaml.safe_load(f)
    displays = doc["Visualization Manager"]["Displays"]
    displays.append({"Class": "rviz/NoSuchDisplay", "Name": "broken one", "Enabled": True})
    scan = [d for d in displays if d["Name"] == "robot_0 scan"][0]
    scan["Topik"] = scan.pop("Topic")
    cmap = [d for d in displays if d["Name"] == "robot_1 global costmap"][0]
    cmap["Alpha"] = "lots"
    doc["Visualization Manager"]["Tools"].append({"Class": "rviz/NoSuchTool"})
    displays.append(dict(displays[1]))                       # a second display named "Map"
    broken = tmp_path / "broken.rviz"
    broken.write_text(yaml.safe_dump(doc))
    with RvizSession(str(broken), str(tmp_path / "rviz")) as rviz:
        rviz.wait_ready(90)
        problems = "\n".join(rviz.config_problems())
    assert "rviz/NoSuchDisplay" in problems and "unknown display class" in problems, problems
    assert "'Topik' is not kept by rviz" in problems, problems
    assert "'lots' became" in problems, problems
    assert "rviz/NoSuchTool" in problems, problems
    assert "display name 'Map' is used 2 times" in problems, problems
