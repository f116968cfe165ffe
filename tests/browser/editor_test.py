#!/usr/bin/env python3
"""The editor in a real browser: Debian's chromium driven by chromedriver over WebDriver.

Loads the page on the demo bar, selects the ends with box drags, drags the handle's gizmo with
pointer events, and checks by screenshot that the handle moved on screen; then saves the edit,
deforms the bar with the CLI under the saved spec and checks that it gives the shape the page
showed. Also measures the page while dragging (frame times, solver updates, round trips).
Then: a box over the bar seen end-on takes only its near end (the visible surface, the page's
default, said in the toolbar) and with X-ray on the whole bar; saving over a file the editor
did not write asks first (declined: the file is kept; accepted: replaced, its mode kept); a
box that catches nothing is not kept and the page says so; the help opens and closes, the legend
shows the strain's scale with Strain; at 1280 px the toolbar keeps its two rows whole; and the
server's log (stderr) says what it did and refused nothing the page asked for, its icon too.

Standard library only (WebDriver is JSON over HTTP; the screenshots are PNGs decoded here).

    RIGIDCELLS_BIN=target/release/rigidcells python3 tests/browser/editor_test.py \
        [--screenshot docs/editor.png] [--help-screenshot docs/editor_help.png]
        [--figures figures.json] [--input FILE --cells N]
"""

import argparse
import base64
import json
import os
import socket
import struct
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
import zlib


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Driver:
    """A minimal W3C WebDriver client."""

    def __init__(self, port):
        self.base = f"http://127.0.0.1:{port}"
        caps = {
            "capabilities": {
                "alwaysMatch": {
                    "browserName": "chrome",
                    "goog:chromeOptions": {
                        "binary": "/usr/bin/chromium",
                        "args": [
                            "--headless=new",
                            "--no-sandbox",
                            "--enable-unsafe-swiftshader",
                            "--use-angle=swiftshader",
                            "--window-size=1200,800",
                            "--force-device-scale-factor=1",
                        ],
                    },
                }
            }
        }
        self.session = self.call("POST", "/session", caps)["sessionId"]

    def call(self, method, path, body=None):
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(
            self.base + path, data=data, method=method, headers={"Content-Type": "application/json"}
        )
        with urllib.request.urlopen(req, timeout=120) as r:
            return json.loads(r.read())["value"]

    def s(self, method, path, body=None):
        return self.call(method, f"/session/{self.session}{path}", body)

    def js(self, script, *args):
        return self.s("POST", "/execute/sync", {"script": script, "args": list(args)})

    def wait(self, script, timeout=60):
        end = time.time() + timeout
        while time.time() < end:
            v = self.js(script)
            if v:
                return v
            time.sleep(0.05)
        raise AssertionError(f"timed out waiting for: {script}")

    def click(self, element_id):
        el = self.s("POST", "/element", {"using": "css selector", "value": f"#{element_id}"})
        key = next(iter(el))
        self.s("POST", f"/element/{el[key]}/click", {})

    def type_into(self, element_id, text):
        el = self.s("POST", "/element", {"using": "css selector", "value": f"#{element_id}"})
        key = next(iter(el))
        self.s("POST", f"/element/{el[key]}/clear", {})
        self.s("POST", f"/element/{el[key]}/value", {"text": text})

    def drag(self, path, step_ms=30):
        """A left-button drag along `path` (viewport CSS pixels), one pointer move per point."""
        x0, y0 = path[0]
        actions = [{"type": "pointerMove", "duration": 0, "x": int(x0), "y": int(y0)},
                   {"type": "pointerDown", "button": 0}]
        for x, y in path[1:]:
            actions.append({"type": "pointerMove", "duration": step_ms, "x": int(x), "y": int(y)})
        actions.append({"type": "pointerUp", "button": 0})
        self.s("POST", "/actions", {"actions": [
            {"type": "pointer", "id": "mouse", "parameters": {"pointerType": "mouse"}, "actions": actions}]})
        self.s("DELETE", "/actions")

    def alert_text(self, timeout=30):
        """The text of the open alert or confirm dialog, waiting for one."""
        end = time.time() + timeout
        while time.time() < end:
            try:
                return self.s("GET", "/alert/text")
            except urllib.error.HTTPError:
                time.sleep(0.05)
        raise AssertionError("no dialog opened")

    def screenshot(self):
        return base64.b64decode(self.s("GET", "/screenshot"))

    def quit(self):
        try:
            self.s("DELETE", "")
        except Exception:
            pass


def decode_png(data):
    """RGB(A) 8-bit PNG → (width, height, channels, rows of bytes)."""
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    at, idat, width = 8, b"", 0
    while at < len(data):
        (n,) = struct.unpack(">I", data[at:at + 4])
        kind, body = data[at + 4:at + 8], data[at + 8:at + 8 + n]
        if kind == b"IHDR":
            width, height, depth, color = struct.unpack(">IIBB", body[:10])
            assert depth == 8 and color in (2, 6), (depth, color)
            channels = 3 if color == 2 else 4
        elif kind == b"IDAT":
            idat += body
        at += 12 + n
    raw, stride, rows, prev = zlib.decompress(idat), width * channels, [], bytearray(width * channels)
    for y in range(height):
        f, line = raw[y * (stride + 1)], bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for i in range(stride):
            a = line[i - channels] if i >= channels else 0
            b, c = prev[i], prev[i - channels] if i >= channels else 0
            if f == 1:
                line[i] = (line[i] + a) & 255
            elif f == 2:
                line[i] = (line[i] + b) & 255
            elif f == 3:
                line[i] = (line[i] + (a + b) // 2) & 255
            elif f == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        rows.append(bytes(line))
        prev = line
    return width, height, channels, rows


def top_of_shape(png, x_lo, x_hi, y_lo, y_hi):
    """The topmost row in the window whose pixels differ from the background (32, 35, 42)."""
    w, h, ch, rows = decode_png(png)
    for y in range(max(0, y_lo), min(h, y_hi)):
        row = rows[y]
        for x in range(max(0, x_lo), min(w, x_hi)):
            r, g, b = row[x * ch:x * ch + 3]
            if abs(r - 32) + abs(g - 35) + abs(b - 42) > 60 and not (r > 200 and g > 200 and b < 100):
                return y
    return None


def read_ply_vertices(path):
    """x, y, z of a PLY's vertices (ascii or binary little endian)."""
    data = open(path, "rb").read()
    end = data.index(b"end_header") + len(b"end_header")
    end = data.index(b"\n", end) + 1
    header = data[:end].decode().splitlines()
    fmt = header[1].split()[1]
    types = {"float": "f", "float32": "f", "double": "d", "float64": "d", "uchar": "B", "uint8": "B",
             "char": "b", "int8": "b", "short": "h", "int16": "h", "ushort": "H", "uint16": "H",
             "int": "i", "int32": "i", "uint": "I", "uint32": "I"}
    props, count, element = [], 0, None
    for line in header:
        w = line.split()
        if w[0] == "element":
            element = w[1]
            if element == "vertex":
                count = int(w[2])
        elif w[0] == "property" and element == "vertex":
            props.append((w[-1], types[w[1]]))
    names = [p[0] for p in props]
    ix = [names.index(a) for a in "xyz"]
    if fmt == "ascii":
        lines = data[end:].decode().splitlines()[:count]
        return [[float(l.split()[i]) for i in ix] for l in lines]
    rec = struct.Struct("<" + "".join(p[1] for p in props))
    return [[v[i] for i in ix] for v in (rec.unpack_from(data, end + k * rec.size) for k in range(count))]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--screenshot", help="write the page after the drag here (the README's)")
    ap.add_argument("--figures", help="write the measured figures here (JSON)")
    ap.add_argument("--help-screenshot", help="write the page with its help open here (the README's)")
    ap.add_argument("--input", help="measure on this file instead (no shape checks): fix its west tenth, "
                    "drag its east tenth")
    ap.add_argument("--cells", default="5000", help="with --input: about this many cells")
    args = ap.parse_args()
    binary = os.environ.get("RIGIDCELLS_BIN", "target/release/rigidcells")
    work = tempfile.mkdtemp(prefix="rigidcells-browser-")
    if args.input:
        bar, cells = args.input, ["--cells", args.cells]
    else:
        subprocess.run([binary, "demo", "--out", work, "-q"], check=True)
        bar, cells = os.path.join(work, "bar.ply"), ["--cell-size", "0.5"]
    port = free_port()
    started = time.time()
    # The server's log (what it says on stderr without -q), read at the end.
    log = open(os.path.join(work, "editor.log"), "w+")
    editor = subprocess.Popen([binary, "edit", bar, *cells, "--port", str(port)],
                              stdout=subprocess.PIPE, stderr=log, text=True)
    driver_port = free_port()
    chromedriver = subprocess.Popen(["chromedriver", f"--port={driver_port}"],
                                    stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    driver = None
    try:
        url = editor.stdout.readline().strip()
        assert url.startswith(f"http://127.0.0.1:{port}/?t="), url
        for _ in range(100):
            try:
                urllib.request.urlopen(f"http://127.0.0.1:{driver_port}/status", timeout=1)
                break
            except Exception:
                time.sleep(0.1)
        driver = Driver(driver_port)
        served = time.time() - started
        driver.s("POST", "/url", {"url": url})
        driver.wait("return window.rc && window.rc.ready", timeout=300)
        loaded = time.time() - started

        def box_around(lo, hi):
            corners = [driver.js("return rc.screenOf(arguments[0])", [x, y, z])
                       for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
            xs, ys = [c[0] for c in corners], [c[1] for c in corners]
            w, h = driver.js("return [innerWidth, innerHeight]")
            cx = lambda x: min(max(x, 2), w - 2)
            cy = lambda y: min(max(y, 70), h - 30)
            return (cx(min(xs)), cy(min(ys))), (cx(max(xs)), cy(max(ys)))

        # The demo bar is 10 × 1 × 1, centered on the wire at the origin; another input's west
        # and east tenths along x.
        st = driver.js("return rc.state()")
        lo, hi = st["lo"], st["hi"]
        pad = [0.3 * (hi[a] - lo[a]) + 1e-9 for a in range(3)]
        tenth = 0.1 * (hi[0] - lo[0])
        west = ([lo[0] - pad[0], lo[1] - pad[1], lo[2] - pad[2]], [lo[0] + tenth, hi[1] + pad[1], hi[2] + pad[2]])
        east = ([hi[0] - tenth, lo[1] - pad[1], lo[2] - pad[2]], [hi[0] + pad[0], hi[1] + pad[1], hi[2] + pad[2]])
        if args.input:
            # From above, so that a box on the screen is a box on the ground.
            driver.js("rc.look(-90, 89.9)")
            time.sleep(0.5)
        else:
            west, east = ([-5.3, -0.8, -0.8], [-4.7, 0.8, 0.8]), ([4.7, -0.8, -0.8], [5.3, 0.8, 0.8])
        driver.click("m-box")
        (x0, y0), (x1, y1) = box_around(*west)
        driver.drag([(x0, y0), (x1, y0 + 5), (x1, y1)])
        driver.js("document.getElementById('role').value = 'handle'")
        (x0, y0), (x1, y1) = box_around(*east)
        driver.drag([(x0, y0), (x1, y0 + 5), (x1, y1)])
        state = driver.wait("const s = rc.state(); return rc.updates >= 1 && "
                            "s.edit.handles.length === 1 && s.edit.fixed.length === 1 && s", timeout=300)
        assert len(state["edit"]["fixed"]) == 1 and len(state["edit"]["handles"]) == 1, state
        before = driver.screenshot()

        # Drag the gizmo's z axis up, in 20 pointer moves.
        g = driver.wait("return rc.gizmo()")
        (cx, cy), (zx, zy) = g["center"], g["axes"][2]
        grab = (cx + 0.6 * (zx - cx), cy + 0.6 * (zy - cy))
        updates0 = driver.js("return rc.updates")
        driver.js("rc.sync = true; rc.frameTimes.length = 0; rc.roundTrips.length = 0")
        start = time.time()
        path = [(grab[0], grab[1] - 6 * k) for k in range(21)]
        driver.drag(path, step_ms=50)
        dragging = time.time() - start
        driver.wait("return rc.released >= 1 && rc.state().display === 2", timeout=300)
        stats = driver.js("return {frames: rc.frameTimes.slice(), trips: rc.roundTrips.slice(), updates: rc.updates}")
        after = driver.screenshot()
        if args.screenshot:
            open(args.screenshot, "wb").write(after)

        frames = sorted(stats["frames"])
        figures = {
            "input": bar,
            "samples_shown": state["N"],
            "url_printed_s": served,
            "page_ready_s": loaded,
            "drag_seconds": dragging,
            "solver_updates_during_drag": stats["updates"] - updates0,
            "frames_drawn_during_drag": len(frames),
            "frame_ms_median": frames[len(frames) // 2] if frames else None,
            "round_trip_ms": sorted(round(t, 1) for t in stats["trips"]),
        }
        if args.input:
            print(json.dumps(figures))
            if args.figures:
                json.dump(figures, open(args.figures, "w"), indent=1)
            return
        # On screen: the right end went up, the left end stayed.
        right = (int(x0) - 10, int(x1) + 10)
        lo_before = top_of_shape(before, *right, 60, 780)
        lo_after = top_of_shape(after, *right, 60, 780)
        left_x = box_around(*west)
        left = (int(left_x[0][0]), int(left_x[1][0]))
        assert lo_before is not None and lo_after is not None, (lo_before, lo_after)
        assert lo_after < lo_before - 40, f"the handle's top went from row {lo_before} to {lo_after}"
        assert top_of_shape(before, *left, 60, 780) == top_of_shape(after, *left, 60, 780)

        # Saved (a plain name, into the bar's folder), and the CLI deforms the bar to what the
        # page showed: the selections are of the visible surface, as the page's default.
        spec = os.path.join(work, "bar.edit.toml")
        driver.type_into("spec-path", "bar.edit.toml")
        driver.click("save")
        driver.wait("return rc.messages.some((m) => m.type === 'saved')")
        assert open(spec).read().count("visible = true") == 2, open(spec).read()
        shown = driver.js("return Array.from(rc.final)")
        out = os.path.join(work, "bent.ply")
        subprocess.run([binary, "deform", bar, "-o", out, "--edit", spec, "--cell-size", "0.5", "-q"],
                       check=True)
        cli = read_ply_vertices(out)
        rest = read_ply_vertices(bar)
        lo = [min(v[a] for v in rest) for a in range(3)]
        hi = [max(v[a] for v in rest) for a in range(3)]
        c = [(lo[a] + hi[a]) / 2 for a in range(3)]
        assert len(cli) * 3 == len(shown), (len(cli), len(shown))
        worst = max(abs(cli[i][a] - c[a] - shown[3 * i + a]) for i in range(len(cli)) for a in range(3))
        moved = max(abs(cli[i][a] - rest[i][a]) for i in range(len(cli)) for a in range(3))
        assert moved > 0.5, f"the CLI's bar moved only {moved}"
        assert worst < 1e-3, f"the CLI's shape lies {worst} from the page's"

        figures["cli_vs_page_max"] = worst
        figures["handle_top_rows"] = [lo_before, lo_after]

        # Visible by default, x-ray on demand: the bar end-on from +x, a box over all of it.
        assert driver.js("return rc.xray()") is False
        assert "visible" in driver.js("return document.getElementById('select-mode').textContent")
        n = driver.js("return rc.state().N")
        driver.click("clear")
        driver.js("document.getElementById('role').value = 'fixed'")
        driver.js("rc.look(0, 0)")
        time.sleep(0.3)
        driver.click("m-box")

        def box_count():
            (x0, y0), (x1, y1) = box_around([-5.3, -0.8, -0.8], [5.3, 0.8, 0.8])
            driver.drag([(x0 - 5, y0 - 5), (x1 + 5, y0), (x1 + 5, y1 + 5)])
            driver.wait("return rc.state().edit.fixed.length === 1")
            return driver.wait("const c = rc.selectedCounts(); return c && c.fixed > 0 && c")["fixed"]

        visible = box_count()
        assert driver.js("return rc.state().edit.fixed[0].visible") is True
        assert visible < n / 4, f"the visible near end is {visible} of {n} samples"
        driver.click("clear")
        driver.click("xray")
        assert "x-ray" in driver.js("return document.getElementById('select-mode').textContent")
        through = box_count()
        assert driver.js("return rc.state().edit.fixed[0].visible") is None
        assert through == n, f"x-ray took {through} of {n} samples"
        figures["end_on_box_visible_xray"] = [visible, through]

        # Saving over a file this editor did not write asks first.
        mine = os.path.join(work, "mine.toml")
        open(mine, "w").write("mine")
        os.chmod(mine, 0o600)
        driver.type_into("spec-path", "mine.toml")
        driver.click("save")
        assert "mine.toml" in driver.alert_text()
        driver.s("POST", "/alert/dismiss", {})
        driver.wait("return document.getElementById('status').textContent.startsWith('not replaced')")
        assert open(mine).read() == "mine"
        driver.click("save")
        driver.alert_text()
        driver.s("POST", "/alert/accept", {})
        driver.wait("return rc.messages.some((m) => m.type === 'saved' && m.name === 'mine.toml')")
        assert open(mine).read().startswith("# rigidcells edit")
        assert os.stat(mine).st_mode & 0o777 == 0o600, oct(os.stat(mine).st_mode)

        # A box that catches nothing is not kept, and says so; the status says what one caught.
        driver.click("clear")
        driver.wait("return rc.state().edit.fixed.length === 0")
        w, h = driver.js("return [innerWidth, innerHeight]")
        driver.drag([(w - 160, h - 200), (w - 100, h - 195), (w - 60, h - 120)])
        driver.wait("return document.getElementById('warn').textContent.includes('caught no sample')")
        assert driver.js("return rc.state().edit.fixed.length") == 0
        through = box_count()
        caught = driver.wait("const s = document.getElementById('status').textContent; "
                             "return s.includes('samples shown') && s")
        assert f"{n:,} of {n:,} samples shown" in caught, caught

        # Help and the legend: the help opens and closes; the strain scale shows with Strain.
        assert driver.js("return document.getElementById('help').hidden") is True
        driver.click("help-button")
        assert driver.js("return document.getElementById('help').offsetHeight") > 200
        assert "gizmo" in driver.js("return document.getElementById('help').textContent")
        if args.help_screenshot:
            open(args.help_screenshot, "wb").write(driver.screenshot())
        driver.click("help-button")
        assert driver.js("return document.getElementById('help').hidden") is True
        assert driver.js("return document.getElementById('legend').offsetWidth") > 100
        driver.click("strain")
        assert driver.js("return document.getElementById('strain-scale').hidden") is False
        driver.click("strain")

        # At 1280 px the toolbar keeps its two rows, each whole, and the file names room.
        driver.s("POST", "/window/rect", {"width": 1280, "height": 800})
        time.sleep(0.3)
        rows = driver.js("return [...document.querySelectorAll('#bar .row')]"
                         ".map((r) => [r.scrollWidth, r.clientWidth, r.offsetHeight])")
        assert len(rows) == 2 and all(sw <= cw and oh < 40 for sw, cw, oh in rows), rows
        widths = driver.js("return ['spec-path', 'out-path'].map((i) => document.getElementById(i).offsetWidth)")
        assert min(widths) >= 120, widths
        figures["toolbar_rows_at_1280"] = rows

        # The server said what it did, and refused nothing the page asked for (its icon too).
        log.flush()
        log.seek(0)
        said = log.read()
        assert "page loaded" in said and "page connected" in said, said
        assert f"saved {mine}" in said, said
        assert "refused" not in said and "not found" not in said, said
        print(json.dumps(figures))
        if args.figures:
            json.dump(figures, open(args.figures, "w"), indent=1)
        print("browser test: ok")
    finally:
        if driver:
            driver.quit()
        chromedriver.terminate()
        editor.terminate()


if __name__ == "__main__":
    sys.exit(main())
