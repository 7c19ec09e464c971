"""How the tests wait for a condition: they poll it until a bound, and never sleep a fixed time (a loaded
machine makes things slower, not wrong)."""
import time


def wait_until(predicate, what, timeout, interval=0.02):
    """Returns the first true value of ``predicate()``; AssertionError naming ``what`` after ``timeout`` s."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = predicate()
        if value:
            return value
        time.sleep(interval)
    raise AssertionError("timed out after %.1f s waiting for %s" % (timeout, what))
