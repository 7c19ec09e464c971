#!/usr/bin/python3
"""Builds the upstream navigation stack and Stage where the distribution lacks them.

`make setup` runs it. Where the distribution has move_base, costmap_2d, map_server,
fake_localization and stage_ros (ROS Noetic on Ubuntu 20.04) it builds nothing. Otherwise (Debian 12)
it builds the sources pinned in upstream/pins.txt, with the patches in upstream/patches/, into a
workspace outside the repository that scripts/env.sh overlays:

    $FLEET_UPSTREAM_CACHE (default ~/.cache/fleet_upstream)/<key>/   the build, keyed by pins and patches
    $FLEET_UPSTREAM_CACHE/current -> <key>                           what env.sh sources, once complete

Sources come from the archives in ../shared/upstream, or $FLEET_UPSTREAM_SRC instead (SHA-256 checked), or,
where an archive is absent, from a clone of its repository at the pinned commit. A build that failed
or stopped half way is never used: `current` moves only after every expected program is there.

Usage: build_upstream.py [--jobs N] [--force] [--debian-packages] [--status]
  --debian-packages  print the Debian packages the build needs (nothing when no build is needed)
  --status           say where the stack comes from (distribution, cache or "needs a build"); exit 0/1
"""
import argparse
import contextlib
import fcntl
import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
import tarfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO_ROOT = os.path.dirname(HERE)
PINS_FILE = os.path.join(HERE, "pins.txt")
PATCH_DIR = os.path.join(HERE, "patches")
# Part of the cache key: change it when the way of building changes (flags, layout, steps).
BUILD_TYPE = "RelWithDebInfo"  # -O2 -g, as ROS binary packages are built
RECIPE = "recipe 1: Stage (cmake, install prefix stage/), then catkin_make_isolated, testing off, " + BUILD_TYPE
# What the real stack must provide; a distribution that has all of them needs no build.
REQUIRED_PACKAGES = ("move_base", "costmap_2d", "map_server", "fake_localization", "stage_ros")
# Programs and libraries a complete build holds (relative to the keyed folder).
EXPECTED_FILES = (
    "stage/lib/libstage.so",
    "devel_isolated/setup.bash",
    "devel_isolated/costmap_2d/lib/libcostmap_2d.so",
    "devel_isolated/move_base/lib/move_base/move_base",
    "devel_isolated/map_server/lib/map_server/map_server",
    "devel_isolated/fake_localization/lib/fake_localization/fake_localization",
    "devel_isolated/stage_ros/lib/stage_ros/stageros",
    "devel_isolated/navfn/lib/libnavfn.so",
    "devel_isolated/base_local_planner/lib/libtrajectory_planner_ros.so",
)
# Debian 12 packages the build needs beyond what scripts/setup.sh installs for the project itself.
DEBIAN_BUILD_PACKAGES = (
    # Stage: FLTK (whose CMake config names /usr/bin/fluid, so fluid too), OpenGL/GLU, ltdl, images
    "libfltk1.3-dev", "fluid", "libgl-dev", "libglu1-mesa-dev", "libltdl-dev", "libpng-dev", "libjpeg-dev",
    # class_loader, pluginlib, dynamic_reconfigure
    "libpoco-dev", "libtinyxml2-dev", "libconsole-bridge-dev", "libboost-dev", "libboost-filesystem-dev",
    "libboost-system-dev", "libboost-thread-dev", "libboost-chrono-dev",
    # navigation: costmap_2d, map_server, amcl, move_base and the planners
    "ros-cmake-modules", "libeigen3-dev", "libtf2-sensor-msgs-dev", "libtf2-geometry-msgs-dev",
    "libtf2-ros-dev", "python3-tf2-ros", "liblaser-geometry-dev", "libmap-msgs-dev", "libmove-base-msgs-dev",
    "libactionlib-dev", "libvisualization-msgs-dev", "libstd-srvs-dev", "librosbag-dev", "libmessage-filters-dev",
    "libsdl1.2-dev", "libsdl-image1.2-dev", "libyaml-cpp-dev", "libbullet-dev",
    # stage_ros: ROS 1 tf
    "libtf-dev",
)


class UpstreamError(Exception):
    """A problem the user must fix; the message says what and how."""


def log(message):
    print("upstream: " + message, flush=True)


# --- the pinned list ---------------------------------------------------------------------------

class Pin:
    FIELDS = ("name", "build", "archive", "sha256", "repository", "commit")

    def __init__(self, name, build, archive, sha256, repository, commit, line):
        problems = []
        if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", name):
            problems.append("name %r is not a package folder name" % name)
        if build not in ("catkin", "cmake"):
            problems.append("build %r is neither catkin nor cmake" % build)
        if not re.fullmatch(r"[A-Za-z0-9_.-]+\.tar\.gz", archive):
            problems.append("archive %r is not a plain .tar.gz file name" % archive)
        if not re.fullmatch(r"[0-9a-f]{64}", sha256):
            problems.append("sha256 %r is not 64 hex digits" % sha256)
        if not re.fullmatch(r"https://[^\s]+", repository):
            problems.append("repository %r is not an https URL" % repository)
        if not re.fullmatch(r"[0-9a-f]{40}", commit):
            problems.append("commit %r is not 40 hex digits" % commit)
        if problems:
            raise UpstreamError("pins line %d: %s" % (line, "; ".join(problems)))
        self.name, self.build, self.archive, self.sha256 = name, build, archive, sha256
        self.repository, self.commit = repository, commit


def read_pins(path=PINS_FILE):
    try:
        with open(path, encoding="utf-8") as f:
            lines = f.read().splitlines()
    except OSError as err:
        raise UpstreamError("cannot read the pinned list %s: %s" % (path, err.strerror))
    pins = []
    for number, line in enumerate(lines, 1):
        fields = line.split("#", 1)[0].split()
        if not fields:
            continue
        if len(fields) != len(Pin.FIELDS):
            raise UpstreamError("pins line %d: %d fields, expected %d (%s)" % (
                number, len(fields), len(Pin.FIELDS), " ".join(Pin.FIELDS)))
        pins.append(Pin(*fields, line=number))
    names = [p.name for p in pins]
    if len(set(names)) != len(names) or not pins:
        raise UpstreamError("pins %s: %s" % (path, "no pins" if not pins else "a name appears twice"))
    return pins


def patches_for(name, patch_dir=PATCH_DIR):
    """The patch files of one source, in the order they apply (their file names sort)."""
    if not os.path.isdir(patch_dir):
        return []
    return sorted(os.path.join(patch_dir, f) for f in os.listdir(patch_dir)
                  if f.startswith(name + "-") and f.endswith(".patch"))


def cache_key(pins_path=PINS_FILE, patch_dir=PATCH_DIR):
    """Changes when the pins, a patch or the recipe changes; 16 hex digits name the build folder."""
    digest = hashlib.sha256(RECIPE.encode())
    with open(pins_path, "rb") as f:
        digest.update(f.read())
    for name in sorted(os.listdir(patch_dir)) if os.path.isdir(patch_dir) else []:
        with open(os.path.join(patch_dir, name), "rb") as f:
            digest.update(name.encode() + b"\0" + f.read())
    return digest.hexdigest()[:16]


# --- where things are --------------------------------------------------------------------------

def cache_root():
    explicit = os.environ.get("FLEET_UPSTREAM_CACHE")
    if explicit:
        return os.path.abspath(explicit)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "fleet_upstream")


def source_folders():
    """Where archives are looked for: $FLEET_UPSTREAM_SRC when set, else ../shared/upstream."""
    if os.environ.get("FLEET_UPSTREAM_SRC"):
        return [os.path.abspath(os.environ["FLEET_UPSTREAM_SRC"])]
    return [os.path.normpath(os.path.join(REPO_ROOT, "..", "shared", "upstream"))]


def distribution_packages(cache):
    """The REQUIRED_PACKAGES found outside our own cache and repository: {name: share folder}."""
    roots = [p for p in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if p]
    roots += [os.path.join(p, "share") for p in os.environ.get("CMAKE_PREFIX_PATH", "").split(os.pathsep) if p]
    roots += ["/opt/ros/noetic/share"]
    ours = (os.path.realpath(cache), os.path.realpath(REPO_ROOT))
    found = {}
    for root in roots:
        real = os.path.realpath(root)
        if any(real == o or real.startswith(o + os.sep) for o in ours):
            continue
        for name in REQUIRED_PACKAGES:
            if name not in found and os.path.isfile(os.path.join(root, name, "package.xml")):
                found[name] = os.path.join(root, name)
    return found


def missing_files(build_dir):
    return [f for f in EXPECTED_FILES if not os.path.exists(os.path.join(build_dir, f))]


def complete_build(cache, key):
    """The keyed build folder when it is complete and whole, else None."""
    build_dir = os.path.join(cache, key)
    if os.path.isfile(os.path.join(build_dir, "COMPLETE")) and not missing_files(build_dir):
        return build_dir
    return None


# --- sources -----------------------------------------------------------------------------------

def sha256_of(path):
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def locate_sources(pins, folders, clone_into, try_clone=True):
    """{pin name: ('archive', path) or ('clone', folder)}; every archive's checksum checked first.

    Raises UpstreamError naming every archive that is corrupt, or every source that could be
    neither found nor cloned, with the ways to provide it."""
    found, absent, corrupt = {}, [], []
    for pin in pins:
        path = next((os.path.join(d, pin.archive) for d in folders
                     if os.path.isfile(os.path.join(d, pin.archive))), None)
        if path is None:
            absent.append(pin)
            continue
        actual = sha256_of(path)
        if actual != pin.sha256:
            corrupt.append("%s: SHA-256 %s, pinned %s" % (path, actual, pin.sha256))
        else:
            found[pin.name] = ("archive", path)
    if corrupt:
        raise UpstreamError("checksum mismatch (a corrupted or different archive):\n  " + "\n  ".join(corrupt) +
                            "\nReplace the file with the pinned archive (upstream/pins.txt), or remove it so that "
                            "the pinned commit is cloned instead.")
    clone_errors = []
    for pin in absent:
        if not try_clone or clone_errors:
            clone_errors.append("%s: not tried" % pin.name)
            continue
        target = os.path.join(clone_into, pin.name)
        error = clone_pinned(pin, target)
        if error:
            clone_errors.append("%s: %s" % (pin.name, error))
        else:
            found[pin.name] = ("clone", target)
    if clone_errors:
        raise UpstreamError(
            "the upstream sources are missing: %s\n"
            "  archives looked for in: %s\n"
            "  cloning the pinned commits failed: %s\n"
            "Provide them in one of two ways:\n"
            "  1. put the archives named in upstream/pins.txt in ../shared/upstream beside the repository,\n"
            "     or in a folder you name with FLEET_UPSTREAM_SRC=/that/folder (checksums are checked);\n"
            "  2. give this machine access to github.com: the pinned commits are then cloned.\n"
            "(Or install ROS Noetic's move_base, map_server, fake_localization and stage_ros: then nothing is built.)"
            % (", ".join(p.archive for p in absent), ", ".join(folders), "; ".join(clone_errors)))
    return found


def clone_pinned(pin, target):
    """Fetches exactly the pinned commit into target; returns an error sentence or None."""
    if shutil.which("git") is None:
        return "git is not installed"
    shutil.rmtree(target, ignore_errors=True)
    os.makedirs(target)
    steps = (["git", "init", "-q"], ["git", "fetch", "-q", "--depth", "1", pin.repository, pin.commit],
             ["git", "checkout", "-q", "FETCH_HEAD"])
    for step in steps:
        try:
            proc = subprocess.run(step, cwd=target, capture_output=True, text=True, timeout=600,
                                  env=dict(os.environ, GIT_TERMINAL_PROMPT="0"))
        except subprocess.TimeoutExpired:
            return "%s timed out" % " ".join(step[:2])
        if proc.returncode != 0:
            return (proc.stderr.strip().splitlines() or ["exit %d" % proc.returncode])[-1]
    head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=target, capture_output=True, text=True).stdout.strip()
    if head != pin.commit:
        return "cloned %s, pinned %s" % (head, pin.commit)
    shutil.rmtree(os.path.join(target, ".git"), ignore_errors=True)
    return None


def unpack(pin, source, destination):
    """Puts the source tree of pin at destination/<name>."""
    kind, path = source
    target = os.path.join(destination, pin.name)
    if kind == "clone":
        shutil.copytree(path, target, symlinks=True)
        return target
    with tarfile.open(path) as archive:
        members = archive.getmembers()
        # Debian's Python 3.11.2 has no extraction filters: refuse what would land outside the folder.
        outside = [m.name for m in members if m.name.split("/", 1)[0] != pin.name or ".." in m.name.split("/")
                   or m.isdev() or (m.issym() or m.islnk()) and (m.linkname.startswith("/") or ".." in m.linkname)]
        if outside:
            raise UpstreamError("%s: %d entries outside the folder %s/ (e.g. %s); not the pinned archive" % (
                path, len(outside), pin.name, outside[0]))
        archive.extractall(destination)
    return target


def apply_patches(pin, tree, patch_dir=PATCH_DIR):
    for patch in patches_for(pin.name, patch_dir):
        with open(patch, "rb") as f:
            text = f.read()
        check = subprocess.run(["patch", "-p1", "--dry-run", "-s", "-d", tree], input=text, capture_output=True)
        if check.returncode != 0:
            raise UpstreamError("patch %s does not apply to %s (%s): %s" % (
                os.path.relpath(patch, REPO_ROOT), pin.name, pin.commit[:7],
                check.stdout.decode(errors="replace").strip() or check.stderr.decode(errors="replace").strip()))
        subprocess.run(["patch", "-p1", "-s", "-d", tree], input=text, check=True, capture_output=True)
        log("  patched %s with %s" % (pin.name, os.path.basename(patch)))


# --- the build ---------------------------------------------------------------------------------

def run_logged(cmd, logfile, cwd, env, on_line=None):
    """Runs cmd with its output appended to logfile; on_line sees each line. Raises on failure."""
    with open(logfile, "a", encoding="utf-8") as out:
        out.write("\n$ %s\n" % " ".join(cmd))
        out.flush()
        # PWD too: catkin_make_isolated takes it for the workspace and writes .catkin_workspace there
        proc = subprocess.Popen(cmd, cwd=cwd, env=dict(env, PWD=cwd), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                text=True, errors="replace")
        tail = []
        for line in proc.stdout:
            out.write(line)
            tail = (tail + [line.rstrip()])[-25:]
            if on_line:
                on_line(line)
        if proc.wait() != 0:
            raise UpstreamError("%s failed (exit %d); the last lines of %s:\n    %s" % (
                os.path.basename(cmd[0]), proc.returncode, logfile, "\n    ".join(tail)))


class PackageProgress:
    """Turns catkin_make_isolated's output into one line per package with its time."""
    START = re.compile(r"==> Processing (?:catkin|plain cmake) package: '([^']+)'")
    DONE = re.compile(r"<== Finished processing package \[(\d+) of (\d+)\]: '([^']+)'")
    ANSI = re.compile(r"\x1b\[[0-9;]*m")

    def __init__(self):
        self.started = time.monotonic()
        self.current = None

    def __call__(self, line):
        line = self.ANSI.sub("", line)
        start = self.START.search(line)
        if start:
            self.current, self.started = start.group(1), time.monotonic()
        done = self.DONE.search(line)
        if done:
            log("  [%s/%s] %-22s %5.0f s" % (done.group(1), done.group(2), done.group(3),
                                               time.monotonic() - self.started))


def build(pins, sources, build_dir, jobs):
    os.makedirs(build_dir)
    logfile = os.path.join(build_dir, "build.log")
    env = dict(os.environ, PATH="/usr/bin:" + os.environ.get("PATH", ""))
    src = os.path.join(build_dir, "src")
    cmake_src = os.path.join(build_dir, "cmake_src")
    os.makedirs(src)
    os.makedirs(cmake_src)
    for pin in pins:
        tree = unpack(pin, sources[pin.name], cmake_src if pin.build == "cmake" else src)
        apply_patches(pin, tree)
    # navigation's metapackage is not a catkin package catkin_make_isolated can build.
    meta = os.path.join(src, "navigation", "navigation")
    if os.path.isdir(meta):
        open(os.path.join(meta, "CATKIN_IGNORE"), "w").close()

    prefix = os.path.join(build_dir, "stage")
    for pin in (p for p in pins if p.build == "cmake"):
        started = time.monotonic()
        tree = os.path.join(cmake_src, pin.name)
        work = os.path.join(build_dir, "build_cmake", pin.name)
        os.makedirs(work)
        run_logged(["cmake", tree, "-DCMAKE_BUILD_TYPE=" + BUILD_TYPE, "-DCMAKE_INSTALL_PREFIX=" + prefix],
                   logfile, work, env)
        run_logged(["make", "-j%d" % jobs, "install"], logfile, work, env)
        log("  [cmake] %-22s %5.0f s" % (pin.name, time.monotonic() - started))
    env["CMAKE_PREFIX_PATH"] = os.pathsep.join(p for p in (prefix, env.get("CMAKE_PREFIX_PATH")) if p)
    run_logged(["catkin_make_isolated", "--no-color", "--source", src,
                "--build", os.path.join(build_dir, "build_isolated"), "--devel", os.path.join(build_dir, "devel_isolated"),
                "-j%d" % jobs, "--cmake-args", "-DCMAKE_BUILD_TYPE=" + BUILD_TYPE,
                "-DCATKIN_ENABLE_TESTING=OFF", "-DPYTHON_EXECUTABLE=/usr/bin/python3"],
               logfile, build_dir, env, on_line=PackageProgress())
    absent = missing_files(build_dir)
    if absent:
        raise UpstreamError("the build ended without %s (see %s)" % (", ".join(absent), logfile))


def current_key(cache):
    """The key `current` points to, or None."""
    try:
        return os.readlink(os.path.join(cache, "current"))
    except OSError:
        return None


def point_current(cache, key):
    link = os.path.join(cache, "current")
    temporary = link + ".new"
    with contextlib.suppress(FileNotFoundError):
        os.remove(temporary)
    os.symlink(key, temporary)
    os.replace(temporary, link)


def remove_other_builds(cache, keep):
    """Removes every keyed build but those in `keep`: the new one and the one it replaces, which shells and
    workspaces set up before the switch still use until they source scripts/env.sh and build again."""
    for name in os.listdir(cache):
        path = os.path.join(cache, name)
        if name not in keep and os.path.isdir(path) and not os.path.islink(path) and \
                re.fullmatch(r"[0-9a-f]{16}", name):
            shutil.rmtree(path, ignore_errors=True)


def debian_packages_missing(packages=DEBIAN_BUILD_PACKAGES):
    if shutil.which("dpkg-query") is None:
        return []  # not Debian: the build names what it misses
    missing = []
    for name in packages:
        proc = subprocess.run(["dpkg-query", "-W", "-f=${Status}", name], capture_output=True, text=True)
        if "install ok installed" not in proc.stdout:
            missing.append(name)
    return missing


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=int(os.environ.get("JOBS", "2")))
    parser.add_argument("--force", action="store_true", help="build even when a complete build is cached")
    parser.add_argument("--debian-packages", action="store_true")
    parser.add_argument("--status", action="store_true")
    args = parser.parse_args(argv)
    if args.jobs < 1:
        parser.error("--jobs must be at least 1, got %d" % args.jobs)
    cache = cache_root()
    try:
        pins = read_pins()
        key = cache_key()
        distro = distribution_packages(cache)
        needs_build = len(distro) < len(REQUIRED_PACKAGES) and (args.force or not complete_build(cache, key))
        if args.debian_packages:
            print("\n".join(DEBIAN_BUILD_PACKAGES) if needs_build else "")
            return 0
        if len(distro) == len(REQUIRED_PACKAGES):
            log("the distribution has %s: nothing to build" % ", ".join(REQUIRED_PACKAGES))
            return 0
        if not needs_build:
            point_current(cache, key)
            log("built before: %s (pins and patches unchanged; delete it or use --force to build again)"
                % os.path.join(cache, key))
            return 0
        if args.status:
            log("needs a build (%s is not complete)" % os.path.join(cache, key))
            return 1
        os.makedirs(cache, exist_ok=True)
        with open(os.path.join(cache, ".lock"), "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)  # a second make setup waits for the first, then finds it built
            if not args.force and complete_build(cache, key):
                point_current(cache, key)
                log("built meanwhile by another run: %s" % os.path.join(cache, key))
                return 0
            return build_locked(pins, cache, key, args.jobs)
    except UpstreamError as err:
        print("upstream: ERROR: %s" % err, file=sys.stderr, flush=True)
        return 1


def build_locked(pins, cache, key, jobs):
    build_dir = os.path.join(cache, key)
    if os.path.exists(build_dir):
        log("removing an incomplete build in %s" % build_dir)
        shutil.rmtree(build_dir)
    started = time.monotonic()
    log("locating the pinned sources")
    staging = os.path.join(cache, key + ".clones")
    shutil.rmtree(staging, ignore_errors=True)
    try:
        sources = locate_sources(pins, source_folders(), staging)
        missing = debian_packages_missing()
        if missing:
            raise UpstreamError("Debian packages the build needs are not installed: %s\n"
                                "Run 'make setup' as root (it installs them) or: apt-get install %s"
                                % (" ".join(missing), " ".join(missing)))
        log("building %d upstream sources into %s with -j%d (about 5-9 minutes on 2 cores; log: %s)" % (
            len(pins), build_dir, jobs, os.path.join(build_dir, "build.log")))
        build(pins, sources, build_dir, jobs)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    minutes = (time.monotonic() - started) / 60.0
    with open(os.path.join(build_dir, "COMPLETE"), "w") as f:
        json.dump({"key": key, "built": time.strftime("%Y-%m-%d %H:%M:%S"), "minutes": round(minutes, 1),
                   "pins": {p.name: p.commit for p in pins}}, f, indent=1)
    previous = current_key(cache)
    point_current(cache, key)
    remove_other_builds(cache, {key, previous})
    log("done in %.1f min: %s (scripts/env.sh overlays it)" % (minutes, build_dir))
    return 0


if __name__ == "__main__":
    sys.exit(main())
