"""The live page of `bitrock watch --serve` in a real browser: headless Chromium (Debian's
chromium and chromium-driver) driven through WebDriver, on a simulated well that changes
formation. What the page shows is checked against the watch's own JSON lines."""

import base64
import io
import json
import os
import shutil
import signal
import statistics
import subprocess
import threading
import time
import urllib.request
from pathlib import Path

import pytest
from PIL import Image
from pypdf import PdfReader
from selenium import webdriver
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.by import By
from selenium.webdriver.support.ui import WebDriverWait

BIN = os.path.abspath(os.environ.get("BITROCK_BIN", Path(__file__).resolve().parents[2] / "target/release/bitrock"))
# Where the page's screenshots are kept, to be looked at: every run leaves them there.
ARTEFACTS = Path(os.environ.get("BITROCK_ARTEFACTS", Path(__file__).resolve().parents[2] / "target/test-artefacts"))

# m2 at the paper's estimate for 90 s, then m3 for 90 s, at 20 Hz, where the bit sticks and slips.
WELL = """sample_hz = 20
noise_torque_knm = 0.3
noise_speed_rpm = 0.5
seed = 5

[[segment]]
name = "claystone"
duration_s = 90
law = "m2"
omega_rpm = 60

[[segment]]
name = "sandstone"
duration_s = 90
law = "m3"
omega_rpm = 60
"""


def browser():
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    driver = shutil.which("chromedriver")
    assert chromium and driver, "the browser test needs chromium and chromedriver (scripts/test.sh installs them)"
    options = webdriver.ChromeOptions()
    options.binary_location = chromium
    for arg in ["--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--window-size=1400,2000"]:
        options.add_argument(arg)
    return webdriver.Chrome(service=Service(executable_path=driver), options=options)


class Process:
    """A bitrock command whose standard output lines are timed as they come and whose
    standard error gives the page's address."""

    def __init__(self, args, cwd):
        env = dict(os.environ, NODEVICE_SELECT="1")
        self.proc = subprocess.Popen(
            [BIN, *args], cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env
        )
        self.lines = []  # (ms since the epoch, parsed JSON line)
        self.stderr = []
        self.address = threading.Event()
        self.url = None
        threading.Thread(target=self._read_stdout, daemon=True).start()
        threading.Thread(target=self._read_stderr, daemon=True).start()

    def _read_stdout(self):
        for line in self.proc.stdout:
            self.lines.append((time.time() * 1000.0, json.loads(line)))

    def _read_stderr(self):
        for line in self.proc.stderr:
            self.stderr.append(line)
            if "the live page is at http://" in line:
                self.url = line.split("at ", 1)[1].split()[0]
                self.address.set()

    def wait_for_address(self):
        assert self.address.wait(60), "".join(self.stderr)
        return self.url


@pytest.fixture(scope="module")
def well(tmp_path_factory):
    d = tmp_path_factory.mktemp("well")
    (d / "well.toml").write_text(WELL)
    subprocess.run([BIN, "simulate", "--well", "well.toml", "-o", "well.csv"], cwd=d, check=True, capture_output=True)
    # The bit's depth, as a rig's log gives it: drilling ahead at 36 m/h from 1500 m.
    lines = (d / "well.csv").read_text().splitlines()
    depths = [f"{1500.0 + float(line.split(',')[0]) * 0.01:.3f}" for line in lines[1:]]
    (d / "well.csv").write_text(
        "\n".join([lines[0] + ",DBTM [m]"] + [f"{line},{depth}" for line, depth in zip(lines[1:], depths)]) + "\n"
    )
    return d


def shown(driver, condition):
    """Whether the page holds what `condition` (JavaScript on its state `s`) asks and has drawn it: what arrives
    is drawn on the next animation frame, not at once."""
    return driver.execute_script(f"const s = window.bitrockPage; return ({condition}) && !s.scheduled")


def log_rows(driver):
    """The page's table of windows: window → (probabilities, change, advice) as shown."""
    rows = {}
    for tr in driver.find_elements(By.CSS_SELECTOR, "#log tbody tr"):
        cells = [td.text for td in tr.find_elements(By.TAG_NAME, "td")]
        rows[int(cells[0])] = (cells[3], cells[4], cells[5])
    return rows


def inked(driver):
    """Per canvas of the page, the share of its pixels that are neither blank nor white, read
    from the canvas itself."""
    return driver.execute_script(
        """
        const out = {};
        for (const c of document.querySelectorAll('canvas')) {
          const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
          let inked = 0;
          for (let i = 0; i < d.length; i += 4) {
            if (d[i + 3] > 0 && !(d[i] > 245 && d[i + 1] > 245 && d[i + 2] > 245)) inked++;
          }
          out[c.id] = inked / (c.width * c.height);
        }
        return out;
        """
    )


def shown_probabilities(update):
    if update["uninformative"]:
        return "uninformative"
    return ", ".join(f"{l['law']} {l['probability']:.3f}" for l in update["laws"])


def test_the_page_shows_what_the_watch_says_live(well, capsys):
    out = well / "watch-dir"
    watch = Process(
        [
            "watch", "well.csv", "--json", "--laws", "m2,m3", "--backend", "cpu",
            "--window-s", "20", "--step-s", "10", "--replay-speed", "8",
            "--serve", "127.0.0.1:0", "--out", str(out),
        ],
        cwd=well,
    )
    url = watch.wait_for_address()
    assert url.startswith("http://127.0.0.1:")
    driver = browser()
    late = None
    try:
        driver.get(url)
        # A viewer that comes late gets the history first: a second page opened after some
        # windows ends with the same windows.
        WebDriverWait(driver, 120).until(lambda d: d.execute_script("return window.bitrockPage.updates.length") >= 4)
        first_tab = driver.current_window_handle
        driver.switch_to.new_window("tab")
        late = driver.current_window_handle
        driver.get(url)
        for handle in (first_tab, late):
            driver.switch_to.window(handle)
            WebDriverWait(driver, 300).until(lambda d: shown(d, "s.ended !== null"))
        assert watch.proc.wait(60) == 0, "".join(watch.stderr)
        lines = [u for _, u in watch.lines]
        assert len(lines) == 17

        late_updates = driver.execute_script("return window.bitrockPage.updates")
        driver.switch_to.window(first_tab)
        updates = driver.execute_script("return window.bitrockPage.updates")
        timings = driver.execute_script("return window.bitrockPage.timings")
        assert updates == lines, "the page holds the watch's JSON lines, number for number"
        assert late_updates == lines, "the late viewer's history and live windows"
        assert len(timings) >= 5, "windows arrived live, not only in the history"

        # What the page shows: every window in the table, as the JSON line says it.
        rows = log_rows(driver)
        assert sorted(rows) == [u["window"] for u in lines]
        for u in lines:
            probabilities, change, advice = rows[u["window"]]
            assert probabilities == shown_probabilities(u)
            assert change == ("change" if u["change"] else "")
            assert advice == (u["advice"]["words"] if u["advice"] else "")
        # The formation changes once, from m2 to m3, and the page marks that window.
        changes = [u["window"] for u in lines if u["change"]]
        assert len(changes) == 1, changes
        assert lines[changes[0]]["start_s"] <= 90.0 <= lines[changes[0]]["end_s"]
        changed_rows = [int(tr.find_element(By.TAG_NAME, "td").text) for tr in driver.find_elements(By.CSS_SELECTOR, "#log tr.changed")]
        assert changed_rows == changes
        # The header: the last window.
        last = lines[-1]
        assert driver.find_element(By.ID, "window").text == str(last["window"])
        assert driver.find_element(By.ID, "most-probable").text == last["most_probable"] == "m3"
        for l in last["laws"]:
            cell = driver.find_element(By.CSS_SELECTOR, f"#probabilities tr[data-law='{l['law']}'] td[data-key='probability']")
            assert cell.text == f"{l['probability']:.3f}"
        assert driver.find_element(By.ID, "advice").text == last["advice"]["words"]
        assert "ended" in driver.find_element(By.ID, "status").text

        # The map is drawn: its canvas's plot area is coloured, not blank.
        png = driver.get_screenshot_as_png()
        shot = Image.open(io.BytesIO(png)).convert("RGB")
        canvas = driver.find_element(By.ID, "map")
        ratio = driver.execute_script("return window.devicePixelRatio")
        r = canvas.rect
        box = tuple(int(v * ratio) for v in (r["x"] + 60, r["y"] + 12, r["x"] + r["width"] - 14, r["y"] + r["height"] - 40))
        area = shot.crop(box)
        pixels = list(area.get_flattened_data() if hasattr(area, "get_flattened_data") else area.getdata())
        coloured = sum(1 for p in pixels if p != (255, 255, 255))
        assert coloured > 0.9 * len(pixels), f"{coloured} of {len(pixels)} map pixels drawn"
        ARTEFACTS.mkdir(parents=True, exist_ok=True)
        shot.save(ARTEFACTS / "live-page.png")

        # Every panel is drawn: each canvas holds coloured pixels, whatever is on screen.
        drawn = inked(driver)
        assert sorted(drawn) == ["along", "cloud", "map", "params", "strip"], drawn
        # Measured on this well: along 0.65 (stacked probabilities), cloud 0.07 (points and band),
        # map 0.73 (cells), params 0.25 (bands), strip 0.04 (two traces): each must keep about
        # half of that.
        least = {"along": 0.3, "cloud": 0.04, "map": 0.5, "params": 0.1, "strip": 0.02}
        for panel, share in drawn.items():
            assert share > least[panel], f"{panel}: {share:.4f} of its pixels drawn"
        # The strip's caption: what the last window's bit shows, as its view says.
        view = driver.execute_script("return window.bitrockPage.view")
        caption = driver.find_element(By.ID, "strip-caption").text
        assert f"the bit stuck {view['bit']['stuck_share'] * 100:.0f} % of the time" in caption, caption
        assert f"severity {view['bit']['severity']:.2f}" in caption, caption
        # The window's depth, from the record's DBTM column: 1500 m plus 0.01 m a second.
        top, bottom = view["depth_m"]
        assert abs(top - (1500.0 + 0.01 * lines[-1]["start_s"])) < 0.02 and bottom > top, view["depth_m"]
        assert f"bit depth {top:.1f}–{bottom:.1f} m" in caption, caption
        # Each law's name with whose law it is, from the meta.
        titles = {l["name"]: l["title"] for l in driver.execute_script("return window.bitrockPage.meta.laws")}
        assert titles == {"m2": "Navarro-Lopez & Suarez", "m3": "The paper's new law"}
        for law, title in titles.items():
            cell = driver.find_element(By.CSS_SELECTOR, f"#probabilities tr[data-law='{law}'] td[data-key='law']")
            assert cell.text == f"{law} {title}"
        assert driver.find_element(By.ID, "most-probable-title").text == titles["m3"]
        # Every legend lies within its canvas, wrapped onto more rows where the page is narrow.
        for width in (1400, 640):
            driver.set_window_size(width, 2000)
            WebDriverWait(driver, 10).until(
                lambda d: d.execute_script("return document.getElementById('map').clientWidth") < width
            )
            driver.execute_script("window.dispatchEvent(new Event('resize'))")
            time.sleep(0.5)
            legends = driver.execute_script("return window.bitrockPage.legends")
            for panel in ("along", "cloud", "map"):
                assert legends[panel]["rows"] >= 1 and legends[panel]["right"] <= legends[panel]["width"], (width, legends)
            driver.save_screenshot(str(ARTEFACTS / f"live-page-{width}px.png"))
        # Four laws' names in a narrow plot wrap onto rows that each fit.
        rows = driver.execute_script(
            "const g = document.createElement('canvas').getContext('2d');"
            "return legend(g, 'probe', 58, 300, arguments[0].map((t) => [t, '#000']));",
            ["m1 Tucker & Wang", "m2 Navarro-Lopez & Suarez", "m3 The paper's new law", "m4 Ritto & Aguiar's cubic"],
        )
        probe = driver.execute_script("return window.bitrockPage.legends.probe")
        assert rows >= 2 and probe["right"] <= 300, (rows, probe)
        driver.set_window_size(1400, 2000)

        # The print view of the current state: its pages hold the page's text.
        pdf = driver.execute_cdp_cmd("Page.printToPDF", {"printBackground": True})
        reader = PdfReader(io.BytesIO(base64.b64decode(pdf["data"])))
        # Compared without white space and case: a printed line wraps where the screen's does
        # not, and the labels print in capitals.
        printed = "".join("".join((page.extract_text() or "").split()) for page in reader.pages).lower()
        for text in (last["advice"]["words"], "bitrock watch", f"window {last['window']}", "most probable law m3"):
            assert "".join(text.split()).lower() in printed, f"{text!r} not in the printed pages: {printed[:3000]}"

        # Self-contained: everything the page loaded came from its server, and it is light.
        resources = driver.execute_script("return performance.getEntriesByType('resource').map(e => e.name)")
        assert resources and all(name.startswith(url) for name in resources), resources
        # (The server has stopped with the watch; the page's weight is read from the binary's
        # second server below.)

        by_window = {u["window"]: t for t, u in watch.lines}
        delays = [t["shown_ms"] - by_window[t["window"]] for t in timings]
        with capsys.disabled():
            print(
                f"\nlive page: {len(delays)} windows shown {statistics.median(delays):.0f} ms after their JSON line "
                f"(median; max {max(delays):.0f} ms, min {min(delays):.0f} ms)"
            )
    finally:
        driver.quit()
        if watch.proc.poll() is None:
            watch.proc.kill()

    # The stored watch, served read-only by `bitrock serve`.
    serve = Process(["serve", str(out), "--address", "127.0.0.1:0"], cwd=well)
    url = serve.wait_for_address()
    weight = sum(len(urllib.request.urlopen(url + path).read()) for path in ["", "page.js", "page.css"])
    assert weight <= 500_000, weight
    with urllib.request.urlopen(url + "state.json") as r:
        state = json.load(r)
    assert state["updates"] == lines
    assert state["view"]["window"] == lines[-1]["window"]
    assert state["meta"]["laws"][0]["params"][0] == {"name": "tsb", "unit": "kN·m"}
    driver = browser()
    try:
        driver.get(url)
        WebDriverWait(driver, 60).until(lambda d: shown(d, f"s.updates.length === {len(lines)}"))
        assert driver.find_element(By.ID, "most-probable").text == "m3"
    finally:
        driver.quit()
    serve.proc.send_signal(signal.SIGINT)
    assert serve.proc.wait(30) == 0, "".join(serve.stderr)
    print(f"page weight: {weight} bytes")


def test_a_watch_of_surface_channels_draws_the_bit_its_strings_imply(tmp_path):
    """A record of surface channels alone (m2 at 60 rpm, the bit stuck about half the time),
    watched and served: the strip draws the surface channels and the bit speed its strings
    imply, the torque-speed cloud says why it has nothing to draw."""
    subprocess.run(
        [BIN, "simulate", "--law", "m2", "--omega-rpm", "60", "--duration-s", "180", "--settle-s", "60",
         "--sample-hz", "1", "--channels", "surface", "--noise-torque-knm", "0.2", "--seed", "3", "-o", "rig.csv"],
        cwd=tmp_path, check=True, capture_output=True,
    )
    done = subprocess.run(
        [BIN, "watch", "rig.csv", "--laws", "m2", "--window-s", "120", "--step-s", "60", "--backend", "cpu",
         "--json", "--out", "w"],
        cwd=tmp_path, capture_output=True, text=True, env=dict(os.environ, NODEVICE_SELECT="1"),
    )
    assert done.returncode == 0, done.stderr
    lines = [json.loads(line) for line in done.stdout.splitlines()]
    assert len(lines) == 2 and all(u["uninformative"] is None for u in lines), lines
    serve = Process(["serve", "w", "--address", "127.0.0.1:0"], cwd=tmp_path)
    url = serve.wait_for_address()
    driver = browser()
    try:
        driver.get(url)
        WebDriverWait(driver, 60).until(lambda d: shown(d, "s.updates.length === 2"))
        view = driver.execute_script("return window.bitrockPage.view")
        assert view["speed_rpm"] == [] and len(view["surface"]["bit_rpm"]) == 120
        drawn = inked(driver)
        driver.save_screenshot(str(ARTEFACTS / "surface-page.png"))
        # The strip's band, traces and stuck band ink a good share of it (0.26 on this record);
        # the cloud only its frame and the words that say why (0.027).
        assert drawn["strip"] > 0.13 and 0.01 < drawn["cloud"] < 0.04, drawn
        caption = driver.find_element(By.ID, "strip-caption").text
        assert "the bit speed its simulated strings imply" in caption, caption
        assert f"stuck {view['bit']['stuck_share'] * 100:.0f} % of the time" in caption, caption
        assert drawn["map"] > 0.5 and drawn["params"] > 0.1, drawn
    finally:
        driver.quit()
        serve.proc.send_signal(signal.SIGINT)
    assert serve.proc.wait(30) == 0, "".join(serve.stderr)
