// SPDX-License-Identifier: Apache-2.0
// Browser test of `plumb monitor` (ctest: monitor_browser, label monitor).
//
//   node monitor_browser_test.mjs --plumb PLUMB --fixture FIXTURE --work DIR
//
// 1. FIXTURE writes a scan (DIR/scan/session.lcm: heartbeats + 8 fragments 0.4 s apart) and the
//    backend's output for it (DIR/scan/backend: pose_graph.json with loops, layout.json).
// 2. `plumb monitor --log session.lcm --dir backend --port 0 --token T` replays it in real time.
// 3. Headless Chromium (/usr/bin/chromium, driven by playwright-core) opens the page and waits
//    until all fragments, their outlines and provisional odometry edges are in the DOM; then the
//    test writes the backend's pose_graph.json and the loop edges must appear without a reload
//    (server-sent events).
// 4. Without the token, or with a wrong one, every request is refused and the page says "token
//    required". A screenshot is saved to DIR/monitor.png.
// 5. `plumb monitor --dir backend` reads "watching folder", then "finished" (not a green "live")
//    once the folder's metrics.json says the run is complete (DIR/monitor-folder.png).
// Exit 0 on success, 1 on failure, 77 (ctest skip) when Chromium or playwright-core is missing
// outside CI; under CI=true a missing browser is a failure.
import { spawn, spawnSync } from "node:child_process";
import fs from "node:fs";
import path from "node:path";
import readline from "node:readline";

import { CHROMIUM, harness } from "./harness.mjs";

const TOKEN = "browser-test-token";
const FRAGMENTS = 8;

const { arg, fail, loadChromium } = harness("monitor_browser");

const plumb = arg("--plumb");
const fixture = arg("--fixture");
const work = arg("--work");
fs.rmSync(work, { recursive: true, force: true });
fs.mkdirSync(work, { recursive: true });

const chromium = await loadChromium();

const scan = path.join(work, "scan");
const made = spawnSync(fixture, [scan, "--fragments", String(FRAGMENTS), "--interval", "0.4"], { encoding: "utf8" });
if (made.status !== 0) fail("fixture: " + made.stderr + made.stdout);
console.log("monitor_browser: " + made.stdout.trim());
// The backend's pose graph is held back and written while the page is open: its loop edges must
// then appear without a reload (deterministic proof of the in-place updates).
const graphFile = path.join(scan, "backend", "pose_graph.json");
const heldGraph = path.join(scan, "pose_graph.json.held");
fs.renameSync(graphFile, heldGraph);

const monitor = spawn(plumb, ["monitor", "--log", path.join(scan, "session.lcm"), "--speed", "1",
                              "--dir", path.join(scan, "backend"), "--port", "0", "--token", TOKEN],
                      { stdio: ["ignore", "pipe", "inherit"] });
let monitorExit = null;
monitor.on("exit", (code, signal) => { monitorExit = { code, signal }; });

let browser = null;
let page = null;
async function cleanup() {
  if (browser) await browser.close().catch(() => {});
  if (monitorExit === null) {
    monitor.kill("SIGTERM");
    await new Promise((resolve) => { if (monitorExit !== null) resolve(); else monitor.on("exit", resolve); });
  }
}

try {
  const url = await new Promise((resolve, reject) => {
    const timer = setTimeout(() => reject(new Error("plumb monitor printed no URL within 30 s")), 30000);
    const lines = readline.createInterface({ input: monitor.stdout });
    lines.on("line", (line) => {
      if (line.includes(TOKEN)) reject(new Error("plumb monitor printed its token: " + line));
      const m = line.match(/serving (http:\/\/\S+)/);
      if (m) { clearTimeout(timer); resolve(m[1] + "?token=" + TOKEN); }  // we know the token
    });
    monitor.on("exit", (code) => reject(new Error("plumb monitor exited with " + code)));
  });
  console.log("monitor_browser: page " + url.replace(TOKEN, "<token>"));

  browser = await chromium.launch({
    executablePath: CHROMIUM,
    headless: true,
    args: ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
           "--disable-background-networking", "--disable-component-update", "--disable-sync",
           "--disable-dev-shm-usage"],
  });
  page = await browser.newPage({ viewport: { width: 1400, height: 900 } });
  const external = [];
  page.on("request", (req) => { if (!req.url().startsWith("http://127.0.0.1")) external.push(req.url()); });
  const consoleErrors = [];
  page.on("console", (msg) => { if (msg.type() === "error") consoleErrors.push(msg.text()); });
  page.on("pageerror", (err) => consoleErrors.push(String(err)));

  // Without the token every request is refused: the API, the page and its files.
  for (const p of ["/api/state", "/", "/monitor.js", "/monitor.css"]) {
    const denied = await page.request.get(new URL(p, url).toString());
    if (denied.status() !== 401) throw new Error("GET " + p + " without the token gave " + denied.status());
  }

  await page.goto(url);
  const initial = await page.locator("#fragment-list tr.fragment").count();
  let navigations = 0;
  page.on("framenavigated", () => { navigations += 1; });

  // The replayed fragments arrive with provisional odometry edges (no pose graph yet).
  await page.waitForFunction((n) =>
    document.querySelectorAll("#fragment-list tr.fragment").length >= n &&
    document.querySelectorAll("#map polygon.fragment-outline").length >= n &&
    document.querySelectorAll("#map line.edge.odometry").length >= n - 1 &&
    document.querySelector("#map polygon.room") !== null &&
    /^replay/.test(document.getElementById("connection").textContent),
    FRAGMENTS, { timeout: 120000, polling: 100 });
  const before = await page.locator("#map line.edge.loop").count();
  if (before !== 0) fail("loop edges before the pose graph was written: " + before);

  // The backend writes its pose graph: the loops must appear through the open page.
  fs.copyFileSync(heldGraph, graphFile + ".tmp");
  fs.renameSync(graphFile + ".tmp", graphFile);
  await page.waitForFunction(() => document.querySelectorAll("#map line.edge.loop").length >= 2,
                             null, { timeout: 30000, polling: 100 });

  const counts = await page.evaluate(() => ({
    fragments: document.querySelectorAll("#fragment-list tr.fragment").length,
    outlines: document.querySelectorAll("#map polygon.fragment-outline").length,
    odometry: document.querySelectorAll("#map line.edge.odometry").length,
    loops: document.querySelectorAll("#map line.edge.loop").length,
    pruned: document.querySelectorAll("#map line.edge.pruned").length,
    edgeRows: document.querySelectorAll("#edge-list tr.edge").length,
    gaps: document.querySelectorAll("#map rect.gap").length,
    tracking: document.querySelector("#device dd") ? document.querySelector("#device dd").textContent : "",
    version: Number(document.body.dataset.version),
  }));
  console.log("monitor_browser: initial fragments " + initial + ", final " + JSON.stringify(counts) +
              ", navigations after load " + navigations);
  if (counts.fragments !== FRAGMENTS) fail("expected " + FRAGMENTS + " fragment rows, saw " + counts.fragments);
  if (counts.odometry !== FRAGMENTS - 1) fail("expected " + (FRAGMENTS - 1) + " odometry edges, saw " + counts.odometry);
  if (counts.loops !== 2 || counts.pruned !== 1) fail("expected 2 loop edges (1 pruned), saw " + counts.loops + "/" + counts.pruned);
  if (counts.tracking !== "ok") fail("device panel shows tracking '" + counts.tracking + "'");
  if (navigations !== 0) fail("the page reloaded instead of updating in place");
  if (external.length) fail("the page requested other origins: " + external.join(", "));
  if (consoleErrors.length) fail("console errors: " + consoleErrors.join(" | "));

  // The loop edge's colour follows its weight: the kept loop (0.9) is green, the pruned one grey.
  const loopColours = await page.evaluate(() =>
    [...document.querySelectorAll("#map line.edge.loop")].map((e) => e.getAttribute("stroke")));
  if (!loopColours.some((c) => c.startsWith("hsl(108"))) fail("loop edge colours " + loopColours.join(", "));

  // A replayed log is not "live": the badge names what is shown.
  const badge = await page.locator("#connection").textContent();
  if (badge !== "replaying" && badge !== "replay finished") fail("connection badge of a replay reads '" + badge + "'");

  // Without the token, or with a wrong one, the page says "token required" (not "reconnecting")
  // and shows nothing of the scan.
  for (const [address, says] of [[url.replace("?token=" + TOKEN, ""), "add ?token="],
                                 [url.replace(TOKEN, "wrong-token"), "the token in the address is wrong"]]) {
    const bare = await browser.newPage();
    await bare.goto(address);
    await bare.waitForFunction(() => document.getElementById("connection") !== null &&
                               document.getElementById("connection").textContent.startsWith("token required"),
                               null, { timeout: 30000, polling: 100 });
    const text = await bare.locator("#connection").textContent();
    if (!text.includes(says)) throw new Error("the page without the right token says '" + text + "'");
    if (await bare.locator("#fragment-list tr.fragment").count() !== 0) fail("the page without the token shows fragments");
    await bare.close();
  }

  const shot = path.join(work, "monitor.png");
  await page.screenshot({ path: shot, fullPage: true });
  const size = fs.statSync(shot).size;
  if (size < 10000) fail("screenshot is only " + size + " bytes");
  console.log("monitor_browser: screenshot " + shot + " (" + size + " bytes)");

  // A folder under review: "watching folder" while the run writes it, "finished" (never a green
  // "live") once its metrics.json says the run is complete.
  const folder = path.join(scan, "backend");
  const review = spawn(plumb, ["monitor", "--dir", folder, "--port", "0"], { stdio: ["ignore", "pipe", "inherit"] });
  let reviewExit = null;
  review.on("exit", (code, signal) => { reviewExit = { code, signal }; });
  try {
    const reviewUrl = await new Promise((resolve, reject) => {
      const timer = setTimeout(() => reject(new Error("plumb monitor --dir printed no URL within 30 s")), 30000);
      readline.createInterface({ input: review.stdout }).on("line", (line) => {
        const m = line.match(/serving (http:\/\/\S+)/);
        if (m) { clearTimeout(timer); resolve(m[1]); }
      });
      review.on("exit", (code) => reject(new Error("plumb monitor --dir exited with " + code)));
    });
    const folderPage = await browser.newPage();
    await folderPage.goto(reviewUrl);
    const badgeIs = (text) => folderPage.waitForFunction((t) => document.getElementById("connection").textContent === t,
                                                         text, { timeout: 30000, polling: 100 });
    await badgeIs("watching folder");
    fs.writeFileSync(path.join(folder, "metrics.json.tmp"), JSON.stringify({ format: "plumb-metrics-1", status: "complete" }));
    fs.renameSync(path.join(folder, "metrics.json.tmp"), path.join(folder, "metrics.json"));
    await badgeIs("finished");
    const cls = await folderPage.locator("#connection").getAttribute("class");
    if (cls.includes("good")) throw new Error("a finished folder's badge is green: class '" + cls + "'");
    await folderPage.screenshot({ path: path.join(work, "monitor-folder.png") });
    await folderPage.close();
  } finally {
    if (reviewExit === null) {
      review.kill("SIGTERM");
      await new Promise((resolve) => { if (reviewExit !== null) resolve(); else review.on("exit", resolve); });
    }
  }
  if (!reviewExit || reviewExit.code !== 0) fail("plumb monitor --dir did not stop cleanly: " + JSON.stringify(reviewExit));
  console.log("monitor_browser: a finished folder reads 'finished'");

  await cleanup();
  if (!monitorExit || monitorExit.code !== 0) fail("plumb monitor did not stop cleanly: " + JSON.stringify(monitorExit));
  console.log("1 passed, 0 failed");
  process.exit(0);
} catch (err) {
  // Say what the page showed when a wait gave up, so a failure can be told apart from slowness.
  let shown = "";
  try {
    shown = "\npage: " + JSON.stringify(await page.evaluate(() => ({
      fragments: document.querySelectorAll("#fragment-list tr.fragment").length,
      outlines: document.querySelectorAll("#map polygon.fragment-outline").length,
      odometry: document.querySelectorAll("#map line.edge.odometry").length,
      loops: document.querySelectorAll("#map line.edge.loop").length,
      room: document.querySelector("#map polygon.room") !== null,
      connection: document.getElementById("connection").textContent,
      version: Number(document.body.dataset.version),
    })));
  } catch (e) {
    shown = "\npage state unavailable: " + String(e);
  }
  await cleanup();
  fail((err && err.stack ? err.stack : String(err)) + shown);
}
