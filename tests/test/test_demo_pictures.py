"""The demo's picture helpers (fleet_tests.demo): trails drawn where the robots drove, the
corridors a track drove through, and the count of fleet-obstacle marker pixels in an RViz
screenshot (0 in one taken before anything was shared)."""
from PIL import Image

from fleet_tests.demo import TRAIL_COLOURS, corridors_driven, draw_trails, marker_pixels

CORRIDORS = {"left": (1.0, 3.4, 2.8, 6.8), "middle": (5.9, 3.4, 7.7, 6.8), "right": (10.4, 3.4, 12.2, 6.8)}


def test_trails_are_drawn_where_the_robots_drove():
    image = Image.new("RGB", (640, 400), "white")          # a 16 x 10 m map at 40 px/m, origin (0, 0)
    trails = {"robot_0": [(0.0, 2.0, 1.0), (1.0, 2.0, 9.0)], "robot_1": [(0.0, 14.0, 1.0), (1.0, 14.0, 2.0)]}
    draw_trails(image, trails, 0.0, 0.0, 10.0, 40.0)
    assert image.getpixel((80, 200)) == TRAIL_COLOURS[0]     # x 2 m, y 5 m: on robot_0's trail
    assert image.getpixel((560, 340)) == TRAIL_COLOURS[1]    # x 14 m, y 1.5 m: on robot_1's
    assert image.getpixel((320, 200)) == (255, 255, 255)     # nobody drove there


def test_corridors_driven_through_not_only_entered():
    up_left = [(t, 2.0, 1.0 + t * 0.5) for t in range(0, 18)]                  # y 1 -> 9.5 in the left corridor
    into_right_and_back = [(t, 11.0, 2.0 + t * 0.5) for t in range(0, 6)] + [(6 + t, 11.0, 4.5 - t * 0.5)
                                                                             for t in range(0, 6)]
    assert corridors_driven(up_left, CORRIDORS) == ["left"]
    assert corridors_driven(into_right_and_back, CORRIDORS) == []
    later = [(t + 100, x, y) for t, x, y in [(0, 11.0, 9.0), (1, 11.0, 5.0), (2, 11.0, 1.0)]]
    assert corridors_driven(up_left + later, CORRIDORS) == ["left", "right"]


def test_marker_pixels_counts_the_marker_colour_only(tmp_path):
    path = str(tmp_path / "shot.png")
    image = Image.new("RGB", (200, 100), (48, 48, 48))
    image.paste((78, 154, 6), (0, 0, 50, 50))         # robot_1's plan/scan green in fleet.rviz: not a marker
    image.save(path)
    marker = (190 / 255.0, 229 / 255.0, 34 / 255.0)    # source_colour("robot_0")
    assert marker_pixels(path, [marker]) == 0
    image.paste((190, 229, 34), (100, 0, 110, 10))
    image.paste((150, 181, 27), (120, 0, 130, 10))    # the same hue, shaded by RViz's lighting
    image.save(path)
    assert marker_pixels(path, [marker]) == 200
