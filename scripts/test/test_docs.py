"""The READMEs cannot go stale unnoticed (issue 31).

- every relative link of every README (and CHANGELOG.md) reaches a file, and its #anchor a heading;
- the top README is a product page: at most about 1,500 words, no commit hashes in its prose;
- every command in a README's code blocks names what exists: `roslaunch PKG FILE arg:=v` a launch
  file of that package that declares each arg; `rosrun PKG EXE` a program of that package;
  `rostest PKG FILE` a test file; `make TARGET` a Makefile target; `make bench NAME=x` a benchmark;
- YAML and XML snippets parse, and what they name (plugin types, node packages and types) exists;
- no table row of measured figures or parameters appears in two documents (one place per table);
- no README cites a document or an issue that is not in the repository (a design note, an issue
  number, a path beside the repository): a reader of a clone has only the clone;
- every `fleet_obstacles` command in a README is one the tool accepts.
Running the commands themselves is the demo's and the tests' job; this checks they still point at
what is there.
"""
import glob
import os
import re
import shlex
import sys
import xml.etree.ElementTree as ET

import pytest
import yaml

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.join(ROOT, "scripts"))
import run_bench  # noqa: E402

# folder -> ROS package name (the folder `launch` holds fleet_launch, `tests` fleet_tests)
PACKAGES = {}
for _xml in glob.glob(os.path.join(ROOT, "*", "package.xml")):
    PACKAGES[ET.parse(_xml).getroot().findtext("name")] = os.path.dirname(_xml)

DOCS = sorted(glob.glob(os.path.join(ROOT, "*.md")) + [
    p for p in glob.glob(os.path.join(ROOT, "**", "README.md"), recursive=True)
    if os.path.dirname(p) != ROOT and not os.path.relpath(p, ROOT).startswith(("catkin_ws" + os.sep, "out" + os.sep))
    and "node_modules" not in os.path.relpath(p, ROOT).split(os.sep)])  # npm's downloads are not our documents
READMES = [d for d in DOCS if os.path.basename(d) == "README.md"]
TOP = os.path.join(ROOT, "README.md")
# Packages the READMEs may name that are not ours: upstream's, present only where they are installed.
UPSTREAM = {"move_base", "stage_ros", "map_server", "fake_localization", "rqt_reconfigure", "dynamic_reconfigure",
            "costmap_2d", "rviz", "rosbag", "amcl"}
COSTMAP_2D_PLUGINS = {"costmap_2d::StaticLayer", "costmap_2d::ObstacleLayer", "costmap_2d::InflationLayer",
                      "costmap_2d::VoxelLayer"}


def rel(path):
    return os.path.relpath(path, ROOT)


def read(path):
    with open(path, encoding="utf-8") as f:
        return f.read()


def slug(heading):
    """GitHub's anchor of a heading: lower case, punctuation but '-' and '_' dropped, spaces to '-'."""
    text = re.sub(r"`|\*\*|\[|\]\([^)]*\)", "", heading.strip()).lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(path):
    out, seen = set(), {}
    in_code = False
    for line in read(path).splitlines():
        if line.startswith("```"):
            in_code = not in_code
        if in_code:
            continue
        m = re.match(r"#{1,6} (.*)", line)
        if m:
            base = slug(m.group(1))
            n = seen.get(base, 0)
            seen[base] = n + 1
            out.add(base if n == 0 else "%s-%d" % (base, n))
    return out


def prose(text):
    """The text outside code blocks."""
    return re.sub(r"```.*?```", "", text, flags=re.S)


def code_blocks(text):
    """(language, body) of each fenced block."""
    return re.findall(r"```([\w-]*)\n(.*?)```", text, flags=re.S)


TOOLS = ("roslaunch", "rostest", "rosrun", "make")


def commands(text):
    """The roslaunch/rostest/rosrun/make lines of the code blocks (sh or unlabelled; other lines there are
    diagrams or sample output), comments stripped, `a; b` split, optional `[arg:=v]` unbracketed."""
    out = []
    for lang, body in code_blocks(text):
        if lang not in ("", "sh", "bash", "shell"):
            continue
        for line in body.splitlines():
            for part in line.split(" #", 1)[0].split(";"):
                part = part.strip().replace("[", "").replace("]", "")
                if part.split(" ", 1)[0] in TOOLS:
                    out.append(part)
    return out


LINK = re.compile(r"\]\(([^)\s]+)\)")


@pytest.mark.parametrize("doc", DOCS, ids=rel)
def test_every_relative_link_reaches_a_file_and_its_anchor(doc):
    broken = []
    for target in LINK.findall(prose(read(doc))):
        if re.match(r"[a-z]+://", target) or target.startswith("mailto:"):
            continue
        path, _, anchor = target.partition("#")
        full = os.path.normpath(os.path.join(os.path.dirname(doc), path)) if path else doc
        if not os.path.exists(full):
            broken.append("%s (no such file)" % target)
        elif anchor and full.endswith(".md") and anchor not in anchors(full):
            broken.append("%s (no heading with that anchor in %s)" % (target, rel(full)))
    assert not broken, "%s: broken links: %s" % (rel(doc), "; ".join(broken))


def test_top_readme_is_a_product_page():
    text = read(TOP)
    words = len(prose(text).split()) + sum(len(b.split()) for _l, b in code_blocks(text))
    assert words <= 1600, "README.md has %d words; the product page is at most about 1,500" % words
    hashes = [h for h in re.findall(r"\b[0-9a-f]{7,40}\b", prose(text)) if re.search(r"[a-f]", h)
              and re.search(r"[0-9]", h)]
    assert not hashes, "README.md cites commit hashes in its prose (history goes to CHANGELOG.md): %s" % hashes
    for doc in DOCS:
        if doc != TOP and os.path.basename(doc) == "README.md":
            folder = os.path.dirname(rel(doc))
            assert "](%s" % rel(doc) in text or "](%s/)" % folder in text, "README.md does not link %s" % rel(doc)


def launch_args(path):
    root = ET.parse(path).getroot()
    return {a.get("name") for a in root.iter("arg")}


def check_command(line):
    """A problem with one README command line, or None."""
    try:
        words = shlex.split(line)
    except ValueError as err:
        return "cannot parse %r: %s" % (line, err)
    if not words:
        return None
    tool, args = words[0], words[1:]
    if tool == "roslaunch":
        args = [a for a in args if a not in ("--ros-args", "--nodes", "--dump-params", "--files")]
    if tool in ("roslaunch", "rostest", "rosrun") and args and args[0] in UPSTREAM:
        return None
    if tool == "rostest" and args and args[0].endswith(".test"):
        return None if os.path.exists(os.path.join(ROOT, args[0])) else "%r: no file %s" % (line, args[0])
    if tool in ("roslaunch", "rostest"):
        if len(args) < 2 or args[0] not in PACKAGES:
            return "%r: no package of ours named %r" % (line, args[0] if args else "")
        found = glob.glob(os.path.join(PACKAGES[args[0]], "**", args[1]), recursive=True)
        if not found:
            return "%r: package %s has no file %s" % (line, args[0], args[1])
        declared = launch_args(found[0])
        for word in args[2:]:
            if ":=" in word and not word.startswith("_"):
                name = word.split(":=", 1)[0]
                if name not in declared:
                    return "%r: %s declares no arg %r" % (line, rel(found[0]), name)
    elif tool == "rosrun":
        if len(args) < 2 or args[0] not in PACKAGES:
            return "%r: no package of ours named %r" % (line, args[0] if args else "")
        pkg_dir = PACKAGES[args[0]]
        scripts = [p for p in glob.glob(os.path.join(pkg_dir, "**", args[1]), recursive=True)
                   if os.access(p, os.X_OK) and "/test/" not in p]
        built = os.path.join(ROOT, "catkin_ws", "devel", "lib", args[0], args[1])
        cmake = read(os.path.join(pkg_dir, "CMakeLists.txt"))
        if not scripts and not os.path.exists(built) and not re.search(r"add_executable\(\s*%s\b" % re.escape(args[1]), cmake):
            return "%r: package %s has no program %s" % (line, args[0], args[1])
    elif tool == "make":
        targets = set(re.findall(r"^([\w-]+):", read(os.path.join(ROOT, "Makefile")), flags=re.M))
        goals = [a for a in args if "=" not in a]
        for goal in goals:
            if goal not in targets:
                return "%r: the Makefile has no target %s" % (line, goal)
        for a in args:
            if a.startswith("NAME=") and a[5:] not in run_bench.BENCHMARKS and "<" not in a and "..." not in a:
                return "%r: no benchmark named %s (scripts/run_bench.py)" % (line, a[5:])
    return None


# CHANGELOG.md names commands that are gone on purpose (what they were renamed to).
@pytest.mark.parametrize("doc", [d for d in DOCS if os.path.basename(d) != "CHANGELOG.md"], ids=rel)
def test_every_command_names_what_exists(doc):
    text = read(doc)
    lines = commands(text) + [c.replace("[", "").replace("]", "") for c in
                              re.findall(r"`((?:roslaunch|rostest|rosrun|make) [^`]+)`", prose(text))]
    problems = [p for p in (check_command(c) for c in lines) if p]
    assert not problems, "%s:\n  %s" % (rel(doc), "\n  ".join(problems))


def declared_plugins():
    names = set(COSTMAP_2D_PLUGINS)
    for xml in glob.glob(os.path.join(ROOT, "*", "*plugin*.xml")):
        names |= {c.get("name") or c.get("type") for c in ET.parse(xml).getroot().iter("class")}
    return names


@pytest.mark.parametrize("doc", DOCS, ids=rel)
def test_snippets_parse_and_name_what_exists(doc):
    plugins = declared_plugins()
    for lang, body in code_blocks(read(doc)):
        if lang == "yaml":
            data = yaml.safe_load(body)
            for costmap in (data or {}).values():
                for plugin in (costmap or {}).get("plugins", []) if isinstance(costmap, dict) else []:
                    assert plugin["type"] in plugins, "%s: plugin type %s is declared nowhere" % (rel(doc), plugin["type"])
        elif lang == "xml":
            root = ET.fromstring("<snippet>%s</snippet>" % re.sub(r"<\?xml[^>]*\?>", "", body))
            for node in root.iter("node"):
                pkg, exe = node.get("pkg"), node.get("type")
                if pkg in UPSTREAM:
                    continue
                assert check_command("rosrun %s %s" % (pkg, exe)) is None, \
                    "%s: <node pkg=%s type=%s> names no program of ours" % (rel(doc), pkg, exe)


def table_rows(text):
    """Data rows of the document's tables that carry a figure or a default: at least 3 cells and a digit."""
    rows = []
    for line in prose(text).splitlines():
        line = line.strip()
        if line.startswith("|") and not re.match(r"\|[-| :]+\|$", line):
            cells = [c.strip() for c in line.strip("|").split("|")]
            if len(cells) >= 3 and re.search(r"\d", line):
                rows.append(line)
    return rows


def test_no_measured_or_parameter_row_is_in_two_documents():
    where = {}
    for doc in DOCS:
        for row in set(table_rows(read(doc))):
            where.setdefault(row, []).append(rel(doc))
    twice = {row: docs for row, docs in where.items() if len(docs) > 1}
    assert not twice, "table rows in more than one document (keep each table in one place, link to it):\n" + \
        "\n".join("%s: %s" % (", ".join(d), r[:120]) for r, d in sorted(twice.items()))


# A reference to something a clone does not hold. Issue numbers: the tracker is not in the clone (CHANGELOG.md
# keeps them as history). A section sign: a section of a document, which then must be named and present.
ISSUE = re.compile(r"\b(?:issues?|pull requests?|PRs?)\s+#?\d+", re.I)
SECTION = re.compile(r"§")
DOCUMENT = re.compile(r"(?<![\w/.-])((?:\.\./|\./)*[\w.-]+(?:/[\w.-]+)*\.(?:md|pdf|docx?))\b")
OUTSIDE = re.compile(r"(?<![\w/.-])((?:\.\./)+[\w.-]+(?:/[\w.-]+)*)")
URL = re.compile(r"[a-z]+://\S+")
# What the project's own commands write (make demo's report): named, not cited.
GENERATED = ("out/",)
# What may name a folder beside the repository: where `make setup` looks for the upstream source archives.
OUTSIDE_ALLOWED = {("upstream/README.md", "../shared/upstream")}


def tracked_names():
    names = set()
    for path in glob.glob(os.path.join(ROOT, "**", "*"), recursive=True):
        if "catkin_ws" not in os.path.relpath(path, ROOT).split(os.sep)[:1]:
            names.add(os.path.basename(path))
    return names


def outside_citations(text, doc_path, names=None):
    """What a README cites that the repository does not hold, as lines."""
    names = tracked_names() if names is None else names
    rel_doc = os.path.relpath(doc_path, ROOT)
    found = []
    for number, line in enumerate(text.splitlines(), 1):
        line = URL.sub("", line)
        for m in ISSUE.finditer(line):
            found.append("%s:%d: an issue (%s): say the reason instead" % (rel_doc, number, m.group(0)))
        if SECTION.search(line):
            found.append("%s:%d: a section sign (%s): name the document and section, or say it" % (
                rel_doc, number, line.strip()[:60]))
        for m in DOCUMENT.finditer(line):
            target = m.group(1)
            if target.startswith(GENERATED):
                continue
            candidates = [os.path.normpath(os.path.join(base, target)) for base in (os.path.dirname(doc_path), ROOT)]
            if any(c.startswith(ROOT + os.sep) and os.path.exists(c) for c in candidates):
                continue
            if "/" not in target and target in names:
                continue
            found.append("%s:%d: a document not in the repository: %s" % (rel_doc, number, target))
        for m in OUTSIDE.finditer(line):
            target = os.path.normpath(os.path.join(os.path.dirname(doc_path), m.group(1)))
            if not (target + os.sep).startswith(ROOT + os.sep) and (rel_doc, m.group(1)) not in OUTSIDE_ALLOWED:
                found.append("%s:%d: a path beside the repository: %s" % (rel_doc, number, m.group(1)))
    return found


@pytest.mark.parametrize("doc", READMES, ids=rel)
def test_no_readme_cites_a_document_or_issue_outside_the_repository(doc):
    found = outside_citations(read(doc), doc)
    assert not found, "\n".join(found)


def fleet_obstacles_parser():
    import importlib.machinery
    import importlib.util
    path = os.path.join(ROOT, "sharing_handler_py", "scripts", "fleet_obstacles")
    loader = importlib.machinery.SourceFileLoader("fleet_obstacles_tool", path)
    spec = importlib.util.spec_from_loader("fleet_obstacles_tool", loader)
    module = importlib.util.module_from_spec(spec)
    loader.exec_module(module)
    return module.parse


# Placeholders a README writes for what the user fills in.
PLACEHOLDERS = {"UUID": "00000000-0000-4000-8000-000000000001", "NAME": "anna", "robot_N": "robot_0"}


def fleet_obstacles_commands(text):
    """The argument lists of the `fleet_obstacles ...` commands of a README (code and backticks), brackets
    of optional parts removed, alternatives (a|b) taken as written."""
    out = []
    lines = [line for _lang, body in code_blocks(text) for line in body.splitlines()]
    lines += re.findall(r"`([^`]*fleet_obstacles [^`]+)`", prose(text))
    for line in lines:
        m = re.search(r"\bfleet_obstacles\s+(.*)", line.split(" #", 1)[0])
        if m:
            words = shlex.split(m.group(1).replace("[", "").replace("]", ""))
            out.append([PLACEHOLDERS.get(w, w) for w in words])
    return out


@pytest.mark.parametrize("doc", READMES, ids=rel)
def test_every_fleet_obstacles_command_is_accepted_by_the_tool(doc):
    commands_found = fleet_obstacles_commands(read(doc))
    if not commands_found:
        return
    parse = fleet_obstacles_parser()
    refused = []
    for args in commands_found:
        try:
            parse(args)
        except SystemExit:
            refused.append(" ".join(args))
    assert not refused, "%s: fleet_obstacles refuses: %s" % (rel(doc), "; ".join(refused))


def test_the_checks_find_what_they_guard():
    """The checkers themselves: each names a made-up command, link and row."""
    assert check_command("roslaunch fleet_launch fleet.launch no_such_arg:=1")
    assert check_command("rosrun coaty_bridge no_such_program")
    assert check_command("make bench NAME=no_such_bench")
    assert check_command("make no_such_target")
    assert check_command("roslaunch fleet_launch fleet.launch robots:=2") is None
    assert slug("On the real stack: upstream move_base and Stage (`move_base_fleet.launch`)") == \
        "on-the-real-stack-upstream-move_base-and-stage-move_base_fleetlaunch"
    assert table_rows("| a | 1 | b |\n|---|---|---|\n| x | y |") == ["| a | 1 | b |"]
    doc = os.path.join(ROOT, "coaty_bridge", "README.md")
    cited = outside_citations("as in issue 27; see DESIGN.md §6 and `../shared/COATY.md`, STYLE.md\n"
                              "PR #12; [spec](https://example.org/docs/spec.md); CHANGELOG.md; ../README.md", doc)
    assert len(cited) == 6 and all(":1:" in c for c in cited[:5]) and ":2: an issue (PR #12)" in cited[5], cited
    assert any("../shared/COATY.md" in c for c in cited), cited
    assert outside_citations("the archives in `../shared/upstream`", os.path.join(ROOT, "upstream", "README.md")) == []
    assert fleet_obstacles_commands("`rosrun sharing_handler_py fleet_obstacles list|remove UUID`") == \
        [["list|remove", "00000000-0000-4000-8000-000000000001"]]
