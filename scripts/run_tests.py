#!/usr/bin/python3
"""Runs every test of the workspace: the package dependency check, gtest binaries, pytest
suites, rostests.

Each phase writes JUnit XML under test_results/, and the run ends with one line
"N passed, N failed, N skipped". The exit code is non-zero when a test failed,
when a phase could not run, or when no test ran at all.

Usage: run_tests.py [--phase deps|gtest|pytest|rostest ...] [-k PYTEST_EXPR]
"""
import argparse
import glob
import os
import shutil
import subprocess
import sys
import time
import xml.etree.ElementTree as ET

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RESULTS = os.path.join(ROOT, "test_results")
DEVEL = os.path.join(ROOT, "catkin_ws", "devel")
# Package folders, bottom of the dependency graph first (scripts/check_package_deps.py checks it).
PACKAGES = ["sharing_msgs", "sharing_layer_cpp", "sharing_handler_py", "coaty_bridge",
            "fleet_sim", "fleet_nav", "sharing_replay", "launch", "tests"]
# pytest folders that are not packages: the repository's own tools.
TOOL_TEST_FOLDERS = ["scripts"]


class Tally:
    def __init__(self):
        self.passed = self.failed = self.skipped = 0
        self.failures = []

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
                if case.find("failure") is not None or case.find("error") is not None:
                    self.failed += 1
                    self.failures.append("%s: %s" % (label, name))
                elif case.find("skipped") is not None:
                    self.skipped += 1
                else:
                    self.passed += 1

    def fail(self, reason):
        self.failed += 1
        self.failures.append(reason)


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


def run_rostests(tally):
    files = []
    for pkg in PACKAGES:
        files += glob.glob(os.path.join(ROOT, pkg, "test", "**", "*.test"), recursive=True)
    files.sort()
    if not files:
        print("[rostest] no .test files", flush=True)
        return
    for i, path in enumerate(files, 1):
        rel = os.path.relpath(path, ROOT)
        name = os.path.splitext(rel)[0].replace(os.sep, "_")
        out_dir = os.path.join(RESULTS, "rostest", name)
        shutil.rmtree(out_dir, ignore_errors=True)  # a stale result must not count as this run's
        print("[rostest %d/%d] %s" % (i, len(files), rel), flush=True)
        start = time.time()
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


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--phase", action="append", choices=["deps", "gtest", "pytest", "rostest"])
    parser.add_argument("-k", dest="expr", help="pytest -k expression")
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
        run_rostests(tally)

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
