"""The fleet's secure default (issue 27, item 9; issue 43): one broker login per robot, generated on first use.

    creds = FleetCredentials.ensure(credentials_dir(), ["robot_0", "robot_1"])
    creds.password_file("robot_0")      # the bridge's ~password_file (its login: its identity id)
    lines = creds.broker_config(tmpdir)  # mosquitto lines: password file, ACL
    creds.add("robot_3"); creds.rotate("robot_0")   # while the fleet runs (fleet_credentials)

Layout of the credentials folder (default ``$ROS_HOME/fleet_security``, i.e. ``~/.ros/fleet_security``):

    robots/<robot>.password   one random secret per robot (mode 0600), made when first needed
    monitor.password          the secret of the read-only login ``fleet_monitor`` ($SYS/# only)
    broker.password           the secret of run_broker's own login (``fleet_broker``: it tells a robot about
                              other connections under its login, logins.py)
    master_control.password   master control's VDA 5050 login (orders, instant actions, zone sets)
    operators/<name>.password the fleet console's operator logins: they may publish obstacles under their own
                              identity (remove, confirm, add; the bridges take them with ~operators)
    viewers/<name>.password   the fleet console's read-only logins: only their Identity, last will and Discovers

Only the plain secrets persist there; the hashed mosquitto password file and the ACL are written
into the broker's own private directory at every start and whenever a secret in the folder changes
(run_broker watches it and has mosquitto reload them, no restart), so adding a robot is just naming
it. Every robot with a secret in the folder has a login. Secrets are linked into place whole, so two
launches sharing the folder agree on them.

Why under $ROS_HOME and not in the repository: it is per user (root and a normal user each get
their own, so neither meets the other's 0600 files), it works from a read-only install space,
and it is never inside a git tree, so a secret cannot be committed or copied with the sources.
"""
import ipaddress
import os
import secrets
import shutil
import subprocess
import tempfile

from coaty_bridge.identity import identity_for
from coaty_bridge.topics import check_name

#: the read-only login for broker statistics ($SYS/#), e.g. the fleet bench's byte counters
MONITOR = "fleet_monitor"
#: run_broker's own login (a robot name no robot may take): it publishes the login alerts (logins.py)
BROKER_LOGIN = "fleet_broker"
#: master control's VDA 5050 login (its areas' source name too; no robot may take it)
MASTER_CONTROL_LOGIN = "master_control"
#: the fleet console's login roles (folder name -> role): an operator may act, a viewer only reads
CONSOLE_ROLES = {"operators": "operator", "viewers": "viewer"}
#: robot names that are roles, not robots
RESERVED_NAMES = (BROKER_LOGIN, MASTER_CONTROL_LOGIN, MONITOR)
MOSQUITTO_PASSWD = "mosquitto_passwd"
ACL_FILE = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
                        "config", "mosquitto_acl.conf")


def acl_file():
    """The shipped ACL: beside the sources (devel space), else in the package's share folder."""
    if os.path.exists(ACL_FILE):
        return ACL_FILE
    import rospkg
    return os.path.join(rospkg.RosPack().get_path("coaty_bridge"), "config", "mosquitto_acl.conf")

INSECURE_WARNING = ("INSECURE (insecure:=true): the broker takes anonymous logins and has no ACL, so any "
                    "process that can reach it can publish obstacles under any robot's name, erase or "
                    "freeze the fleet's shared obstacles and take over a robot's MQTT client id; use only "
                    "on a machine you alone use")


def credentials_dir(explicit=None):
    """The credentials folder: ``explicit``, else $ROS_HOME/fleet_security (ROS_HOME defaults to ~/.ros)."""
    if explicit:
        return os.path.abspath(os.path.expanduser(explicit))
    ros_home = os.environ.get("ROS_HOME") or os.path.join(os.path.expanduser("~"), ".ros")
    return os.path.join(ros_home, "fleet_security")


def robot_names(robots):
    """A robot count (N: robot_0..robot_N-1), a list of names or a space/comma-separated string -> names."""
    if isinstance(robots, bool):
        raise ValueError("robots = %r: a count or robot names" % (robots,))
    if isinstance(robots, int) or (isinstance(robots, str) and robots.strip().isdigit()):
        count = int(robots)
        if not 1 <= count <= 10000:
            raise ValueError("robots = %r: a count must be 1..10000" % (robots,))
        return ["robot_%d" % i for i in range(count)]
    if isinstance(robots, str):
        robots = robots.replace(",", " ").split()
    if not isinstance(robots, (list, tuple)) or not robots:
        raise ValueError("robots = %r: a count or robot names" % (robots,))
    names = []
    for name in robots:
        check_name(name, "robot name")
        if name in RESERVED_NAMES:
            raise ValueError("robot name %r is reserved (%s are roles, not robots)" % (name, ", ".join(RESERVED_NAMES)))
        if name not in names:
            names.append(name)
    return names


def is_loopback(host):
    """True for localhost and loopback IP literals (127.0.0.0/8, ::1); no DNS lookup."""
    if host in ("localhost", "localhost.localdomain", "ip6-localhost"):
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def read_password_file(path):
    """The secret in ``path`` (first line, without its newline); ValueError naming the file."""
    try:
        with open(path) as handle:
            secret = handle.readline().rstrip("\r\n")
    except OSError as err:
        raise ValueError("password_file %r: %s" % (path, err.strerror or err)) from None
    if not secret:
        raise ValueError("password_file %r is empty" % (path,))
    return secret


def _secret_file(path):
    """Reads the secret in ``path``, creating it (0600) with a fresh random one first. Written to a
    temporary file and linked into place, so a concurrent launch never reads a half-written one and
    the first to link wins."""
    if os.path.exists(path):
        return read_password_file(path)
    fd, temporary = tempfile.mkstemp(dir=os.path.dirname(path), prefix=".new_")   # mode 0600
    try:
        with os.fdopen(fd, "w") as out:
            out.write(secrets.token_urlsafe(24) + "\n")
        try:
            os.link(temporary, path)
        except FileExistsError:
            pass
    finally:
        os.unlink(temporary)
    return read_password_file(path)


class FleetCredentials:
    """The per-robot secrets of one fleet (namespace) in one folder."""

    def __init__(self, directory, robots, namespace="fleet"):
        self.directory = directory
        self.robots = list(robots)
        self.namespace = namespace

    @classmethod
    def ensure(cls, directory, robots, namespace="fleet"):
        """Creates the folder (0700) and every missing secret; existing ones are kept."""
        check_name(namespace, "namespace")
        robots = robot_names(robots)
        os.makedirs(os.path.join(directory, "robots"), mode=0o700, exist_ok=True)
        os.chmod(directory, 0o700)
        os.chmod(os.path.join(directory, "robots"), 0o700)
        creds = cls(directory, robots, namespace)
        for robot in robots:
            _secret_file(creds.password_file(robot))
        for path in (creds.monitor_password_file, creds.broker_password_file, creds.master_control_password_file):
            _secret_file(path)
        return creds

    def robots_in_folder(self):
        """Every robot with a secret in the folder (the configured ones, and those added since), sorted."""
        folder = os.path.join(self.directory, "robots")
        names = set(self.robots)
        for entry in os.listdir(folder):
            name = entry[:-len(".password")]
            if entry.endswith(".password") and name not in RESERVED_NAMES:
                try:
                    check_name(name, "robot name")
                except ValueError:
                    continue
                names.add(name)
        return sorted(names)

    def add(self, robot):
        """Gives ``robot`` a login (a new secret) unless it has one; returns True when it was made."""
        robot_names([robot])
        path = self.password_file(robot)
        if os.path.exists(path):
            return False
        _secret_file(path)
        return True

    def rotate(self, robot):
        """Replaces ``robot``'s secret (its bridge reads the file again on its next connection)."""
        robot_names([robot])
        path = self.password_file(robot)
        if not os.path.exists(path):
            raise ValueError("robot %s has no login in %s (add it first)" % (robot, self.directory))
        fd, temporary = tempfile.mkstemp(dir=os.path.dirname(path), prefix=".rotate_")   # mode 0600
        with os.fdopen(fd, "w") as out:
            out.write(secrets.token_urlsafe(24) + "\n")
        os.replace(temporary, path)

    def fingerprint(self):
        """What the broker's logins are made of now: (robot, secret) pairs and the roles' secrets; run_broker
        rewrites the password file when it changes."""
        robots = self.robots_in_folder()
        return tuple((robot, read_password_file(self.password_file(robot))) for robot in robots) + tuple(
            (name, role, read_password_file(self.console_password_file(name, role)))
            for name, role in self.console_logins()) + tuple(
            read_password_file(p) for p in (self.monitor_password_file, self.broker_password_file,
                                            self.master_control_password_file))

    def password_file(self, robot):
        return os.path.join(self.directory, "robots", robot + ".password")

    def console_logins(self):
        """The fleet console's logins with a secret in the folder: sorted (name, role) pairs."""
        logins = []
        for folder, role in sorted(CONSOLE_ROLES.items()):
            path = os.path.join(self.directory, folder)
            for entry in (os.listdir(path) if os.path.isdir(path) else ()):
                name = entry[:-len(".password")]
                if entry.endswith(".password") and not entry.startswith("."):
                    try:
                        check_name(name, "console login")
                    except ValueError:
                        continue
                    logins.append((name, role))
        return sorted(logins)

    def console_password_file(self, name, role):
        folder = {r: f for f, r in CONSOLE_ROLES.items()}[role]
        return os.path.join(self.directory, folder, name + ".password")

    def add_console_login(self, name, role):
        """Gives the console login ``name`` (role "operator" or "viewer") a secret unless it has one; returns its
        password file. A name is one login: not a robot's, not a role's, not both an operator and a viewer."""
        if role not in CONSOLE_ROLES.values():
            raise ValueError("role %r: operator or viewer" % (role,))
        check_name(name, "console login")
        if name in RESERVED_NAMES or name in self.robots_in_folder():
            raise ValueError("%r is a robot's or a role's name; a console login needs its own" % (name,))
        for other, other_role in self.console_logins():
            if other == name and other_role != role:
                raise ValueError("%r is already a %s login (remove %s first)"
                                 % (name, other_role, self.console_password_file(name, other_role)))
        path = self.console_password_file(name, role)
        os.makedirs(os.path.dirname(path), mode=0o700, exist_ok=True)
        _secret_file(path)
        return path

    def console_acl(self):
        """ACL lines of the console logins (their username is their name, their sourceId their identity): an
        operator writes every Coaty event under its own identity; a viewer only what joining needs (its Identity
        advert, its last will, its Discovers), so it can never change an obstacle."""
        lines = []
        for name, role in self.console_logins():
            ident = identity_for(self.namespace, name)
            lines.append("user %s" % name)
            if role == "operator":
                lines += ["topic write coaty/3/+/+/%s" % ident, "topic write coaty/3/+/+/%s/+" % ident]
            else:
                lines += ["topic write coaty/3/+/ADV:Identity/%s" % ident, "topic write coaty/3/+/DAD/%s" % ident,
                          "topic write coaty/3/+/DSC/%s/+" % ident]
            lines.append("")
        return lines

    @property
    def monitor_password_file(self):
        return os.path.join(self.directory, "monitor.password")

    @property
    def broker_password_file(self):
        return os.path.join(self.directory, "broker.password")

    @property
    def master_control_password_file(self):
        return os.path.join(self.directory, "master_control.password")

    def broker_login(self):
        """(username, password) of run_broker's own login: the identity of the reserved name fleet_broker."""
        return identity_for(self.namespace, BROKER_LOGIN), read_password_file(self.broker_password_file)

    def login(self, robot):
        """(username, password) of a robot: its identity id and its secret."""
        return identity_for(self.namespace, robot), read_password_file(self.password_file(robot))

    def broker_config(self, directory):
        """Writes the hashed password file and the ACL into ``directory`` (the broker's private
        folder, mode 0600) and returns the mosquitto config lines that use them. The client id is not
        the login (issue 43, item 6): a second connection under a robot's login would take the robot
        off the broker; the bridge's client id carries a secret nonce instead."""
        self.write_logins(directory)
        return ["password_file " + os.path.join(directory, "passwords"),
                "acl_file " + os.path.join(directory, "acl.conf")]

    def write_logins(self, directory):
        """(Re)writes the hashed password file and the ACL in ``directory`` for every robot with a secret in
        the folder; mosquitto reads them again on SIGHUP. Returns the robots that have a login."""
        if not shutil.which(MOSQUITTO_PASSWD):
            raise RuntimeError("%s not found (apt-get install mosquitto)" % MOSQUITTO_PASSWD)
        robots = self.robots_in_folder()
        passwords = os.path.join(directory, "passwords")
        fd, staged = tempfile.mkstemp(dir=directory, prefix=".passwords_")   # mode 0600
        with os.fdopen(fd, "w") as out:
            for robot in robots:
                username, secret = self.login(robot)
                out.write("%s:%s\n" % (username, secret))
                # the robot's VDA 5050 login: its name (its serial number there), the same secret
                out.write("%s:%s\n" % (robot, secret))
            out.write("%s:%s\n" % (MONITOR, read_password_file(self.monitor_password_file)))
            out.write("%s:%s\n" % self.broker_login())
            out.write("%s:%s\n" % (MASTER_CONTROL_LOGIN, read_password_file(self.master_control_password_file)))
            for name, role in self.console_logins():   # the fleet console's logins: their name is their username
                out.write("%s:%s\n" % (name, read_password_file(self.console_password_file(name, role))))
        # -U hashes the plain "user:password" lines in place (no secret on a command line)
        proc = subprocess.run([MOSQUITTO_PASSWD, "-U", staged], stdout=subprocess.PIPE,
                              stderr=subprocess.STDOUT, text=True, timeout=60)
        if proc.returncode != 0:
            os.unlink(staged)
            raise RuntimeError("mosquitto_passwd -U failed: %s" % proc.stdout.strip()[-300:])
        os.replace(staged, passwords)   # mosquitto never reads a half-written file
        acl = os.path.join(directory, "acl.conf")
        with open(acl_file()) as shipped:
            rules = shipped.read()
        fd, staged = tempfile.mkstemp(dir=directory, prefix=".acl_")   # mode 0600
        with os.fdopen(fd, "w") as out:
            # user rules first: mosquitto applies pattern rules to every login, user rules to one
            out.write("# generated by coaty_bridge.security from config/mosquitto_acl.conf\n"
                      "user %s\ntopic read $SYS/#\n\n%s\n%s" % (MONITOR, "\n".join(self.console_acl()), rules))
        os.replace(staged, acl)
        self.robots = robots
        return robots
