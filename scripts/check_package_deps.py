#!/usr/bin/python3
"""Checks that every package.xml of the workspace declares what its code uses, and that the
declared graph between workspace packages has no cycle.

What counts as use, per package folder:
  - Python: `import X` / `from X import` (also inside functions), `pytest.importorskip("X")`;
  - C++: `#include <X/...>` or `"X/..."` of another package's headers or of a ROS package;
  - CMakeLists.txt: find_package(X) and find_package(catkin ... COMPONENTS X Y);
  - launch and rostest files: `$(find X)` and `pkg="X"`;
  - Python strings that start a ROS tool on a package: "roslaunch", "X" / "rosrun", "X";
  - .msg/.srv/.action files: field types `X/Type`.
A use in a test/ folder (test/..., plugin/test/...) may be declared as test_depend; a use in C++ or CMake needs a build dependency;
any other use needs an exec dependency (`depend` covers all three).

Rules:
  1. every workspace package, ROS package and Python library a package uses is declared;
  2. every workspace package a package declares is used (an unused edge still orders the build
     and hides the architecture);
  3. the declared graph between workspace packages has no cycle.

Usage: check_package_deps.py [--root DIR] [--edges] [--junit FILE]
Exit 0 when every rule holds, 1 with one line per violation otherwise.
"""
import argparse
import ast
import os
import re
import sys
import xml.etree.ElementTree as ET
from xml.sax.saxutils import escape

SKIP_DIRS = {"catkin_ws", "out", "test_results", "build", "devel", "install", "node_modules", "__pycache__",
             ".git", ".ci"}

# Python modules that come from outside ROS, by the rosdep key that installs them.
PYTHON_LIBRARIES = {
    "numpy": "python3-numpy", "scipy": "python3-scipy", "yaml": "python3-yaml", "PIL": "python3-pil",
    "paho": "python3-paho-mqtt", "websockets": "python3-websockets", "selenium": "python3-selenium", "pytest": "python3-pytest", "hypothesis": "python3-hypothesis",
    "rospkg": "python3-rospkg", "catkin_pkg": "python3-catkin-pkg", "jsonschema": "python3-jsonschema",
}
# ROS packages that a Python import or C++ include may name, beyond every *_msgs / *_srvs package.
ROS_PACKAGES = {
    "rospy", "roscpp", "rostest", "rosbag", "rosgraph", "rosnode", "roslaunch", "rosservice", "rostopic",
    "actionlib", "tf", "tf2", "tf2_ros", "tf2_py", "tf2_sensor_msgs", "tf2_geometry_msgs", "costmap_2d",
    "pluginlib", "laser_geometry", "message_filters", "dynamic_reconfigure", "voxel_grid", "topic_tools",
    "map_server", "stage_ros", "move_base", "angles", "rviz", "message_generation", "message_runtime", "genpy",
}
# C++ include folders that are not a package of the same name.
CPP_INCLUDES = {"ros": "roscpp", "pybind11": "pybind11-dev", "gtest": "gtest", "gmock": "gtest"}
STDLIB = set(sys.stdlib_module_names)

BUILD, EXEC, TEST = "build", "exec", "test"
SATISFIES = {  # which declaration satisfies which kind of use
    "depend": {BUILD, EXEC, TEST}, "build_depend": {BUILD, TEST}, "build_export_depend": {BUILD},
    "buildtool_depend": {BUILD}, "exec_depend": {EXEC, TEST}, "run_depend": {EXEC, TEST},
    "test_depend": {TEST},
}

IMPORT_STRING_RE = re.compile(r"importorskip\(\s*[\"']([A-Za-z_][\w.]*)[\"']")
TOOL_RE = re.compile(r"[\"'](?:roslaunch|rosrun)[\"']\s*,\s*[\"']([A-Za-z_]\w*)[\"']")
INCLUDE_RE = re.compile(r"^\s*#\s*include\s*[<\"]([A-Za-z_]\w*)/", re.M)
FIND_RE = re.compile(r"\$\(find\s+([A-Za-z_]\w*)\)")
PKG_ATTR_RE = re.compile(r"\bpkg\s*=\s*\"([A-Za-z_]\w*)\"")
FIND_PACKAGE_RE = re.compile(r"find_package\s*\(([^)]*)\)", re.S)
FIELD_TYPE_RE = re.compile(r"^\s*([A-Za-z_]\w*)/\w+(?:\[\d*\])?\s+\w+", re.M)


class Package:
    def __init__(self, folder, name, declared):
        self.folder = folder          # path relative to the root
        self.name = name
        self.declared = declared      # {dependency: set of declaration tags}
        self.python_modules = set()   # top-level Python modules this package provides
        self.include_dirs = set()     # include/<dir> folders this package provides
        self.uses = {}                # {dependency: {kind: [where, ...]}}

    def use(self, dependency, kind, where):
        self.uses.setdefault(dependency, {}).setdefault(kind, []).append(where)


def read_package(root, folder):
    path = os.path.join(root, folder, "package.xml")
    tree = ET.parse(path).getroot()
    name = tree.findtext("name", "").strip()
    declared = {}
    for tag in SATISFIES:
        for element in tree.findall(tag):
            declared.setdefault((element.text or "").strip(), set()).add(tag)
    package = Package(folder, name, declared)
    src = os.path.join(root, folder, "src")
    if os.path.isdir(src):
        for entry in os.listdir(src):
            if os.path.isfile(os.path.join(src, entry, "__init__.py")):
                package.python_modules.add(entry)
    for generated in ("msg", "srv", "action"):
        if os.path.isdir(os.path.join(root, folder, generated)):
            package.python_modules.add(name)
    include = os.path.join(root, folder, "include")
    if os.path.isdir(include):
        package.include_dirs.update(e for e in os.listdir(include) if os.path.isdir(os.path.join(include, e)))
    return package


def find_packages(root):
    packages = []
    for entry in sorted(os.listdir(root)):
        if entry in SKIP_DIRS or entry.startswith("."):
            continue
        if os.path.isfile(os.path.join(root, entry, "package.xml")):
            packages.append(read_package(root, entry))
    return packages


def package_files(root, package):
    base = os.path.join(root, package.folder)
    for directory, dirs, files in os.walk(base):
        dirs[:] = sorted(d for d in dirs if d not in SKIP_DIRS and not d.startswith("."))
        for name in sorted(files):
            path = os.path.join(directory, name)
            rel = os.path.relpath(path, base)
            yield path, rel


def is_python(path, name):
    if name.endswith(".py"):
        return True
    if "." in name:
        return False
    try:
        with open(path, "rb") as f:
            first = f.readline(200)
    except OSError:
        return False
    return first.startswith(b"#!") and b"python" in first


def python_imports(source, where):
    """Top-level names of every module the source imports, anywhere in it."""
    try:
        tree = ast.parse(source)
    except SyntaxError as err:
        raise ValueError("%s: cannot parse Python (%s)" % (where, err)) from None
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    names.update(m.split(".")[0] for m in IMPORT_STRING_RE.findall(source))
    return names


class Checker:
    def __init__(self, root):
        self.root = root
        self.packages = find_packages(root)
        self.by_name = {p.name: p for p in self.packages}
        self.module_owner = {m: p.name for p in self.packages for m in p.python_modules}
        self.include_owner = {d: p.name for p in self.packages for d in p.include_dirs}
        self.errors = []           # (package name or "", message)

    def error(self, package, message):
        self.errors.append((package, message))

    # --- what the code uses -------------------------------------------------------------------
    def python_dependency(self, package, module, test_dir):
        """The dependency a Python module name stands for, None for the package itself or the
        standard library; records an error for a module nobody knows."""
        if module in STDLIB or module in package.python_modules or module == "__future__":
            return None
        if module in self.module_owner:
            return self.module_owner[module]
        if module in PYTHON_LIBRARIES:
            return PYTHON_LIBRARIES[module]
        if module in ROS_PACKAGES or module.endswith("_msgs") or module.endswith("_srvs"):
            return module
        if test_dir is not None and os.path.isfile(os.path.join(test_dir, module + ".py")):
            return None  # a helper module beside the test
        return False

    def scan(self, package):
        for path, rel in package_files(self.root, package):
            name = os.path.basename(path)
            in_test = "test" in rel.split(os.sep)[:-1]  # test/..., or a part's own tests (plugin/test/...)
            where = os.path.join(package.folder, rel)
            if name == "package.xml" or name == "setup.py":
                continue
            try:
                with open(path, encoding="utf-8") as f:
                    text = f.read()
            except (UnicodeDecodeError, OSError):
                continue  # images, bags, worlds with other encodings: no code
            if is_python(path, name):
                kind = TEST if in_test else EXEC
                try:
                    modules = python_imports(text, where)
                except ValueError as err:
                    self.error(package.name, str(err))
                    continue
                for module in sorted(modules):
                    dependency = self.python_dependency(package, module, os.path.dirname(path))
                    if dependency is False:
                        self.error(package.name, "%s imports '%s', which is neither a workspace package, "
                                   "a ROS package nor a known Python library (add it to the tables in %s)"
                                   % (where, module, os.path.relpath(__file__, self.root)))
                    elif dependency:
                        package.use(dependency, kind, where)
                for tool_package in TOOL_RE.findall(text):
                    package.use(tool_package, kind, where)
            elif name.endswith((".cpp", ".h", ".hpp", ".cc")):
                kind = TEST if in_test else BUILD
                for include in INCLUDE_RE.findall(text):
                    dependency = self.include_owner.get(include) or CPP_INCLUDES.get(include)
                    if dependency is None and (include in ROS_PACKAGES or include.endswith("_msgs")):
                        dependency = include
                    if dependency and dependency != package.name:
                        package.use(dependency, kind, where)
            elif name == "CMakeLists.txt":
                for args in FIND_PACKAGE_RE.findall(text):
                    words = args.split()
                    if not words:
                        continue
                    named = words[1:] if words[0] == "catkin" else [words[0]]
                    if words[0] == "catkin":
                        named = words[words.index("COMPONENTS") + 1:] if "COMPONENTS" in words else []
                    for dependency in named:
                        if dependency.isupper() or dependency in ("pybind11", "GTest", "Python3"):
                            continue  # CMake keywords and non-ROS CMake packages
                        if dependency != package.name:
                            test_only = dependency in ("rostest", "rosunit", "gtest")
                            package.use(dependency, TEST if test_only else BUILD, where)
            elif name.endswith((".launch", ".test", ".xml")):
                kind = TEST if in_test else EXEC
                for dependency in set(FIND_RE.findall(text)) | set(PKG_ATTR_RE.findall(text)):
                    if dependency != package.name:
                        package.use(dependency, kind, where)
            elif name.endswith((".msg", ".srv", ".action")):
                for dependency in FIELD_TYPE_RE.findall(text):
                    if dependency != package.name:
                        package.use(dependency, BUILD, where)

    # --- the rules ----------------------------------------------------------------------------
    def check_declared(self, package):
        for dependency, kinds in sorted(package.uses.items()):
            tags = package.declared.get(dependency, set())
            satisfied = set().union(*(SATISFIES[t] for t in tags)) if tags else set()
            for kind in sorted(kinds):
                if kind not in satisfied:
                    needed = {BUILD: "<depend> or <build_depend>", EXEC: "<depend> or <exec_depend>",
                              TEST: "<test_depend> (or any of depend/build/exec)"}[kind]
                    self.error(package.name, "%s uses %s (%s) but %s/package.xml does not declare it as %s"
                               % (package.name, dependency, kinds[kind][0], package.folder, needed))
        for dependency in sorted(package.declared):
            if dependency in self.by_name and dependency not in package.uses:
                self.error(package.name, "%s/package.xml declares %s, but nothing in %s uses it"
                           % (package.folder, dependency, package.folder))

    def edges(self):
        """Declared edges between workspace packages."""
        return sorted((p.name, d) for p in self.packages for d in p.declared if d in self.by_name and d != p.name)

    def used_edges(self):
        """Edges between workspace packages by what the code uses, declared or not."""
        return sorted((p.name, d) for p in self.packages for d in p.uses if d in self.by_name and d != p.name)

    def check_cycles(self):
        graph = {}
        for source, target in self.edges():
            graph.setdefault(source, []).append(target)
        state = {}
        stack = []

        def visit(node):
            state[node] = "open"
            stack.append(node)
            for nxt in graph.get(node, []):
                if state.get(nxt) == "open":
                    cycle = stack[stack.index(nxt):] + [nxt]
                    self.error("", "declared dependency cycle: %s" % " -> ".join(cycle))
                elif nxt not in state:
                    visit(nxt)
            stack.pop()
            state[node] = "done"

        for node in sorted(graph):
            if node not in state:
                visit(node)

    def run(self):
        for package in self.packages:
            self.scan(package)
            self.check_declared(package)
        self.check_cycles()
        return not self.errors


def write_junit(path, checker):
    cases = [(p.name, [m for owner, m in checker.errors if owner == p.name]) for p in checker.packages]
    cases.append(("no_cycles", [m for owner, m in checker.errors if owner == ""]))
    failures = sum(1 for _, messages in cases if messages)
    lines = ['<?xml version="1.0" encoding="utf-8"?>',
             '<testsuite name="package_deps" tests="%d" failures="%d">' % (len(cases), failures)]
    for name, messages in cases:
        lines.append('  <testcase classname="package_deps" name="%s">' % escape(name))
        if messages:
            lines.append('    <failure message="%s">%s</failure>'
                         % (escape(messages[0], {'"': "&quot;"}), escape("\n".join(messages))))
        lines.append("  </testcase>")
    lines.append("</testsuite>")
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", default=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    parser.add_argument("--edges", action="store_true", help="print the declared workspace graph")
    parser.add_argument("--used-edges", action="store_true", help="print the graph by what the code uses")
    parser.add_argument("--junit", help="also write the result as JUnit XML (one case per package)")
    args = parser.parse_args(argv)
    checker = Checker(args.root)
    ok = checker.run()
    if args.edges:
        for source, target in checker.edges():
            print("%s -> %s" % (source, target))
    if args.used_edges:
        for source, target in checker.used_edges():
            print("%s -> %s (used)" % (source, target))
    for _, message in checker.errors:
        print("package deps: %s" % message)
    if args.junit:
        write_junit(args.junit, checker)
    if ok:
        print("package deps: %d packages, %d workspace edges, no undeclared use, no cycle"
              % (len(checker.packages), len(checker.edges())))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
