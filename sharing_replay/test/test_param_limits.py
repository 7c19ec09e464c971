"""The replay's numeric command-line ranges, just inside and just outside: a limit moved by one (``<=`` for
``<``, a bound off by one) turns one of these red. Pure and quick: the bag named does not exist, so a value the
checks take ends at "bag unreadable" (exit 3) before anything is replayed, and one they refuse at usage (exit 2)."""
import io

import pytest

from sharing_replay import cli, report


def exit_code(tmp_path, *args):
    stdout, stderr = io.StringIO(), io.StringIO()
    code, summary = cli.run([str(tmp_path / "missing.bag"), "--out-dir", str(tmp_path / "out"), "--progress",
                             "never"] + list(args), stdout, stderr)
    assert summary is None
    return code, stderr.getvalue()


@pytest.mark.parametrize("value,accepted", [(1, True), (0, False), (50, True), (51, False)])
def test_png_scale_is_1_to_50_pixels_per_cell(tmp_path, value, accepted):
    """0 pixels per cell draws nothing; beyond 50 a fleet map is a picture of hundreds of megapixels."""
    code, text = exit_code(tmp_path, "--png-scale", str(value))
    if accepted:
        assert code == report.EXIT_BAG_UNREADABLE and "does not exist" in text, text
    else:
        assert code == report.EXIT_USAGE and text == "replay: --png-scale must be 1..50, got %d\n" % value, text


@pytest.mark.parametrize("value,accepted", [(0, True), (-0.01, False), (10, True), (10.01, False)])
def test_robot_exclusion_trail_is_0_to_10_s(tmp_path, value, accepted):
    """The layer's limits (FleetRobotParams): a trail longer than 10 s is not a scan's age but a robot's history."""
    code, text = exit_code(tmp_path, "--param", "sharing/robot_exclusion_trail=%s" % value)
    if accepted:
        assert code == report.EXIT_BAG_UNREADABLE and "does not exist" in text, text
    else:
        assert code == report.EXIT_USAGE and "robot_exclusion_trail" in text, text
