"""A small PKI for a fleet over mqtts:// (issue 15, item 3), made with the openssl CLI.

    ca = make_ca(directory)                              # ca.key, ca.crt
    make_cert(ca, directory, "broker", ip="127.0.0.1")   # server cert (subjectAltName IP)
    make_cert(ca, directory, identity_for(ns, "robot_0"))  # client cert, CN = identity id

The broker runs with `require_certificate true` and `use_identity_as_username true`, so a
robot's login is the CN of its certificate, which the ACL (config/mosquitto_acl.conf) ties to
its Coaty sourceId. Used by the tests and the deployment recipe in README.md; keys are
unencrypted files (mode 0600), as a robot must start unattended.
"""
import os
import subprocess
from dataclasses import dataclass

OPENSSL = "openssl"


@dataclass(frozen=True)
class Credentials:
    cert: str   # PEM certificate path
    key: str    # PEM private key path


def _run(args, cwd):
    proc = subprocess.run([OPENSSL] + args, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                          text=True, timeout=60)
    if proc.returncode != 0:
        raise RuntimeError("openssl %s failed: %s" % (" ".join(args[:2]), proc.stderr.strip()[-400:]))


def make_ca(directory, name="fleet-ca", days=3650):
    """A self-signed CA in `directory` (ca.key, ca.crt)."""
    directory = os.path.abspath(directory)   # openssl runs in `directory`: relative paths would point below it
    os.makedirs(directory, exist_ok=True)
    key, cert = os.path.join(directory, "ca.key"), os.path.join(directory, "ca.crt")
    _run(["req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout", key, "-out", cert, "-days", str(days),
          "-subj", "/CN=%s" % name, "-addext", "basicConstraints=critical,CA:TRUE",
          "-addext", "keyUsage=critical,keyCertSign,cRLSign"], directory)
    os.chmod(key, 0o600)
    return Credentials(cert, key)


def make_cert(ca, directory, common_name, ip=None, dns=None, days=825):
    """A certificate signed by `ca` with CN `common_name` (a robot: its identity id; the
    broker: its host name), with subjectAltName IP/DNS for a server. Files <CN>.key/.crt."""
    directory = os.path.abspath(directory)
    ca = Credentials(os.path.abspath(ca.cert), os.path.abspath(ca.key))
    os.makedirs(directory, exist_ok=True)
    base = os.path.join(directory, common_name.replace("/", "_"))
    key, csr, cert, ext = base + ".key", base + ".csr", base + ".crt", base + ".ext"
    _run(["req", "-newkey", "rsa:2048", "-nodes", "-keyout", key, "-out", csr, "-subj", "/CN=%s" % common_name],
         directory)
    with open(ext, "w") as out:
        names = (["IP:%s" % ip] if ip else []) + (["DNS:%s" % dns] if dns else [])
        out.write("basicConstraints=CA:FALSE\n")
        if names:
            out.write("subjectAltName=%s\nextendedKeyUsage=serverAuth\n" % ",".join(names))
        else:
            out.write("extendedKeyUsage=clientAuth\n")
    _run(["x509", "-req", "-in", csr, "-CA", ca.cert, "-CAkey", ca.key, "-CAcreateserial", "-out", cert,
          "-days", str(days), "-extfile", ext], directory)
    os.chmod(key, 0o600)
    return Credentials(cert, key)
