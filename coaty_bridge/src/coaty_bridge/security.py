"""The fleet's secure default (issue 27, item 9): one broker login per robot, generated on first use.

    creds = FleetCredentials.ensure(credentials_dir(), ["robot_0", "robot_1"])
    creds.password_file("robot_0")      # the bridge's ~password_file (its login: its identity id)
    lines = creds.broker_config(tmpdir)  # mosquitto lines: password file, ACL, client id = login

Layout of the credentials folder (default ``$ROS_HOME/fleet_security``, i.e. ``~/.ros/fleet_security``):

    robots/<robot>.password   one random secret per robot (mode 0600), made when first needed
    monitor.password          the secret of the read-only login ``fleet_monitor`` ($SYS/# only)

Only the plain secrets persist there; the hashed mosquitto password file and the ACL are written
into the broker's own private directory at every start, so adding a robot is just naming it.
Secrets are linked into place whole, so two launches sharing the folder agree on them.

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
        _secret_file(creds.monitor_password_file)
        return creds

    def password_file(self, robot):
        return os.path.join(self.directory, "robots", robot + ".password")

    @property
    def monitor_password_file(self):
        return os.path.join(self.directory, "monitor.password")

    def login(self, robot):
        """(username, password) of a robot: its identity id and its secret."""
        return identity_for(self.namespace, robot), read_password_file(self.password_file(robot))

    def broker_config(self, directory):
        """Writes the hashed password file and the ACL into ``directory`` (the broker's private
        folder, mode 0600) and returns the mosquitto config lines that use them."""
        if not shutil.which(MOSQUITTO_PASSWD):
            raise RuntimeError("%s not found (apt-get install mosquitto)" % MOSQUITTO_PASSWD)
        passwords = os.path.join(directory, "passwords")
        fd = os.open(passwords, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, "w") as out:
            for robot in self.robots:
                out.write("%s:%s\n" % self.login(robot))
            out.write("%s:%s\n" % (MONITOR, read_password_file(self.monitor_password_file)))
        # -U hashes the plain "user:password" lines in place (no secret on a command line)
        proc = subprocess.run([MOSQUITTO_PASSWD, "-U", passwords], stdout=subprocess.PIPE,
                              stderr=subprocess.STDOUT, text=True, timeout=60)
        if proc.returncode != 0:
            raise RuntimeError("mosquitto_passwd -U failed: %s" % proc.stdout.strip()[-300:])
        acl = os.path.join(directory, "acl.conf")
        with open(acl_file()) as shipped:
            rules = shipped.read()
        fd = os.open(acl, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, "w") as out:
            # user rules first: mosquitto applies pattern rules to every login, user rules to one
            out.write("# generated by coaty_bridge.security from config/mosquitto_acl.conf\n"
                      "user %s\ntopic read $SYS/#\n\n%s" % (MONITOR, rules))
        return ["password_file " + passwords, "acl_file " + acl,
                # the client id is the login: a peer that knows a robot's client id cannot connect
                # under it without the robot's password (issue 27, attack 5)
                "use_username_as_clientid true"]
