"""The console's model moves a driving robot's dead-reckoned footprint on as the bridges do (coaty_bridge
footprint.py, HeardRobot.points_at): at its advert's velocity from when it was heard, for at most validFor / 2.5 s;
a bad velocity is no velocity. Runs web/model.js in node (the page's own file); skips where node is absent."""
import json
import os
import shutil
import subprocess

import pytest

MODEL = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "web", "model.js")
SCRIPT = """
const { FleetModel } = require(%r);
let now = 10000;
const model = new FleetModel(() => now);
const out = [];
for (const advert of %s) {
  now = 10000;
  model.footprint(Object.assign({robot: "robot_0", objectId: "x", stamp: 1.0,
                                 footprint: [[0, 0], [0.6, 0], [0.6, 0.6]]}, advert));
  const r = model.robot("robot_0");
  const at = [];
  for (const t of [0, 1000, 1990, 2010, 5000]) { now = 10000 + t; at.push(model.footprintAt(r)[0][0]); }
  out.push(at);
}
console.log(JSON.stringify(out));
"""


def run(adverts):
    if shutil.which("node") is None:
        pytest.skip("node is not installed (make setup installs it)")
    text = subprocess.run(["node", "-e", SCRIPT % (MODEL, json.dumps(adverts))], capture_output=True, text=True,
                          check=True).stdout
    return json.loads(text)


def test_a_dead_reckoned_footprint_moves_on_for_at_most_the_senders_interval():
    moving, parked, no_validity, bad = run([{"velocity": [0.5, 0.0], "validFor": 5.0}, {"validFor": 75.0},
                                            {"velocity": [0.5, 0.0]}, {"velocity": ["fast", 0], "validFor": 5.0}])
    assert moving == pytest.approx([0.0, 0.5, 0.995, 1.0, 1.0])     # 2 s = 5.0 / 2.5 at most
    assert parked == no_validity == bad == [0.0] * 5
