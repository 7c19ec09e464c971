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


def join_after(first, start_second, wait_for):
    """Starts a second bridge once ``first`` is subscribed; returns it once it is subscribed too and ``first`` has
    answered its connect-time Discover. An obstacle ``first`` publishes after that reaches the second once, by its
    Advertise: started together, the second's Discover could reach ``first`` after it holds the obstacle, and the
    answer would deliver it a second time."""
    wait_for(lambda: first.subscribed, what="the first bridge subscribed")
    second = start_second()
    wait_for(lambda: second.subscribed and first.counters().get("discovers_answered"),
             what="the second bridge subscribed, its Discover answered by the first")
    return second
