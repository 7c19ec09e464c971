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


def make_cert(ca, directory, common_name, ip=None, dns=None, days=825, valid_from=None, valid_until=None):
    """A certificate signed by `ca` with CN `common_name` (a robot: its identity id; the
    broker: its host name), with subjectAltName IP/DNS for a server. Files <CN>.key/.crt.
    ``valid_from``/``valid_until`` (openssl times, e.g. "20200101000000Z") instead of ``days``: a certificate
    already expired, or not valid yet (the tests of the bridges' errors for them)."""
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
    if valid_from or valid_until:
        # openssl x509 signs only from now on; openssl ca takes any validity, from a throwaway database
        db = os.path.join(directory, "ca_db")
        os.makedirs(db, exist_ok=True)
        open(os.path.join(db, "index.txt"), "a").close()
        if not os.path.exists(os.path.join(db, "serial")):
            with open(os.path.join(db, "serial"), "w") as out:
                out.write("01\n")
        conf = os.path.join(db, "ca.cnf")
        with open(conf, "w") as out:
            out.write("[ca]\ndefault_ca = fleet\n[fleet]\ndatabase = %s/index.txt\nserial = %s/serial\n"
                      "new_certs_dir = %s\ndefault_md = sha256\npolicy = any\nunique_subject = no\n"
                      "[any]\ncommonName = supplied\n" % (db, db, db))
        _run(["ca", "-batch", "-config", conf, "-cert", ca.cert, "-keyfile", ca.key, "-in", csr, "-out", cert,
              "-startdate", valid_from or "20200101000000Z", "-enddate", valid_until or "20991231000000Z",
              "-extfile", ext], directory)
    else:
        _run(["x509", "-req", "-in", csr, "-CA", ca.cert, "-CAkey", ca.key, "-CAcreateserial", "-out", cert,
              "-days", str(days), "-extfile", ext], directory)
    os.chmod(key, 0o600)
    return Credentials(cert, key)
