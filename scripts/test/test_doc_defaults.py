"""A README's parameter table says the defaults the code and launch files use.

Every table of a package README whose header reads `| name/parameter/argument | default | ...` is
compared, row by row, with the defaults the package itself declares:
- launch files: `<arg name="x" default="v"/>` (only the launch file the README names last before the
  table, when it names one: `fleet.launch`'s table is not `move_base_fleet.launch`'s);
- Python: `get_param("~x", v)` and dataclass fields `x: type = v` with a literal value;
- C++: `nh.param("x", field, v)`.
A row whose default is prose ("namespace", "fresh uuid4 per start") or whose name no source declares
with a literal is not compared; a row that parses and differs fails, naming both places.
"""
import ast
import glob
import os
import re

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
READMES = sorted(p for p in glob.glob(os.path.join(ROOT, "*", "README.md"))
                 if not os.path.relpath(p, ROOT).startswith(("catkin_ws", "out", "upstream")))
HEADER = re.compile(r"^\|\s*(name|parameter|param|argument|arg)s?\s*\|\s*default\s*\|", re.I)
LAUNCH_NAME = re.compile(r"\b([\w-]+\.launch)\b")
NOT_LOOKED_AT = ("test", "bench", "catkin_ws", "node_modules", "__pycache__")


def literal(text):
    """A Python/XML literal as a value, or None when the text is not one."""
    text = text.strip().replace("\u2212", "-")
    if text.lower() in ("true", "false"):
        return text.lower() == "true"
    try:
        value = ast.literal_eval(text)
    except (ValueError, SyntaxError, TypeError, MemoryError, RecursionError):
        return None
    return value if isinstance(value, (bool, int, float, str, tuple, list)) else None


def readme_value(cell):
    """The default a README cell states, or None for prose: `"x"`, `[]`, 2.5 m, true; the note after is ignored."""
    cell = cell.strip().replace("\u2212", "-")
    quoted = re.match(r"`([^`]*)`", cell)
    if quoted:
        value = literal(quoted.group(1))
        return quoted.group(1) if value is None else value
    word = re.match(r"(-?[\d.]+(?:e-?\d+)?|true|false)(?=[\s;,)]|$)", cell, re.I)
    return literal(word.group(1)) if word else None


def same(a, b):
    if isinstance(a, bool) or isinstance(b, bool):
        return a is b
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return float(a) == float(b)
    if isinstance(a, (tuple, list)) and isinstance(b, (tuple, list)):
        return list(a) == list(b)
    return a == b


def declared_defaults(package, launch_only=None):
    """name -> [(value, file)] of the defaults the package's own sources declare."""
    out = {}

    def put(name, value, path):
        out.setdefault(name.lstrip("~"), []).append((value, os.path.relpath(path, ROOT)))
    for path in sorted(glob.glob(os.path.join(package, "**", "*"), recursive=True)):
        parts = os.path.relpath(path, package).split(os.sep)
        if not os.path.isfile(path) or any(p in NOT_LOOKED_AT for p in parts):
            continue
        if path.endswith(".launch"):
            if launch_only and os.path.basename(path) != launch_only:
                continue
            for m in re.finditer(r'<arg\s+name="(\w+)"\s+default="([^"$]*)"', _read(path)):
                value = literal(m.group(2))
                put(m.group(1), m.group(2) if value is None else value, path)
        elif path.endswith(".py") or "scripts" in parts[:-1]:
            text = _read(path)
            for m in re.finditer(r'get_param\(\s*"(~?\w+)"\s*,\s*([^,()\n]+?)\s*\)', text):
                value = literal(m.group(2))
                if value is not None:
                    put(m.group(1), value, path)
            for m in re.finditer(r"^    (\w+):\s*[\w\[\], .]+=\s*([^#\n]+?)\s*(?:#.*)?$", text, re.M):
                value = literal(m.group(2))
                if value is not None:
                    put(m.group(1), value, path)
        elif path.endswith((".cpp", ".h")):
            for m in re.finditer(r'param\(\s*"(\w+)"\s*,\s*[\w.\[\]>-]+\s*,\s*([^;]+?)\)\s*;', _read(path)):
                value = literal(m.group(2))
                if value is not None:
                    put(m.group(1), value, path)
    return out


def _read(path):
    try:
        with open(path, encoding="utf-8") as f:
            return f.read()
    except (OSError, UnicodeDecodeError):
        return ""


def tables(text):
    """(line number, cells, launch file named last before the table or None) of every parameter row."""
    lines = text.splitlines()
    inside, launch = False, None
    for number, line in enumerate(lines, 1):
        if HEADER.match(line):
            inside = True
            continue
        if inside and line.startswith("|"):
            if not set(line.replace("|", "").strip()) <= set("-: "):
                yield number, [c.strip() for c in line.strip().strip("|").split("|")], launch
            continue
        inside = False
        named = LAUNCH_NAME.findall(line)
        if named:
            launch = named[-1]


def mismatches(readme, text=None, package=None):
    """Lines naming each row whose stated default differs from what the package declares."""
    package = package or os.path.dirname(readme)
    text = _read(readme) if text is None else text
    found, cache = [], {}
    for number, cells, launch in tables(text):
        if len(cells) < 2:
            continue
        names = re.findall(r"`~?(\w+)`", cells[0])
        values = [v for v in cells[1].split(",")] if len(names) > 1 else [cells[1]]
        if len(values) != len(names):
            continue
        if launch not in cache:
            cache[launch] = declared_defaults(package, launch)
        declared = cache[launch]
        for name, cell in zip(names, values):
            stated = readme_value(cell)
            if stated is None or name not in declared or (isinstance(stated, str) and stated in declared):
                continue   # prose, undeclared, or another parameter's name (`sim_time` x `max_vel_x`)
            if not any(same(stated, value) for value, _ in declared[name]):
                found.append("%s:%d: `%s` default %r, but %s" % (
                    os.path.relpath(readme, ROOT), number, name, stated,
                    "; ".join("%s declares %r" % (where, value) for value, where in declared[name])))
    return found


@pytest.mark.parametrize("readme", READMES, ids=lambda p: os.path.relpath(p, ROOT))
def test_every_parameter_default_in_a_readme_is_the_declared_one(readme):
    assert mismatches(readme) == []


def test_the_check_compares_rows_it_can_read(tmp_path):
    """Enough rows are compared that a drift is noticed: the tables of the nodes and the fleet launch."""
    compared = 0
    for readme in READMES:
        declared = None
        for _, cells, launch in tables(_read(readme)):
            declared = declared_defaults(os.path.dirname(readme), launch)
            compared += sum(1 for n in re.findall(r"`~?(\w+)`", cells[0]) if n in declared)
    assert compared >= 100, compared


def test_the_check_finds_a_changed_default(tmp_path):
    package = tmp_path / "pkg"
    (package / "launch").mkdir(parents=True)
    (package / "launch" / "a.launch").write_text('<launch><arg name="robots" default="3"/></launch>')
    (package / "launch" / "b.launch").write_text('<launch><arg name="robots" default="2"/></launch>')
    (package / "node.py").write_text('x = rospy.get_param("~rate", 2.0)\n')
    readme = str(package / "README.md")
    table = "`%s`\n\n| argument | default | |\n|---|---|---|\n| `robots` | %s | n |\n| `rate` | %s Hz | r |\n"
    assert mismatches(readme, table % ("a.launch", "3", "2.0"), str(package)) == []
    assert len(mismatches(readme, table % ("a.launch", "2", "2.0"), str(package))) == 1, "b.launch's 2 is not a's"
    assert len(mismatches(readme, table % ("a.launch", "3", "2.5"), str(package))) == 1
    assert readme_value("`\"\"` (off)") == "" and readme_value("namespace") is None
    assert readme_value("\u22121 (no limit)") == -1 and readme_value("true; the core's defaults") is True
