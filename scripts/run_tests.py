#!/usr/bin/python3
"""Runs every test of the workspace: the package dependency check, gtest binaries, pytest
suites, rostests.

Each phase writes JUnit XML under test_results/, and the run ends with one line
"N passed, N failed, N skipped". The exit code is non-zero when a test failed,
when a phase could not run, or when no test ran at all.

Rostests: every `.test` file anywhere in a package folder (not only under test/). `make setup`
provides every ROS package a test needs (upstream move_base and Stage included), so a `.test` whose
launch needs a package that is not here, or a test program its package builds only where an optional
dependency is found (sharing_layer_cpp's plugin_layer_tests needs costmap_2d), is a failure naming
it; with --allow-missing-ros-packages (a machine set up by hand) it is a skip with the reason.
The summary lists each rostest with its outcome and the host it ran on: Stage with upstream
move_base, our stand-ins (fleet_sim + fleet_nav), or no simulator.

Usage: run_tests.py [--phase deps|gtest|pytest|rostest ...] [-k PYTEST_EXPR] [--allow-missing-ros-packages]
"""
import argparse
import glob
import os
import shutil
import subprocess
import sys
import time
import xml.etree.ElementTree as ET

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from flaky_run import failure_reason  # noqa: E402 - the one reading of a JUnit failure's text

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RESULTS = os.path.join(ROOT, "test_results")
DEVEL = os.path.join(ROOT, "catkin_ws", "devel")
# Package folders, bottom of the dependency graph first (scripts/check_package_deps.py checks it).
PACKAGES = ["sharing_msgs", "sharing_layer_cpp", "sharing_handler_py", "coaty_bridge",
            "fleet_sim", "fleet_nav", "sharing_replay", "vda5050_bridge", "fleet_console", "launch", "tests"]
# pytest folders that are not packages: the repository's own tools.
TOOL_TEST_FOLDERS = ["scripts", "upstream"]


def case_failure_reason(failure):
    """Why one JUnit case failed: pytest's message attribute ("AssertionError: timed out waiting for ..."),
    else the first line of rosunit's text."""
    message = (failure.get("message") or "").strip()
    if message:
        return message.splitlines()[0][:400]
    return failure_reason(failure.text)


class Tally:
    def __init__(self):
        self.passed = self.failed = self.skipped = 0
        self.failures = []
        self.skips = []
        self.hosts = []  # (rostest file, outcome, host)

    def add_junit(self, path, label):
        """Adds the counts of one JUnit XML file; a file that can't be read is a failure."""
        try:
            root = ET.parse(path).getroot()
        except (ET.ParseError, OSError) as err:
            self.failed += 1
            self.failures.append("%s: unreadable result file %s (%s)" % (label, path, err))
            return
        suites = [root] if root.tag == "testsuite" else root.iter("testsuite")
        for suite in suites:
            for case in suite.iter("testcase"):
                name = "%s.%s" % (case.get("classname", ""), case.get("name", ""))
                failure = case.find("failure")
                failure = failure if failure is not None else case.find("error")
                if failure is not None:
                    # the reason goes into the summary: CI keeps only the end of the log
                    self.failed += 1
                    self.failures.append("%s: %s: %s" % (label, name, case_failure_reason(failure)))
                elif case.find("skipped") is not None:
                    self.skipped += 1
                else:
                    self.passed += 1

    def fail(self, reason):
        self.failed += 1
        self.failures.append(reason)

    def skip(self, label, reason):
        self.skipped += 1
        self.skips.append("%s: %s" % (label, reason))


def run_dependency_check(tally):
    """Every package.xml declares what its code uses, and the declared graph has no cycle."""
    xml = os.path.join(RESULTS, "deps", "package_deps.xml")
    if os.path.exists(xml):
        os.remove(xml)
    print("[deps] scripts/check_package_deps.py", flush=True)
    proc = subprocess.run([sys.executable, os.path.join(ROOT, "scripts", "check_package_deps.py"),
                           "--junit", xml], cwd=ROOT)
    if os.path.exists(xml):
        tally.add_junit(xml, "deps")
    else:
        tally.fail("deps: the dependency check crashed (exit %d, no result file)" % proc.returncode)


def run_gtests(tally):
    binaries = sorted(p for p in glob.glob(os.path.join(DEVEL, "lib", "*", "test_*"))
                      if os.access(p, os.X_OK) and os.path.isfile(p))
    if not binaries:
        tally.fail("gtest: no test binaries under %s/lib (did 'make build' run?)" % DEVEL)
        return
    for i, binary in enumerate(binaries, 1):
        name = os.path.basename(binary)
        xml = os.path.join(RESULTS, "gtest", name + ".xml")
        print("[gtest %d/%d] %s" % (i, len(binaries), name), flush=True)
        proc = subprocess.run([binary, "--gtest_output=xml:" + xml], cwd=ROOT)
        if os.path.exists(xml):
            tally.add_junit(xml, "gtest " + name)
            if proc.returncode != 0 and not tally.failures:
                tally.fail("gtest %s exited %d" % (name, proc.returncode))
        else:
            tally.fail("gtest %s crashed (exit %d, no result file)" % (name, proc.returncode))


def run_pytest(tally, expr):
    """One pytest process per package, so that one package's broken import or conftest cannot hide
    another package's results, and test module names only need to be unique within a package."""
    packages = [pkg for pkg in PACKAGES + TOOL_TEST_FOLDERS if os.path.isdir(os.path.join(ROOT, pkg, "test"))]
    if not packages:
        tally.fail("pytest: no test folders found")
        return
    for i, pkg in enumerate(packages, 1):
        xml = os.path.join(RESULTS, "pytest", pkg + ".xml")
        if os.path.exists(xml):
            os.remove(xml)
        cmd = [sys.executable, "-m", "pytest", "-q", "-rs", "--junitxml=" + xml,
               "-p", "no:cacheprovider", os.path.join(pkg, "test")]
        if expr:
            cmd += ["-k", expr]
        print("[pytest %d/%d] %s/test" % (i, len(packages), pkg), flush=True)
        proc = subprocess.run(cmd, cwd=ROOT)
        if os.path.exists(xml):
            tally.add_junit(xml, "pytest " + pkg)
        if proc.returncode not in (0, 1, 5):
            tally.fail("pytest %s exited %d (usage, collection or internal error)" % (pkg, proc.returncode))


# Folders of a package that hold no sources of its tests (build output, caches, npm downloads).
_NOT_SOURCES = {"build", "devel", "install", "node_modules", "__pycache__"}


def discover_rostests(root=ROOT, packages=PACKAGES):
    """Every .test file in a package folder, at any depth (a package's plugin/test/ too), sorted."""
    files = []
    for pkg in packages:
        for folder, subfolders, names in os.walk(os.path.join(root, pkg)):
            subfolders[:] = sorted(d for d in subfolders if not d.startswith(".") and d not in _NOT_SOURCES)
            files += [os.path.join(folder, name) for name in names if name.endswith(".test")]
    return sorted(files)


def missing_requirements(path):
    """Why the rostest ``path`` cannot run here (a sentence), or None when it can.

    Reads the launch file as roslaunch does (includes, args, $(find ...)) and checks that every
    package it names is installed and that every <test> program exists. A test program that is
    missing although its package is there is a skip only when the package declares a dependency
    that is not installed (it builds that program only with it); otherwise the test runs and
    rostest reports the missing program as a failure ('make build' did not build it)."""
    try:
        import rospkg
        import roslaunch.config
        import roslib.packages
    except ImportError as err:
        return "roslaunch is not importable (%s); source scripts/env.sh" % err
    rospack = rospkg.RosPack()
    try:
        config = roslaunch.config.load_config_default([path], None, verbose=False)
    except rospkg.ResourceNotFound as err:
        # roslaunch wraps a $(find pkg) failure: "The following package was not found in <tag>: pkg\nROS path ..."
        package = str(err.args[0]).splitlines()[0].rsplit(": ", 1)[-1] if err.args else "?"
        return "needs ROS package %s, which is not installed" % package
    except Exception:  # noqa: BLE001 - another launch error: rostest runs it and reports it as a failure
        return None
    for node in list(config.tests) + list(config.nodes):
        try:
            rospack.get_path(node.package)
        except rospkg.ResourceNotFound:
            return "needs ROS package %s (for %s), which is not installed" % (node.package, node.type)
    for test in config.tests:
        try:
            found = roslib.packages.find_node(test.package, test.type, rospack=rospack)
        except rospkg.ResourceNotFound:
            found = []
        if found:
            continue
        absent = _uninstalled_dependencies(test.package, rospack)
        if absent:
            return "test program %s/%s is not built here: %s depends on %s, which %s not installed " \
                   "(it builds its optional parts only where found)" % (
                       test.package, test.type, test.package, ", ".join(absent),
                       "are" if len(absent) > 1 else "is")
    return None


def _uninstalled_dependencies(package, rospack):
    """Dependencies that ``package``'s package.xml declares, are ROS packages and are not
    installed. Keys that are not ROS package names (python3-numpy, pybind11-dev) and gtest are left
    out: make setup installs those, and rospack cannot find them anyway."""
    import rospkg
    try:
        root = ET.parse(os.path.join(rospack.get_path(package), "package.xml")).getroot()
    except (rospkg.ResourceNotFound, ET.ParseError, OSError):
        return []
    absent = []
    for element in root:
        name = (element.text or "").strip()
        if not element.tag.endswith("depend") or element.tag in ("buildtool_depend", "doc_depend"):
            continue
        if not name or name in absent or "-" in name or name in ("gtest", "catkin"):
            continue
        try:
            rospack.get_path(name)
        except rospkg.ResourceNotFound:
            absent.append(name)
    return absent


def write_skipped_junit(xml, name, reason):
    os.makedirs(os.path.dirname(xml), exist_ok=True)
    suite = ET.Element("testsuite", name=name, tests="1", failures="0", errors="0", skipped="1")
    case = ET.SubElement(suite, "testcase", classname="rostest", name=name)
    ET.SubElement(case, "skipped", message=reason)
    ET.ElementTree(suite).write(xml, encoding="utf-8", xml_declaration=True)


def test_host(path):
    """Which simulator and navigation host the rostest ``path`` runs on, read from its launch."""
    try:
        import roslaunch.config
        config = roslaunch.config.load_config_default([path], None, verbose=False)
    except Exception:  # noqa: BLE001 - an unreadable launch: rostest reports it
        return "unknown"
    nodes = list(config.nodes) + list(config.tests)
    packages = {node.package for node in nodes}
    # fleet_launch's stage_world runs stageros (at a speed of its own)
    if "stage_ros" in packages or any(n.package == "fleet_launch" and n.type == "stage_world" for n in nodes):
        return "Stage + upstream move_base" if "move_base" in packages else "Stage"
    if "fleet_sim" in packages:
        return "stand-ins: fleet_sim + fleet_nav" if "fleet_nav" in packages else "stand-in fleet_sim"
    return "no simulator"


def run_rostests(tally, allow_missing=False):
    files = discover_rostests()
    if not files:
        print("[rostest] no .test files", flush=True)
        return
    for i, path in enumerate(files, 1):
        rel = os.path.relpath(path, ROOT)
        name = os.path.splitext(rel)[0].replace(os.sep, "_")
        out_dir = os.path.join(RESULTS, "rostest", name)
        shutil.rmtree(out_dir, ignore_errors=True)  # a stale result must not count as this run's
        reason = missing_requirements(path)
        if reason and allow_missing:
            print("[rostest %d/%d] %s SKIPPED: %s" % (i, len(files), rel, reason), flush=True)
            write_skipped_junit(os.path.join(out_dir, "skipped.xml"), name, reason)
            tally.skip("rostest " + rel, reason)
            tally.hosts.append((rel, "skipped", "-"))
            continue
        if reason:
            print("[rostest %d/%d] %s FAILED: %s" % (i, len(files), rel, reason), flush=True)
            tally.fail("rostest %s: %s (make setup provides it: run it, or pass --allow-missing-ros-packages)"
                       % (rel, reason))
            tally.hosts.append((rel, "failed", "-"))
            continue
        host = test_host(path)
        print("[rostest %d/%d] %s (%s)" % (i, len(files), rel, host), flush=True)
        start = time.time()
        failed_before = tally.failed
        proc = subprocess.run(["rostest", "--results-base-dir", out_dir, path], cwd=ROOT)
        results = glob.glob(os.path.join(out_dir, "**", "rosunit-*.xml"), recursive=True) + \
            glob.glob(os.path.join(out_dir, "**", "rostest-*.xml"), recursive=True)
        counted = False
        for xml in sorted(set(glob.glob(os.path.join(out_dir, "**", "*.xml"), recursive=True))):
            if os.path.basename(xml).startswith("rostest-"):
                continue  # the summary file duplicates the per-test files
            tally.add_junit(xml, "rostest " + name)
            counted = True
        if not counted and results:
            for xml in results:
                tally.add_junit(xml, "rostest " + name)
                counted = True
        if proc.returncode != 0 and not any(name in f for f in tally.failures):
            tally.fail("rostest %s exited %d after %.0f s" % (rel, proc.returncode, time.time() - start))
        elif not counted:
            tally.fail("rostest %s produced no results" % rel)
        tally.hosts.append((rel, "failed" if tally.failed > failed_before else "passed", host))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--phase", action="append", choices=["deps", "gtest", "pytest", "rostest"])
    parser.add_argument("-k", dest="expr", help="pytest -k expression")
    parser.add_argument("--allow-missing-ros-packages", action="store_true",
                        help="skip, instead of failing, a rostest whose ROS packages are not installed")
    args = parser.parse_args()
    phases = args.phase or ["deps", "gtest", "pytest", "rostest"]
    os.makedirs(RESULTS, exist_ok=True)

    tally = Tally()
    if "deps" in phases:
        run_dependency_check(tally)
    if "gtest" in phases:
        run_gtests(tally)
    if "pytest" in phases:
        run_pytest(tally, args.expr)
    if "rostest" in phases:
        run_rostests(tally, args.allow_missing_ros_packages)

    if tally.hosts:
        print("rostests and the host each ran on:")
        for rel, outcome, host in tally.hosts:
            print("  %-7s %-58s %s" % (outcome, rel, host))
    for skip in tally.skips:
        print("SKIPPED " + skip)
    for failure in tally.failures:
        print("FAILED  " + failure)
    if tally.passed + tally.failed == 0:
        print("run_tests: no test ran")
        print("0 passed, 1 failed")
        return 1
    print("%d passed, %d failed, %d skipped" % (tally.passed, tally.failed, tally.skipped))
    return 1 if tally.failed else 0


if __name__ == "__main__":
    sys.exit(main())
