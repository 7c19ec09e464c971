"""Driving the console page in Debian's headless Chromium (python3-selenium, chromium-driver), for the tests and
the demo's screenshot. The page's own state is read through ``window.fleetConsole``."""
import os
import shutil
import time

CHROMIUM = ("/usr/bin/chromium", "/usr/bin/chromium-browser")
DRIVER = ("/usr/bin/chromedriver",)


def missing():
    """What is not installed (scripts/setup.sh installs it), or ""."""
    lacks = []
    if not any(os.path.exists(p) for p in CHROMIUM):
        lacks.append("chromium")
    if not any(os.path.exists(p) for p in DRIVER) and not shutil.which("chromedriver"):
        lacks.append("chromium-driver")
    try:
        import selenium  # noqa: F401
    except ImportError:
        lacks.append("python3-selenium")
    return ", ".join(lacks)


class ConsolePage:
    """One headless Chromium on the console's URL."""

    def __init__(self, url, width=1500, height=1000):
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
        options = webdriver.ChromeOptions()
        options.binary_location = next(p for p in CHROMIUM if os.path.exists(p))
        for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                    "--window-size=%d,%d" % (width, height), "--no-first-run", "--disable-extensions"):
            options.add_argument(arg)
        driver = next((p for p in DRIVER if os.path.exists(p)), None) or shutil.which("chromedriver")
        self.driver = webdriver.Chrome(service=Service(driver), options=options)
        self.driver.set_page_load_timeout(30)
        self.driver.get(url)
        self.wait(lambda: self.js("return !!(window.fleetConsole && window.fleetConsole.config)"), "the page's config")

    def js(self, script, *args):
        return self.driver.execute_script(script, *args)

    def wait(self, predicate, what, timeout=30.0, step=0.05):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            value = predicate()
            if value:
                return value
            time.sleep(step)
        raise AssertionError("the console page: timed out waiting for %s; its status: %r" % (what, self.status()))

    def status(self):
        try:
            return self.js("return document.getElementById('status').textContent")
        except Exception as err:   # the page itself is gone
            return "(no page: %s)" % err

    def login(self, name, password):
        """Types the login into the form and submits it, as an operator would."""
        from selenium.webdriver.common.by import By
        for field, value in (("name", name), ("password", password)):
            box = self.driver.find_element(By.ID, field)
            box.clear()
            box.send_keys(value)
        self.driver.find_element(By.ID, "login-btn").click()

    def listed(self):
        """uuid -> first shown (ms, the browser's wall clock) of every obstacle the page lists."""
        return self.js("const C = window.fleetConsole; const out = {};"
                       "for (const e of C.model.listed()) out[e.uuid] = C.shownAt[e.uuid] || null; return out;")

    def table_uuids(self):
        return self.js("return Array.from(document.querySelectorAll('#obstacles-body tr')).map(r => r.dataset.uuid)")

    def screenshot(self, path):
        os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
        self.driver.save_screenshot(path)
        return path

    def close(self):
        try:
            self.driver.quit()
        except Exception:
            pass
