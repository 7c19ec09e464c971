"""The package dependency check (scripts/check_package_deps.py) fails on what it is there to catch.

Each test copies the repository's package folders into a temporary tree, breaks one rule there on
purpose, and asserts that the check reports it naming the package, the file and the dependency.
"""
import importlib.util
import os
import shutil
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CHECKER = os.path.join(ROOT, "scripts", "check_package_deps.py")


def load_checker():
    spec = importlib.util.spec_from_file_location("check_package_deps", CHECKER)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


deps = load_checker()


@pytest.fixture
def tree(tmp_path):
    """A copy of every package folder of the repository (sources and package.xml only)."""
    ignore = shutil.ignore_patterns("__pycache__", "*.png", "*.pgm", "*.bag", "node_modules")
    for entry in os.listdir(ROOT):
        if os.path.isfile(os.path.join(ROOT, entry, "package.xml")):
            shutil.copytree(os.path.join(ROOT, entry), tmp_path / entry, ignore=ignore, symlinks=True)
    return tmp_path


def errors_of(root):
    checker = deps.Checker(str(root))
    checker.run()
    return [message for _, message in checker.errors]


def set_declared(path, old, new):
    text = path.read_text()
    assert old in text, "%s has no %r to replace" % (path, old)
    path.write_text(text.replace(old, new, 1))


def test_the_repository_passes():
    errors = errors_of(ROOT)
    assert errors == []


def test_the_copied_tree_passes(tree):
    assert errors_of(tree) == []


def test_an_undeclared_import_of_a_higher_package_fails(tree):
    # The core importing the simulator is exactly the upward edge this layout exists to prevent.
    bad = tree / "sharing_layer_cpp" / "src" / "sharing_layer_cpp" / "bad_upward_import.py"
    bad.write_text("from fleet_sim.frames import yaw_quaternion\n")
    errors = errors_of(tree)
    assert any("sharing_layer_cpp uses fleet_sim" in e and "bad_upward_import.py" in e for e in errors), errors


def test_an_import_inside_a_function_counts(tree):
    bad = tree / "sharing_handler_py" / "src" / "sharing_handler_py" / "lazy.py"
    bad.write_text("def f():\n    from coaty_bridge import codec\n    return codec\n")
    errors = errors_of(tree)
    assert any("sharing_handler_py uses coaty_bridge" in e for e in errors), errors


def test_an_undeclared_ros_package_in_a_launch_file_fails(tree):
    launch = tree / "fleet_sim" / "launch" / "extra.launch"
    launch.write_text('<launch><node pkg="map_server" type="map_server" name="m"/></launch>\n')
    errors = errors_of(tree)
    assert any("fleet_sim uses map_server" in e and "extra.launch" in e for e in errors), errors


def test_a_test_only_dependency_does_not_cover_runtime_code(tree):
    # hypothesis is a test_depend of fleet_sim: using it outside test/ must be reported.
    bad = tree / "fleet_sim" / "src" / "fleet_sim" / "uses_hypothesis.py"
    bad.write_text("import hypothesis\n")
    errors = errors_of(tree)
    assert any("fleet_sim uses python3-hypothesis" in e and "<exec_depend>" in e for e in errors), errors


def test_an_unknown_module_is_reported_not_ignored(tree):
    bad = tree / "fleet_nav" / "src" / "fleet_nav" / "mystery.py"
    bad.write_text("import some_module_nobody_installs\n")
    errors = errors_of(tree)
    assert any("'some_module_nobody_installs'" in e for e in errors), errors


def test_a_declared_but_unused_workspace_package_fails(tree):
    set_declared(tree / "sharing_handler_py" / "package.xml", "<depend>sharing_msgs</depend>",
                 "<depend>sharing_msgs</depend>\n  <exec_depend>coaty_bridge</exec_depend>")
    errors = errors_of(tree)
    assert any("declares coaty_bridge, but nothing in sharing_handler_py uses it" in e for e in errors), errors


def test_a_declared_cycle_fails(tree):
    # sharing_msgs -> fleet_tests closes a loop through every layer; declare and use it.
    set_declared(tree / "sharing_msgs" / "package.xml", "<depend>std_msgs</depend>",
                 "<depend>std_msgs</depend>\n  <exec_depend>fleet_tests</exec_depend>")
    launch = tree / "sharing_msgs" / "uses_tests.launch"
    launch.write_text('<launch><include file="$(find fleet_tests)/x.launch"/></launch>\n')
    errors = errors_of(tree)
    cycles = [e for e in errors if e.startswith("declared dependency cycle")]
    assert cycles, errors
    assert "sharing_msgs" in cycles[0] and "fleet_tests" in cycles[0]


def test_the_command_line_exits_1_and_writes_a_failing_junit_case(tree):
    bad = tree / "sharing_msgs" / "bad.py"
    bad.write_text("import fleet_nav\n")
    junit = tree / "deps.xml"
    proc = subprocess.run([sys.executable, CHECKER, "--root", str(tree), "--junit", str(junit)],
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT, universal_newlines=True)
    assert proc.returncode == 1, proc.stdout
    assert "sharing_msgs uses fleet_nav" in proc.stdout
    text = junit.read_text()
    assert '<testcase classname="package_deps" name="sharing_msgs">' in text
    assert "<failure" in text
