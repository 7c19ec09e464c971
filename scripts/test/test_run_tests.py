"""The test runner (scripts/run_tests.py) runs every rostest of every package: its glob once only
looked under <package>/test/, so sharing_layer_cpp/plugin/test/plugin_layer.test never ran, even
where costmap_2d is installed. A .test whose needs are not installed here is skipped with the
reason, not failed (issue 28)."""
import importlib.util
import os
import xml.etree.ElementTree as ET

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
# Not packages: the workspace (src/ links the packages again, build/ and devel/ are generated) and
# the runner's own output.
NOT_PACKAGES = {"catkin_ws", "test_results", "out"}


def load_runner():
    spec = importlib.util.spec_from_file_location("run_tests", os.path.join(ROOT, "scripts", "run_tests.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


runner = load_runner()


def every_test_file_in_the_repository():
    """A walk of its own (not the runner's): every .test under a top-level folder other than the
    workspace, hidden folders and npm downloads left out."""
    found = set()
    for top in sorted(os.listdir(ROOT)):
        if top.startswith(".") or top in NOT_PACKAGES or not os.path.isdir(os.path.join(ROOT, top)):
            continue
        for folder, subfolders, names in os.walk(os.path.join(ROOT, top)):
            subfolders[:] = [d for d in subfolders if not d.startswith(".") and d != "node_modules"]
            found.update(os.path.join(folder, n) for n in names if n.endswith(".test"))
    return found


def test_every_package_folder_is_in_the_runners_list():
    packages = {d for d in os.listdir(ROOT) if d not in NOT_PACKAGES
                and os.path.isfile(os.path.join(ROOT, d, "package.xml"))}
    assert packages == set(runner.PACKAGES), "scripts/run_tests.py PACKAGES misses %s or lists %s" % (
        sorted(packages - set(runner.PACKAGES)), sorted(set(runner.PACKAGES) - packages))


def test_every_test_file_of_every_package_is_run():
    expected = every_test_file_in_the_repository()
    discovered = set(runner.discover_rostests())
    assert expected, "no .test file found at all"
    assert expected <= discovered, "the runner does not pick up %s" % sorted(
        os.path.relpath(p, ROOT) for p in expected - discovered)
    # the file that the old <package>/test/**/*.test glob missed
    assert os.path.join(ROOT, "sharing_layer_cpp", "plugin", "test", "plugin_layer.test") in discovered


def test_discovery_finds_nested_test_files_and_leaves_out_build_and_hidden_folders(tmp_path):
    for rel in ("pkg_a/test/a.test", "pkg_a/plugin/test/deep/b.test", "pkg_a/c.test",
                "pkg_a/build/x.test", "pkg_a/.hidden/y.test", "pkg_a/node_modules/z.test", "pkg_b/d.test",
                "pkg_a/test/not_a_test.launch"):
        path = tmp_path / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text("<launch/>")
    found = [os.path.relpath(p, str(tmp_path)) for p in runner.discover_rostests(str(tmp_path), ["pkg_a"])]
    assert found == ["pkg_a/c.test", "pkg_a/plugin/test/deep/b.test", "pkg_a/test/a.test"]


def ros_or_skip():
    try:
        import roslaunch  # noqa: F401
        import rospkg
        rospkg.RosPack().get_path("rostest")
    except (ImportError, Exception) as err:  # noqa: BLE001
        pytest.skip("ROS (roslaunch, rostest) not available here: %s" % err)


def write(tmp_path, name, body):
    path = tmp_path / name
    path.write_text("<launch>\n%s\n</launch>\n" % body)
    return str(path)


def test_a_test_needing_an_uninstalled_package_is_skipped_with_the_reason(tmp_path):
    ros_or_skip()
    include = write(tmp_path, "include.test", '<include file="$(find no_such_package_q28)/launch/x.launch"/>\n'
                    '<test test-name="t" pkg="rostest" type="hztest"/>')
    node = write(tmp_path, "node.test", '<node pkg="no_such_package_r28" type="prog" name="n"/>\n'
                 '<test test-name="t" pkg="rostest" type="hztest"/>')
    assert "no_such_package_q28" in runner.missing_requirements(include)
    assert "no_such_package_r28" in runner.missing_requirements(node)


def test_a_missing_program_of_a_complete_package_is_not_a_skip(tmp_path):
    """rostest's own dependencies are installed: a missing program there is a build failure, and the
    runner lets rostest report it as one."""
    ros_or_skip()
    path = write(tmp_path, "missing.test", '<test test-name="t" pkg="rostest" type="no_such_program_q28"/>')
    assert runner.missing_requirements(path) is None


def test_the_plugin_test_and_the_real_stack_test_run_here():
    """make setup builds upstream costmap_2d, move_base and Stage where the distribution lacks them,
    so neither the plugin test nor the real-stack test may be left out (issue 49)."""
    ros_or_skip()
    for rel in ("sharing_layer_cpp/plugin/test/plugin_layer.test", "tests/test/move_base_corridors.test"):
        assert runner.missing_requirements(os.path.join(ROOT, rel)) is None, rel


def test_each_rostest_names_the_host_it_runs_on():
    ros_or_skip()
    assert runner.test_host(os.path.join(ROOT, "tests", "test", "move_base_corridors.test")) == \
        "Stage + upstream move_base"
    assert runner.test_host(os.path.join(ROOT, "tests", "test", "turn_share_fleet_sim.test")) == \
        "stand-ins: fleet_sim + fleet_nav"
    assert runner.test_host(os.path.join(ROOT, "sharing_layer_cpp", "plugin", "test", "plugin_layer.test")) == \
        "no simulator"


def test_a_rostest_missing_a_ros_package_fails_unless_allowed(tmp_path, monkeypatch):
    ros_or_skip()
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    write(pkg, "needs.test", '<arg name="_needs" value="$(find no_such_package_t49)"/>\n'
          '<test test-name="t" pkg="rostest" type="hztest"/>')
    monkeypatch.setattr(runner, "discover_rostests", lambda: [str(pkg / "needs.test")])
    monkeypatch.setattr(runner, "RESULTS", str(tmp_path / "results"))
    strict = runner.Tally()
    runner.run_rostests(strict)
    assert (strict.failed, strict.skipped) == (1, 0) and "no_such_package_t49" in strict.failures[0]
    lenient = runner.Tally()
    runner.run_rostests(lenient, allow_missing=True)
    assert (lenient.failed, lenient.skipped) == (0, 1)


def test_a_find_in_an_arg_is_skipped_naming_just_the_package(tmp_path):
    """roslaunch wraps a failed $(find) in an <arg> as "The following package was not found in <arg
    ...>: pkg" plus the ROS path; the reason names the package alone."""
    ros_or_skip()
    path = write(tmp_path, "arg.test", '<arg name="_needs" value="$(find no_such_package_s28)"/>\n'
                 '<test test-name="t" pkg="rostest" type="hztest"/>')
    assert runner.missing_requirements(path) == "needs ROS package no_such_package_s28, which is not installed"


def test_a_skip_is_counted_and_kept_as_junit(tmp_path):
    xml = str(tmp_path / "rostest" / "x" / "skipped.xml")
    runner.write_skipped_junit(xml, "x", "needs ROS package costmap_2d, which is not installed")
    tally = runner.Tally()
    tally.add_junit(xml, "rostest x")
    assert (tally.passed, tally.failed, tally.skipped) == (0, 0, 1)
    case = ET.parse(xml).getroot().find("testcase")
    assert "costmap_2d" in case.find("skipped").get("message")


def test_a_failed_case_is_listed_with_its_reason(tmp_path):
    """CI shows only the end of the log: the summary line of a failed case carries why it failed."""
    xml = tmp_path / "pytest.xml"
    xml.write_text('<testsuites><testsuite name="s" tests="3">'
                   '<testcase classname="test.test_a" name="test_x"><failure message="AssertionError: timed out '
                   'waiting for the area&#10;assert False">trace</failure></testcase>'
                   '<testcase classname="r" name="test_y"><error>Traceback (most recent call last):\n'
                   '  File "x.py", line 3\nRuntimeError: no broker\n</error></testcase>'
                   '<testcase classname="r" name="test_z"/></testsuite></testsuites>')
    tally = runner.Tally()
    tally.add_junit(str(xml), "pytest pkg")
    assert (tally.passed, tally.failed) == (1, 2)
    assert tally.failures == ["pytest pkg: test.test_a.test_x: AssertionError: timed out waiting for the area",
                              "pytest pkg: r.test_y: no broker"]
