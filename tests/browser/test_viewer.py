#!/usr/bin/python3
"""The viewer in a real browser (issue 12), end to end.

Starts `fovead serve` on the mock living room and `fovea-operator --view`, loads
the page in Debian's chromium (headless, WebGL2 on SwiftShader, driven through
chromedriver by python3-selenium), and checks from the page's own state and from
screenshots that:
  - the room is drawn (a large share of non-background pixels) and the fovea is
    denser than the periphery (points per square degree, region by region);
  - a cursor move steers the robot: the gaze the robot reports in its status
    turns to the cursor's ray, and the fovea (region 0's pixels in region
    colours) moves to the cursor in the next screenshots;
  - a second tab and a tab sending garbage are served and counted without
    disturbing the stream.
Then it measures the loop's latency from a cursor move to the moved fovea drawn
in the page (the page's own clock), over --moves moves, and the page's frame
rate, and prints them (and writes them to --report as JSON).

Exit 77 (CTest's skip) when chromium, chromedriver or selenium is missing.
--screenshots DIR also writes the README's two screenshots there.
"""

import argparse
import json
import math
import os
import re
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time

SKIP = 77
BACKGROUND = (0x0B, 0x0D, 0x10)
REGION0 = (255, 48, 48)  # the page's false colour of region 0 (red)


def fail(message):
    print(f"test_viewer: FAILED: {message}", flush=True)
    sys.exit(1)


def time_scale():
    try:
        return max(1.0, float(os.environ.get("FOVEA_TEST_TIME_SCALE", "1")))
    except ValueError:
        return 1.0


def wait_for(predicate, timeout_s, what):
    deadline = time.monotonic() + timeout_s * time_scale()
    last = None
    while time.monotonic() < deadline:
        last = predicate()
        if last:
            return last
        time.sleep(0.1)
    fail(f"timed out after {timeout_s * time_scale():.0f} s waiting for {what}")


def read_line_matching(path, pattern, process, timeout_s, what):
    regex = re.compile(pattern)

    def found():
        with open(path, encoding="utf-8", errors="replace") as f:
            for line in f:
                m = regex.search(line)
                if m:
                    return m.group(1)
        if process.poll() is not None:
            with open(path, encoding="utf-8", errors="replace") as f:
                fail(f"{what}: the process exited ({process.returncode}) before saying it:\n{f.read()}")
        return None

    return wait_for(found, timeout_s, what)


def angle_deg(a, b):
    dot = sum(x * y for x, y in zip(a, b))
    na = math.sqrt(sum(x * x for x in a))
    nb = math.sqrt(sum(x * x for x in b))
    return math.degrees(math.acos(max(-1.0, min(1.0, dot / (na * nb)))))


def quantile(values, q):
    s = sorted(values)
    return s[min(len(s) - 1, max(0, math.ceil(q * len(s)) - 1))]


class Screenshot:
    """A screenshot's pixels (PIL), with the counts the checks need."""

    def __init__(self, driver, path=None):
        from PIL import Image
        import io

        png = driver.get_screenshot_as_png()
        if path:
            with open(path, "wb") as f:
                f.write(png)
        self.image = Image.open(io.BytesIO(png)).convert("RGB")
        self.width, self.height = self.image.size
        self.pixels = self.image.load()

    def share_not_background(self):
        # Every 4th pixel each way is plenty for a share.
        drawn = total = 0
        for y in range(0, self.height, 4):
            for x in range(0, self.width, 4):
                p = self.pixels[x, y]
                total += 1
                drawn += max(abs(p[i] - BACKGROUND[i]) for i in range(3)) > 12
        return drawn / total

    def centroid_of(self, colour, tolerance=40):
        sx = sy = n = 0
        for y in range(0, self.height, 2):
            for x in range(0, self.width, 2):
                p = self.pixels[x, y]
                if all(abs(p[i] - colour[i]) <= tolerance for i in range(3)):
                    sx += x
                    sy += y
                    n += 1
        return (sx / n, sy / n, n) if n else None


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--build", required=True, help="the build tree (firmware/fovead, tools/fovea-operator)")
    parser.add_argument("--moves", type=int, default=12, help="cursor moves timed for the latency figure")
    parser.add_argument("--screenshots", help="write the README's screenshots into this directory")
    parser.add_argument("--report", help="write the measured figures here as JSON")
    parser.add_argument("--size", default="1024,640", help="browser window, WIDTH,HEIGHT")
    args = parser.parse_args()

    chromium = shutil.which("chromium") or "/usr/bin/chromium"
    chromedriver = shutil.which("chromedriver") or "/usr/bin/chromedriver"
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
        from selenium.webdriver.common.action_chains import ActionChains
        from selenium.webdriver.common.by import By
        import PIL  # noqa: F401 (the screenshots)
    except ImportError as e:
        print(f"test_viewer: skipped: {e} (toolchain/setup-host --browser installs python3-selenium and python3-pil)")
        return SKIP
    for path in (chromium, chromedriver):
        if not os.access(path, os.X_OK):
            print(f"test_viewer: skipped: no {path} (toolchain/setup-host --browser installs chromium and chromium-driver)")
            return SKIP

    fovead = os.path.join(args.build, "firmware", "fovead")
    operator = os.path.join(args.build, "tools", "fovea-operator")
    for path in (fovead, operator):
        if not os.access(path, os.X_OK):
            fail(f"no {path}: build it first")

    work = tempfile.mkdtemp(prefix="fovea-viewer-test-")
    processes = []
    driver = None
    figures = {}
    try:
        key = os.path.join(work, "viewer.key")
        subprocess.run([fovead, "keygen", key], check=True, stdout=subprocess.DEVNULL)
        robot_log = os.path.join(work, "robot.log")
        robot = subprocess.Popen(
            [fovead, "serve", "--board", "host-mock", "--listen", "127.0.0.1:0", "--key-file", key,
             "--set", "runtime.status_interval_ms=1000"],
            stdout=open(robot_log, "w"), stderr=subprocess.STDOUT)
        processes.append(robot)
        address = read_line_matching(robot_log, r"^streaming: listening on (\S+)", robot, 30, "the robot's address")

        operator_log = os.path.join(work, "operator.log")
        summary = os.path.join(work, "operator.json")
        op = subprocess.Popen(
            [operator, "--connect", address, "--key-file", key, "--view", "127.0.0.1:0", "--quiet",
             "--name", "viewer-test", "--summary", summary],
            stdout=open(operator_log, "w"), stderr=subprocess.STDOUT)
        processes.append(op)
        url = read_line_matching(operator_log, r"^viewer: open (\S+)", op, 30, "the viewer's URL")

        options = webdriver.ChromeOptions()
        options.binary_location = chromium
        for a in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--use-angle=swiftshader",
                  "--enable-unsafe-swiftshader", "--hide-scrollbars", f"--window-size={args.size}"):
            options.add_argument(a)
        driver = webdriver.Chrome(service=Service(chromedriver), options=options)
        # A metre into the room from the camera, so the room fills most of the page.
        driver.get(url + "?eye=3,1.35,1.5&target=3,3.3,1.25")
        state = lambda: driver.execute_script("return window.fovea ? window.fovea : null")
        wait_for(lambda: (s := state()) and s["state"] == "streaming" and s["framesDrawn"] >= 5, 60,
                 "the page to draw frames of the stream")
        canvas = driver.find_element(By.TAG_NAME, "canvas")
        width, height = canvas.size["width"], canvas.size["height"]

        # The room is drawn (true colour, overlay hidden for the count).
        driver.execute_script("window.fovea.setHud && window.fovea.setHud(false)")
        shot = Screenshot(driver, os.path.join(work, "true-colour.png"))
        drawn = shot.share_not_background()
        print(f"test_viewer: {drawn:.0%} of the page is drawn", flush=True)
        if drawn < 0.35:
            fail(f"only {drawn:.0%} of the page is drawn (screenshot {work}/true-colour.png)")

        # The fovea is denser than the periphery, region by region (points per square degree).
        density = driver.execute_script("return window.fovea.angularDensity()")
        print(f"test_viewer: points per square degree by region: {density}", flush=True)
        if not density or len(density) < 3 or not all(density[i] > density[i + 1] for i in range(len(density) - 1)):
            fail(f"the density does not fall from the fovea outwards: {density}")

        def gaze_to(px, py):
            """Moves the cursor to canvas pixel (px, py); returns the gaze direction the page sent."""
            before = (state()["lastGazeSent"] or {}).get("t")
            ActionChains(driver).move_to_element_with_offset(canvas, int(px - width / 2), int(py - height / 2)).perform()
            # The page sends at most gaze_hz samples a second: wait for the one after the move.
            sent = wait_for(lambda: (g := state()["lastGazeSent"]) and g.get("t") != before and g, 5,
                            "the page to send the gaze")
            return sent["direction"]

        def robot_turns_to(direction):
            def turned():
                stats = state()["lastStats"] or {}
                robot_dir = (stats.get("robot") or {}).get("gaze_direction")
                return robot_dir and angle_deg(robot_dir, direction) < 1.0
            wait_for(turned, 10, "the robot's status to report the new gaze")

        def fovea_at(px, py, label):
            # Region colours: region 0's pixels gather around the cursor.
            def near():
                s = Screenshot(driver)
                c = s.centroid_of(REGION0)
                return c if c and math.hypot(c[0] - px, c[1] - py) < 0.06 * width else None
            c = wait_for(near, 10, f"region 0's pixels around the cursor at {label}")
            print(f"test_viewer: fovea at ({c[0]:.0f}, {c[1]:.0f}), cursor at ({px:.0f}, {py:.0f}) [{label}]", flush=True)
            return c

        driver.execute_script("window.fovea.setRegionColours(true)")
        points = [(0.5 * width, 0.45 * height), (0.3 * width, 0.62 * height), (0.68 * width, 0.3 * height)]
        robot_turns_to(gaze_to(*points[0]))
        first = fovea_at(*points[0], "before the move")
        robot_turns_to(gaze_to(*points[1]))
        second = fovea_at(*points[1], "after the move")
        if math.hypot(second[0] - first[0], second[1] - first[1]) < 0.15 * width:
            fail(f"the fovea did not move with the cursor: {first} then {second}")

        # Two more tabs: one that views, one that sends garbage; both counted, the stream unaffected.
        main_tab = driver.current_window_handle
        driver.switch_to.new_window("tab")
        driver.get(url)
        wait_for(lambda: (s := state()) and s["framesDrawn"] >= 2, 60, "the second tab to draw frames")
        driver.execute_script(
            "const ws = new WebSocket(location.href.replace(/^http/, 'ws').replace(/\\/[^/]*$/, '/ws'));"
            "ws.onopen = () => { ws.send('not json'); ws.send('{\"type\":\"gaze\",\"origin\":[0,0]}');"
            " ws.send(new Uint8Array([1, 2, 3])); setTimeout(() => ws.close(), 300); };")
        time.sleep(1.0)
        driver.close()
        driver.switch_to.window(main_tab)
        frames_before = state()["framesDrawn"]
        wait_for(lambda: state()["framesDrawn"] > frames_before + 5, 20, "the first tab to keep drawing")

        # The loop's latency: the page times each cursor move to the moved fovea drawn.
        driver.execute_script("window.fovea.moveLatenciesMs.length = 0")
        for i in range(args.moves):
            gaze_to(*points[i % 2 + 1])
            time.sleep(0.9)
        latencies = driver.execute_script("return window.fovea.moveLatenciesMs.slice()")
        abandoned = driver.execute_script("return window.fovea.movesAbandoned")
        render_fps = []
        for _ in range(3):
            time.sleep(1.0)
            render_fps.append(state()["renderFps"])
        if len(latencies) < args.moves // 2:
            fail(f"only {len(latencies)} of {args.moves} moves reached the fovea ({abandoned} abandoned)")
        figures = {
            "moves": args.moves,
            "moves_timed": len(latencies),
            "move_to_fovea_ms": {"median": statistics.median(latencies), "p99": quantile(latencies, 0.99),
                                 "min": min(latencies), "max": max(latencies)},
            "page_fps": statistics.median(render_fps),
            "stream": state()["lastStats"],
            "drawn_share": drawn,
            "density_per_deg2": density,
            "window": args.size,
        }
        print(f"test_viewer: cursor move to moved fovea drawn: median {figures['move_to_fovea_ms']['median']:.0f} ms, "
              f"p99 {figures['move_to_fovea_ms']['p99']:.0f} ms over {len(latencies)} moves; "
              f"page {figures['page_fps']:.1f} fps", flush=True)

        if args.screenshots:
            os.makedirs(args.screenshots, exist_ok=True)
            driver.execute_script("window.fovea.setHud && window.fovea.setHud(true)")
            gaze_to(*points[0])
            time.sleep(1.5)
            driver.execute_script("window.fovea.setRegionColours(false)")
            time.sleep(1.0)
            Screenshot(driver, os.path.join(args.screenshots, "viewer-true-colour.png"))
            driver.execute_script("window.fovea.setRegionColours(true)")
            time.sleep(1.0)
            Screenshot(driver, os.path.join(args.screenshots, "viewer-regions.png"))
            print(f"test_viewer: screenshots in {args.screenshots}", flush=True)

        driver.quit()
        driver = None
        op.send_signal(signal.SIGTERM)
        op.wait(timeout=30 * time_scale())
        with open(summary, encoding="utf-8") as f:
            result = json.load(f)
        viewer = result.get("viewer", {})
        print(f"test_viewer: operator summary: {result.get('frames')} frames, viewer {viewer}", flush=True)
        if viewer.get("tabs_served", 0) < 3 or viewer.get("malformed", 0) < 3:
            fail(f"the operator did not count the tabs (3) and malformed messages (3): {viewer}")
        if result.get("datagrams_invalid", 1) != 0 or result.get("sessions") != 1:
            fail(f"the UDP session was disturbed: {result}")
        figures["operator_summary"] = result
        if args.report:
            with open(args.report, "w", encoding="utf-8") as f:
                json.dump(figures, f, indent=2)
        print("test_viewer: passed", flush=True)
        return 0
    finally:
        if driver is not None:
            driver.quit()
        for p in reversed(processes):
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
                try:
                    p.wait(timeout=20)
                except subprocess.TimeoutExpired:
                    p.kill()
        if os.environ.get("FOVEA_KEEP_TEST_DIR"):
            print(f"test_viewer: logs in {work}")
        else:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
