"""Fixtures of the vda5050_bridge tests: the pure modules from src/ (no built workspace needed),
the VDA 5050 2.0.0 schemas (shipped in schemas/2.0.0; $VDA5050_SCHEMA_DIR or a local clone of
github.com/VDA5050/VDA5050 in $VDA5050_REPO instead, to test against other copies), and a private
mosquitto on 127.0.0.1."""
import os
import shutil
import subprocess
import sys
import time

import pytest

SRC = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "src")
if SRC not in sys.path:
    sys.path.insert(0, SRC)
# sharing_msgs' pure helpers (the rules of authority) without a built workspace; appended, so a sourced
# workspace's sharing_msgs (with the generated msg package) wins.
MSGS_SRC = os.path.join(os.path.dirname(os.path.dirname(SRC)), "sharing_msgs", "src")
if MSGS_SRC not in sys.path:
    sys.path.append(MSGS_SRC)

#: a git clone of github.com/VDA5050/VDA5050 (tag 2.0.0 is read from it) to test against instead of the
#: shipped 2.0.0 schemas, if any
VDA_CLONE = os.environ.get("VDA5050_REPO", "")


def pytest_configure(config):
    config.addinivalue_line("markers", "broker: needs /usr/sbin/mosquitto (each test starts its own)")


@pytest.fixture(scope="session")
def schema_2_0_0(tmp_path_factory):
    """The folder the 2.0.0 schemas are read from: $VDA5050_SCHEMA_DIR, else those of a clone in
    $VDA5050_REPO (made available through $VDA5050_SCHEMA_DIR), else the shipped ones."""
    from vda5050_bridge import schemas
    env = os.environ.get("VDA5050_SCHEMA_DIR")
    if env and os.path.isfile(os.path.join(env, "2.0.0", "state.schema")):
        return env
    if not VDA_CLONE:
        assert os.path.isfile(os.path.join(schemas.PACKAGE_SCHEMAS, "2.0.0", "state.schema")), \
            "the shipped VDA 5050 2.0.0 schemas are missing from %s" % schemas.PACKAGE_SCHEMAS
        return schemas.PACKAGE_SCHEMAS
    if not os.path.isdir(VDA_CLONE) or not shutil.which("git"):
        pytest.skip("VDA5050_REPO=%s is not a git clone of github.com/VDA5050/VDA5050 (or git is missing); "
                    "unset it to test against the shipped 2.0.0 schemas" % VDA_CLONE)
    root = tmp_path_factory.mktemp("vda_schemas")
    os.makedirs(os.path.join(str(root), "2.0.0"))
    for name in ("state", "order", "instantActions", "connection"):
        out = subprocess.run(["git", "--git-dir", VDA_CLONE, "show", "2.0.0:json_schemas/%s.schema" % name],
                             capture_output=True)
        if out.returncode != 0:
            out = subprocess.run(["git", "-C", VDA_CLONE, "show", "2.0.0:json_schemas/%s.schema" % name],
                                 capture_output=True)
        if out.returncode != 0:
            pytest.skip("cannot read tag 2.0.0 from %s: %s" % (VDA_CLONE, out.stderr.decode()[-200:]))
        with open(os.path.join(str(root), "2.0.0", name + ".schema"), "wb") as f:
            f.write(out.stdout)
    os.environ["VDA5050_SCHEMA_DIR"] = str(root)
    return str(root)


@pytest.fixture
def wait_for():
    def wait(predicate, timeout=10.0, what="condition"):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if predicate():
                return
            time.sleep(0.01)
        raise AssertionError("timed out after %.1f s waiting for %s" % (timeout, what))
    return wait


@pytest.fixture
def broker():
    """A private mosquitto on 127.0.0.1 and a free port (the project's own launcher, coaty_bridge.broker);
    yields (host, port); stopped after."""
    from coaty_bridge.broker import Broker
    if not os.access("/usr/sbin/mosquitto", os.X_OK):
        pytest.skip("mosquitto is not installed (/usr/sbin/mosquitto)")
    with Broker() as running:
        yield (running.host, running.port)
