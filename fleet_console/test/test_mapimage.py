"""fleet_console.mapimage, pure: a grid or a map_server YAML file becomes a PNG and its geometry, and every bad map
is a MapError that names what is wrong (the page shows it; nothing else may escape and stop the console)."""
import io
import struct
import zlib

import pytest
from PIL import Image

from fleet_console import mapimage
from fleet_console.mapimage import MapError


def png_pixels(console_map):
    with Image.open(io.BytesIO(console_map.png)) as image:
        return image.convert("L").load(), image.size


def test_a_grid_is_drawn_free_white_occupied_black_unknown_grey_with_row_0_at_the_bottom():
    # 3 x 2: row 0 (y = origin) is free, occupied, unknown; row 1 is 50 % and two out-of-range values
    grid = [0, 100, -1, 50, 127, 200]
    m = mapimage.from_grid(grid, 0.05, -1.0, 2.0, 3, 2, "/map")
    pixels, size = png_pixels(m)
    assert size == (3, 2)
    assert [pixels[x, 1] for x in range(3)] == [255, 0, 205]        # the grid's row 0 is the image's last row
    assert pixels[0, 0] == 255 - int(255 * 50 / 100) and pixels[1, 0] == 0
    assert pixels[2, 0] == 205                                       # 200 is -56 as a signed byte: unknown
    assert m.meta() == {"resolution": 0.05, "origin": [-1.0, 2.0], "width": 3, "height": 2, "source": "/map",
                        "url": "/map.png"}
    assert mapimage.from_grid(bytes([0, 100, 255, 50, 127, 200]), 0.05, 0, 0, 3, 2).png   # bytes as rospy gives


@pytest.mark.parametrize("args,text", [
    (([0] * 5, 0.05, 0, 0, 3, 2), "5 cells for a 3 x 2 grid"),
    (([0] * 6, 0.0, 0, 0, 3, 2), "resolution 0.0 must be > 0"),
    (([0] * 6, -0.05, 0, 0, 3, 2), "resolution -0.05 must be > 0"),
    (([0] * 6, float("nan"), 0, 0, 3, 2), "resolution nan is not a finite number"),
    (([0] * 6, 0.05, float("inf"), 0, 3, 2), "origin x inf is not a finite number"),
    (([0] * 6, 0.05, 0, "1", 3, 2), "origin y '1' is not a finite number"),
    (([0] * 6, True, 0, 0, 3, 2), "resolution True is not a finite number"),
    (([], 0.05, 0, 0, 0, 0), "size 0 x 0"),
    (([0] * 6, 0.05, 0, 0, 3.0, 2), "size 3.0 x 2"),
    (([0], 0.05, 0, 0, 100000, 100000), "at most %d cells" % mapimage.MAX_CELLS),
])
def test_a_bad_grid_is_a_map_error_naming_the_field(args, text):
    with pytest.raises(MapError, match=text.replace("(", r"\(").replace(".", r"\.")) as err:
        mapimage.from_grid(*args, source="/map")
    assert str(err.value).startswith("map /map: ")


def write_map(folder, yaml_text, image=None, name="map.pgm"):
    (folder / "map.yaml").write_text(yaml_text)
    if image is not None:
        if isinstance(image, bytes):
            (folder / name).write_bytes(image)
        else:
            image.save(str(folder / name))
    return str(folder / "map.yaml")


def test_a_map_server_file_is_drawn_as_it_is(tmp_path):
    image = Image.new("L", (4, 3), 254)
    image.putpixel((0, 0), 0)
    path = write_map(tmp_path, "image: map.pgm\nresolution: 0.1\norigin: [-2.0, 1.5, 0.0]\n", image)
    m = mapimage.from_yaml(path)
    pixels, size = png_pixels(m)
    assert size == (4, 3) and pixels[0, 0] == 0 and pixels[3, 2] == 254
    assert (m.resolution, m.origin_x, m.origin_y, m.source) == (0.1, -2.0, 1.5, path)


def huge_png(width, height):
    """A PNG header claiming width x height (no pixel data): what a decompression bomb looks like to Pillow."""
    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(b"")) + chunk(b"IEND", b""))


@pytest.mark.parametrize("yaml_text,image,text", [
    (None, None, "No such file or directory"),
    ("image: [unclosed\n", None, "is not YAML"),
    ("- a list\n", None, "needs image, resolution and origin"),
    ("image: map.pgm\nresolution: 0.05\n", None, "needs image, resolution and origin"),
    ("image: map.pgm\nresolution: 0.05\norigin: 3\n", None, "origin 3 must be [x, y, yaw]"),
    ("image: map.pgm\nresolution: 0.05\norigin: [1]\n", None, "origin [1] must be [x, y, yaw]"),
    ("image: gone.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n", None, "image gone.pgm cannot be read"),
    ("image: map.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n", b"P5 not really a pgm", "image map.pgm cannot be read"),
    ("image: map.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n", b"", "image map.pgm cannot be read"),
    ("image: map.png\nresolution: 0.05\norigin: [0, 0, 0]\n", huge_png(30000, 30000), "decompression bomb"),
    ("image: map.png\nresolution: 0.05\norigin: [0, 0, 0]\n", huge_png(12000, 12000), "is 12000 x 12000 pixels, more"),
    ("image: map.pgm\nresolution: fine\norigin: [0, 0, 0]\n", Image.new("L", (2, 2)), "resolution 'fine' is not"),
    ("image: map.pgm\nresolution: -1\norigin: [0, 0, 0]\n", Image.new("L", (2, 2)), "resolution -1 must be > 0"),
    ("image: map.pgm\nresolution: .nan\norigin: [0, 0, 0]\n", Image.new("L", (2, 2)), "resolution nan is not"),
    ("image: map.pgm\nresolution: 0.05\norigin: [x, 0, 0]\n", Image.new("L", (2, 2)), "origin x 'x' is not"),
])
def test_a_bad_map_file_is_a_map_error_naming_the_file_and_what_is_wrong(tmp_path, yaml_text, image, text):
    if yaml_text is None:
        path = str(tmp_path / "missing.yaml")
    else:
        path = write_map(tmp_path, yaml_text, image, "map.png" if isinstance(image, bytes) and
                         image.startswith(b"\x89PNG") else "map.pgm")
    with pytest.raises(MapError) as err:
        mapimage.from_yaml(path)
    message = str(err.value)
    assert message.startswith("map file %s" % path) and text in message, message


def test_an_unreadable_map_file_is_a_map_error(tmp_path):
    import os
    path = write_map(tmp_path, "image: map.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n", Image.new("L", (2, 2)))
    os.chmod(path, 0)
    try:
        if os.access(path, os.R_OK):
            pytest.skip("running as a user who reads any file (root)")
        with pytest.raises(MapError, match="Permission denied"):
            mapimage.from_yaml(path)
    finally:
        os.chmod(path, 0o644)


def test_a_directory_given_as_the_map_file_is_a_map_error(tmp_path):
    with pytest.raises(MapError, match="map file"):
        mapimage.from_yaml(str(tmp_path))



def test_an_image_that_cannot_be_opened_is_a_map_error(tmp_path):
    """What root cannot read either: the image named is a folder."""
    (tmp_path / "map.pgm").mkdir()
    path = write_map(tmp_path, "image: map.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n")
    with pytest.raises(MapError, match="image map.pgm cannot be read: .*Is a directory"):
        mapimage.from_yaml(path)
