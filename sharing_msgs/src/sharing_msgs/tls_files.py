"""Certificate and key files checked before a bridge uses them (issue 43, item 9), so that an operator reads
which file is wrong, what is wrong with it and what to do, instead of a traceback without a file name (an
absent file) or only "unreachable" (an expired certificate). Pure Python (ssl); no ROS, no paho. Used by the
Coaty bridge and the VDA 5050 bridge alike.

    problem = tls_problem(ca="ca.crt", cert="robot_0.crt", key="robot_0.key")   # None when all is well

A bridge with a problem does not give up: it says so (ERROR in its log and /diagnostics) and checks again
every RETRY_INTERVAL s, connecting as soon as the files are right.
"""
import os
import ssl
import time

#: s between two checks of files that were wrong
RETRY_INTERVAL = 10.0
#: what an operator does about each kind of problem
_WHAT_TO_DO = ("copy it there (the fleet's CA certificate, or this robot's certificate and key), or fix the "
               "bridge's tls_ca / tls_cert / tls_key parameter")


def _decode_certificate(path):
    """The certificate's fields (notBefore, notAfter, subject) as ssl reports them, or None when unavailable."""
    decode = getattr(getattr(ssl, "_ssl", None), "_test_decode_cert", None)   # CPython's; stable since 3.2
    if decode is None:
        return None
    return decode(path)


def _dates(path):
    fields = _decode_certificate(path)
    if not fields:
        return None, None
    return (ssl.cert_time_to_seconds(fields["notBefore"]) if "notBefore" in fields else None,
            ssl.cert_time_to_seconds(fields["notAfter"]) if "notAfter" in fields else None)


def _when(seconds):
    return time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime(seconds))


def _file_problem(name, path):
    if not os.path.exists(path):
        folder = os.path.dirname(os.path.abspath(path))
        while folder and not os.path.isdir(folder):
            folder = os.path.dirname(folder)
        if folder and not os.access(folder, os.X_OK):
            return ("%s %s cannot be reached: the folder %s is not open to this user (uid %d): give it access, or "
                    "put the file where it can read it" % (name, path, folder, os.geteuid()))
        return "%s %s does not exist: %s" % (name, path, _WHAT_TO_DO)
    if not os.path.isfile(path):
        return "%s %s is not a file: %s" % (name, path, _WHAT_TO_DO)
    try:
        with open(path, "rb") as handle:
            handle.read(1)
    except OSError as err:
        return ("%s %s cannot be read: %s (the bridge runs as uid %d; the file is mode %o, owner uid %d): give this "
                "user read access (keys: mode 0600, owned by the user that runs the robot's nodes)"
                % (name, path, err.strerror or err, os.geteuid(), os.stat(path).st_mode & 0o777, os.stat(path).st_uid))
    return None


def _certificate_problem(name, path, now):
    problem = _file_problem(name, path)
    if problem:
        return problem
    try:
        not_before, not_after = _dates(path)
    except (ssl.SSLError, ValueError, OSError) as err:
        return "%s %s is not a PEM certificate (%s): %s" % (name, path, err, _WHAT_TO_DO)
    if not_after is not None and now > not_after:
        return ("%s %s expired on %s (%.1f days ago): issue a new one with the fleet's CA and copy it there (coaty_bridge "
                "README, 'A broker on another machine: TLS'); the bridge checks again every %g s"
                % (name, path, _when(not_after), (now - not_after) / 86400.0, RETRY_INTERVAL))
    if not_before is not None and now < not_before:
        return ("%s %s is not valid before %s (this machine's clock says %s): check the clock (NTP), or the certificate"
                % (name, path, _when(not_before), _when(now)))
    return None


def tls_problem(ca="", cert="", key="", now=None):
    """What is wrong with the TLS files a bridge is told to use (one line: which file, what, what to do), or None.
    Empty names are not checked (tls_ca "" = the system's CA store)."""
    now = time.time() if now is None else now
    for name, path in (("tls_ca", ca), ("tls_cert", cert)):
        if path:
            problem = _certificate_problem(name, path, now)
            if problem:
                return problem
    if key:
        problem = _file_problem("tls_key", key)
        if problem:
            return problem
    context = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
    if ca:
        try:
            context.load_verify_locations(cafile=ca)
        except (ssl.SSLError, OSError) as err:
            return "tls_ca %s holds no usable CA certificate (%s): %s" % (ca, err, _WHAT_TO_DO)
    if cert and key:
        try:
            context.load_cert_chain(certfile=cert, keyfile=key)
        except (ssl.SSLError, OSError) as err:
            return ("tls_cert %s and tls_key %s do not go together or cannot be loaded (%s): give this robot's own "
                    "certificate and its key (unencrypted)" % (cert, key, err))
    return None
